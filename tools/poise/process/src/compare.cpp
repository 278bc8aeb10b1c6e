#include "poise/process/compare.h"

#include "poise/core/attitude.h"
#include "poise/dds/convert.h"
#include "poise/dds/topics.h"
#include "poise/record/mcap.h"
#include "decode.h"

#include <poise/msg/estimatesPubSubTypes.h>

#include <Eigen/Geometry>

#include <cmath>
#include <cstdio>
#include <iterator>
#include <limits>
#include <map>
#include <sstream>
#include <tuple>

namespace poise::record {

namespace {

struct Sample {
  int64_t stamp_ns = 0;
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
  Eigen::Vector3d position{0, 0, 0};
  double height_m = 0.0;
  bool mag_trusted = false;
  bool vision_fused = false;
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();  ///< attitude: the published covariance, rad^2
};

/// Against truth: the error's heading part (deg) and NEES of the estimate's covariance.
struct TruthError {
  double heading_deg = 0.0;
  double nees = 0.0;
};
TruthError truth_error(const Sample& estimate, const Sample& truth) {
  const Eigen::Quaterniond e = estimate.q.normalized() * truth.q.normalized().conjugate();
  return {heading_inclination_of_world_error(e).heading_rad * kDegPerRad,
          attitude_nees(world_attitude_error(estimate.q, truth.q), estimate.cov)};
}

using Key = std::tuple<std::string, int64_t, uint32_t>;  // sensor_id, stamp, seq
struct Series {
  std::string kind;
  std::map<Key, Sample> samples;
};

/// The difference (in the series' unit) between two samples of a kind.
double difference(const std::string& kind, const Sample& a, const Sample& b) {
  if (kind == "attitude") {
    return a.q.angularDistance(b.q) * kDegPerRad;
  }
  if (kind == "pose") {
    return (a.position - b.position).norm();
  }
  return std::abs(a.height_m - b.height_m);
}

void add_flag(FlagDifference& d, bool processed, bool live, double t_s, bool* in_interval) {
  d.processed_yes += processed ? 1 : 0;
  d.live_yes += live ? 1 : 0;
  if (processed == live) {
    *in_interval = false;
    return;
  }
  (processed ? d.processed_only : d.live_only) += 1;
  if (!*in_interval) {
    d.intervals.push_back({t_s, t_s, 0});
    *in_interval = true;
  }
  d.intervals.back().end_s = t_s;
  ++d.intervals.back().samples;
}

std::string format_flag(const char* what, const FlagDifference& d) {
  std::ostringstream os;
  os << "    " << what << " at " << d.processed_yes << " processed / " << d.live_yes
     << " live samples; ";
  if (d.processed_only + d.live_only == 0) {
    os << "the same at every matched sample\n";
    return os.str();
  }
  os << "differently at " << d.processed_only + d.live_only << " samples ("
     << d.processed_only << " processed only, " << d.live_only << " live only) in "
     << d.intervals.size() << " interval(s):";
  constexpr size_t kShown = 6;
  for (size_t i = 0; i < d.intervals.size() && i < kShown; ++i) {
    char buf[64];
    std::snprintf(buf, sizeof(buf), " %.2f-%.2f s", d.intervals[i].start_s, d.intervals[i].end_s);
    os << buf;
  }
  if (d.intervals.size() > kShown) {
    os << " ...";
  }
  os << "\n";
  return os.str();
}

}  // namespace

namespace {

/// A recording made before AttitudeEstimate.heading_status (its channel's schema text lacks it):
/// the payload with the field appended as HEADING_NO_REFERENCE (a 4-byte enum after
/// gyro_bias_rps, whose doubles leave the end 8-aligned), so its live estimates still compare.
/// Any other message unchanged.
MessageView pre_heading_status(const MessageView& m) {
  static thread_local std::vector<uint8_t> padded;
  const std::string schema_text(m.schema->data.begin(), m.schema->data.end());
  if (schema_text.find("heading_status") != std::string::npos || m.size < 4 || (m.size - 4) % 8 != 0) {
    return m;
  }
  padded.assign(m.data, m.data + m.size);
  padded.insert(padded.end(), 4, 0);
  MessageView out = m;
  out.data = padded.data();
  out.size = padded.size();
  return out;
}

/// Decodes an estimate message into (kind, sensor, seq, sample); false when it is not one.
bool decode_estimate(const MessageView& m, std::string& kind, std::string& sensor, uint32_t& seq, Sample& s) {
  const std::string& type = m.schema->name;
  if (type == dds::type_names::kAttitudeEstimate) {
    msg::AttitudeEstimate e;
    if (decode<msg::AttitudeEstimatePubSubType>(pre_heading_status(m), e)) {
      return false;
    }
    kind = "attitude";
    s.stamp_ns = e.header().stamp_ns();
    seq = e.header().seq();
    sensor = e.sensor_id().to_string();
    s.q = dds::from_msg(e.q_world_body());
    s.mag_trusted = e.mag_trusted();
    s.vision_fused = (e.sources_fused() & msg::SOURCE_VISION) != 0;
    for (int k = 0; k < 9; ++k) {
      s.cov(k / 3, k % 3) = e.attitude_covariance()[static_cast<size_t>(k)];
    }
    return true;
  }
  if (type == dds::type_names::kPoseEstimate) {
    msg::PoseEstimate e;
    if (decode<msg::PoseEstimatePubSubType>(m, e)) {
      return false;
    }
    kind = "pose";
    s.stamp_ns = e.header().stamp_ns();
    seq = e.header().seq();
    sensor = e.sensor_id().to_string();
    s.position = dds::from_msg(e.position_m());
    s.q = dds::from_msg(e.q_world_body());
    return true;
  }
  if (type == dds::type_names::kAltitudeEstimate) {
    msg::AltitudeEstimate e;
    if (decode<msg::AltitudeEstimatePubSubType>(m, e)) {
      return false;
    }
    kind = "altitude";
    s.stamp_ns = e.header().stamp_ns();
    seq = e.header().seq();
    sensor = e.sensor_id().to_string();
    s.height_m = e.height_m();
    return true;
  }
  return false;
}

/// Per processed topic and sensor: the running sums of the comparison.
struct Running {
  SeriesComparison c;
  int64_t first_stamp = 0;
  bool mag_in = false;
  bool vision_in = false;
  double sum_sq = 0.0;
  double truth_sq = 0.0;
  double truth_heading_sq = 0.0;
  double window_sq = 0.0;
  double window_heading_sq = 0.0;
};

/// Per live topic and sensor: its estimates and their error against truth.
struct LiveRunning {
  uint64_t live = 0;
  uint64_t truth_matched = 0;
  double truth_sq = 0.0;
  double truth_heading_sq = 0.0;
  NeesSummary nees;
};

// Estimates are compared once the newest stamp read is this far past theirs: the processed
// estimate, the live one and the truth of a sample sit close together in the file (written
// after the input that caused them, recorded on arrival), so only that much is held, whatever
// the recording's length.
constexpr int64_t kHorizonNs = 10'000'000'000LL;  // 10 s of sample time
constexpr int64_t kFinalizeEveryNs = 1'000'000'000LL;

}  // namespace

namespace {

/// The comparison as it reads a file in one stream: estimates wait until the newest stamp is
/// kHorizonNs past them, then are compared and dropped.
class StreamComparison {
 public:
  StreamComparison(std::string prefix, const CompareWindow& window) : prefix_(std::move(prefix)), window_(window) {}

