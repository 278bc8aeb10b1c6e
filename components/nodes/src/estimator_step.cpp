#include "poise/nodes/estimator_step.h"

#include "poise/core/north_yaml.h"
#include "poise/runtime/utc_date.h"

#include <cmath>
#include <cstdio>
#include <sstream>

namespace poise::nodes {

const std::vector<std::string>& NodeParams::keys() {
  static const std::vector<std::string> k{"diagnostics_rate_hz", "diagnostics_every", "diagnostics_period_s",
                                          "input_deadline_s", "input_age", "imu_sensor_id"};
  return k;
}

NodeParams node_params(const runtime::ComponentSpec& spec) {
  NodeParams p;
  p.diagnostics_rate_hz = runtime::param<double>(spec, "diagnostics_rate_hz", p.diagnostics_rate_hz);
  if (!(p.diagnostics_rate_hz >= 0.01 && p.diagnostics_rate_hz <= 1000.0)) {
    throw runtime::ConfigError(spec.origin + ": diagnostics_rate_hz must be in [0.01, 1000] Hz");
  }
  p.diagnostics_every = runtime::param<int>(spec, "diagnostics_every", p.diagnostics_every);
  if (p.diagnostics_every < 0) {
    throw runtime::ConfigError(spec.origin + ": diagnostics_every must be >= 0 samples (0: by diagnostics_rate_hz, "
                                             "1: every sample)");
  }
  p.diagnostics_period_s = runtime::param<double>(spec, "diagnostics_period_s", p.diagnostics_period_s);
  if (!(p.diagnostics_period_s >= 0.01 && p.diagnostics_period_s <= 3600.0)) {
    throw runtime::ConfigError(spec.origin + ": diagnostics_period_s must be in [0.01, 3600] s");
  }
  p.input_deadline_s = runtime::param<double>(spec, "input_deadline_s", p.input_deadline_s);
  if (!(p.input_deadline_s > 0.0 && p.input_deadline_s <= 3600.0)) {
    throw runtime::ConfigError(spec.origin + ": input_deadline_s must be in (0, 3600] s");
  }
  const std::string age = runtime::param<std::string>(spec, "input_age", to_string(p.input_age));
  try {
    p.input_age = parse_age_method(age);
  } catch (const std::invalid_argument& e) {
    throw runtime::ConfigError(spec.origin + ": input_age: " + e.what());
  }
  p.imu_sensor_id = runtime::param<std::string>(spec, "imu_sensor_id", p.imu_sensor_id);
  if (!p.imu_sensor_id.empty()) {
    try {
      dds::checked_sensor_id(p.imu_sensor_id, spec.origin + ": imu_sensor_id");
    } catch (const std::invalid_argument& e) {
      throw runtime::ConfigError(e.what());
    }
  }
  return p;
}

const std::vector<std::string>& north_keys() { return north_param_keys(); }

NorthReference north_reference(const runtime::ComponentSpec& spec) {
  const std::string where = spec.origin + ": component '" + spec.name + "': ";
  try {
    return resolve_north(read_north_params(spec.params), runtime::utc_today());
  } catch (const std::exception& e) {
    throw runtime::ConfigError(where + e.what());
  }
}

bool AttitudeStep::estimate(const ImuSample& sample, StepOutputs& out) {
  report_ = AttitudeReport{};
  if (!attitude(report_)) {
    return false;
  }
  report_.stamp_ns = sample.stamp_ns;
  report_.seq = sample.seq;
  report_.frame_id = north_.frame_id();
  if (north_.true_north) {  // no-op without a declination: outputs unchanged bit for bit
    report_.q_world_body = north_.to_true(report_.q_world_body);
    report_.covariance = north_.to_true(report_.covariance);
    report_.ext_accel_world_mps2 = north_.to_true(report_.ext_accel_world_mps2);
    report_.mag_disturbance_world_ut = north_.to_true(report_.mag_disturbance_world_ut);
  }
  out.attitude(to_attitude_msg(report_, sensor_id(), component()));
  return true;
}

StepRunner::StepRunner(std::unique_ptr<EstimatorStep> step, const NodeParams& params,
                       dds::TopicNames topics, Clock clock)
    : step_(std::move(step)),
      params_(params),
      topics_(std::move(topics)),
      clock_(std::move(clock)),
      diagnostics_interval_ns_(static_cast<int64_t>(1e9 / params_.diagnostics_rate_hz)),
      inputs_(static_cast<int64_t>(params_.input_deadline_s * 1e9), clock_()),
      ages_(params_.input_age, static_cast<int64_t>(params_.input_deadline_s * 1e9)) {
  inputs_.expect(topics_.imu);
}

void StepRunner::imu(const ImuSample& sample, const std::string& source, const std::string& writer,
                     StepOutputs& out) {
  if (!follows(source)) {
    return;
  }
  ++received_;
  if (!imu_infos_.empty()) {
    const auto it = imu_infos_.find(source);
    if (it != imu_infos_.end()) {
      const msg::ImuSensorInfo& info = it->second;
      char what[160];
      std::snprintf(what, sizeof what, "%s setting %d, gyro %.2f ms, accel %.2f ms, from %s",
                    info.chip().c_str(), info.filter_setting(), info.gyro_delay_s() * 1e3,
                    info.accel_delay_s() * 1e3, info.origin().c_str());
      if (step_->published_imu_delay(info.gyro_delay_s(), what) && step_->imu_delay() != nullptr) {
        pending_log_message_ = step_->imu_delay()->describe();
      }
      imu_infos_.erase(it);
    }
  }
  const int64_t arrival = clock_();
  inputs_.on_sample(topics_.imu, source, sample.seq, writer, arrival);
  last_seq_ = sample.seq;
  const InputAge::Verdict age = ages_.judge(topics_.imu, writer, sample.stamp_ns, arrival);
  if (age.stale) {
    // counted by ages_ (imu_stale), never stepped: no estimator fuses stale input
  } else if (!step_->step(sample)) {
    ++rejected_;
  } else {
    ages_.fused(topics_.imu, age.age_ns);
    if (step_->estimate(sample, out)) {
      ++published_;
      last_latency_ns_ = clock_() - sample.stamp_ns;
    }
  }
  const int64_t now = clock_();
  if (params_.diagnostics_every > 0) {
    if (++since_diagnostics_ < static_cast<uint64_t>(params_.diagnostics_every)) {
      return;
    }
    since_diagnostics_ = 0;
  } else if (diagnostics_sent_ && now - last_diagnostics_ns_ < diagnostics_interval_ns_) {
    return;
  }
  core_report_ = DiagnosticsReport{};
  step_->diagnostics(core_report_);
  publish_diagnostics(sample.stamp_ns, sample.seq, now, out);
}

void StepRunner::vision(const msg::VisionPose& m, const std::string& writer) {
  if (!step_->uses_vision()) {
    return;
  }
  ++vision_received_;
  const int64_t arrival = clock_();
  inputs_.on_sample(topics_.vision_pose, m.sensor_id().to_string(), m.header().seq(), writer, arrival);
  if (pass_on(topics_.vision_pose, writer, m.header().stamp_ns(), arrival)) {
    step_->vision(m);
  }
}

void StepRunner::vehicle_input(const msg::VehicleInput& m, const std::string& writer) {
  if (!step_->uses_vehicle_input()) {
    return;
  }
  ++vehicle_received_;
  const int64_t arrival = clock_();
  inputs_.on_sample(topics_.vehicle_input, m.sensor_id().to_string(), m.header().seq(), writer,
                    arrival);
  if (pass_on(topics_.vehicle_input, writer, m.header().stamp_ns(), arrival)) {
    step_->vehicle_input(m);
  }
}

bool StepRunner::pass_on(const std::string& topic, const std::string& writer, int64_t stamp_ns,
                         int64_t arrival_ns) {
  const InputAge::Verdict age = ages_.judge(topic, writer, stamp_ns, arrival_ns);
  if (!age.stale) {
    ages_.fused(topic, age.age_ns);  // handed to the core (which may still refuse it)
  }
  return !age.stale;
}

std::string StepRunner::imu_info(const msg::ImuSensorInfo& m) {
  // A delay outside [0, 0.05] s (the filters' range) or not finite is not offered: counted.
  if (!(m.gyro_delay_s() >= 0.0 && m.gyro_delay_s() <= 0.05)) {
    ++imu_info_refused_;
    return "refused imu_info of '" + m.sensor_id().to_string() + "': gyro_delay_s " +
           std::to_string(m.gyro_delay_s()) + " is not in [0, 0.05] s";
  }
  // One entry per sensor_id until that sensor's next sample takes it: a writer inventing ids
  // (never followed by samples) may not grow it without bound.
  const std::string id = m.sensor_id().to_string();
  if (imu_infos_.size() >= kMaxPendingImuInfos && imu_infos_.count(id) == 0) {
    ++imu_info_refused_;
    return "refused imu_info of '" + id + "': already " + std::to_string(kMaxPendingImuInfos) +
           " sensors' info waiting for their samples";
  }
  imu_info_seen_ = true;
  imu_infos_[id] = m;
  return {};
}

std::string StepRunner::take_log_message() {
  std::string m;
  m.swap(pending_log_message_);
  return m;
}

namespace {
/// A name from the network, printable: every byte outside ' '..'~' as \xNN.
std::string printable(const std::string& s) {
  std::string out;
  for (const char c : s) {
    if (c >= ' ' && c <= '~') {
      out += c;
    } else {
      char hex[8];
      std::snprintf(hex, sizeof hex, "\\x%02X", static_cast<unsigned>(static_cast<unsigned char>(c)));
      out += hex;
    }
  }
  return out;
}
}  // namespace

std::string StepRunner::other_imu_summary() const {
  if (imu_other_sensor_ == 0) {
    return {};
  }
  return "followed IMU '" + printable(followed_imu_) + "', " + std::to_string(imu_other_sensor_) +
         " sample(s) of other IMUs on " + topics_.imu + " not run (imu_sensor_id chooses)";
}

bool StepRunner::follows(const std::string& source) {
  if (followed_imu_.empty()) {
    followed_imu_ = params_.imu_sensor_id.empty() ? source : params_.imu_sensor_id;
  }
  if (source == followed_imu_) {
    return true;
  }
  if (imu_other_sensor_++ == 0) {
    pending_log_message_ = "ignoring the samples of IMU '" + printable(source) + "' on " + topics_.imu +
                           ": this component follows '" + printable(followed_imu_) + "' (" +
                           (params_.imu_sensor_id.empty() ? "the first one heard; imu_sensor_id chooses"
                                                          : "imu_sensor_id") +
                           "); counted as imu_other_sensor";
  }
  return false;
}

bool StepRunner::periodic_diagnostics(StepOutputs& out) {
  const int64_t now = clock_();
  const auto half_period_ns = static_cast<int64_t>(params_.diagnostics_period_s * 0.5e9);
  if (diagnostics_sent_ && now - last_diagnostics_ns_ < half_period_ns) {
    return false;  // the input path publishes: the timer has nothing to add
  }
  publish_diagnostics(now, last_seq_, now, out);
  return true;
}

void StepRunner::publish_diagnostics(int64_t stamp_ns, uint32_t seq, int64_t now_ns, StepOutputs& out) {
  DiagnosticsReport diag = core_report_;
  diag.stamp_ns = stamp_ns;
  diag.seq = seq;
  diag.component = step_->component();
  inputs_.report(now_ns, diag);
  ages_.report(diag);
  diag.metrics.push_back({"latency", static_cast<double>(last_latency_ns_) * 1e-6, "ms"});
  diag.counters["samples_received"] = received_;
  diag.counters["samples_rejected"] = rejected_;
  diag.counters["samples_malformed"] = imu_malformed_.load();
  diag.counters["estimates_published"] = published_;
  if (imu_other_sensor_ > 0) {  // another IMU on the topic: never stepped
    diag.counters["imu_other_sensor"] = imu_other_sensor_;
  }
  if (imu_info_seen_ || imu_info_refused_ > 0) {  // only with an IMU that publishes its delay
    diag.counters["imu_info_refused"] = imu_info_refused_;
    if (const ImuDelayChoice* d = step_->imu_delay()) {
      if (std::isfinite(d->in_use_s())) {  // NaN: not known (the filter assumes half a sample)
        diag.metrics.push_back({"imu_delay", d->in_use_s(), "s"});
      }
      diag.counters["imu_delay_published"] = d->published_in_use() ? 1 : 0;
    }
  }
  if (step_->uses_vision()) {
    diag.counters["vision_malformed"] = vision_malformed_.load();
  }
  if (step_->uses_vehicle_input()) {
    diag.counters["vehicle_input_malformed"] = vehicle_input_malformed_.load();
  }
  out.diagnostics(to_diagnostics_msg(diag, step_->sensor_id()));
  ++diagnostics_published_;
  diagnostics_sent_ = true;
  last_diagnostics_ns_ = now_ns;
}

std::string StepRunner::status() const {
  std::ostringstream os;
  const std::string silence = describe_silence(inputs_.silent(clock_()));
  if (!silence.empty()) {
    os << silence << "; ";
  }
  os << "imu lost " << inputs_.totals(topics_.imu).lost << ", imu in " << received_
     << ", estimates out " << published_ << ", rejected " << rejected_;
  if (ages_.method() != AgeMethod::kOff) {
    os << ", stale " << ages_.stale(topics_.imu);
  }
  os << ", malformed "
     << imu_malformed_.load() << ", last latency " << static_cast<double>(last_latency_ns_) * 1e-3
     << " us";
  if (step_->uses_vision()) {
    os << ", vision in " << vision_received_ << ", vision malformed " << vision_malformed_.load();
  }
  if (step_->uses_vehicle_input()) {
    os << ", vehicle_input in " << vehicle_received_ << ", vehicle_input malformed "
       << vehicle_input_malformed_.load();
  }
  if (const ImuDelayChoice* d = step_->imu_delay()) {
    os << ", " << d->describe();
  }
  return os.str();
}

}  // namespace poise::nodes
