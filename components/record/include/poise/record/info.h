// `poise info`: a human-readable description of an MCAP file (pure; no I/O besides the reader).
#pragma once

#include "poise/record/mcap.h"

#include <string>
#include <vector>

namespace poise::record {

struct TopicSummary {
  std::string topic;
  std::string type;             ///< schema name ("" when schemaless)
  std::string message_encoding;
  uint64_t messages = 0;
  double rate_hz = 0.0;         ///< messages / recording span (log time, first to last message of the file); 0 for a span of 0
};

/// One entry per channel, sorted by topic.
std::vector<TopicSummary> summarise_topics(const McapReader& reader);

/// The `poise info` text: state (complete / recovered + problems), duration, topics table.
std::string format_info(const McapReader& reader, const std::string& path);

}  // namespace poise::record
