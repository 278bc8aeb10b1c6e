// MCAP writer/reader: round trips in memory, chunking on size and injected time, truncation at
// every byte, corrupted CRCs, write failures (disk full).
#include "poise/record/info.h"
#include "poise/record/mcap.h"
#include "poise/testing/testing.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <set>
#include <string>
#include <vector>

namespace poise::record {
namespace {

constexpr uint32_t kSeed = 20261122;

struct Expected {
  uint16_t channel;
  uint32_t sequence;
  uint64_t log_ns;
  uint64_t publish_ns;
  std::vector<uint8_t> data;
};

/// A clock the test moves by hand.
struct FakeClock {
  int64_t now_ns = 0;
  std::function<int64_t()> fn() {
    return [this] { return now_ns; };
  }
};

/// Writes a file with 3 channels (2 schemas) and `count` messages, advancing the fake clock by
/// `step_ns` per message; returns what was written.
std::vector<Expected> write_sample(McapWriter& w, FakeClock& clock, int count, int64_t step_ns,
                                   std::mt19937& rng) {
  const uint16_t s1 = w.add_schema("poise::msg::A", "omgidl", {'s', 't', 'r', 'u', 'c', 't'});
  const uint16_t s2 = w.add_schema("poise::msg::B", "omgidl", {'x'});
  const uint16_t c0 = w.add_channel(s1, "imu", "cdr", {{"qos", "best_effort"}});
  const uint16_t c1 = w.add_channel(s2, "attitude/pkf", "cdr", {});
  const uint16_t c2 = w.add_channel(s1, "imu2", "cdr", {{"a", "1"}, {"b", "2"}});
  const uint16_t ids[3] = {c0, c1, c2};
  std::vector<Expected> out;
  std::uniform_int_distribution<int> size_dist(0, 120);
  std::uniform_int_distribution<int> byte_dist(0, 255);
  for (int i = 0; i < count; ++i) {
    Expected e;
    e.channel = ids[i % 3];
    e.sequence = static_cast<uint32_t>(i);
    e.log_ns = 1'000'000'000ULL + static_cast<uint64_t>(i) * 1'000'000ULL;
    e.publish_ns = e.log_ns - 500;
    e.data.resize(static_cast<size_t>(size_dist(rng)));
    for (auto& b : e.data) {
      b = static_cast<uint8_t>(byte_dist(rng));
    }
    w.write(e.channel, e.sequence, e.log_ns, e.publish_ns, e.data.data(), e.data.size());
    clock.now_ns += step_ns;
    out.push_back(std::move(e));
  }
  return out;
}

std::vector<Expected> read_all(const McapReader& r, std::vector<std::string>* problems = nullptr,
                               ReadFilter filter = {}) {
  std::vector<Expected> out;
  MessageCursor cursor = r.messages(std::move(filter));
  while (const MessageView* m = cursor.next()) {
    out.push_back({m->channel->id, m->sequence, m->log_time_ns, m->publish_time_ns,
                   std::vector<uint8_t>(m->data, m->data + m->size)});
  }
  if (problems != nullptr) {
    *problems = cursor.problems();
  }
  return out;
}

void expect_same(const std::vector<Expected>& want, const std::vector<Expected>& got) {
  ASSERT_EQ(want.size(), got.size());
  for (size_t i = 0; i < want.size(); ++i) {
    EXPECT_EQ(want[i].channel, got[i].channel) << i;
    EXPECT_EQ(want[i].sequence, got[i].sequence) << i;
    EXPECT_EQ(want[i].log_ns, got[i].log_ns) << i;
    EXPECT_EQ(want[i].publish_ns, got[i].publish_ns) << i;
    EXPECT_EQ(want[i].data, got[i].data) << i;
  }
}

std::string joined(const std::vector<std::string>& v) {
  std::string s;
  for (const auto& x : v) {
    s += x + "\n";
  }
  return s;
}

/// A sink that fails (like a full disk) once `capacity` bytes are stored; truncate frees space.
class FailingSink : public Sink {
 public:
  FailingSink(std::vector<uint8_t>& buffer, uint64_t capacity, bool truncate_works = true)
      : buffer_(buffer), capacity_(capacity), truncate_works_(truncate_works) {
    buffer_.clear();
  }
  void write(const uint8_t* data, size_t size) override {
    const size_t room = static_cast<size_t>(capacity_ - std::min<uint64_t>(capacity_, buffer_.size()));
    buffer_.insert(buffer_.end(), data, data + std::min(room, size));
    if (size > room) {
      throw IoError("writing test sink failed: No space left on device");
    }
  }
  void truncate(uint64_t size) override {
    if (!truncate_works_) {
      throw IoError("truncate not supported");
    }
    buffer_.resize(static_cast<size_t>(size));
  }
  [[nodiscard]] uint64_t position() const override { return buffer_.size(); }
  [[nodiscard]] std::string name() const override { return "test sink"; }