  /// One decoded estimate or truth sample of `topic`.
  void add(const std::string& topic, const std::string& kind, const std::string& sensor, uint32_t seq,
           const Sample& s) {
    Series& ser = series_[topic];
    ser.kind = kind;
    if (is_truth(topic)) {
      // truth by seq (the simulator numbers its samples as the IMU it feeds); the later one of a
      // seq read twice, as the recording's order gives them
      truth_[topic][seq] = s;
    } else {
      ser.samples[Key{sensor, s.stamp_ns, seq}] = s;
    }
    if (s.stamp_ns > newest_) {
      newest_ = s.stamp_ns;
      // finalized_at_ <= newest_ - kHorizonNs <= INT64_MAX - kHorizonNs: the sum cannot overflow
      if (newest_ > std::numeric_limits<int64_t>::min() + kHorizonNs &&
          (finalized_at_ == std::numeric_limits<int64_t>::min() ||
           newest_ - kHorizonNs >= finalized_at_ + kFinalizeEveryNs)) {
        finalized_at_ = newest_ - kHorizonNs;
        finalize(finalized_at_, false);
      }
    }
  }

  /// Compares what is left and gives one comparison per processed topic and sensor.
  std::vector<SeriesComparison> finish() {
    finalize(std::numeric_limits<int64_t>::max(), true);
    std::vector<SeriesComparison> out;
    for (auto& [topic, by_sensor] : running_) {
      const std::string live_topic = topic.substr(prefix_.size());
      const auto live_it = live_running_.find(live_topic);
      for (auto& [sensor, r] : by_sensor) {
        SeriesComparison& c = r.c;
        if (live_it != live_running_.end()) {
          const auto l = live_it->second.find(sensor);
          if (l != live_it->second.end()) {
            c.live = l->second.live;
            c.truth_matched_live = l->second.truth_matched;
            const double n_live = static_cast<double>(l->second.truth_matched);
            c.live_truth_rmse = n_live > 0 ? std::sqrt(l->second.truth_sq / n_live) : 0.0;
            c.live_truth_heading_rmse = n_live > 0 ? std::sqrt(l->second.truth_heading_sq / n_live) : 0.0;
            c.live_nees = l->second.nees;
          }
        }
        c.rmse = c.matched > 0 ? std::sqrt(r.sum_sq / static_cast<double>(c.matched)) : 0.0;
        const double n_truth = static_cast<double>(c.truth_matched);
        c.processed_truth_rmse = n_truth > 0 ? std::sqrt(r.truth_sq / n_truth) : 0.0;
        c.processed_truth_heading_rmse = n_truth > 0 ? std::sqrt(r.truth_heading_sq / n_truth) : 0.0;
        c.window = window_;
        const double n_window = static_cast<double>(c.in_window.samples);
        c.in_window.rmse = n_window > 0 ? std::sqrt(r.window_sq / n_window) : 0.0;
        c.in_window.heading_rmse = n_window > 0 ? std::sqrt(r.window_heading_sq / n_window) : 0.0;
        out.push_back(c);
      }
    }
    return out;
  }

