#include "poise/record/info.h"

#include <algorithm>
#include <cstdio>
#include <sstream>

namespace poise::record {

std::vector<TopicSummary> summarise_topics(const McapReader& reader) {
  const FileReport& report = reader.report();
  const double file_span_s = static_cast<double>(report.end_ns - report.start_ns) * 1e-9;
  std::vector<TopicSummary> out;
  for (const auto& [id, channel] : reader.channels()) {
    TopicSummary t;
    t.topic = channel.topic;
    t.message_encoding = channel.message_encoding;
    const auto schema = reader.schemas().find(channel.schema_id);
    if (schema != reader.schemas().end()) {
      t.type = schema->second.name;
    }
    const auto counts = report.channels.find(id);
    if (counts != report.channels.end()) {
      const ChannelCounts& c = counts->second;
      t.messages = c.messages;
      // One formula whatever was read: the summary's per-channel counts (no per-channel times)
      // or every chunk (--verify) give the same count and the same recording span.
      if (file_span_s > 0.0) {
        t.rate_hz = static_cast<double>(t.messages) / file_span_s;
      }
    }
    out.push_back(std::move(t));
  }
  std::sort(out.begin(), out.end(),
            [](const TopicSummary& a, const TopicSummary& b) { return a.topic < b.topic; });
  return out;
}

std::string format_info(const McapReader& reader, const std::string& path) {
  const FileReport& r = reader.report();
  std::ostringstream os;
  char buf[256];
  os << "file:      " << path << " (" << r.file_size << " bytes)\n";
  os << "state:     "
     << (r.complete ? "complete (summary and footer valid)"
                    : "RECOVERED (incomplete or damaged; the readable part is listed)")
     << "\n";
  for (const std::string& p : r.problems) {
    os << "  problem: " << p << "\n";
  }
  if (!r.library.empty()) {
    os << "library:   " << r.library << "\n";
  }
  const double duration_s =
      r.messages > 0 ? static_cast<double>(r.end_ns - r.start_ns) * 1e-9 : 0.0;
  std::snprintf(buf, sizeof(buf), "duration:  %.3f s (log time %llu .. %llu ns)\n", duration_s,
                static_cast<unsigned long long>(r.start_ns),
                static_cast<unsigned long long>(r.end_ns));
  os << buf;
  os << "messages:  " << r.messages << " in " << r.chunks << " chunks\n";
  os << "topics:    " << reader.channels().size() << "\n";
  for (const TopicSummary& t : summarise_topics(reader)) {
    std::snprintf(buf, sizeof(buf), "  %-28s %-30s %9llu msgs %9.2f Hz  %s\n", t.topic.c_str(),
                  t.type.empty() ? "(no schema)" : t.type.c_str(),
                  static_cast<unsigned long long>(t.messages), t.rate_hz,
                  t.message_encoding.c_str());
    os << buf;
  }
  return os.str();
}

}  // namespace poise::record