 private:
  std::vector<uint8_t>& buffer_;
  uint64_t capacity_;
  bool truncate_works_;
};

McapReader read_buffer(const std::vector<uint8_t>& bytes) {
  return McapReader(std::make_unique<MemorySource>(bytes));
}

/// A closed in-memory file of write_sample(count) with chunks of `chunk_size_bytes`.
std::vector<uint8_t> sample_file(int count, std::size_t chunk_size_bytes) {
  std::mt19937 rng(kSeed);
  std::vector<uint8_t> buf;
  FakeClock clock;
  WriterOptions opt;
  opt.chunk_size_bytes = chunk_size_bytes;
  opt.clock = clock.fn();
  McapWriter w(std::make_unique<MemorySink>(buf), opt);
  write_sample(w, clock, count, 1000, rng);
  w.close();
  return buf;
}

TEST(Mcap, RoundTripInMemoryKeepsEveryFieldAndByte) {
  // GIVEN a writer on a memory buffer with small chunks
  std::mt19937 rng(kSeed);
  std::vector<uint8_t> buf;
  FakeClock clock;
  WriterOptions opt;
  opt.chunk_size_bytes = 1000;
  opt.clock = clock.fn();
  std::vector<Expected> written;
  {
    McapWriter w(std::make_unique<MemorySink>(buf), opt);
    // WHEN 300 messages are written and the writer is closed
    written = write_sample(w, clock, 300, 1000, rng);
    w.close();
    EXPECT_EQ(w.stats().messages, 300u);
    EXPECT_GT(w.stats().chunks, 5u);
  }
  // THEN the reader sees a complete file with the same messages, channels and schemas
  McapReader r = read_buffer(buf);
  EXPECT_TRUE(r.report().complete) << joined(r.report().problems);
  EXPECT_TRUE(r.report().problems.empty()) << joined(r.report().problems);
  EXPECT_EQ(r.report().messages, 300u);
  EXPECT_EQ(r.report().start_ns, written.front().log_ns);
  EXPECT_EQ(r.report().end_ns, written.back().log_ns);
  EXPECT_EQ(r.report().library, "poise 0.1.0");
  ASSERT_EQ(r.channels().size(), 3u);
  EXPECT_EQ(r.channels().at(0).topic, "imu");
  EXPECT_EQ(r.channels().at(0).metadata.at("qos"), "best_effort");
  EXPECT_EQ(r.channels().at(2).metadata.size(), 2u);
  EXPECT_EQ(r.schemas().at(1).name, "poise::msg::A");
  EXPECT_EQ(r.schemas().at(2).encoding, "omgidl");
  EXPECT_EQ(r.report().channels.at(1).messages, 100u);
  std::vector<std::string> problems;
  expect_same(written, read_all(r, &problems));
  EXPECT_TRUE(problems.empty()) << joined(problems);
  // AND a full verification scan agrees (every chunk CRC, the data CRC)
  McapReader v = read_buffer(buf);
  v.verify();
  EXPECT_TRUE(v.report().complete) << joined(v.report().problems);
  EXPECT_EQ(v.report().messages, 300u);
  EXPECT_EQ(v.report().chunks, r.report().chunks);
}

// Issue 20: `poise info` and `poise info --verify` report one rate per topic: messages over the
// recording's span, whether the counts come from the summary or from reading every chunk.
TEST(McapInfo, GivenTheSummaryOrAFullScanWhenTopicsAreSummarisedThenTheRatesAreTheSame) {
  const std::vector<uint8_t> buf = sample_file(301, 1000);  // 3 channels, 1 ms apart: span 0.3 s
  const McapReader summary = read_buffer(buf);
  McapReader scanned = read_buffer(buf);
  scanned.verify();
  const auto a = summarise_topics(summary);
  const auto b = summarise_topics(scanned);
  ASSERT_EQ(a.size(), 3U);
  ASSERT_EQ(b.size(), 3U);
  constexpr double kSpanS = 0.3;
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].topic, b[i].topic);
    EXPECT_EQ(a[i].messages, b[i].messages);
    EXPECT_DOUBLE_EQ(a[i].rate_hz, b[i].rate_hz) << a[i].topic;
    EXPECT_NEAR(a[i].rate_hz, static_cast<double>(a[i].messages) / kSpanS, 1e-9) << a[i].topic;
  }
}

