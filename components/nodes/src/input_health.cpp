#include "poise/nodes/input_health.h"

#include <algorithm>
#include <cstdio>

namespace poise::nodes {

InputHealth::InputHealth(int64_t deadline_ns, int64_t start_ns)
    : deadline_ns_(deadline_ns), start_ns_(start_ns) {}

InputHealth::Input& InputHealth::input(const std::string& topic) {
  auto [it, inserted] = inputs_.try_emplace(topic);
  if (inserted) {
    it->second.last_ns = start_ns_;
  }
  return it->second;
}

void InputHealth::expect(const std::string& topic) { input(topic); }

uint64_t InputHealth::on_sample(const std::string& topic, const std::string& source, uint32_t seq,
                                const std::string& writer, int64_t now_ns) {
  Input& in = input(topic);
  in.last_ns = std::max(in.last_ns, now_ns);
  in.silent = false;
  return in.gaps.on_sample(source, seq, writer).lost;
}

void InputHealth::tick(int64_t now_ns) {
  for (auto& [topic, in] : inputs_) {
    const bool silent = now_ns - in.last_ns > deadline_ns_;
    if (silent && !in.silent) {
      ++in.silences;
    }
    in.silent = silent;
  }
}

void InputHealth::report(int64_t now_ns, DiagnosticsReport& out) {
  tick(now_ns);
  for (const auto& [topic, in] : inputs_) {
    const dds::SequenceGaps::Totals t = in.gaps.totals();
    out.counters[topic + "_received"] = t.received;
    out.counters[topic + "_lost"] = t.lost;
    out.counters[topic + "_gaps"] = t.gaps;
    out.counters[topic + "_restarts"] = t.restarts;
    out.counters[topic + "_silences"] = in.silences;
    out.metrics.push_back(
        {topic + "_silence", static_cast<double>(std::max<int64_t>(0, now_ns - in.last_ns)) * 1e-9, "s"});
    out.metrics.push_back({topic + "_silent", in.silent ? 1.0 : 0.0, "bool"});
  }
}

std::vector<InputHealth::Silence> InputHealth::silent(int64_t now_ns) const {
  std::vector<Silence> out;
  for (const auto& [topic, in] : inputs_) {
    if (now_ns - in.last_ns > deadline_ns_) {
      out.push_back({topic, static_cast<double>(now_ns - in.last_ns) * 1e-9});
    }
  }
  std::sort(out.begin(), out.end(), [](const Silence& a, const Silence& b) { return a.seconds > b.seconds; });
  return out;
}

dds::SequenceGaps::Totals InputHealth::totals(const std::string& topic) const {
  const auto it = inputs_.find(topic);
  return it == inputs_.end() ? dds::SequenceGaps::Totals{} : it->second.gaps.totals();
}

std::string describe_silence(const std::vector<InputHealth::Silence>& silent) {
  std::string out;
  for (const auto& s : silent) {
    char text[160];
    std::snprintf(text, sizeof text, "%sno input on %s for %.1f s", out.empty() ? "" : "; ",
                  s.topic.c_str(), s.seconds);
    out += text;
  }
  return out;
}

}  // namespace poise::nodes
