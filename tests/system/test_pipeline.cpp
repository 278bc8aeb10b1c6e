// End to end: a `poise run` process hosts the simulated serial IMU (pseudo-terminal), the serial
// driver, the synthetic camera and the estimators; this test process subscribes as a separate
// participant and checks every estimate against the simulated truth (matched by IMU seq). The run
// lasts a number of samples (every filter matched to truth kMinCompared times), not a sleep.
#include "poise/demo/monitor.h"
#include "poise/gauss_newton/gauss_newton.h"
#include "poise/sim/sensor_simulator.h"
#include "poise/testing/testing.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <csignal>
#include <fstream>
#include <iomanip>
#include <limits>
#include <map>

namespace poise::testing {
namespace {

using namespace std::chrono_literals;

// Stated bounds (RMS over the run after the start-up, degrees). The scenario is the 30 s `tour`
// (seed 1, 100 Hz): handheld motion, a magnet brought near and an attached magnet, stairs, tag lost.
constexpr double kParallelKfRmseDeg = 3.0;
constexpr double kSelectiveEkfRmseDeg = 3.0;
// Gauss-Newton's oracle is the same core run here on the simulator's own samples (no serial line,
// no DDS), both with the tour's dip configured: the pipeline must give the same errors, sample by
// sample (same seq). What may differ: the
// serial line carries 5 decimals (accelerometer 1e-5 m/s^2 of 9.8, magnetometer 1e-5 uT of ~50: an
// attitude change below 1e-4 deg), so 0.01 deg is two orders above the transport's resolution and
// far below any estimation effect (the baseline's own RMS error is several degrees on the tour).
constexpr double kGaussNewtonSameAsCoreDeg = 0.01;
// The run: every filter matched to truth this many times (20 s at 100 Hz), bounded wait.
constexpr uint64_t kMinCompared = 2000;
constexpr auto kRunTimeout = std::chrono::seconds(90);
constexpr uint64_t kSimSeed = 1;  // sim_imu's default seed
constexpr double kSimRateHz = 100.0;

/// The tour's field dip, deg: both Gauss-Newtons are configured with it, so neither depends on
/// which samples it learnt the dip from (the pipeline's node may start a sample late).
double tour_dip_deg() { return sim::make_scenario("tour", kSimRateHz, kSimSeed).field.dip_deg; }

std::string write_gauss_newton_file() {
  const std::string path = "/tmp/poise-e2e-gn-" + std::to_string(::getpid()) + ".yaml";
  std::ofstream(path) << "gauss_newton:\n  dip_deg: " << std::setprecision(17) << tour_dip_deg() << "\n";
  return path;
}

std::string write_host(const std::string& link, const std::string& gn_file) {
  const std::string path = "/tmp/poise-e2e-" + std::to_string(::getpid()) + ".yaml";
  std::ofstream(path) << "components:\n"
                         "  - {type: sim_imu, params: {link: " << link << ", scenario: tour, rate_hz: 100, seed: 1}}\n"
                         "  - {type: imu_driver, name: imu0, params: {port: " << link << "}}\n"
                         "  - {type: sim_camera, name: camera0, params: {fps: 8, blackouts: [[9, 13]]}}\n"
                         "  - {type: parallel_kf}\n"
                         "  - {type: selective_ekf, params: {q_body_camera: [0, 1, 0, 0]}}\n"
                         "  - {type: gauss_newton, params: {filter_file: " << gn_file << "}}\n"
                         "  - {type: altitude, params: {relative_to_start: true}}\n";
  return path;
}

double rmse(const demo::FilterStats& s) {
  return s.compared ? std::sqrt(s.sum_sq_error / static_cast<double>(s.compared))
                    : std::numeric_limits<double>::quiet_NaN();
}

/// Gauss-Newton's error per IMU seq when the core runs on the simulator's samples in-process.
std::map<uint32_t, double> gauss_newton_errors_in_process(uint32_t last_seq) {
  sim::SimConfig config = sim::make_scenario("tour", kSimRateHz, kSimSeed);
  config.duration_s = 0.0;  // as sim_imu (endless)
  sim::SensorSimulator simulator(config);
  GaussNewtonParams p;
  p.dip_deg = tour_dip_deg();
  GaussNewton gn(p);
  std::map<uint32_t, double> out;
  for (uint32_t seq = 0; seq <= last_seq; ++seq) {
    const sim::SimSample s = simulator.next();
    if (gn.update(s.imu)) {
      out[seq] = quat_angle_between(gn.result().q_world_body, s.truth.q_world_body) * kDegPerRad;
    }
  }
  return out;
}

/// Heights matched to the truth by seq: RMS error of the filter's height and of the raw barometric
/// height it fuses (both relative to the start), m; `n` the samples compared.
struct AltitudeErrors {
  double height_rmse_m = std::numeric_limits<double>::quiet_NaN();
  double baro_rmse_m = std::numeric_limits<double>::quiet_NaN();
  size_t n = 0;
};
AltitudeErrors altitude_errors(const std::vector<demo::AltitudePoint>& estimates,
                               const std::vector<demo::AltitudePoint>& truth) {
  std::map<uint32_t, double> truth_by_seq;
  for (const auto& t : truth) {
    truth_by_seq[t.seq] = t.height_m;
  }
  double sh = 0.0;
  double sb = 0.0;
  AltitudeErrors out;
  for (const auto& e : estimates) {
    const auto it = truth_by_seq.find(e.seq);
    if (it == truth_by_seq.end() || !std::isfinite(e.baro_height_m)) {
      continue;
    }
    sh += (e.height_m - it->second) * (e.height_m - it->second);
    sb += (e.baro_height_m - it->second) * (e.baro_height_m - it->second);
    ++out.n;
  }
  if (out.n > 0) {
    out.height_rmse_m = std::sqrt(sh / static_cast<double>(out.n));
    out.baro_rmse_m = std::sqrt(sb / static_cast<double>(out.n));
  }
  return out;
}

TEST(Pipeline, EstimatesFromAnotherProcessAgreeWithTheSimulatedTruth) {
  DomainLease domain;
  const std::string link = "/tmp/poise-e2e-imu-" + std::to_string(::getpid());
  const std::string gn_file = write_gauss_newton_file();
  const std::string host = write_host(link, gn_file);
  dds::Participant participant({domain.id(), "", "", "e2e_monitor"});
  demo::PipelineMonitor monitor(participant, dds::TopicNames{},
                                {"parallel_kf", "selective_ekf", "gauss_newton"});
  Child pipeline({bin("poise"), "run", host, "--domain", std::to_string(domain.id()), "--quiet"});
  // GIVEN the pipeline runs WHEN every filter has been matched to truth kMinCompared times
  const bool enough = wait_until([&] {
    const auto s = monitor.filter_stats();
    for (const char* f : {"parallel_kf", "selective_ekf", "gauss_newton"}) {
      if (!s.count(f) || s.at(f).compared < kMinCompared) {
        return false;
      }
    }
    return true;
  }, kRunTimeout);
  ASSERT_TRUE(enough) << "pipeline output:\n" << pipeline.output();
  pipeline.signal(SIGINT);
  const auto code = pipeline.wait_for(15s);
  ASSERT_TRUE(code.has_value()) << "poise run did not stop on SIGINT";
  EXPECT_EQ(*code, 0) << pipeline.output();

  // THEN the simulated IMU's $INF line (no delay: its samples are the simulator's at their
  // stamps) reached the filters through the driver's imu_info, so they use 0 and not half a sample
  const std::string out = pipeline.output();
  for (const char* f : {"parallel_kf parallel_kf: ", "selective_ekf selective_ekf: "}) {
    EXPECT_NE(out.find(std::string(f) + "imu_delay_s 0.000000 s (published by the IMU driver: SIM"), std::string::npos)
        << f << "\n" << out;
  }
  // AND the attitude filters stay within their stated bounds
  const auto stats = monitor.filter_stats();
  EXPECT_LT(rmse(stats.at("parallel_kf")), kParallelKfRmseDeg);
  EXPECT_LT(rmse(stats.at("selective_ekf")), kSelectiveEkfRmseDeg);
  // AND Gauss-Newton gives the core's errors on the same samples (seq by seq)
  const auto gn_pipeline = monitor.errors_by_seq().at("gauss_newton");
  ASSERT_FALSE(gn_pipeline.empty());
  const auto gn_core = gauss_newton_errors_in_process(gn_pipeline.rbegin()->first);
  double worst_deg = 0.0;
  size_t matched = 0;
  for (const auto& [seq, e] : gn_pipeline) {
    const auto it = gn_core.find(seq);
    if (it != gn_core.end()) {
      worst_deg = std::max(worst_deg, std::abs(e - it->second));
      ++matched;
    }
  }
  EXPECT_GE(matched, kMinCompared);
  EXPECT_LT(worst_deg, kGaussNewtonSameAsCoreDeg) << "over " << matched << " samples";
  std::printf("gauss_newton: RMSE %.3f deg, largest difference from the in-process core %.2e deg over %zu samples\n",
              rmse(stats.at("gauss_newton")), worst_deg, matched);
  // AND the altitude filter beats the raw barometer it fuses (the oracle: the same run's baro
  // heights against the same truth), on at least kMinCompared / 2 matched samples
  const auto camera = monitor.camera_stats();
  EXPECT_GT(camera.poses, 20U) << "the synthetic camera produced vision poses";
  const auto alt = monitor.altitude_series();
  ASSERT_TRUE(alt.count("altitude") && alt.count("truth"));
  const AltitudeErrors ae = altitude_errors(alt.at("altitude"), alt.at("truth"));
  EXPECT_GE(ae.n, kMinCompared / 2);
  EXPECT_LT(ae.height_rmse_m, ae.baro_rmse_m);
  std::printf("altitude: height RMSE %.3f m, raw barometer %.3f m over %zu samples\n", ae.height_rmse_m,
              ae.baro_rmse_m, ae.n);
  ::unlink(host.c_str());
  ::unlink(gn_file.c_str());
}

}  // namespace
}  // namespace poise::testing