TEST(Mcap, ZstdRoundTrip) {
  if (!zstd_available()) {
    POISE_SKIP("built without libzstd");
  }
  std::mt19937 rng(kSeed);
  std::vector<uint8_t> buf;
  FakeClock clock;
  WriterOptions opt;
  opt.compression = Compression::kZstd;
  opt.chunk_size_bytes = 2000;
  opt.clock = clock.fn();
  std::vector<Expected> written;
  {
    McapWriter w(std::make_unique<MemorySink>(buf), opt);
    written = write_sample(w, clock, 200, 1000, rng);
  }  // the destructor closes
  McapReader r = read_buffer(buf);
  EXPECT_TRUE(r.report().complete) << joined(r.report().problems);
  expect_same(written, read_all(r));
  r.verify();
  EXPECT_TRUE(r.report().complete) << joined(r.report().problems);
}

TEST(Mcap, ChunkIsFlushedOnceItIsOlderThanTheMaximumDuration) {
  // GIVEN a writer with 1 s maximum chunk age and big chunks
  std::vector<uint8_t> buf;
  FakeClock clock;
  WriterOptions opt;
  opt.clock = clock.fn();
  opt.max_chunk_duration_ns = 1'000'000'000;
  McapWriter w(std::make_unique<MemorySink>(buf), opt);
  const uint16_t ch = w.add_channel(0, "t", "cdr", {});
  const uint8_t payload[4] = {1, 2, 3, 4};
  // WHEN one message is written and 0.9 s pass
  w.write(ch, 0, 10, 10, payload, 4);
  clock.now_ns += 900'000'000;
  w.tick();
  // THEN it is still in the open chunk
  EXPECT_EQ(w.stats().chunks, 0u);
  EXPECT_EQ(w.stats().pending_messages, 1u);
  // WHEN 1.0 s has passed since the chunk opened
  clock.now_ns += 100'000'000;
  w.tick();
  // THEN the chunk is in the sink, and a reader of the bytes so far (as after kill -9) finds it
  EXPECT_EQ(w.stats().chunks, 1u);
  McapReader r = read_buffer(buf);
  EXPECT_FALSE(r.report().complete);
  EXPECT_TRUE(r.report().recovered);
  EXPECT_EQ(r.report().messages, 1u);
  // AND a write after the deadline closes the chunk without tick()
  w.write(ch, 1, 20, 20, payload, 4);
  clock.now_ns += 1'000'000'000;
  w.write(ch, 2, 30, 30, payload, 4);
  EXPECT_EQ(w.stats().chunks, 2u);
}

TEST(Mcap, TruncationAtEveryByteRecoversEveryCompleteChunk) {
  std::mt19937 rng(kSeed);
  std::vector<uint8_t> buf;
  FakeClock clock;
  WriterOptions opt;
  opt.chunk_size_bytes = 400;
  opt.clock = clock.fn();
  std::vector<Expected> written;
  {
    McapWriter w(std::make_unique<MemorySink>(buf), opt);
    written = write_sample(w, clock, 60, 1000, rng);
  }
  const McapReader full = read_buffer(buf);
  ASSERT_TRUE(full.report().complete);
  const auto chunks = full.chunks();
  ASSERT_GT(chunks.size(), 4u);
  // Oracle: messages of every chunk whose record lies entirely before the cut, in order.
  std::vector<std::vector<Expected>> per_chunk;
  {
    for (const auto& c : chunks) {
      (void)c;
      per_chunk.emplace_back();
    }
    size_t k = 0;
    size_t in_chunk = 0;
    for (const auto& e : written) {
      // Messages were written in order; chunk i holds messages with log time in [start, end].
      while (e.log_ns > chunks[k].end_ns) {
        ++k;
        in_chunk = 0;
      }
      per_chunk[k].push_back(e);
      ++in_chunk;
    }
  }
  size_t checked = 0;
  for (size_t cut = 17; cut < buf.size(); ++cut) {
    std::vector<uint8_t> part(buf.begin(), buf.begin() + static_cast<std::ptrdiff_t>(cut));
    std::vector<Expected> want;
    for (size_t i = 0; i < chunks.size(); ++i) {
      if (chunks[i].offset + chunks[i].length <= cut) {
        want.insert(want.end(), per_chunk[i].begin(), per_chunk[i].end());
      }
    }
    const McapReader r = read_buffer(part);
    ASSERT_FALSE(r.report().complete) << "cut " << cut;
    ASSERT_FALSE(r.report().problems.empty()) << "cut " << cut;
    ASSERT_EQ(r.report().messages, want.size()) << "cut " << cut << "\n"
                                                << joined(r.report().problems);
    const auto got = read_all(r);
    ASSERT_EQ(got.size(), want.size()) << "cut " << cut;
    for (size_t i = 0; i < got.size(); ++i) {
      ASSERT_EQ(got[i].data, want[i].data) << "cut " << cut << " message " << i;
      ASSERT_EQ(got[i].log_ns, want[i].log_ns) << "cut " << cut << " message " << i;
    }
    ++checked;
  }
  EXPECT_GT(checked, 1000u);
  // A cut inside a chunk says so.
  std::vector<uint8_t> mid(buf.begin(),
                           buf.begin() + static_cast<std::ptrdiff_t>(chunks[2].offset + 50));
  const McapReader r = read_buffer(mid);
  const std::string text = joined(r.report().problems);
  EXPECT_NE(text.find("ends inside a Chunk record at byte " + std::to_string(chunks[2].offset)),
            std::string::npos)
      << text;
  EXPECT_NE(text.find("recovered " + std::to_string(per_chunk[0].size() + per_chunk[1].size()) +
                      " messages in 2 complete chunks"),
            std::string::npos)
      << text;
}

