#include "poise/nodes/input_age.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <stdexcept>

namespace poise::nodes {

namespace {
// Stamps outside [0, 2^62] ns are not judged here: the cores refuse them (`stamp_out_of_range`),
// and differences of in-range values cannot overflow.
constexpr int64_t kMaxStamp = int64_t{1} << 62;
bool judgeable(int64_t stamp_ns, int64_t arrival_ns) {
  return stamp_ns >= 0 && stamp_ns <= kMaxStamp && arrival_ns >= 0 && arrival_ns <= kMaxStamp;
}
}  // namespace

const char* to_string(AgeMethod method) {
  switch (method) {
    case AgeMethod::kRelative: return "relative";
    case AgeMethod::kHostClock: return "host_clock";
    case AgeMethod::kOff: return "off";
  }
  return "relative";
}

AgeMethod parse_age_method(const std::string& name) {
  for (const AgeMethod m : {AgeMethod::kRelative, AgeMethod::kHostClock, AgeMethod::kOff}) {
    if (name == to_string(m)) {
      return m;
    }
  }
  throw std::invalid_argument("'" + name + "' is not an input age method (relative, host_clock, off)");
}

int64_t InputAge::relative_age(const std::string& topic, const std::string& writer, int64_t stamp_ns,
                               int64_t arrival_ns) {
  const int64_t offset = arrival_ns - stamp_ns;
  auto [it, first] = references_.try_emplace({topic, writer});
  Reference& ref = it->second;
  if (first) {  // a new publisher: its first sample is its reference
    ref = Reference{offset, arrival_ns, -1};
    return 0;
  }
  const double since_s = static_cast<double>(std::max<int64_t>(0, arrival_ns - ref.arrival_ns)) * 1e-9;
  const int64_t bound = ref.offset_ns + static_cast<int64_t>(std::llround(since_s * kDriftAllowance * 1e9));
  if (offset < bound - max_age_ns_) {
    // Stamped more than the deadline ahead of every sample before it: one such sample (a glitched
    // stamp) must not become the reference, or every normal sample after it would look stale for
    // kReanchorAfterNs. A second one in a row that agrees with it is a clock that really jumped.
    if (ref.early_pending && std::abs(offset - ref.early_offset_ns) <= max_age_ns_) {
      ref = Reference{offset, arrival_ns, -1};
    } else {
      ref.early_pending = true;
      ref.early_offset_ns = offset;
    }
    return 0;
  }
  if (offset <= bound) {  // the freshest delivery so far (drift allowed for)
    ref = Reference{offset, arrival_ns, -1};
    return 0;
  }
  ref.early_pending = false;
  const int64_t age = offset - bound;
  if (age <= max_age_ns_) {
    ref.stale_since_ns = -1;
    return age;
  }
  // Stale. A stale burst arrives within milliseconds; stale for longer than kReanchorAfterNs of
  // arrivals without a fresh sample in between means the reference is wrong (the publisher's clock
  // was reset, a replay looped, the path's delay grew for good): start a new one.
  if (ref.stale_since_ns < 0) {
    ref.stale_since_ns = arrival_ns;
  } else if (arrival_ns - ref.stale_since_ns > kReanchorAfterNs) {
    ref = Reference{offset, arrival_ns, -1};
    ++topics_[topic].reanchored;
    return 0;
  }
  return age;
}

InputAge::Verdict InputAge::judge(const std::string& topic, const std::string& writer,
                                  int64_t stamp_ns, int64_t arrival_ns) {
  Verdict v;
  if (method_ == AgeMethod::kOff || !judgeable(stamp_ns, arrival_ns)) {
    return v;
  }
  v.age_ns = method_ == AgeMethod::kHostClock ? std::max<int64_t>(0, arrival_ns - stamp_ns)
                                              : relative_age(topic, writer, stamp_ns, arrival_ns);
  v.stale = v.age_ns > max_age_ns_;
  Topic& t = topics_[topic];
  t.stale += v.stale ? 1U : 0U;
  return v;
}

void InputAge::fused(const std::string& topic, int64_t age_ns) {
  if (method_ == AgeMethod::kOff) {
    return;
  }
  Topic& t = topics_[topic];
  t.last_age_ns = age_ns;
  t.max_age_ns = std::max(t.max_age_ns, age_ns);
}

void InputAge::report(DiagnosticsReport& out) const {
  if (method_ == AgeMethod::kOff) {
    return;
  }
  for (const auto& [topic, t] : topics_) {
    out.counters[topic + "_stale"] = t.stale;
    out.counters[topic + "_age_reanchored"] = t.reanchored;
    out.metrics.push_back({topic + "_age", static_cast<double>(t.last_age_ns) * 1e-9, "s"});
    out.metrics.push_back({topic + "_age_max", static_cast<double>(t.max_age_ns) * 1e-9, "s"});
  }
}

uint64_t InputAge::stale(const std::string& topic) const {
  const auto it = topics_.find(topic);
  return it == topics_.end() ? 0 : it->second.stale;
}

}  // namespace poise::nodes
