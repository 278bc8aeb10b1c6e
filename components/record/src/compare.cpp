#include "poise/record/compare.h"

#include "poise/core/attitude.h"
#include "poise/dds/convert.h"
#include "poise/dds/topics.h"
#include "poise/record/mcap.h"
#include "decode.h"

#include <poise/msg/estimatesPubSubTypes.h>

#include <Eigen/Geometry>

#include <cmath>
#include <cstdio>
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
};

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

std::vector<SeriesComparison> compare_processed(const std::string& file, const std::string& prefix) {
  std::map<std::string, Series> series;  // by topic
  const McapReader reader = McapReader::open_file(file);
  MessageCursor cursor = reader.messages();
  while (const MessageView* m = cursor.next()) {
    if (m->schema == nullptr) {
      continue;
    }
    const std::string& type = m->schema->name;
    Sample s;
    std::string sensor;
    uint32_t seq = 0;
    std::string kind;
    if (type == dds::type_names::kAttitudeEstimate) {
      msg::AttitudeEstimate e;
      if (decode<msg::AttitudeEstimatePubSubType>(*m, e)) {
        continue;
      }
      kind = "attitude";
      s.stamp_ns = e.header().stamp_ns();
      seq = e.header().seq();
      sensor = e.sensor_id().to_string();
      s.q = dds::from_msg(e.q_world_body());
      s.mag_trusted = e.mag_trusted();
      s.vision_fused = (e.sources_fused() & msg::SOURCE_VISION) != 0;
    } else if (type == dds::type_names::kPoseEstimate) {
      msg::PoseEstimate e;
      if (decode<msg::PoseEstimatePubSubType>(*m, e)) {
        continue;
      }
      kind = "pose";
      s.stamp_ns = e.header().stamp_ns();
      seq = e.header().seq();
      sensor = e.sensor_id().to_string();
      s.position = dds::from_msg(e.position_m());
      s.q = dds::from_msg(e.q_world_body());
    } else if (type == dds::type_names::kAltitudeEstimate) {
      msg::AltitudeEstimate e;
      if (decode<msg::AltitudeEstimatePubSubType>(*m, e)) {
        continue;
      }
      kind = "altitude";
      s.stamp_ns = e.header().stamp_ns();
      seq = e.header().seq();
      sensor = e.sensor_id().to_string();
      s.height_m = e.height_m();
    } else {
      continue;
    }
    Series& ser = series[m->channel->topic];
    ser.kind = kind;
    ser.samples[Key{sensor, s.stamp_ns, seq}] = s;
  }

  std::vector<SeriesComparison> out;
  for (const auto& [topic, processed] : series) {
    if (topic.rfind(prefix, 0) != 0) {
      continue;
    }
    const std::string live_topic = topic.substr(prefix.size());
    const auto live_it = series.find(live_topic);
    const std::string truth_topic = "truth/" + processed.kind;
    const auto truth_it = series.find(truth_topic);
    // truth by seq (the simulator numbers its samples as the IMU it feeds)
    std::map<uint32_t, const Sample*> truth;
    if (truth_it != series.end()) {
      for (const auto& [key, s] : truth_it->second.samples) {
        truth[std::get<2>(key)] = &s;
      }
    }
    // one comparison per sensor_id
    std::map<std::string, SeriesComparison> per_sensor;
    std::map<std::string, int64_t> first_stamp;
    std::map<std::string, std::pair<bool, bool>> in_interval;
    std::map<std::string, double> sum_sq;
    std::map<std::string, double> truth_sq;
    std::map<std::string, double> live_truth_sq;
    for (const auto& [key, s] : processed.samples) {
      const std::string& sensor = std::get<0>(key);
      SeriesComparison& c = per_sensor[sensor];
      if (c.processed == 0) {
        c.kind = processed.kind;
        c.topic = live_topic;
        c.sensor_id = sensor;
        c.unit = processed.kind == "attitude" ? "deg" : "m";
        first_stamp[sensor] = s.stamp_ns;
      }
      ++c.processed;
      const double t_s = static_cast<double>(s.stamp_ns - first_stamp[sensor]) * 1e-9;
      const auto t = truth.find(std::get<2>(key));
      if (t != truth.end()) {
        c.truth_topic = truth_topic;
        ++c.truth_matched;
        const double e = difference(processed.kind, s, *t->second);
        truth_sq[sensor] += e * e;
      }
      if (live_it == series.end()) {
        continue;
      }
      const auto l = live_it->second.samples.find(key);
      if (l == live_it->second.samples.end()) {
        continue;
      }
      ++c.matched;
      const double d = difference(processed.kind, s, l->second);
      sum_sq[sensor] += d * d;
      if (d > c.largest) {
        c.largest = d;
        c.largest_at_s = t_s;
      }
      if (processed.kind == "attitude") {
        auto& [mag_in, vision_in] = in_interval[sensor];
        add_flag(c.mag_trust, s.mag_trusted, l->second.mag_trusted, t_s, &mag_in);
        add_flag(c.vision_fused, s.vision_fused, l->second.vision_fused, t_s, &vision_in);
      }
    }
    if (live_it != series.end()) {
      for (const auto& [key, s] : live_it->second.samples) {
        const auto pc = per_sensor.find(std::get<0>(key));
        if (pc == per_sensor.end()) {
          continue;
        }
        ++pc->second.live;
        const auto t = truth.find(std::get<2>(key));
        if (t != truth.end()) {
          ++pc->second.truth_matched_live;
          const double e = difference(processed.kind, s, *t->second);
          live_truth_sq[std::get<0>(key)] += e * e;
        }
      }
    }
    for (auto& [sensor, c] : per_sensor) {
      c.rmse = c.matched > 0 ? std::sqrt(sum_sq[sensor] / static_cast<double>(c.matched)) : 0.0;
      c.processed_truth_rmse =
          c.truth_matched > 0 ? std::sqrt(truth_sq[sensor] / static_cast<double>(c.truth_matched)) : 0.0;
      c.live_truth_rmse = c.truth_matched_live > 0
                              ? std::sqrt(live_truth_sq[sensor] / static_cast<double>(c.truth_matched_live))
                              : 0.0;
      out.push_back(c);
    }
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
    }
    if (c.kind == "attitude" && c.matched > 0) {
      os << format_flag("magnetometer trusted", c.mag_trust);
      os << format_flag("vision fused", c.vision_fused);
    }
  }
  return os.str();
}

}  // namespace poise::record