TEST(Mcap, RandomCorruptionNeverCrashesTheReader) {
  // Property: whatever bytes are damaged, the reader either rejects the file with ReadError at
  // open (bad magic) or reads it, reporting problems; it never crashes, hangs or throws anything
  // else, and never yields a message that was not written.
  std::mt19937 rng(kSeed);
  std::printf("seed %u\n", kSeed);
  for (Compression compression : {Compression::kNone, Compression::kZstd}) {
    if (compression == Compression::kZstd && !zstd_available()) {
      continue;
    }
    std::vector<uint8_t> clean;
    FakeClock clock;
    WriterOptions opt;
    opt.chunk_size_bytes = 400;
    opt.compression = compression;
    opt.clock = clock.fn();
    std::vector<Expected> written;
    {
      McapWriter w(std::make_unique<MemorySink>(clean), opt);
      written = write_sample(w, clock, 60, 1000, rng);
    }
    std::set<std::vector<uint8_t>> payloads;
    for (const auto& e : written) {
      payloads.insert(e.data);
    }
    std::uniform_int_distribution<size_t> where(0, clean.size() - 1);
    std::uniform_int_distribution<int> how_many(1, 8);
    std::uniform_int_distribution<int> value(0, 255);
    for (int trial = 0; trial < 400; ++trial) {
      std::vector<uint8_t> bytes = clean;
      const int n = how_many(rng);
      for (int k = 0; k < n; ++k) {
        bytes[where(rng)] = static_cast<uint8_t>(value(rng));
      }
      try {
        McapReader r = read_buffer(bytes);
        for (int pass = 0; pass < 2; ++pass) {
          MessageCursor cursor = r.messages();
          while (const MessageView* m = cursor.next()) {
            // A message in a chunk whose CRC matched is one that was written.
            const std::vector<uint8_t> data(m->data, m->data + m->size);
            if (!r.report().complete || pass == 1) {
              ASSERT_TRUE(payloads.count(data) > 0) << "trial " << trial;
            }
          }
          r.verify();
        }
      } catch (const ReadError&) {
        // bad magic or header: rejected at open
      }
    }
  }
}

TEST(Mcap, GivenAChannelNamingASchemaTheFileDoesNotDefineWhenReadThenReportedAndReadSchemaless) {
  // GIVEN a complete file whose Channel records of channel 1 ('attitude/pkf', schema 2) name
  // schema 9 instead (found by fuzz_mcap: `poise process` then failed with "map::at")
  std::vector<uint8_t> bytes = sample_file(30, 1u << 20);
  int patched = 0;
  for (size_t i = 0; i + 13 <= bytes.size(); ++i) {
    if (bytes[i] == static_cast<uint8_t>(Opcode::kChannel) && bytes[i + 9] == 1 &&
        bytes[i + 10] == 0 && bytes[i + 11] == 2 && bytes[i + 12] == 0) {
      bytes[i + 11] = 9;
      ++patched;
    }
  }
  ASSERT_GE(patched, 1);
  // WHEN it is read (summary or scan) and verified
  McapReader r = read_buffer(bytes);
  for (int pass = 0; pass < 2; ++pass) {
    SCOPED_TRACE(pass == 0 ? "open" : "verify");
    // THEN the problem is reported and counted, the channel has no schema, every message is read
    EXPECT_NE(joined(r.report().problems).find("refers to schema 9, which the file does not define"),
              std::string::npos)
        << joined(r.report().problems);
    EXPECT_GE(r.report().corrupt, 1u);
    EXPECT_FALSE(r.report().complete);
    ASSERT_EQ(r.channels().count(1), 1u);
    EXPECT_EQ(r.channels().at(1).schema_id, 0);
    for (const auto& [id, channel] : r.channels()) {
      EXPECT_TRUE(channel.schema_id == 0 || r.schemas().count(channel.schema_id) == 1) << id;
    }
    MessageCursor cursor = r.messages();
    int n = 0;
    while (const MessageView* m = cursor.next()) {
      ++n;
      if (m->channel->id == 1) {
        EXPECT_EQ(m->schema, nullptr);
      }
    }
    EXPECT_EQ(n, 30);
    r.verify();
  }
}

