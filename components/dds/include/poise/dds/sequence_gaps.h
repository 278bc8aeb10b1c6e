// Lost-sample accounting from header.seq: every poise publisher numbers its samples +1 each, so a
// receiver sees a jump as samples lost on the way (best-effort drops, a cut link, an overloaded
// reader) and a new writer for the same source as a publisher restart, not as a loss. Feed it from
// a Reader callback and publish the totals in diagnostics. Pure and single-threaded: the caller
// serialises calls (a Reader's callback already runs on one thread).
#pragma once

#include <fastdds/dds/subscriber/SampleInfo.hpp>

#include <cstdint>
#include <cstdio>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace poise::dds {

class SequenceGaps {
 public:
  /// What one sample meant.
  struct Event {
    bool first = false;      ///< first sample of this source
    bool restart = false;    ///< new writer (or sequence went backwards): counted, not a loss
    bool duplicate = false;  ///< same seq again from the same writer: ignored
    uint64_t lost = 0;       ///< samples missing just before this one
  };
  struct Totals {
    uint64_t received = 0;  ///< samples accepted (duplicates excluded)
    uint64_t lost = 0;      ///< sum of the sequence gaps
    uint64_t gaps = 0;      ///< number of gaps (loss events)
    uint64_t restarts = 0;  ///< writer changes / backward jumps
  };

  /// Records a sample of `source` (e.g. the sensor_id) with sequence number `seq` from `writer`
  /// (an identity of the DataWriter, e.g. writer_key(info)). Wrap-safe (2^32 - 1 -> 0 is +1).
  Event on_sample(const std::string& source, uint32_t seq, const std::string& writer) {
    Event e;
    auto [it, inserted] = sources_.try_emplace(source);
    State& s = it->second;
    if (inserted) {
      e.first = true;
    } else if (writer != s.writer) {
      e.restart = true;
    } else {
      const uint32_t step = seq - s.last_seq;  // modular: wraps correctly
      if (step == 0U) {
        e.duplicate = true;
        return e;
      }
      if (step > 0x80000000U) {
        e.restart = true;  // backwards within one writer: treat as a reset, not a loss
      } else {
        e.lost = step - 1U;
      }
    }
    s.writer = writer;
    s.last_seq = seq;
    ++s.totals.received;
    s.totals.lost += e.lost;
    s.totals.gaps += e.lost > 0 ? 1U : 0U;
    s.totals.restarts += e.restart ? 1U : 0U;
    return e;
  }

  /// Totals of one source (zeros if never seen).
  [[nodiscard]] Totals totals(const std::string& source) const {
    const auto it = sources_.find(source);
    return it == sources_.end() ? Totals{} : it->second.totals;
  }

  /// Totals over all sources.
  [[nodiscard]] Totals totals() const {
    Totals sum;
    for (const auto& [name, s] : sources_) {
      sum.received += s.totals.received;
      sum.lost += s.totals.lost;
      sum.gaps += s.totals.gaps;
      sum.restarts += s.totals.restarts;
    }
    return sum;
  }

  /// Every source seen, with its totals.
  [[nodiscard]] std::map<std::string, Totals> by_source() const {
    std::map<std::string, Totals> out;
    for (const auto& [name, s] : sources_) {
      out.emplace(name, s.totals);
    }
    return out;
  }

 private:
  struct State {
    uint32_t last_seq = 0;
    std::string writer;
    Totals totals;
  };
  std::map<std::string, State> sources_;
};

/// True for the types whose header.seq numbers their messages one by one, so that a gap is a
/// message lost on the way: every poise::msg type but FilterDiagnostics, whose header.seq is that
/// of the step it reports on (an estimator publishes them at a rate, not per step) -- and no type
/// without a poise header (ROS 2 types).
inline bool header_seq_counts_messages(const std::string& type) {
  return type.rfind("poise::msg::", 0) == 0 && type != "poise::msg::FilterDiagnostics";
}

/// header.seq of a serialized poise message (every poise topic type starts with Header{int64
/// stamp_ns; uint32 seq; ...}): `payload` is the full serialized payload, 4-byte encapsulation
/// first (CDR big or little endian). nullopt when it is too short or not plain CDR.
inline std::optional<uint32_t> header_seq_from_payload(const std::vector<uint8_t>& payload) {
  if (payload.size() < 16 || payload[0] != 0 || payload[1] > 1) {
    return std::nullopt;
  }
  const bool little = payload[1] == 1;
  uint32_t seq = 0;
  for (int k = 0; k < 4; ++k) {
    const uint32_t byte = payload[static_cast<size_t>(12 + (little ? 3 - k : k))];
    seq = (seq << 8) | byte;
  }
  return seq;
}

/// An instance or writer handle as 32 hex digits.
inline std::string handle_key(const eprosima::fastrtps::rtps::InstanceHandle_t& handle) {
  std::string out;
  char byte[3];
  for (size_t i = 0; i < 16; ++i) {
    std::snprintf(byte, sizeof(byte), "%02x", static_cast<unsigned>(handle.value[i]));
    out += byte;
  }
  return out;
}

/// The publishing DataWriter's GUID (SampleInfo::publication_handle) as 32 hex digits.
inline std::string writer_key(const eprosima::fastdds::dds::SampleInfo& info) {
  return handle_key(info.publication_handle);
}

}  // namespace poise::dds
