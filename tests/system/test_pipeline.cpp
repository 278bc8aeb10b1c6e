// End to end: a `poise run` process hosts the simulated serial IMU (pseudo-terminal), the serial
// driver, the synthetic camera and the estimators; this test process subscribes as a separate
// participant and checks every estimate against the simulated truth (matched by IMU seq).
#include "poise/demo/monitor.h"
#include "poise/testing/testing.h"

#include <gtest/gtest.h>

#include <cmath>
#include <csignal>
#include <fstream>
#include <limits>

namespace poise::testing {
namespace {

using namespace std::chrono_literals;

// Stated bounds (RMS over the run after the start-up, degrees / metres). The scenario is the
// 30 s `tour`: handheld motion, a magnet brought near and an attached magnet, stairs, tag lost.
constexpr double kParallelKfRmseDeg = 3.0;
constexpr double kSelectiveEkfRmseDeg = 3.0;
constexpr double kGaussNewtonRmseDeg = 45.0;  // the undisturbed baseline: only checks it runs
constexpr double kRunSeconds = 24.0;

std::string write_host(const std::string& link) {
  const std::string path = "/tmp/poise-e2e-" + std::to_string(::getpid()) + ".yaml";
  std::ofstream(path) << "components:\n"
                         "  - {type: sim_imu, params: {link: " << link << ", scenario: tour, rate_hz: 100}}\n"
                         "  - {type: imu_driver, name: imu0, params: {port: " << link << "}}\n"
                         "  - {type: sim_camera, name: camera0, params: {fps: 8, blackouts: [[9, 13]]}}\n"
                         "  - {type: parallel_kf}\n"
                         "  - {type: selective_ekf, params: {q_body_camera: [0, 1, 0, 0]}}\n"
                         "  - {type: gauss_newton}\n"
                         "  - {type: altitude, params: {relative_to_start: true}}\n";
  return path;
}

double rmse(const demo::FilterStats& s) {
  return s.compared ? std::sqrt(s.sum_sq_error / static_cast<double>(s.compared))
                    : std::numeric_limits<double>::quiet_NaN();
}

TEST(Pipeline, EstimatesFromAnotherProcessAgreeWithTheSimulatedTruth) {
  DomainLease domain;
  const std::string link = "/tmp/poise-e2e-imu-" + std::to_string(::getpid());
  const std::string host = write_host(link);
  dds::Participant participant({domain.id(), "", "", "e2e_monitor"});
  demo::PipelineMonitor monitor(participant, dds::TopicNames{},
                                {"parallel_kf", "selective_ekf", "gauss_newton"});
  Child pipeline({bin("poise"), "run", host, "--domain", std::to_string(domain.id()), "--quiet"});
  // GIVEN the pipeline runs WHEN kRunSeconds have passed THEN every filter has published.
  const bool all_running = wait_until([&] {
    const auto s = monitor.filter_stats();
    return s.count("parallel_kf") && s.count("selective_ekf") && s.count("gauss_newton") &&
           s.count("truth");
  }, 30s);
  ASSERT_TRUE(all_running) << "pipeline output:\n" << pipeline.output();
  sleep_ms(static_cast<int>(kRunSeconds * 1000));
  pipeline.signal(SIGINT);
  const auto code = pipeline.wait_for(15s);
  ASSERT_TRUE(code.has_value()) << "poise run did not stop on SIGINT";
  EXPECT_EQ(*code, 0) << pipeline.output();

  const auto stats = monitor.filter_stats();
  for (const char* f : {"parallel_kf", "selective_ekf", "gauss_newton"}) {
    EXPECT_GT(stats.at(f).compared, 1000U) << f << " estimates matched to truth";
  }
  EXPECT_LT(rmse(stats.at("parallel_kf")), kParallelKfRmseDeg);
  EXPECT_LT(rmse(stats.at("selective_ekf")), kSelectiveEkfRmseDeg);
  EXPECT_LT(rmse(stats.at("gauss_newton")), kGaussNewtonRmseDeg);
  const auto camera = monitor.camera_stats();
  EXPECT_GT(camera.poses, 20U) << "the synthetic camera produced vision poses";
  const auto alt = monitor.altitude_series();
  ASSERT_TRUE(alt.count("altitude") && alt.count("truth"));
  EXPECT_GT(alt.at("altitude").size(), 500U);
  ::unlink(host.c_str());
}

}  // namespace
}  // namespace poise::testing
