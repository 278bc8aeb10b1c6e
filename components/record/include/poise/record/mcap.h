// MCAP (mcap.dev, format version 0) writer and reader: our own implementation of the parts poise
// needs. No Fast DDS here: records carry opaque bytes.
//
// Layout written (see docs/RECORDING.md):
//   magic, Header, { Schema | Channel (outside chunks, written when added) | Chunk + its Message
//   Indexes }*, Data End (CRC of every byte before it), summary (Schemas, Channels, Statistics,
//   Chunk Indexes), Summary Offsets, Footer (summary CRC), magic.
// Crash safety: a chunk is closed and handed to the OS when it reaches `chunk_size_bytes` or when
// `max_chunk_duration_ns` of injected clock time has passed since its first message (checked on
// every write and on tick()). After kill -9 the file ends after the last complete chunk (or mid
// chunk); the reader recovers every complete chunk and says what it lost.
#pragma once

#include "poise/record/io.h"

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <vector>

namespace poise::record {

/// MCAP opcodes.
enum class Opcode : uint8_t {
  kHeader = 0x01,
  kFooter = 0x02,
  kSchema = 0x03,
  kChannel = 0x04,
  kMessage = 0x05,
  kChunk = 0x06,
  kMessageIndex = 0x07,
  kChunkIndex = 0x08,
  kAttachment = 0x09,
  kAttachmentIndex = 0x0A,
  kStatistics = 0x0B,
  kMetadata = 0x0C,
  kMetadataIndex = 0x0D,
  kSummaryOffset = 0x0E,
  kDataEnd = 0x0F,
};

/// The 8 magic bytes at both ends of an MCAP file.
extern const uint8_t kMagic[8];

enum class Compression { kNone, kZstd };

/// True when this build can write and read zstd chunks.
bool zstd_available();

struct Schema {
  uint16_t id = 0;       ///< > 0
  std::string name;      ///< e.g. "poise::msg::ImuSample"
  std::string encoding;  ///< e.g. "omgidl"
  std::vector<uint8_t> data;
};

struct Channel {
  uint16_t id = 0;
  uint16_t schema_id = 0;  ///< 0 = schemaless
  std::string topic;
  std::string message_encoding;  ///< e.g. "cdr"
  std::map<std::string, std::string> metadata;
};

struct WriterOptions {
  std::string profile;                   ///< MCAP profile ("" = none)
  std::string library = "poise 0.1.0";   ///< written in the Header
  uint64_t chunk_size_bytes = 1u << 20;  ///< close a chunk at this uncompressed size
  int64_t max_chunk_duration_ns = 1'000'000'000;  ///< close a chunk this long after it opened
  Compression compression = Compression::kNone;
  int zstd_level = 1;  ///< zstd level when compressing (1 = fastest)
  /// Monotonic clock (ns) for the chunk age; steady_clock when empty. Injected by tests.
  std::function<int64_t()> clock;
};

/// Writing stopped (I/O error, disk full). The message says what happened to the file.
class WriteError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// What a writer has written so far.
struct WriterStats {
  uint64_t messages = 0;         ///< messages in closed (durable) chunks
  uint64_t pending_messages = 0; ///< messages in the open chunk
  uint64_t chunks = 0;
  uint64_t bytes = 0;            ///< file position
  uint64_t lost_messages = 0;    ///< messages dropped by a write failure
};

/// Writes one MCAP file. Not thread-safe: one thread writes (the recorder queues for it).
class McapWriter {
 public:
  /// Writes magic + Header at once. Throws WriteError if that fails.
  McapWriter(std::unique_ptr<Sink> sink, WriterOptions options);
  /// Closes (finalises) the file if close() was not called; errors are swallowed there.
  ~McapWriter();
  McapWriter(const McapWriter&) = delete;
  McapWriter& operator=(const McapWriter&) = delete;

  /// Registers a schema and writes it (outside chunks). Returns its id (1, 2, ...).
  uint16_t add_schema(const std::string& name, const std::string& encoding,
                      const std::vector<uint8_t>& data);
  /// Registers a channel and writes it. Returns its id (0, 1, ...). SCHEMA_ID must exist or be 0.
  uint16_t add_channel(uint16_t schema_id, const std::string& topic,
                       const std::string& message_encoding,
                       const std::map<std::string, std::string>& metadata);

  /// Appends one message to the open chunk (closing it first or after as the options require).
  /// Throws WriteError when the file cannot be written: the file has then been finalised with
  /// every complete chunk (see the message), and further calls throw too.
  void write(uint16_t channel_id, uint32_t sequence, uint64_t log_time_ns,
             uint64_t publish_time_ns, const uint8_t* data, size_t size);
  /// Closes the open chunk if it is older than max_chunk_duration_ns. Call periodically (e.g.
  /// every 100 ms) when messages may stop arriving.
  void tick();
  /// Closes the open chunk now (if it has messages).
  void flush();
  /// Writes Data End, the summary and the footer. Idempotent. Throws WriteError on failure (the
  /// file is then finalised as far as possible; the message says how).
  void close();

