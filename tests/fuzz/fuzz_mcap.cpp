// Fuzz target for the MCAP reader (issue 19): a file of arbitrary bytes, read as `poise info`,
// `info --verify`, `replay` and `process` read it (McapReader on the bytes, the report, a full
// CRC scan, every message in log-time order, each payload checked against its omgidl schema).
// Invariant: the reader either refuses the file with ReadError / IoError naming the reason or
// reads it; iteration then never throws, yields messages whose views lie inside the reader's
// buffer and whose channel and schema exist; nothing crashes, hangs
// or allocates beyond the file's size by more than the reader's record limit.
#include "poise/schema/cdr.h"
#include "poise/schema/idl_schema.h"
#include "poise/record/io.h"
#include "poise/record/mcap.h"

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <memory>
#include <string>
#include <vector>

namespace {

void read_all(const poise::record::McapReader& reader, poise::record::ReadFilter filter) {
  auto cursor = reader.messages(std::move(filter));
  uint64_t index = 0;
  while (const poise::record::MessageView* m = cursor.next()) {
    if (m->index != ++index) std::abort();
    if (m->channel == nullptr) std::abort();
    if (m->size > 0 && m->data == nullptr) std::abort();
    volatile uint8_t sink = 0;  // touch every byte: ASan reports a view outside the buffer
    for (size_t k = 0; k < m->size; ++k) sink ^= m->data[k];
    (void)poise::record::describe_position(*m);
    if (m->schema != nullptr) {
      (void)poise::schema::payload_problem(poise::schema::TypeTable::builtin(), m->schema->name,
                                             m->data, m->size);
    }
  }
  (void)cursor.problems();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace poise::record;
  // Size claims (issue 33): the bytes as one Chunk record's body. What it decompresses to never
  // exceeds kMaxCompressionRatio times its bytes nor kMaxChunkBytes (checked before allocating;
  // seed lying_chunk_sizes.mcap: 8 chunks of 10 bytes each claiming 1 GiB).
  try {
    const std::vector<uint8_t> records = chunk_records(data, size);
    if (records.size() > size * kMaxCompressionRatio || records.size() > kMaxChunkBytes) std::abort();
  } catch (const ReadError& e) {
    if (e.what()[0] == '\0') std::abort();
  }
  std::unique_ptr<McapReader> reader;
  try {
    reader = std::make_unique<McapReader>(
        std::make_unique<MemorySource>(std::vector<uint8_t>(data, data + size)));
  } catch (const ReadError& e) {
    if (e.what()[0] == '\0') std::abort();
    return 0;
  } catch (const IoError& e) {
    if (e.what()[0] == '\0') std::abort();
    return 0;
  }
  const FileReport& report = reader->report();
  if (report.complete && report.recovered) std::abort();
  for (const auto& [id, channel] : reader->channels()) {
    if (channel.schema_id != 0 && reader->schemas().count(channel.schema_id) == 0) std::abort();
  }
  read_all(*reader, {});
  ReadFilter some;
  some.start_ns = report.start_ns + (report.end_ns - report.start_ns) / 2;
  if (!reader->channels().empty()) some.topics.insert(reader->channels().begin()->second.topic);
  read_all(*reader, some);
  reader->verify();
  read_all(*reader, {});
  return 0;
}