 private:
  [[nodiscard]] bool is_processed(const std::string& topic) const { return topic.rfind(prefix_, 0) == 0; }
  static bool is_truth(const std::string& topic) { return topic.rfind("truth/", 0) == 0; }

  // Compares (and drops) the estimates stamped before `before` (every one with `all`, at the end:
  // a stamp may be INT64_MAX): processed first (they look up live and truth), then live (they
  // look up truth), then truth older than the horizon.
  void finalize(int64_t before, bool all) {
    for (auto& [topic, processed] : series_) {
      if (is_processed(topic)) {
        compare_processed_series(topic, processed, before, all);
      }
    }
    for (auto& [topic, live] : series_) {
      if (!is_processed(topic) && !is_truth(topic)) {
        compare_live_series(topic, live, before, all);
      }
    }
    // stamps come from the file: every difference below is kept inside int64_t
    const int64_t truth_before = before > std::numeric_limits<int64_t>::min() + kHorizonNs
                                     ? before - kHorizonNs
                                     : std::numeric_limits<int64_t>::min();
    for (auto& [topic, by_seq] : truth_) {
      for (auto it = by_seq.begin(); it != by_seq.end();) {
        it = it->second.stamp_ns < truth_before ? by_seq.erase(it) : std::next(it);
      }
    }
  }

