#include "poise/simulated/sim_imu.h"
#include "poise/simulated/sim_camera.h"

#include "poise/dds/convert.h"
#include "poise/imu/faults.h"
#include "poise/imu/protocol.h"
#include "poise/imu/pty_link.h"
#include "poise/imu/sensor_info.h"
#include "poise/nodes/imu_estimator_node.h"
#include "poise/nodes/reports.h"

#include <poise/msg/estimatesPubSubTypes.h>

#include <algorithm>
#include <cmath>
#include <ctime>
#include <sstream>

namespace poise::simulated {
namespace {

void sleep_until_ns(int64_t t_ns, const std::atomic<bool>& stop) {
  // Short slices so stop() is honoured quickly.
  while (!stop.load()) {
    const int64_t now = nodes::monotonic_ns();
    if (now >= t_ns) {
      return;
    }
    const int64_t slice = std::min<int64_t>(t_ns - now, 20'000'000);
    timespec ts{};
    ts.tv_sec = static_cast<time_t>(slice / 1'000'000'000);
    ts.tv_nsec = static_cast<long>(slice % 1'000'000'000);
    nanosleep(&ts, nullptr);
  }
}

class SimImu : public runtime::Component {
 public:
  SimImu(const runtime::ComponentSpec& spec, runtime::HostContext& host)
      : params_(sim_imu_params(spec)), name_(spec.name) {
    sim::SimConfig config;
    try {
      config = sim::make_scenario(params_.scenario, params_.rate_hz, params_.seed);
      faults_ = imu::FaultSpec::parse(params_.faults);
    } catch (const std::invalid_argument& e) {
      throw runtime::ConfigError(spec.origin + ": " + e.what());
    }
    config.duration_s = params_.duration_s;
    simulator_ = std::make_unique<sim::SensorSimulator>(config);
    if (params_.publish_truth) {
      attitude_ = std::make_unique<dds::Writer<msg::AttitudeEstimatePubSubType>>(
          host.participant, kTruthAttitudeTopic, dds::QosKind::kEstimate);
      pose_ = std::make_unique<dds::Writer<msg::PoseEstimatePubSubType>>(
          host.participant, kTruthPoseTopic, dds::QosKind::kEstimate);
      altitude_ = std::make_unique<dds::Writer<msg::AltitudeEstimatePubSubType>>(
          host.participant, kTruthAltitudeTopic, dds::QosKind::kEstimate);
    }
    try {
      link_ = std::make_unique<imu::PtyLink>(params_.link);
    } catch (const std::exception& e) {
      throw runtime::ConfigError(spec.origin + ": cannot create the pseudo-terminal at '" +
                                 params_.link + "': " + e.what());
    }
  }

  ~SimImu() override { SimImu::stop(); }

  void start() override {
    if (!thread_.joinable()) {
      thread_ = std::thread([this] { run(); });
    }
  }

  void stop() override {
    stop_.store(true);
    if (thread_.joinable()) {
      thread_.join();
    }
  }

  /// Lines sent, read or not (the service watchdog's health check): stops when the scenario ends.
  [[nodiscard]] std::optional<uint64_t> produced() const override {
    return written_.load() + no_reader_.load() + reader_full_.load();
  }

  [[nodiscard]] std::string status() const override {
    std::ostringstream os;
    os << "lines written " << written_.load() << " (" << params_.rate_hz << " Hz, scenario "
       << params_.scenario << "), without reader " << no_reader_.load() << ", lost to a reader stalled over "
       << imu::kSimulatedBoardWaitMs << " ms " << reader_full_.load();
    return os.str();
  }

 private:
  void run() {
    imu::FaultInjector injector(faults_);
    const auto period_ns = static_cast<int64_t>(std::llround(1e9 / params_.rate_hz));
    const int64_t start_ns = nodes::monotonic_ns();
    const std::string info_line = params_.sensor_info ? imu::simulated_sensor_info_line() : std::string();
    const auto info_every = static_cast<int64_t>(std::max(1.0, std::round(params_.rate_hz)));  // 1 s
    uint32_t seq = 0;
    for (int64_t k = 0; !stop_.load() && !simulator_->done(); ++k) {
      const int64_t t_ns = start_ns + k * period_ns;
      sleep_until_ns(t_ns, stop_);
      if (stop_.load()) {
        break;
      }
      if (!info_line.empty() && k % info_every == 0) {
        (void)link_->write(info_line);  // no reader yet: the next one tells it
      }
      const sim::SimSample s = simulator_->next();
      imu::RawSample line;
      line.seq = seq;
      line.t_us = static_cast<uint32_t>(static_cast<uint64_t>((t_ns - start_ns) / 1000) & 0xFFFFFFFFULL);
      line.accel_mps2 = s.imu.accel_mps2;
      line.gyro_rps = s.imu.gyro_rps;
      line.mag_ut = s.imu.mag_ut;
      line.has_mag = s.imu.has_mag;
      line.has_pressure = s.imu.has_pressure;
      line.pressure_pa = s.imu.pressure_pa;
      line.has_temperature = s.imu.has_temperature;
      line.temperature_c = s.imu.temperature_c;
      const std::string bytes = injector.apply(imu::format_imu_line(line));
      if (!bytes.empty()) {
        switch (link_->write(bytes, imu::kSimulatedBoardWaitMs)) {
          case imu::PtyLink::WriteStatus::kWritten: written_.fetch_add(1); break;
          case imu::PtyLink::WriteStatus::kFull: reader_full_.fetch_add(1); break;
          default: no_reader_.fetch_add(1); break;
        }
      }
      if (params_.publish_truth) {
        publish_truth(s.truth, seq, t_ns);
      }
      ++seq;
    }
  }

  void publish_truth(const sim::Truth& t, uint32_t seq, int64_t stamp_ns) {
    nodes::AttitudeReport r;
    r.stamp_ns = stamp_ns;
    r.seq = seq;
    r.q_world_body = t.q_world_body;
    r.ext_accel_body_mps2 = t.ext_accel_body_mps2;
    r.ext_accel_world_mps2 = t.a_world_mps2;
    r.mag_disturbance_body_ut = t.mag_disturbance_body_ut;
    r.mag_disturbance_world_ut = t.mag_disturbance_world_ut;
    r.mag_trusted = t.mag_disturbance_world_ut.norm() < 1.0;
    r.gyro_bias_rps = t.gyro_bias_rps;
    attitude_->write(nodes::to_attitude_msg(r, name_, "truth"));

    msg::PoseEstimate pose;
    pose.header(dds::make_header(stamp_ns, seq, "world"));
    pose.sensor_id(name_);
    pose.filter_id("truth");
    pose.position_m(dds::to_msg(t.p_world_m));
    pose.velocity_mps(dds::to_msg(t.v_world_mps));
    pose.q_world_body(dds::to_msg(t.q_world_body));
    pose_->write(pose);

    msg::AltitudeEstimate alt;
    alt.header(dds::make_header(stamp_ns, seq, "world"));
    alt.sensor_id(name_);
    alt.filter_id("truth");
    alt.method("truth");
    alt.height_m(t.p_world_m.z());
    alt.vertical_velocity_mps(t.v_world_mps.z());
    alt.vertical_accel_mps2(t.a_world_mps2.z());
    alt.stationary(!t.moving);
    altitude_->write(alt);
  }

  SimImuParams params_;
  std::string name_;
  imu::FaultSpec faults_;
  std::unique_ptr<sim::SensorSimulator> simulator_;
  std::unique_ptr<dds::Writer<msg::AttitudeEstimatePubSubType>> attitude_;
  std::unique_ptr<dds::Writer<msg::PoseEstimatePubSubType>> pose_;
  std::unique_ptr<dds::Writer<msg::AltitudeEstimatePubSubType>> altitude_;
  std::unique_ptr<imu::PtyLink> link_;
  std::atomic<bool> stop_{false};
  std::atomic<uint64_t> written_{0};
  std::atomic<uint64_t> no_reader_{0};
  std::atomic<uint64_t> reader_full_{0};
  std::thread thread_;
};

}  // namespace

SimImuParams sim_imu_params(const runtime::ComponentSpec& spec) {
  runtime::check_known_params(spec, {"link", "scenario", "rate_hz", "seed", "faults", "duration_s",
                                     "publish_truth", "sensor_info"});
  SimImuParams p;
  p.link = runtime::param<std::string>(spec, "link", "");
  if (p.link.empty()) {
    throw runtime::ConfigError(spec.origin + ": sim_imu needs 'link' (the path of the simulated "
                               "device, e.g. /tmp/poise-imu)");
  }
  p.scenario = runtime::param<std::string>(spec, "scenario", p.scenario);
  p.rate_hz = runtime::param<double>(spec, "rate_hz", p.rate_hz);
  p.seed = runtime::param<uint64_t>(spec, "seed", p.seed);
  p.faults = runtime::param<std::string>(spec, "faults", p.faults);
  p.duration_s = runtime::param<double>(spec, "duration_s", p.duration_s);
  p.publish_truth = runtime::param<bool>(spec, "publish_truth", p.publish_truth);
  p.sensor_info = runtime::param<bool>(spec, "sensor_info", p.sensor_info);
  if (!(p.rate_hz > 0.0 && p.rate_hz <= 10000.0)) {
    throw runtime::ConfigError(spec.origin + ": rate_hz must be in (0, 10000]");
  }
  return p;
}

void register_sim_imu(runtime::ComponentRegistry& registry) {
  registry.add({"sim_imu",
                "Simulated serial IMU on a pseudo-terminal (poise protocol) + simulated truth topics",
                [](const runtime::ComponentSpec& spec, runtime::HostContext& host) {
                  return std::make_unique<SimImu>(spec, host);
                },
                /*standalone_command=*/false});  // `poise sim-imu` (drivers/imu) runs it alone
}

}  // namespace poise::simulated

namespace poise::runtime {
void register_sim_nodes(ComponentRegistry& registry) {
  simulated::register_sim_imu(registry);
#if POISE_WITH_CAMERA
  simulated::register_sim_camera(registry);
#endif
}
}  // namespace poise::runtime