/// Little-endian bytes appended one at a time (MCAP's field encodings).
struct Bytes {
  std::vector<uint8_t> v;
  Bytes& uint(uint64_t x, int n) {
    for (int i = 0; i < n; ++i) v.push_back(static_cast<uint8_t>(x >> (8 * i)));
    return *this;
  }
  Bytes& u16(uint16_t x) { return uint(x, 2); }
  Bytes& u32(uint32_t x) { return uint(x, 4); }
  Bytes& u64(uint64_t x) { return uint(x, 8); }
  Bytes& raw(const std::vector<uint8_t>& b) {
    for (const uint8_t x : b) v.push_back(x);
    return *this;
  }
  Bytes& str(const std::string& s) {
    u32(static_cast<uint32_t>(s.size()));
    for (const char c : s) v.push_back(static_cast<uint8_t>(c));
    return *this;
  }
  /// A record: opcode, u64 length, body.
  Bytes& record(Opcode op, const std::vector<uint8_t>& body) {
    v.push_back(static_cast<uint8_t>(op));
    return u64(body.size()).raw(body);
  }
};

/// A hand-written MCAP (no writer, so it can lie): records appended in order, then Data End, an
/// empty Footer and the magic.
class RawMcap {
 public:
  RawMcap() {
    for (int i = 0; i < 8; ++i) bytes_.v.push_back(kMagic[i]);
    bytes_.record(Opcode::kHeader, Bytes{}.str("").str("test").v);
  }
  void record(Opcode op, const std::vector<uint8_t>& body) { bytes_.record(op, body); }
  static std::vector<uint8_t> channel(uint16_t id, const std::string& topic) {
    return Bytes{}.u16(id).u16(0).str(topic).str("cdr").u32(0).v;
  }
  static std::vector<uint8_t> message(uint16_t channel, uint64_t log_ns) {
    return Bytes{}.u16(channel).u32(0).u64(log_ns).u64(log_ns).raw({1, 2, 3}).v;
  }
  /// A Chunk record body: `records` stored as given, claiming `uncompressed` bytes.
  static std::vector<uint8_t> chunk(const std::string& compression, const std::vector<uint8_t>& records,
                                    uint64_t uncompressed) {
    return Bytes{}.u64(0).u64(0).u64(uncompressed).u32(0).str(compression).u64(records.size()).raw(records).v;
  }
  std::vector<uint8_t> finish() {
    bytes_.record(Opcode::kDataEnd, Bytes{}.u32(0).v);
    bytes_.record(Opcode::kFooter, Bytes{}.u64(0).u64(0).u32(0).v);
    for (int i = 0; i < 8; ++i) bytes_.v.push_back(kMagic[i]);
    return bytes_.v;
  }

 private:
  Bytes bytes_;
};

/// A 10-byte zstd frame without a content size: one raw block holding one byte.
const std::vector<uint8_t> kTinyZstdFrame = {0x28, 0xB5, 0x2F, 0xFD, 0x00, 0x00, 0x09, 0x00, 0x00, 0x7A};

/// The process's peak resident memory so far (VmHWM), MiB; -1 when /proc is not there.
long peak_rss_mib() {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("VmHWM:", 0) == 0) {
      return std::stol(line.substr(6)) / 1024;
    }
  }
  return -1;
}

bool have_zstd() {
  try {
    (void)chunk_records(RawMcap::chunk("zstd", kTinyZstdFrame, 1).data(), RawMcap::chunk("zstd", kTinyZstdFrame, 1).size());
  } catch (const ReadError& e) {
    return std::string(e.what()).find("no libzstd") == std::string::npos;
  }
  return true;
}

// Issue 33, "memory on a lying MCAP": 8 chunks of a 10-byte zstd frame (no content size), each
// claiming 1 GiB, took `info` to 1.13 GB. Each claim is now checked against the chunk's compressed
// size (at most kMaxCompressionRatio times it, never above kMaxChunkBytes) before anything is
// allocated. Oracles: the documented message per chunk, the count, and the process's peak memory
// (a 1 GiB allocation would show; the bound is far above what the reader needs).
TEST(Mcap, GivenChunksClaimingFarMoreThanTheyHoldWhenReadThenEachIsRefusedBeforeAllocating) {
  constexpr long kPeakBoundMib = 200;
  RawMcap raw;
  for (int i = 0; i < 8; ++i) {
    raw.record(Opcode::kChunk, RawMcap::chunk("zstd", kTinyZstdFrame, 1ULL << 30));
  }
  const std::vector<uint8_t> bytes = raw.finish();
  McapReader r = read_buffer(bytes);
  EXPECT_EQ(r.report().corrupt, 8u) << joined(r.report().problems);
  EXPECT_NE(joined(r.report().problems)
                .find("chunk claims 1073741824 bytes uncompressed from 10 compressed: more than the 1000x / "
                      "128 MiB a chunk may hold"),
            std::string::npos)
      << joined(r.report().problems);
  r.verify();
  EXPECT_EQ(r.report().corrupt, 8u);
  const long peak = peak_rss_mib();
  std::printf("peak resident memory after reading: %ld MiB (bound %ld)\n", peak, kPeakBoundMib);
  EXPECT_LT(peak, kPeakBoundMib);
}