  [[nodiscard]] const WriterStats& stats() const { return stats_; }
  /// After a write failure: what happened and what the file holds, without the count of messages
  /// lost (the writer's failure message adds the ones it knows of; a caller that queued more, the
  /// recorder, gives its own total). "" before any failure.
  [[nodiscard]] const std::string& failure_detail() const { return failure_detail_; }
  /// Messages per channel id in closed (durable) chunks: what the file holds.
  [[nodiscard]] const std::map<uint16_t, uint64_t>& channel_messages() const {
    return channel_counts_;
  }
  [[nodiscard]] bool closed() const { return closed_; }
  [[nodiscard]] const std::string& sink_name() const { return sink_name_; }

 private:
  struct ChunkIndexEntry {
    uint64_t start_ns, end_ns, offset, length;
    std::map<uint16_t, uint64_t> message_index_offsets;
    uint64_t message_index_length;
    uint64_t compressed_size, uncompressed_size;
  };
  void write_raw(const std::vector<uint8_t>& bytes);  // throws IoError
  void close_chunk();
  [[noreturn]] void fail(const std::string& what);
  void finalise();  // DataEnd + summary + footer at the current (good) position
  int64_t now() const;

  std::unique_ptr<Sink> sink_;
  std::string sink_name_;
  WriterOptions options_;
  bool closed_ = false;
  std::string failure_;  // non-empty once writing failed
  std::string failure_detail_;  // failure_ without the lost count

  std::vector<Schema> schemas_;
  std::vector<Channel> channels_;
  uint32_t data_crc_ = 0;     // running CRC of every byte written (data section)
  uint64_t good_offset_ = 0;  // end of the last completely written record group

  // The open chunk.
  std::vector<uint8_t> chunk_;
  std::map<uint16_t, std::vector<std::pair<uint64_t, uint64_t>>> chunk_index_;  // log time, offset
  uint64_t chunk_start_ns_ = 0, chunk_end_ns_ = 0;
  uint64_t chunk_messages_ = 0;
  int64_t chunk_opened_at_ = 0;

  std::vector<ChunkIndexEntry> chunk_indexes_;
  std::map<uint16_t, uint64_t> channel_counts_;
  uint64_t message_start_ns_ = 0, message_end_ns_ = 0;
  WriterStats stats_;
};

/// Per-channel figures.
struct ChannelCounts {
  uint64_t messages = 0;
  uint64_t first_log_ns = 0;  ///< 0 when unknown (summary without per-channel times)
  uint64_t last_log_ns = 0;
};

/// What the reader found out about a file.
struct FileReport {
  bool complete = false;   ///< valid footer + summary (with matching CRC); nothing recovered
  bool recovered = false;  ///< read by scanning: some part was truncated or corrupt
  std::vector<std::string> problems;  ///< human-readable, one per problem, with byte offsets
  /// Corrupt chunks, byte ranges and records found by scanning (data lost inside the file). A
  /// file merely cut short (killed writer) is incomplete but not corrupt.
  uint64_t corrupt = 0;
  uint64_t file_size = 0;
  uint64_t messages = 0;
  uint64_t chunks = 0;
  uint64_t start_ns = 0, end_ns = 0;  ///< log time range (0, 0 without messages)
  std::map<uint16_t, ChannelCounts> channels;
  std::string profile, library;
};

/// One message as the reader yields it; DATA points into the reader's buffer and stays valid
/// until the next call to MessageCursor::next().
struct MessageView {
  const Channel* channel = nullptr;
  const Schema* schema = nullptr;  ///< nullptr for schemaless channels
  uint32_t sequence = 0;
  uint64_t log_time_ns = 0;
  uint64_t publish_time_ns = 0;
  const uint8_t* data = nullptr;
  size_t size = 0;
  uint64_t index = 0;         ///< 1-based position in the cursor's iteration
  uint64_t chunk_offset = 0;  ///< file offset of the Chunk (or loose Message) record holding it
  uint64_t record_offset = 0; ///< offset of the Message record in the chunk's uncompressed records
};

/// "message #12 (log time 5000001000 ns, chunk at byte 4096, record 230 in it)": where a message
/// is, for reports about it.
std::string describe_position(const MessageView& m);
/// Reports describe at most this many skipped messages one by one (the rest are counted).
inline constexpr size_t kMaxDescribedSkips = 10;

/// Selects messages: log time in [start_ns, end_ns] and topic in TOPICS (all when empty).
struct ReadFilter {
  std::optional<uint64_t> start_ns;
  std::optional<uint64_t> end_ns;
  std::set<std::string> topics;
};

/// The file could not be read as MCAP at all (not MCAP, unreadable).
class ReadError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

class McapReader;

/// Iterates messages in log-time order (chunks by start time, messages in a chunk by log time,
/// then file order). Chunks that turn out corrupt are skipped and reported in problems().
class MessageCursor {
 public:
  /// The next message, or nullptr at the end.
  const MessageView* next();
  /// Problems met while iterating (e.g. a chunk whose CRC does not match).
  [[nodiscard]] const std::vector<std::string>& problems() const { return problems_; }

