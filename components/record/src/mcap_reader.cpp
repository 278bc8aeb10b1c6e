#include "poise/record/mcap.h"

#include "bytes.h"

#include <algorithm>
#include <cstring>
#include <memory>

#ifdef POISE_RECORD_HAVE_ZSTD
#include <zstd.h>
#endif

namespace poise::record {

using detail::get_u32;
using detail::get_u64;
using detail::opcode_name;
using detail::Parser;

namespace {

constexpr uint64_t kRecordHeader = 9;           // opcode + length
constexpr uint64_t kFooterRecord = 9 + 20;      // Footer with its fields
constexpr uint64_t kMaxRecordBytes = 1ULL << 30;  // refuse to load larger records (corruption)

std::string at_byte(uint64_t offset) { return "at byte " + std::to_string(offset); }

Schema parse_schema(const uint8_t* body, size_t size) {
  Parser p(body, size, "Schema");
  Schema s;
  s.id = p.u16();
  s.name = p.str();
  s.encoding = p.str();
  s.data = p.bytes32();
  if (s.id == 0) {
    throw ReadError("Schema record with id 0 (reserved)");
  }
  return s;
}

Channel parse_channel(const uint8_t* body, size_t size) {
  Parser p(body, size, "Channel");
  Channel c;
  c.id = p.u16();
  c.schema_id = p.u16();
  c.topic = p.str();
  c.message_encoding = p.str();
  const uint32_t map_len = p.u32();
  p.need(map_len);
  Parser m(p.here(), map_len, "Channel metadata");
  while (m.left() > 0) {
    std::string key = m.str();
    c.metadata[key] = m.str();
  }
  return c;
}

/// Calls VISIT(opcode, body, body_size, offset) for each record in RECORDS; throws ReadError on
/// framing errors.
template <typename Visit>
void for_each_record(const uint8_t* records, size_t size, const char* where, Visit visit) {
  size_t pos = 0;
  while (pos < size) {
    if (size - pos < kRecordHeader) {
      throw ReadError(std::string(where) + ": record header cut short at offset " +
                      std::to_string(pos));
    }
    const uint8_t op = records[pos];
    const uint64_t len = get_u64(records + pos + 1);
    if (len > size - pos - kRecordHeader) {
      throw ReadError(std::string(where) + ": " + opcode_name(op) + " record at offset " +
                      std::to_string(pos) + " claims " + std::to_string(len) +
                      " bytes, only " + std::to_string(size - pos - kRecordHeader) + " left");
    }
    visit(op, records + pos + kRecordHeader, static_cast<size_t>(len), pos);
    pos += kRecordHeader + static_cast<size_t>(len);
  }
}

}  // namespace

std::vector<uint8_t> chunk_records(const uint8_t* body, size_t size) {
  Parser p(body, size, "Chunk");
  p.u64();  // message start time
  p.u64();  // message end time
  const uint64_t uncompressed_size = p.u64();
  const uint32_t crc = p.u32();
  const std::string compression = p.str();
  const uint64_t records_len = p.u64();
  p.need(records_len);
  if (p.left() != records_len) {
    throw ReadError("Chunk record has " + std::to_string(p.left() - records_len) +
                    " stray bytes after its records");
  }
  if (compression.empty() && records_len != uncompressed_size) {
    throw ReadError("uncompressed Chunk: records length " + std::to_string(records_len) +
                    " != uncompressed size " + std::to_string(uncompressed_size));
  }
  if (!compression.empty() &&
      (uncompressed_size > kMaxChunkBytes || uncompressed_size > records_len * kMaxCompressionRatio)) {  // records_len: bytes in memory, no overflow
    throw ReadError("chunk claims " + std::to_string(uncompressed_size) + " bytes uncompressed from " +
                    std::to_string(records_len) + " compressed: more than the " +
                    std::to_string(kMaxCompressionRatio) + "x / " + std::to_string(kMaxChunkBytes >> 20) +
                    " MiB a chunk may hold (corrupt)");
  }
  std::vector<uint8_t> out;
  if (compression.empty()) {
    out.assign(p.here(), p.here() + records_len);  // bytes that are in the file
  } else if (compression == "zstd") {
#ifdef POISE_RECORD_HAVE_ZSTD
    const unsigned long long frame_size =
        ZSTD_getFrameContentSize(p.here(), static_cast<size_t>(records_len));
    if (frame_size != ZSTD_CONTENTSIZE_UNKNOWN && frame_size != ZSTD_CONTENTSIZE_ERROR &&
        frame_size != uncompressed_size) {
      throw ReadError("zstd chunk holds " + std::to_string(frame_size) +
                      " bytes but claims " + std::to_string(uncompressed_size));
    }
    // Streamed: the buffer grows by what zstd produces (at most the claimed size), so a frame
    // without a content size that claims much and holds little costs what it holds.
    const std::unique_ptr<ZSTD_DStream, size_t (*)(ZSTD_DStream*)> stream(ZSTD_createDStream(), ZSTD_freeDStream);
    if (!stream) {
      throw ReadError("zstd: cannot create a decompression stream");
    }
    ZSTD_inBuffer in{p.here(), static_cast<size_t>(records_len), 0};
    constexpr size_t kStep = size_t{1} << 20;
    const auto step = [&stream, &in](ZSTD_outBuffer& o) {
      const size_t before_in = in.pos;
      const size_t before_out = o.pos;
      const size_t r = ZSTD_decompressStream(stream.get(), &o, &in);
      if (ZSTD_isError(r) != 0U) {
        throw ReadError(std::string("zstd chunk does not decompress: ") + ZSTD_getErrorName(r));
      }
      if (r != 0 && in.pos == before_in && o.pos == before_out) {
        throw ReadError("zstd chunk is cut short (its frame does not end)");
      }
      return r == 0 && in.pos == in.size;  // every frame decoded and flushed
    };
    size_t produced = 0;
    for (bool done = false; !done;) {
      if (produced == out.size() && out.size() == uncompressed_size) {
        uint8_t extra = 0;  // full: one byte more would exceed the claim
        ZSTD_outBuffer probe{&extra, 1, 0};
        done = step(probe);
        if (probe.pos > 0) {
          throw ReadError("zstd chunk decompresses to more than the " + std::to_string(uncompressed_size) +
                          " bytes it claims");
        }
        continue;
      }
      if (produced == out.size()) {
        out.resize(static_cast<size_t>(std::min<uint64_t>(uncompressed_size, out.size() + kStep)));
      }
      ZSTD_outBuffer o{out.data(), out.size(), produced};
      done = step(o);
      produced = o.pos;
    }
    if (produced != uncompressed_size) {
      throw ReadError("zstd chunk decompressed to " + std::to_string(produced) + " bytes, expected " +
                      std::to_string(uncompressed_size));
    }
    out.resize(produced);
#else
    throw ReadError("zstd-compressed chunk but this build has no libzstd (install libzstd-dev "
                    "and rebuild)");
#endif
  } else {
    throw ReadError("chunk compression '" + compression +
                    "' is not supported (poise reads uncompressed and zstd chunks)");
  }
  if (crc != 0) {
    const uint32_t actual = crc32_update(0, out.data(), out.size());
    if (actual != crc) {
      throw ReadError("chunk CRC mismatch (stored " + std::to_string(crc) + ", computed " +
                      std::to_string(actual) + "): the chunk is corrupt");
    }
  }
  return out;
}

McapReader::McapReader(std::unique_ptr<Source> source) : source_(std::move(source)) {
  report_.file_size = source_->size();
  if (report_.file_size < 8 + kRecordHeader) {
    throw ReadError(source_->name() + " is not an MCAP file: only " +
                    std::to_string(report_.file_size) + " bytes");
  }
  uint8_t magic[8];
  source_->read(0, 8, magic);
  if (std::memcmp(magic, kMagic, 8) != 0) {
    throw ReadError(source_->name() + " is not an MCAP file (wrong magic bytes at the start)");
  }
  // Header.
  uint8_t head[kRecordHeader];
  source_->read(8, kRecordHeader, head);
  const uint64_t header_len = get_u64(head + 1);
  if (head[0] == static_cast<uint8_t>(Opcode::kHeader) &&
      header_len <= report_.file_size - 8 - kRecordHeader && header_len < (1u << 20)) {
    std::vector<uint8_t> body(static_cast<size_t>(header_len));
    source_->read(8 + kRecordHeader, body.size(), body.data());
    try {
      Parser p(body.data(), body.size(), "Header");
      report_.profile = p.str();
      report_.library = p.str();
    } catch (const ReadError& e) {
      report_.problems.push_back(std::string("Header: ") + e.what());
    }
  } else {
    report_.problems.push_back("the first record is not a valid Header");
  }
  if (!read_summary()) {
    scan();
  }
  check_channel_schemas();
}

void McapReader::check_channel_schemas() {
  for (auto& [id, channel] : channels_) {
    if (channel.schema_id != 0 && schemas_.count(channel.schema_id) == 0) {
      report_.problems.push_back("Channel " + std::to_string(id) + " ('" + channel.topic +
                                 "') refers to schema " + std::to_string(channel.schema_id) +
                                 ", which the file does not define: read without a schema");
      ++report_.corrupt;
      report_.complete = false;
      channel.schema_id = 0;
    }
  }
  // Messages on a channel id without a Channel record cannot be read (no topic, no type): said
  // and counted, never dropped silently.
  for (const auto& [id, counts] : report_.channels) {
    if (counts.messages > 0 && channels_.count(id) == 0) {
      report_.problems.push_back(std::to_string(counts.messages) + " messages on channel " + std::to_string(id) +
                                 ", which the file does not define (no Channel record): they cannot be read");
      ++report_.corrupt;
      report_.complete = false;
    }
  }
}

McapReader McapReader::open_file(const std::string& path) {
  try {
    return McapReader(open_file_source(path));
  } catch (const IoError& e) {
    throw ReadError(e.what());
  }
}

void McapReader::add_schema(Schema schema) {
  const uint16_t id = schema.id;
  schemas_[id] = std::move(schema);
}

void McapReader::add_channel(Channel channel) {
  const uint16_t id = channel.id;
  channels_[id] = std::move(channel);
}

// not split: the MCAP footer -> summary -> index walk, where each record's offsets are checked
// against the one before before anything is trusted.
bool McapReader::read_summary() {
  const uint64_t size = report_.file_size;
  if (size < 8 + kRecordHeader + kFooterRecord + 8) {
    report_.problems.push_back("no footer: the file is cut short (" + std::to_string(size) +
                               " bytes)");
    return false;
  }
  const uint64_t footer_at = size - 8 - kFooterRecord;
  uint8_t tail[kFooterRecord + 8];
  source_->read(footer_at, sizeof(tail), tail);
  if (std::memcmp(tail + kFooterRecord, kMagic, 8) != 0 ||
      tail[0] != static_cast<uint8_t>(Opcode::kFooter) || get_u64(tail + 1) != 20) {
    report_.problems.push_back("no footer at the end: the recording was not finalised (writer "
                               "killed, or still recording)");
    return false;
  }
  const uint64_t summary_start = get_u64(tail + 9);
  const uint64_t summary_offset_start = get_u64(tail + 17);
  const uint32_t summary_crc = get_u32(tail + 25);
  if (summary_start == 0) {
    report_.problems.push_back("the file has no summary section (the writer could not write "
                               "it): scanned the data section");
    return false;
  }
  if (summary_start < 8 || summary_start > footer_at ||
      (summary_offset_start != 0 &&
       (summary_offset_start < summary_start || summary_offset_start > footer_at))) {
    report_.problems.push_back("the footer's summary offsets are out of range (corrupt footer)");
    return false;
  }
  const uint64_t crc_len = footer_at + 17 - summary_start + 8;  // through summary_offset_start
  if (crc_len > kMaxRecordBytes) {
    report_.problems.push_back("summary section too large to load");
    return false;
  }
  std::vector<uint8_t> summary(static_cast<size_t>(crc_len));
  source_->read(summary_start, summary.size(), summary.data());
  if (summary_crc != 0) {
    const uint32_t actual = crc32_update(0, summary.data(), summary.size());
    if (actual != summary_crc) {
      report_.problems.push_back("summary CRC mismatch (stored " + std::to_string(summary_crc) +
                                 ", computed " + std::to_string(actual) +
                                 "): the summary is corrupt; scanned the data section");
      return false;
    }
  }
  const uint64_t summary_end =
      (summary_offset_start != 0 ? summary_offset_start : footer_at) - summary_start;
  bool have_stats = false;
  std::vector<ChunkLocation> chunks;
  try {
    for_each_record(summary.data(), static_cast<size_t>(summary_end), "summary",
                    [&](uint8_t op, const uint8_t* body, size_t len, size_t /*offset*/) {
                      switch (static_cast<Opcode>(op)) {
                        case Opcode::kSchema:
                          add_schema(parse_schema(body, len));
                          break;
                        case Opcode::kChannel:
                          add_channel(parse_channel(body, len));
                          break;
                        case Opcode::kChunkIndex: {
                          Parser p(body, len, "Chunk Index");
                          ChunkLocation c;
                          c.start_ns = p.u64();
                          c.end_ns = p.u64();
                          c.offset = p.u64();
                          c.length = p.u64();
                          if (c.offset < 8 || c.offset > size || c.length > size - c.offset) {
                            throw ReadError("Chunk Index points outside the file");
                          }
                          chunks.push_back(c);
                          break;
                        }
                        case Opcode::kStatistics: {
                          Parser p(body, len, "Statistics");
                          report_.messages = p.u64();
                          p.u16();
                          p.u32();
                          p.u32();
                          p.u32();
                          report_.chunks = p.u32();
                          report_.start_ns = p.u64();
                          report_.end_ns = p.u64();
                          const uint32_t map_len = p.u32();
                          p.need(map_len);
                          Parser m(p.here(), map_len, "Statistics channel counts");
                          while (m.left() > 0) {
                            const uint16_t id = m.u16();
                            report_.channels[id].messages = m.u64();
                          }
                          have_stats = true;
                          break;
                        }
                        default:
                          break;
                      }
                    });
  } catch (const ReadError& e) {
    report_.problems.push_back(std::string("unreadable summary (") + e.what() +
                               "): scanned the data section");
    schemas_.clear();
    channels_.clear();
    report_.channels.clear();
    return false;
  }
  if (!have_stats || (chunks.empty() && report_.messages > 0)) {
    // Summary without statistics (another writer): count by scanning, but the file is intact.
    schemas_.clear();
    channels_.clear();
    report_.channels.clear();
    scan();
    report_.complete = report_.problems.empty();
    report_.recovered = !report_.complete;
    return true;
  }
  std::stable_sort(chunks.begin(), chunks.end(),
                   [](const ChunkLocation& a, const ChunkLocation& b) {
                     return a.start_ns < b.start_ns;
                   });
  chunks_ = std::move(chunks);
  report_.complete = true;
  report_.recovered = false;
  return true;
}

const FileReport& McapReader::verify() {
  schemas_.clear();
  channels_.clear();
  const std::string profile = report_.profile;
  const std::string library = report_.library;
  const bool had_summary = report_.complete;
  std::vector<std::string> header_problems;
  for (const std::string& p : report_.problems) {
    if (p.rfind("Header", 0) == 0 || p.rfind("the first record", 0) == 0) {
      header_problems.push_back(p);
    }
  }
  report_ = FileReport{};
  report_.file_size = source_->size();
  report_.profile = profile;
  report_.library = library;
  report_.problems = header_problems;
  scan();
  check_channel_schemas();
  if (had_summary && report_.problems.empty()) {
    report_.complete = true;
    report_.recovered = false;
  }
  return report_;
}

void McapReader::count_message(uint16_t channel_id, uint64_t log_time) {
  ChannelCounts& c = report_.channels[channel_id];
  if (c.messages == 0 || log_time < c.first_log_ns) {
    c.first_log_ns = log_time;
  }
  c.last_log_ns = std::max(c.last_log_ns, log_time);
  ++c.messages;
  const bool first = report_.messages == 0;
  if (first || log_time < report_.start_ns) {
    report_.start_ns = log_time;
  }
  if (first || log_time > report_.end_ns) {
    report_.end_ns = log_time;
  }
  ++report_.messages;
}

std::optional<uint64_t> McapReader::find_chunk(uint64_t from) const {
  const uint64_t size = report_.file_size;
  constexpr size_t kWindow = 1 << 20;
  constexpr uint64_t kChunkFixed = 8 + 8 + 8 + 4 + 4;
  std::vector<uint8_t> window;
  for (uint64_t base = from; base + kRecordHeader + kChunkFixed < size; base += kWindow) {
    const size_t n = static_cast<size_t>(std::min<uint64_t>(kWindow + 128, size - base));
    window.resize(n);
    source_->read(base, n, window.data());
    for (size_t i = 0; i < std::min(kWindow, n); ++i) {
      if (window[i] != static_cast<uint8_t>(Opcode::kChunk) || i + kRecordHeader + kChunkFixed > n) {
        continue;
      }
      const uint8_t* r = window.data() + i;
      const uint64_t len = get_u64(r + 1);
      const uint64_t start = get_u64(r + 9);
      const uint64_t end = get_u64(r + 17);
      const uint32_t clen = get_u32(r + 9 + 28);
      if (clen > 16 || start > end || len > size - base - i - kRecordHeader ||
          i + kRecordHeader + kChunkFixed + clen + 8 > n) {
        continue;
      }
      const uint64_t rlen = get_u64(r + kRecordHeader + kChunkFixed + clen);
      if (len == kChunkFixed + clen + 8 + rlen) {
        return base + i;
      }
    }
  }
  return std::nullopt;
}

void McapReader::scan_chunk(uint64_t pos, const std::vector<uint8_t>& record, ScanState& state) {
  const uint8_t* body = record.data() + kRecordHeader;
  const size_t body_len = record.size() - kRecordHeader;
  std::vector<uint8_t> records;
  try {
    records = chunk_records(body, body_len);
  } catch (const ReadError& e) {
    ++state.chunk_fail;
    ++report_.corrupt;
    report_.problems.push_back("chunk " + at_byte(pos) + " (" + std::to_string(record.size()) +
                               " bytes): " + e.what() + "; its messages are skipped");
    return;
  }
  ChunkLocation loc{pos, record.size(), get_u64(body), get_u64(body + 8), true};
  for_each_record(records.data(), records.size(), "chunk",
                  [&](uint8_t rop, const uint8_t* rbody, size_t rlen, size_t) {
                    if (rop == static_cast<uint8_t>(Opcode::kSchema)) {
                      add_schema(parse_schema(rbody, rlen));
                    } else if (rop == static_cast<uint8_t>(Opcode::kChannel)) {
                      add_channel(parse_channel(rbody, rlen));
                    } else if (rop == static_cast<uint8_t>(Opcode::kMessage)) {
                      Parser p(rbody, rlen, "Message");
                      const uint16_t channel_id = p.u16();
                      p.u32();
                      count_message(channel_id, p.u64());
                    }
                  });
  chunks_.push_back(loc);
  ++report_.chunks;
}

bool McapReader::scan_record(uint64_t pos, const std::vector<uint8_t>& record, ScanState& state) {
  const uint8_t op = record[0];
  const uint8_t* body = record.data() + kRecordHeader;
  const size_t body_len = record.size() - kRecordHeader;
  bool stop = false;
  try {
    switch (static_cast<Opcode>(op)) {
      case Opcode::kHeader:
        break;
      case Opcode::kSchema:
        add_schema(parse_schema(body, body_len));
        break;
      case Opcode::kChannel:
        add_channel(parse_channel(body, body_len));
        break;
      case Opcode::kMessage: {
        Parser p(body, body_len, "Message");
        const uint16_t channel_id = p.u16();
        p.u32();
        const uint64_t log_time = p.u64();
        count_message(channel_id, log_time);
        chunks_.push_back({pos, record.size(), log_time, log_time, false});
        break;
      }
      case Opcode::kChunk:
        scan_chunk(pos, record, state);
        break;
      case Opcode::kDataEnd: {
        Parser p(body, body_len, "Data End");
        const uint32_t stored = p.u32();
        if (stored != 0 && state.crc_valid && stored != state.data_crc) {
          ++report_.corrupt;
          report_.problems.push_back("data section CRC mismatch (stored " + std::to_string(stored) +
                                     ", computed " + std::to_string(state.data_crc) +
                                     "): some bytes are corrupt");
        }
        state.saw_data_end = true;
        stop = true;
        break;
      }
      case Opcode::kFooter:
        stop = true;
        break;
      default:
        break;  // indexes, attachments, metadata: not needed to read messages
    }
  } catch (const ReadError& e) {
    ++report_.corrupt;
    report_.problems.push_back(std::string(opcode_name(op)) + " record " + at_byte(pos) + ": " + e.what() +
                               "; skipped");
  }
  return stop;
}

void McapReader::scan() {
  const uint64_t size = report_.file_size;
  chunks_.clear();
  report_.messages = 0;
  report_.chunks = 0;
  report_.channels.clear();
  report_.complete = false;
  ScanState state;
  uint64_t last_good_end = 8;
  uint8_t magic[8];
  source_->read(0, 8, magic);
  state.data_crc = crc32_update(0, magic, 8);
  std::vector<uint8_t> record;

  uint64_t pos = 8;
  while (pos < size) {
    if (size - pos < kRecordHeader) {
      report_.problems.push_back("the file ends inside a record header " + at_byte(pos) + ": cut short");
      break;
    }
    uint8_t head[kRecordHeader];
    source_->read(pos, kRecordHeader, head);
    const uint8_t op = head[0];
    const uint64_t len = get_u64(head + 1);
    const bool valid_op = op >= 0x01 && op <= 0x0F;
    if (!valid_op || len > size - pos - kRecordHeader || len > kMaxRecordBytes) {
      std::string why;
      if (!valid_op) {
        why = "invalid record opcode " + std::to_string(op) + " " + at_byte(pos);
      } else {
        why = "the file ends inside a " + std::string(opcode_name(op)) + " record " + at_byte(pos) +
              " (it needs " + std::to_string(len) + " bytes, " + std::to_string(size - pos - kRecordHeader) +
              " are present)";
      }
      const std::optional<uint64_t> next = find_chunk(pos + 1);
      if (next) {
        report_.problems.push_back(why + ": skipped " + std::to_string(*next - pos) +
                                   " corrupt bytes, resumed at the chunk at byte " + std::to_string(*next));
        state.crc_valid = false;
        ++report_.corrupt;
        pos = *next;
        continue;
      }
      report_.problems.push_back(why + ": the file was cut short (writer killed or out of space?); everything after byte " +
                                 std::to_string(pos) + " is lost");
      break;
    }
    record.resize(static_cast<size_t>(kRecordHeader + len));
    source_->read(pos, record.size(), record.data());
    const bool stop = scan_record(pos, record, state);
    state.data_crc = crc32_update(state.data_crc, record.data(), record.size());
    pos += record.size();
    last_good_end = pos;
    if (stop) {
      break;
    }
  }
  if (!state.saw_data_end) {
    report_.problems.push_back("no Data End record: recovered " + std::to_string(report_.messages) +
                               " messages in " + std::to_string(report_.chunks) + " complete chunks (bytes 0-" +
                               std::to_string(last_good_end) + " of " + std::to_string(size) + ")");
  } else if (state.chunk_fail > 0) {
    report_.problems.push_back("recovered " + std::to_string(report_.messages) + " messages in " +
                               std::to_string(report_.chunks) + " chunks; " + std::to_string(state.chunk_fail) +
                               " corrupt chunks skipped");
  }
  std::stable_sort(chunks_.begin(), chunks_.end(),
                   [](const ChunkLocation& a, const ChunkLocation& b) { return a.start_ns < b.start_ns; });
  report_.recovered = true;
}

MessageCursor McapReader::messages(ReadFilter filter) const {
  return MessageCursor(*this, std::move(filter));
}

MessageCursor::MessageCursor(const McapReader& reader, ReadFilter filter)
    : reader_(&reader), filter_(std::move(filter)) {
  for (const auto& [id, channel] : reader_->channels_) {
    if (filter_.topics.empty() || filter_.topics.count(channel.topic) > 0) {
      channel_ids_.insert(id);
    }
  }
}

bool MessageCursor::load_next_chunk() {
  const auto& chunks = reader_->chunks_;
  while (next_chunk_ < chunks.size()) {
    const McapReader::ChunkLocation& c = chunks[next_chunk_++];
    if ((filter_.start_ns && c.end_ns < *filter_.start_ns) ||
        (filter_.end_ns && c.start_ns > *filter_.end_ns)) {
      continue;
    }
    std::vector<uint8_t> record(static_cast<size_t>(c.length));
    try {
      reader_->source_->read(c.offset, record.size(), record.data());
      if (c.is_chunk) {
        if (record.size() < kRecordHeader || record[0] != static_cast<uint8_t>(Opcode::kChunk)) {
          throw ReadError("no Chunk record there (stale or corrupt chunk index)");
        }
        records_ = chunk_records(record.data() + kRecordHeader, record.size() - kRecordHeader);
      } else {
        records_ = std::move(record);
      }
    } catch (const std::exception& e) {
      problems_.push_back("chunk " + at_byte(c.offset) + ": " + e.what() +
                          "; its messages are skipped");
      continue;
    }
    entries_.clear();
    next_entry_ = 0;
    chunk_offset_ = c.offset;
    try {
      for_each_record(records_.data(), records_.size(), "chunk",
                      [&](uint8_t op, const uint8_t* body, size_t len, size_t offset) {
                        if (op != static_cast<uint8_t>(Opcode::kMessage)) {
                          return;
                        }
                        Parser p(body, len, "Message");
                        const uint16_t channel_id = p.u16();
                        p.u32();
                        const uint64_t log_time = p.u64();
                        p.u64();
                        if (channel_ids_.count(channel_id) == 0 ||
                            (filter_.start_ns && log_time < *filter_.start_ns) ||
                            (filter_.end_ns && log_time > *filter_.end_ns)) {
                          return;
                        }
                        entries_.push_back({log_time, offset});
                      });
    } catch (const ReadError& e) {
      problems_.push_back("chunk " + at_byte(c.offset) + ": " + e.what() +
                          "; the rest of the chunk is skipped");
    }
    std::stable_sort(entries_.begin(), entries_.end(),
                     [](const Entry& a, const Entry& b) { return a.log_time < b.log_time; });
    if (!entries_.empty()) {
      return true;
    }
  }
  return false;
}

const MessageView* MessageCursor::next() {
  while (next_entry_ >= entries_.size()) {
    if (!load_next_chunk()) {
      return nullptr;
    }
  }
  const Entry& e = entries_[next_entry_++];
  const uint8_t* r = records_.data() + e.offset;
  const uint64_t len = get_u64(r + 1);
  const uint8_t* body = r + kRecordHeader;
  const uint16_t channel_id = detail::get_u16(body);
  view_.channel = &reader_->channels_.at(channel_id);
  const auto schema = reader_->schemas_.find(view_.channel->schema_id);
  view_.schema = schema == reader_->schemas_.end() ? nullptr : &schema->second;
  view_.sequence = get_u32(body + 2);
  view_.log_time_ns = get_u64(body + 6);
  view_.publish_time_ns = get_u64(body + 14);
  view_.data = body + 22;
  view_.size = static_cast<size_t>(len - 22);
  view_.index = ++delivered_;
  view_.chunk_offset = chunk_offset_;
  view_.record_offset = e.offset;
  return &view_;
}

std::string describe_position(const MessageView& m) {
  return "message #" + std::to_string(m.index) + " (log time " + std::to_string(m.log_time_ns) +
         " ns, chunk at byte " + std::to_string(m.chunk_offset) + ", record " +
         std::to_string(m.record_offset) + " in it)";
}

}  // namespace poise::record