  void compare_processed_series(const std::string& topic, Series& processed, int64_t before, bool all) {
    const std::string live_topic = topic.substr(prefix_.size());
    const auto live_it = series_.find(live_topic);
    const std::string truth_topic = "truth/" + processed.kind;
    const auto truth_it = truth_.find(truth_topic);
    for (auto it = processed.samples.begin(); it != processed.samples.end();) {
      const auto& [key, s] = *it;
      if (!all && s.stamp_ns >= before) {
        ++it;
        continue;
      }
      const std::string& sensor = std::get<0>(key);
      Running& r = running_[topic][sensor];
      SeriesComparison& c = r.c;
      if (c.processed == 0) {
        c.kind = processed.kind;
        c.topic = live_topic;
        c.sensor_id = sensor;
        c.unit = processed.kind == "attitude" ? "deg" : "m";
        r.first_stamp = s.stamp_ns;
      }
      ++c.processed;
      const double t_s = (static_cast<double>(s.stamp_ns) - static_cast<double>(r.first_stamp)) * 1e-9;
      if (truth_it != truth_.end()) {
        const auto t = truth_it->second.find(std::get<2>(key));
        if (t != truth_it->second.end()) {
          c.truth_topic = truth_topic;
          ++c.truth_matched;
          const double e = difference(processed.kind, s, t->second);
          r.truth_sq += e * e;
          if (processed.kind == "attitude") {
            const TruthError te = truth_error(s, t->second);
            r.truth_heading_sq += te.heading_deg * te.heading_deg;
            c.processed_nees.add(te.nees);
            if (window_.enabled() && window_.contains(t_s)) {
              ++c.in_window.samples;
              r.window_sq += e * e;
              r.window_heading_sq += te.heading_deg * te.heading_deg;
              c.in_window.nees.add(te.nees);
            }
          }
        }
      }
      if (live_it != series_.end()) {
        const auto l = live_it->second.samples.find(key);
        if (l != live_it->second.samples.end()) {
          ++c.matched;
          const double d = difference(processed.kind, s, l->second);
          r.sum_sq += d * d;
          if (d > c.largest) {
            c.largest = d;
            c.largest_at_s = t_s;
          }
          if (processed.kind == "attitude") {
            add_flag(c.mag_trust, s.mag_trusted, l->second.mag_trusted, t_s, &r.mag_in);
            add_flag(c.vision_fused, s.vision_fused, l->second.vision_fused, t_s, &r.vision_in);
          }
        }
      }
      it = processed.samples.erase(it);
    }
  }

  void compare_live_series(const std::string& topic, Series& live, int64_t before, bool all) {
    const auto truth_it = truth_.find("truth/" + live.kind);
    for (auto it = live.samples.begin(); it != live.samples.end();) {
      const auto& [key, s] = *it;
      if (!all && s.stamp_ns >= before) {
        ++it;
        continue;
      }
      LiveRunning& l = live_running_[topic][std::get<0>(key)];
      ++l.live;
      if (truth_it != truth_.end()) {
        const auto t = truth_it->second.find(std::get<2>(key));
        if (t != truth_it->second.end()) {
          ++l.truth_matched;
          const double e = difference(live.kind, s, t->second);
          l.truth_sq += e * e;
          if (live.kind == "attitude") {
            const TruthError te = truth_error(s, t->second);
            l.truth_heading_sq += te.heading_deg * te.heading_deg;
            l.nees.add(te.nees);
          }
        }
      }
      it = live.samples.erase(it);
    }
  }