 private:
  friend class McapReader;
  MessageCursor(const McapReader& reader, ReadFilter filter);
  bool load_next_chunk();

  const McapReader* reader_;
  ReadFilter filter_;
  std::set<uint16_t> channel_ids_;
  size_t next_chunk_ = 0;
  std::vector<uint8_t> records_;  // uncompressed records of the current chunk
  struct Entry {
    uint64_t log_time;
    size_t offset;  // of the message record in records_
  };
  std::vector<Entry> entries_;
  size_t next_entry_ = 0;
  uint64_t chunk_offset_ = 0;  // of the chunk whose records_ are loaded
  uint64_t delivered_ = 0;
  MessageView view_;
  std::vector<std::string> problems_;
};

/// Reads an MCAP file written by poise or any conforming writer. A complete file is read through
/// its summary; otherwise (truncated, corrupt summary or chunk) the data section is scanned and
/// every readable chunk recovered, with the problems listed in report().
class McapReader {
 public:
  /// Throws ReadError if SOURCE is not an MCAP file (bad magic, too short).
  explicit McapReader(std::unique_ptr<Source> source);
  /// Opens PATH; throws ReadError with the path in the message.
  static McapReader open_file(const std::string& path);

  [[nodiscard]] const FileReport& report() const { return report_; }
  [[nodiscard]] const std::map<uint16_t, Schema>& schemas() const { return schemas_; }
  [[nodiscard]] const std::map<uint16_t, Channel>& channels() const { return channels_; }
  [[nodiscard]] const Source& source() const { return *source_; }

  /// Re-reads the whole data section, checking every CRC, even if the summary is valid; the
  /// report then reflects the scan. Returns report().
  const FileReport& verify();

  /// Iterates messages (see MessageCursor).
  [[nodiscard]] MessageCursor messages(ReadFilter filter = {}) const;

  /// Where a chunk (or a loose message record) sits in the file.
  struct ChunkLocation {
    uint64_t offset = 0;  ///< of the record's opcode
    uint64_t length = 0;  ///< whole record, opcode included
    uint64_t start_ns = 0, end_ns = 0;
    bool is_chunk = true;  ///< false: a single Message record outside chunks
  };
  [[nodiscard]] const std::vector<ChunkLocation>& chunks() const { return chunks_; }

 private:
  friend class MessageCursor;
  bool read_summary();
  /// The scan's running state over the data section (scan(), scan_record()).
  struct ScanState {
    uint64_t chunk_fail = 0;
    bool saw_data_end = false;
    bool crc_valid = true;
    uint32_t data_crc = 0;
  };
  void scan();
  /// One whole record at byte POS (header included) into the report; true at the end of data.
  bool scan_record(uint64_t pos, const std::vector<uint8_t>& record, ScanState& state);
  /// The schemas, channels and messages of a Chunk record (decompressed), counted; a corrupt one
  /// is counted and reported.
  void scan_chunk(uint64_t pos, const std::vector<uint8_t>& record, ScanState& state);
  void count_message(uint16_t channel_id, uint64_t log_time);
  /// The next offset > FROM where a plausible Chunk record starts (resynchronisation).
  [[nodiscard]] std::optional<uint64_t> find_chunk(uint64_t from) const;
  void add_schema(Schema schema);
  void add_channel(Channel channel);
  // A channel naming a schema id the file does not define: reported, counted corrupt, schemaless.
  void check_channel_schemas();

  std::unique_ptr<Source> source_;
  FileReport report_;
  std::map<uint16_t, Schema> schemas_;
  std::map<uint16_t, Channel> channels_;
  std::vector<ChunkLocation> chunks_;
};

/// What a chunk may claim to hold once decompressed, checked before anything is allocated (a
/// lying file must not cost memory): at most kMaxCompressionRatio times its compressed records
/// (zstd reaches about 10x on poise recordings; 1000x is zeros) and never more than
/// kMaxChunkBytes (the writer closes chunks at 1 MiB; other writers use a few MiB). Larger claims
/// are a corrupt chunk: "chunk claims N bytes uncompressed from M compressed: more than the
/// 1000x / 128 MiB a chunk may hold".
inline constexpr uint64_t kMaxCompressionRatio = 1000;
inline constexpr uint64_t kMaxChunkBytes = 128ULL << 20;

/// Decompresses/validates one chunk record body. Throws ReadError with the reason. The output
/// grows with what zstd actually produces (streamed, never the claimed size at once), up to the
/// claimed size. Exposed for the cursor and tests.
std::vector<uint8_t> chunk_records(const uint8_t* body, size_t size);

}  // namespace poise::record
