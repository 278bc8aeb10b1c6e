#include "poise/record/mcap.h"

#include "bytes.h"

#include <chrono>

#ifdef POISE_RECORD_HAVE_ZSTD
#include <zstd.h>
#endif

namespace poise::record {

using detail::begin_record;
using detail::end_record;
using detail::put_bytes32;
using detail::put_string;
using detail::put_u16;
using detail::put_u32;
using detail::put_u64;
using detail::put_u8;

const uint8_t kMagic[8] = {0x89, 'M', 'C', 'A', 'P', 0x30, '\r', '\n'};

bool zstd_available() {
#ifdef POISE_RECORD_HAVE_ZSTD
  return true;
#else
  return false;
#endif
}

McapWriter::McapWriter(std::unique_ptr<Sink> sink, WriterOptions options)
    : sink_(std::move(sink)), sink_name_(sink_->name()), options_(std::move(options)) {
  if (options_.compression == Compression::kZstd && !zstd_available()) {
    throw WriteError("zstd compression requested but this build has no libzstd (install "
                     "libzstd-dev and rebuild, or record uncompressed)");
  }
  if (options_.chunk_size_bytes == 0 || options_.max_chunk_duration_ns <= 0) {
    throw WriteError("chunk size and chunk duration must be positive");
  }
  std::vector<uint8_t> out(kMagic, kMagic + 8);
  const size_t at = begin_record(out, Opcode::kHeader);
  put_string(out, options_.profile);
  put_string(out, options_.library);
  end_record(out, at);
  try {
    write_raw(out);
  } catch (const IoError& e) {
    closed_ = true;
    failure_ = e.what();
    throw WriteError(std::string(e.what()) + "; no recording was started");
  }
}

McapWriter::~McapWriter() {
  try {
    close();
  } catch (...) {  // NOLINT(bugprone-empty-catch): a destructor must not throw; close() reports
  }
}

int64_t McapWriter::now() const {
  if (options_.clock) {
    return options_.clock();
  }
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

void McapWriter::write_raw(const std::vector<uint8_t>& bytes) {
  sink_->write(bytes.data(), bytes.size());
  data_crc_ = crc32_update(data_crc_, bytes.data(), bytes.size());
  good_offset_ += bytes.size();
  stats_.bytes = good_offset_;
}

uint16_t McapWriter::add_schema(const std::string& name, const std::string& encoding,
                                const std::vector<uint8_t>& data) {
  if (!failure_.empty()) {
    throw WriteError(failure_);
  }
  if (closed_) {
    throw WriteError("add_schema after close()");
  }
  if (schemas_.size() >= 0xFFFEu) {
    throw WriteError("too many schemas (MCAP allows 65535)");
  }
  Schema schema;
  schema.id = static_cast<uint16_t>(schemas_.size() + 1);
  schema.name = name;
  schema.encoding = encoding;
  schema.data = data;
  std::vector<uint8_t> out;
  const size_t at = begin_record(out, Opcode::kSchema);
  put_u16(out, schema.id);
  put_string(out, schema.name);
  put_string(out, schema.encoding);
  put_bytes32(out, schema.data);
  end_record(out, at);
  try {
    write_raw(out);
  } catch (const IoError& e) {
    fail(e.what());
  }
  schemas_.push_back(std::move(schema));
  return schemas_.back().id;
}

uint16_t McapWriter::add_channel(uint16_t schema_id, const std::string& topic,
                                 const std::string& message_encoding,
                                 const std::map<std::string, std::string>& metadata) {
  if (!failure_.empty()) {
    throw WriteError(failure_);
  }
  if (closed_) {
    throw WriteError("add_channel after close()");
  }
  if (schema_id > schemas_.size()) {
    throw WriteError("add_channel: unknown schema id " + std::to_string(schema_id));
  }
  if (channels_.size() > 0xFFFFu) {  // ids 0..65535 are all taken
    throw WriteError("too many channels: an MCAP file holds at most 65536 (channel ids 0-65535)");
  }
  Channel channel;
  channel.id = static_cast<uint16_t>(channels_.size());
  channel.schema_id = schema_id;
  channel.topic = topic;
  channel.message_encoding = message_encoding;
  channel.metadata = metadata;
  std::vector<uint8_t> out;
  const size_t at = begin_record(out, Opcode::kChannel);
  put_u16(out, channel.id);
  put_u16(out, channel.schema_id);
  put_string(out, channel.topic);
  put_string(out, channel.message_encoding);
  std::vector<uint8_t> map;
  for (const auto& [key, value] : channel.metadata) {
    put_string(map, key);
    put_string(map, value);
  }
  put_bytes32(out, map);
  end_record(out, at);
  try {
    write_raw(out);
  } catch (const IoError& e) {
    fail(e.what());
  }
  channels_.push_back(std::move(channel));
  return channels_.back().id;
}

void McapWriter::write(uint16_t channel_id, uint32_t sequence, uint64_t log_time_ns,
                       uint64_t publish_time_ns, const uint8_t* data, size_t size) {
  if (!failure_.empty()) {
    throw WriteError(failure_);
  }
  if (closed_) {
    throw WriteError("write after close()");
  }
  if (channel_id >= channels_.size()) {
    throw WriteError("write: unknown channel id " + std::to_string(channel_id));
  }
  if (chunk_messages_ == 0) {
    chunk_opened_at_ = now();
    chunk_start_ns_ = log_time_ns;
    chunk_end_ns_ = log_time_ns;
  }
  const uint64_t offset = chunk_.size();
  const size_t at = begin_record(chunk_, Opcode::kMessage);
  put_u16(chunk_, channel_id);
  put_u32(chunk_, sequence);
  put_u64(chunk_, log_time_ns);
  put_u64(chunk_, publish_time_ns);
  chunk_.insert(chunk_.end(), data, data + size);
  end_record(chunk_, at);
  chunk_index_[channel_id].emplace_back(log_time_ns, offset);
  chunk_start_ns_ = std::min(chunk_start_ns_, log_time_ns);
  chunk_end_ns_ = std::max(chunk_end_ns_, log_time_ns);
  ++chunk_messages_;
  stats_.pending_messages = chunk_messages_;
  if (chunk_.size() >= options_.chunk_size_bytes ||
      now() - chunk_opened_at_ >= options_.max_chunk_duration_ns) {
    close_chunk();
  }
}

void McapWriter::tick() {
  if (!failure_.empty() || closed_ || chunk_messages_ == 0) {
    return;
  }
  if (now() - chunk_opened_at_ >= options_.max_chunk_duration_ns) {
    close_chunk();
  }
}

void McapWriter::flush() {
  if (!failure_.empty()) {
    throw WriteError(failure_);
  }
  if (!closed_) {
    close_chunk();
  }
}

void McapWriter::close_chunk() {
  if (chunk_messages_ == 0) {
    return;
  }
  const uint32_t crc = crc32_update(0, chunk_.data(), chunk_.size());
  const std::vector<uint8_t>* body = &chunk_;
  std::vector<uint8_t> compressed;
  std::string compression;
#ifdef POISE_RECORD_HAVE_ZSTD
  if (options_.compression == Compression::kZstd) {
    compressed.resize(ZSTD_compressBound(chunk_.size()));
    const size_t n = ZSTD_compress(compressed.data(), compressed.size(), chunk_.data(),
                                   chunk_.size(), options_.zstd_level);
    if (ZSTD_isError(n) != 0U) {
      fail(std::string("zstd compression failed: ") + ZSTD_getErrorName(n));
    }
    compressed.resize(n);
    body = &compressed;
    compression = "zstd";
  }
#endif
  std::vector<uint8_t> out;
  out.reserve(body->size() + 64 + chunk_index_.size() * 64 + chunk_messages_ * 16);
  const size_t at = begin_record(out, Opcode::kChunk);
  put_u64(out, chunk_start_ns_);
  put_u64(out, chunk_end_ns_);
  put_u64(out, chunk_.size());
  put_u32(out, crc);
  put_string(out, compression);
  put_u64(out, body->size());
  out.insert(out.end(), body->begin(), body->end());
  end_record(out, at);
  ChunkIndexEntry entry{};
  entry.start_ns = chunk_start_ns_;
  entry.end_ns = chunk_end_ns_;
  entry.offset = good_offset_;
  entry.length = out.size();
  entry.compressed_size = body->size();
  entry.uncompressed_size = chunk_.size();
  for (const auto& [channel_id, records] : chunk_index_) {
    entry.message_index_offsets[channel_id] = good_offset_ + out.size();
    const size_t mat = begin_record(out, Opcode::kMessageIndex);
    put_u16(out, channel_id);
    put_u32(out, static_cast<uint32_t>(records.size() * 16));
    for (const auto& [log_time, offset] : records) {
      put_u64(out, log_time);
      put_u64(out, offset);
    }
    end_record(out, mat);
  }
  entry.message_index_length = good_offset_ + out.size() - entry.offset - entry.length;
  try {
    write_raw(out);
  } catch (const IoError& e) {
    fail(e.what());
  }
  // Durable: commit the chunk's figures.
  if (stats_.messages == 0) {
    message_start_ns_ = chunk_start_ns_;
    message_end_ns_ = chunk_end_ns_;
  }
  message_start_ns_ = std::min(message_start_ns_, chunk_start_ns_);
  message_end_ns_ = std::max(message_end_ns_, chunk_end_ns_);
  for (const auto& [channel_id, records] : chunk_index_) {
    channel_counts_[channel_id] += records.size();
  }
  chunk_indexes_.push_back(std::move(entry));
  stats_.messages += chunk_messages_;
  stats_.chunks += 1;
  stats_.pending_messages = 0;
  chunk_.clear();
  chunk_index_.clear();
  chunk_messages_ = 0;
}

// not split: the MCAP summary section written in the order the specification gives (schemas,
// channels, statistics, indexes, offsets, footer), with one running CRC.
void McapWriter::finalise() {
  std::vector<uint8_t> out;
  size_t at = begin_record(out, Opcode::kDataEnd);
  put_u32(out, data_crc_);
  end_record(out, at);
  const uint64_t summary_start = good_offset_ + out.size();
  const size_t summary_pos = out.size();

  struct Group {
    Opcode op;
    uint64_t start, length;
  };
  std::vector<Group> groups;
  auto open_group = [&](Opcode op) { groups.push_back({op, good_offset_ + out.size(), 0}); };
  auto close_group = [&]() { groups.back().length = good_offset_ + out.size() - groups.back().start; };

  if (!schemas_.empty()) {
    open_group(Opcode::kSchema);
    for (const Schema& s : schemas_) {
      at = begin_record(out, Opcode::kSchema);
      put_u16(out, s.id);
      put_string(out, s.name);
      put_string(out, s.encoding);
      put_bytes32(out, s.data);
      end_record(out, at);
    }
    close_group();
  }
  if (!channels_.empty()) {
    open_group(Opcode::kChannel);
    for (const Channel& c : channels_) {
      at = begin_record(out, Opcode::kChannel);
      put_u16(out, c.id);
      put_u16(out, c.schema_id);
      put_string(out, c.topic);
      put_string(out, c.message_encoding);
      std::vector<uint8_t> map;
      for (const auto& [key, value] : c.metadata) {
        put_string(map, key);
        put_string(map, value);
      }
      put_bytes32(out, map);
      end_record(out, at);
    }
    close_group();
  }
  open_group(Opcode::kStatistics);
  at = begin_record(out, Opcode::kStatistics);
  put_u64(out, stats_.messages);
  put_u16(out, static_cast<uint16_t>(schemas_.size()));
  put_u32(out, static_cast<uint32_t>(channels_.size()));
  put_u32(out, 0);  // attachments
  put_u32(out, 0);  // metadata
  put_u32(out, static_cast<uint32_t>(chunk_indexes_.size()));
  put_u64(out, stats_.messages > 0 ? message_start_ns_ : 0);
  put_u64(out, stats_.messages > 0 ? message_end_ns_ : 0);
  std::vector<uint8_t> counts;
  for (const auto& [channel_id, count] : channel_counts_) {
    put_u16(counts, channel_id);
    put_u64(counts, count);
  }
  put_bytes32(out, counts);
  end_record(out, at);
  close_group();
  if (!chunk_indexes_.empty()) {
    open_group(Opcode::kChunkIndex);
    for (const ChunkIndexEntry& c : chunk_indexes_) {
      at = begin_record(out, Opcode::kChunkIndex);
      put_u64(out, c.start_ns);
      put_u64(out, c.end_ns);
      put_u64(out, c.offset);
      put_u64(out, c.length);
      std::vector<uint8_t> map;
      for (const auto& [channel_id, offset] : c.message_index_offsets) {
        put_u16(map, channel_id);
        put_u64(map, offset);
      }
      put_bytes32(out, map);
      put_u64(out, c.message_index_length);
      put_string(out, options_.compression == Compression::kZstd ? "zstd" : "");
      put_u64(out, c.compressed_size);
      put_u64(out, c.uncompressed_size);
      end_record(out, at);
    }
    close_group();
  }
  const uint64_t summary_offset_start = good_offset_ + out.size();
  for (const Group& g : groups) {
    at = begin_record(out, Opcode::kSummaryOffset);
    put_u8(out, static_cast<uint8_t>(g.op));
    put_u64(out, g.start);
    put_u64(out, g.length);
    end_record(out, at);
  }
  put_u8(out, static_cast<uint8_t>(Opcode::kFooter));
  put_u64(out, 20);  // summary_start + summary_offset_start + summary_crc
  put_u64(out, summary_start);
  put_u64(out, summary_offset_start);
  // The summary CRC covers the summary, the summary offsets and the footer up to this field.
  put_u32(out, crc32_update(0, out.data() + summary_pos, out.size() - summary_pos));
  out.insert(out.end(), kMagic, kMagic + 8);
  sink_->write(out.data(), out.size());
  stats_.bytes = sink_->position();
  closed_ = true;
}

void McapWriter::close() {
  if (closed_) {
    return;
  }
  close_chunk();  // throws WriteError via fail() on I/O failure (the file is then finalised)
  try {
    finalise();
  } catch (const IoError& e) {
    fail(e.what());
  }
}

void McapWriter::fail(const std::string& what) {
  stats_.lost_messages += chunk_messages_;  // the open chunk never reached the file
  chunk_.clear();
  chunk_index_.clear();
  chunk_messages_ = 0;
  stats_.pending_messages = 0;
  std::string outcome;
  try {
    sink_->truncate(good_offset_);
    finalise();
    outcome = "the file was finalised with the " + std::to_string(stats_.messages) +
              " messages of its " + std::to_string(stats_.chunks) + " complete chunks";
  } catch (const IoError& e1) {
    // Not even room for the summary: end the data section without one (readers scan it).
    try {
      sink_->truncate(good_offset_);
      std::vector<uint8_t> out;
      size_t at = begin_record(out, Opcode::kDataEnd);
      put_u32(out, data_crc_);
      end_record(out, at);
      at = begin_record(out, Opcode::kFooter);
      put_u64(out, 0);
      put_u64(out, 0);
      put_u32(out, 0);
      end_record(out, at);
      out.insert(out.end(), kMagic, kMagic + 8);
      sink_->write(out.data(), out.size());
      outcome = "the file was ended without a summary (" + std::string(e1.what()) +
                "); its " + std::to_string(stats_.messages) +
                " messages are readable (poise info recovers them)";
    } catch (const IoError& e2) {
      outcome = "the file could not be finalised (" + std::string(e2.what()) +
                "); it holds " + std::to_string(stats_.messages) +
                " messages up to byte " + std::to_string(good_offset_) +
                " which `poise info` recovers";
    }
  }
  closed_ = true;
  failure_detail_ = "recording to " + sink_name_ + " stopped: " + what + "; " + outcome;
  failure_ = failure_detail_ + " (" + std::to_string(stats_.lost_messages) + " messages lost)";
  stats_.bytes = sink_->position();
  throw WriteError(failure_);
}

}  // namespace poise::record