// A claim within the ratio is decompressed by streaming: the buffer grows with what zstd gives,
// and a frame that gives less or more than the claim is refused with what it gave.
TEST(Mcap, GivenAZstdFrameWithoutContentSizeWhenItHoldsLessOrMoreThanClaimedThenRefusedNamingBoth) {
  if (!have_zstd()) {
    POISE_SKIP("this build has no libzstd");
  }
  const auto error = [](uint64_t claim) {
    const std::vector<uint8_t> body = RawMcap::chunk("zstd", kTinyZstdFrame, claim);
    try {
      (void)chunk_records(body.data(), body.size());
    } catch (const ReadError& e) {
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  EXPECT_EQ(error(5000), "zstd chunk decompressed to 1 bytes, expected 5000");
  EXPECT_EQ(error(0), "zstd chunk decompresses to more than the 0 bytes it claims");
  EXPECT_EQ(error(10001), "chunk claims 10001 bytes uncompressed from 10 compressed: more than the 1000x / 128 MiB a "
                          "chunk may hold (corrupt)");
  const std::vector<uint8_t> exact = RawMcap::chunk("zstd", kTinyZstdFrame, 1);
  EXPECT_EQ(chunk_records(exact.data(), exact.size()), std::vector<uint8_t>{0x7A});
  std::vector<uint8_t> cut = kTinyZstdFrame;
  cut.resize(8);  // the block header promises a byte that is not there
  const std::vector<uint8_t> cut_body = RawMcap::chunk("zstd", cut, 1);
  EXPECT_THROW((void)chunk_records(cut_body.data(), cut_body.size()), ReadError);
}

// Issue 33: messages on a channel id without a Channel record were counted by `info` and dropped
// silently by everything that reads them. They are now a counted problem of the file.
TEST(Mcap, GivenMessagesOnAChannelTheFileDoesNotDefineWhenReadThenTheyAreCountedAndReported) {
  RawMcap raw;
  Bytes records;
  records.record(Opcode::kChannel, RawMcap::channel(1, "imu"));
  records.record(Opcode::kMessage, RawMcap::message(1, 10));
  records.record(Opcode::kMessage, RawMcap::message(7, 11));
  records.record(Opcode::kMessage, RawMcap::message(7, 12));
  raw.record(Opcode::kChunk, RawMcap::chunk("", records.v, records.v.size()));
  McapReader r = read_buffer(raw.finish());
  EXPECT_NE(joined(r.report().problems)
                .find("2 messages on channel 7, which the file does not define (no Channel record): they cannot be read"),
            std::string::npos)
      << joined(r.report().problems);
  EXPECT_GE(r.report().corrupt, 1u);
  EXPECT_FALSE(r.report().complete);
  EXPECT_EQ(read_all(r).size(), 1u);
}

// Issue 33, "wrong words": the writer refused the 65536th channel saying "MCAP allows 65536".
// Channel ids are 0-65535: all 65536 are accepted, the next is refused saying so.
TEST(Mcap, GivenEveryChannelIdTakenWhenOneMoreIsAddedThenRefusedWithTheTrueLimit) {
  std::vector<uint8_t> buf;
  McapWriter w(std::make_unique<MemorySink>(buf), WriterOptions{});
  const uint16_t schema = w.add_schema("poise::msg::A", "omgidl", {'x'});
  for (uint32_t i = 0; i < 65536; ++i) {
    ASSERT_EQ(w.add_channel(schema, "t", "cdr", {}), static_cast<uint16_t>(i));
  }
  try {
    (void)w.add_channel(schema, "t", "cdr", {});
    ADD_FAILURE() << "accepted";
  } catch (const WriteError& e) {
    EXPECT_STREQ(e.what(), "too many channels: an MCAP file holds at most 65536 (channel ids 0-65535)");
  }
}

TEST(Mcap, GivenAMemorySourceWhenZeroBytesAreReadIntoAnEmptyBufferThenNothingIsTouched) {
  // GIVEN a memory source; WHEN an empty record body is read into an empty vector (data() null;
  // found by fuzz_mcap under UBSan: memcpy to a null pointer) THEN it returns, and a read past the
  // end is still an IoError
  const MemorySource source(std::vector<uint8_t>{1, 2, 3});
  std::vector<uint8_t> empty;
  EXPECT_NO_THROW(source.read(3, 0, empty.data()));
  EXPECT_THROW(source.read(4, 0, empty.data()), IoError);
}

TEST(Mcap, TooShortOrForeignFilesAreRejectedClearly) {
  EXPECT_THROW(read_buffer({1, 2, 3}), ReadError);
  std::vector<uint8_t> foreign(100, 'x');
  try {
    read_buffer(foreign);
    FAIL() << "no error";
  } catch (const ReadError& e) {
    EXPECT_NE(std::string(e.what()).find("not an MCAP file"), std::string::npos) << e.what();
  }
  EXPECT_THROW(McapReader::open_file("/nonexistent/x.mcap"), ReadError);
}

struct SmallFile {
  std::vector<uint8_t> bytes;
  std::vector<Expected> written;
  std::vector<McapReader::ChunkLocation> chunks;
};

SmallFile small_file() {
  std::mt19937 rng(kSeed);
  SmallFile f;
  FakeClock clock;
  WriterOptions opt;
  opt.chunk_size_bytes = 400;
  opt.clock = clock.fn();
  {
    McapWriter w(std::make_unique<MemorySink>(f.bytes), opt);
    f.written = write_sample(w, clock, 60, 1000, rng);
  }
  f.chunks = read_buffer(f.bytes).chunks();
  return f;
}

TEST(Mcap, CorruptChunkIsSkippedAndReportedOthersAreRead) {
  // GIVEN a complete file with one byte flipped inside the records of chunk 1
  SmallFile f = small_file();
  ASSERT_GT(f.chunks.size(), 3u);
  const auto& c1 = f.chunks[1];
  f.bytes[c1.offset + c1.length - 5] ^= 0x40;
  // WHEN it is read through the (intact) summary
  McapReader r = read_buffer(f.bytes);
  EXPECT_TRUE(r.report().complete);
  std::vector<std::string> problems;
  const auto got = read_all(r, &problems);
  // THEN the cursor skips that chunk and says why
  ASSERT_EQ(problems.size(), 1u);
  EXPECT_NE(problems[0].find("chunk CRC mismatch"), std::string::npos) << problems[0];
  EXPECT_LT(got.size(), f.written.size());
  EXPECT_GT(got.size(), 0u);
  // AND verify() reports the damaged chunk and the data section CRC
  r.verify();
  EXPECT_FALSE(r.report().complete);
  const std::string text = joined(r.report().problems);
  EXPECT_NE(text.find("chunk at byte " + std::to_string(c1.offset)), std::string::npos) << text;
  EXPECT_NE(text.find("data section CRC mismatch"), std::string::npos) << text;
  EXPECT_EQ(r.report().messages, got.size());
}

TEST(Mcap, CorruptSummaryFallsBackToScanningEverything) {
  SmallFile f = small_file();
  // Flip a byte in the summary (just before the summary offsets / footer).
  f.bytes[f.bytes.size() - 8 - 29 - 20] ^= 0x01;
  McapReader r = read_buffer(f.bytes);
  EXPECT_FALSE(r.report().complete);
  EXPECT_TRUE(r.report().recovered);
  EXPECT_NE(joined(r.report().problems).find("summary CRC mismatch"), std::string::npos)
      << joined(r.report().problems);
  expect_same(f.written, read_all(r));
}

TEST(Mcap, CorruptRecordLengthResynchronisesOnTheNextChunk) {
  SmallFile f = small_file();
  const auto& c2 = f.chunks[2];
  // Damage chunk 2's length field so that it overruns the file.
  f.bytes[c2.offset + 8] = 0x7F;
  McapReader r = read_buffer(f.bytes);
  EXPECT_TRUE(r.report().complete);  // the summary is intact: only verify() reads the chunks
  r.verify();
  const std::string text = joined(r.report().problems);
  EXPECT_NE(text.find("resumed at the chunk at byte " + std::to_string(f.chunks[3].offset)),
            std::string::npos)
      << text;
  // Every chunk but chunk 2 is recovered.
  size_t in_c2 = 0;
  for (const auto& e : f.written) {
    in_c2 += (e.log_ns >= c2.start_ns && e.log_ns <= c2.end_ns) ? 1 : 0;
  }
  EXPECT_EQ(r.report().messages, f.written.size() - in_c2) << joined(r.report().problems);
}

TEST(Mcap, DiskFullStopsWithAFinalisedFileAtEveryFailurePoint) {
  const std::vector<uint8_t> reference = sample_file(60, 400);
  size_t failures_seen = 0;
  for (uint64_t capacity = 200; capacity < reference.size(); capacity += 37) {
    std::vector<uint8_t> buf;
    FakeClock clock;
    WriterOptions opt;
    opt.chunk_size_bytes = 400;
    opt.clock = clock.fn();
    std::mt19937 rng2(kSeed);
    std::string error;
    uint64_t durable = 0;
    try {
      McapWriter w(std::make_unique<FailingSink>(buf, capacity), opt);
      try {
        write_sample(w, clock, 60, 1000, rng2);
        w.close();
      } catch (const WriteError& e) {
        error = e.what();
      }
      durable = w.stats().messages;
      // Further writes keep failing with the same message.
      if (!error.empty()) {
        EXPECT_THROW(w.write(0, 0, 0, 0, nullptr, 0), WriteError);
      }
    } catch (const WriteError& e) {
      error = e.what();  // the header or a schema did not fit
    }
    if (error.empty()) {
      continue;  // it fitted (the summary is smaller than a chunk)
    }
    ++failures_seen;
    EXPECT_NE(error.find("No space left on device"), std::string::npos) << error;
    if (buf.size() < 8 + 9 + 29 + 8) {
      continue;
    }
    const McapReader r = read_buffer(buf);
    if (error.find("the file was finalised") != std::string::npos) {
      EXPECT_TRUE(r.report().complete) << "capacity " << capacity << "\n"
                                       << joined(r.report().problems);
    }
    EXPECT_EQ(r.report().messages, durable) << "capacity " << capacity << " " << error;
    EXPECT_EQ(read_all(r).size(), durable);
  }
  EXPECT_GT(failures_seen, 10u);
}

TEST(Mcap, WriteFailureWithoutRoomForTheSummaryLeavesARecoverableFile) {
  // GIVEN a sink that cannot truncate (no space is ever freed) and fails mid-recording
  std::mt19937 rng(kSeed);
  std::vector<uint8_t> buf;
  FakeClock clock;
  WriterOptions opt;
  opt.chunk_size_bytes = 400;
  opt.clock = clock.fn();
  McapWriter w(std::make_unique<FailingSink>(buf, 1500, false), opt);
  std::string error;
  try {
    write_sample(w, clock, 60, 1000, rng);
  } catch (const WriteError& e) {
    error = e.what();
  }
  // THEN the error says the file could not be finalised, and a reader recovers the durable part
  ASSERT_FALSE(error.empty());
  EXPECT_NE(error.find("could not be finalised"), std::string::npos) << error;
  const McapReader r = read_buffer(buf);
  EXPECT_FALSE(r.report().complete);
  // The writer counts as durable only what it finished writing; the reader may find more (a chunk
  // whose record was complete when its message indexes did not fit), never less.
  EXPECT_GE(r.report().messages, w.stats().messages);
  EXPECT_LE(r.report().messages, w.stats().messages + w.stats().lost_messages);
  EXPECT_GT(w.stats().messages, 0u);
}

TEST(Mcap, DevFullGivesAClearError) {
  if (!std::filesystem::exists("/dev/full")) {
    POISE_SKIP("/dev/full not present");
  }
  try {
    McapWriter w(open_file_sink("/dev/full"), WriterOptions{});
    FAIL() << "writing to /dev/full succeeded";
  } catch (const WriteError& e) {
    EXPECT_NE(std::string(e.what()).find("No space left on device"), std::string::npos)
        << e.what();
    EXPECT_NE(std::string(e.what()).find("/dev/full"), std::string::npos) << e.what();
  }
}

TEST(Mcap, FileRoundTripAndFilters) {
  std::mt19937 rng(kSeed);
  const std::string path =
      (std::filesystem::temp_directory_path() / ("poise_mcap_" + std::to_string(::getpid()) + ".mcap"))
          .string();
  FakeClock clock;
  WriterOptions opt;
  opt.chunk_size_bytes = 500;
  opt.clock = clock.fn();
  std::vector<Expected> written;
  {
    McapWriter w(open_file_sink(path), opt);
    written = write_sample(w, clock, 90, 1000, rng);
    w.close();
  }
  McapReader r = McapReader::open_file(path);
  EXPECT_TRUE(r.report().complete);
  expect_same(written, read_all(r));
  // Topic filter.
  ReadFilter only_imu;
  only_imu.topics = {"imu"};
  const auto imu = read_all(r, nullptr, only_imu);
  EXPECT_EQ(imu.size(), 30u);
  for (const auto& e : imu) {
    EXPECT_EQ(e.channel, 0u);
  }
  // Time filter: [start + 10 ms, start + 19 ms] holds 10 messages (1 ms apart).
  ReadFilter window;
  window.start_ns = written.front().log_ns + 10'000'000;
  window.end_ns = written.front().log_ns + 19'000'000;
  const auto in_window = read_all(r, nullptr, window);
  ASSERT_EQ(in_window.size(), 10u);
  EXPECT_EQ(in_window.front().sequence, 10u);
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace poise::record