  const std::string prefix_;
  const CompareWindow window_;
  std::map<std::string, Series> series_;  // by topic: the estimates not yet compared
  std::map<std::string, std::map<std::string, Running>> running_;  // by processed topic, sensor
  std::map<std::string, std::map<std::string, LiveRunning>> live_running_;  // by live topic, sensor
  std::map<std::string, std::map<uint32_t, Sample>> truth_;  // by truth topic, seq
  int64_t newest_ = std::numeric_limits<int64_t>::min();
  int64_t finalized_at_ = std::numeric_limits<int64_t>::min();
};

}  // namespace

std::vector<SeriesComparison> compare_processed(const std::string& file, const std::string& prefix,
                                               const CompareWindow& window) {
  StreamComparison comparison(prefix, window);
  const McapReader reader = McapReader::open_file(file);
  MessageCursor cursor = reader.messages();
  while (const MessageView* m = cursor.next()) {
    if (m->schema == nullptr) {
      continue;
    }
    Sample s;
    std::string sensor;
    uint32_t seq = 0;
    std::string kind;
    if (decode_estimate(*m, kind, sensor, seq, s)) {
      comparison.add(m->channel->topic, kind, sensor, seq, s);
    }
  }
  return comparison.finish();
}

std::string format_nees(const NeesSummary& nees) {
  if (nees.samples() == 0) {
    return "no usable covariance (none, all zero or not positive definite)";
  }
  char buf[160];
  std::snprintf(buf, sizeof(buf), "median NEES %.3g, %.1f %% inside the 95 %% ellipsoid", nees.median(),
                100.0 * nees.fraction_inside(kNees95Dof3));
  std::string out = buf;
  if (nees.without_covariance() > 0) {
    out += " (" + std::to_string(nees.without_covariance()) + " samples without a usable one)";
  }
  return out;
}

std::string format_comparison(const std::vector<SeriesComparison>& series) {
  std::ostringstream os;
  os << "comparison: processed/<topic> vs the recorded live <topic> (same sensor_id, seq and stamp)"
        " and vs truth/* (same seq)\n";
  if (series.empty()) {
    os << "  nothing processed to compare\n";
  }
  char buf[256];
  for (const SeriesComparison& c : series) {
    os << "  " << c.topic << " [" << c.sensor_id << "]: " << c.processed << " processed, " << c.live
       << " live, " << c.matched << " matched\n";
    if (c.matched > 0) {
      std::snprintf(buf, sizeof(buf), "    processed - live: RMSE %.4g %s, largest %.4g %s at %.2f s\n",
                    c.rmse, c.unit.c_str(), c.largest, c.unit.c_str(), c.largest_at_s);
      os << buf;
      if (c.live > c.matched) {
        os << "    " << c.live - c.matched
           << " live estimate(s) without a processed one (an input the recording lacks, or an "
              "estimate the component did not give offline)\n";
      }
    } else {
      os << "    no live estimate of the same sample in the recording\n";
    }
    if (!c.truth_topic.empty()) {
      std::snprintf(buf, sizeof(buf),
                    "    vs %s: processed RMSE %.4g %s (%llu samples), live RMSE %.4g %s (%llu samples)\n",
                    c.truth_topic.c_str(), c.processed_truth_rmse, c.unit.c_str(),
                    static_cast<unsigned long long>(c.truth_matched), c.live_truth_rmse, c.unit.c_str(),
                    static_cast<unsigned long long>(c.truth_matched_live));
      os << buf;
      if (c.kind == "attitude") {
        std::snprintf(buf, sizeof(buf), "      heading RMSE %.4g deg processed, %.4g deg live\n",
                      c.processed_truth_heading_rmse, c.live_truth_heading_rmse);
        os << buf << "      covariance: processed " << format_nees(c.processed_nees) << "; live "
           << format_nees(c.live_nees) << "\n";
        if (c.window.enabled()) {
          std::snprintf(buf, sizeof(buf),
                        "      processed from %.3g to %.3g s (%llu samples): RMSE %.4g deg, heading RMSE %.4g deg, ",
                        c.window.from_s, c.window.to_s, static_cast<unsigned long long>(c.in_window.samples),
                        c.in_window.rmse, c.in_window.heading_rmse);
          os << buf << format_nees(c.in_window.nees) << "\n";
        }
      }
    }
    if (c.kind == "attitude" && c.matched > 0) {
      os << format_flag("magnetometer trusted", c.mag_trust);
      os << format_flag("vision fused", c.vision_fused);
    }
  }
  return os.str();
}

}  // namespace poise::record
