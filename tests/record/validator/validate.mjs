// Independent check of MCAP files written by poise (test-only; run by tests/record through
// node_validator.h). For each FILE.mcap with a FILE.expected.json beside it:
//  1. McapStreamReader (validateCrcs) reads every record: framing, magic, chunk CRCs;
//     the data section CRC in Data End is recomputed over bytes [0, Data End).
//  2. McapIndexedReader reads the summary (summary CRC), then every message through the chunk and
//     message indexes; the messages must equal the stream reader's, and Statistics must match.
//  3. Each payload is decoded with the channel's omgidl schema (@foxglove/omgidl-parser +
//     @foxglove/omgidl-serialization, as Foxglove does) and compared with the expected values.
// Expected JSON: messages, min_chunks, channels {topic: {schema, count, min_count, metadata}},
// values [{topic, sequence, log_time?, publish_time?, value}], undecodable ["topic/sequence"]
// (payloads written invalid on purpose: they must fail to decode).
// Prints one line per file; exits 1 if any check fails.
import { McapIndexedReader, McapStreamReader } from "@mcap/core";
import { FileHandleReadable } from "@mcap/nodejs";
import { parseIDL } from "@foxglove/omgidl-parser";
import { MessageReader } from "@foxglove/omgidl-serialization";
import { crc32 } from "@foxglove/crc";
import { decompress as zstdDecompress } from "fzstd";
import fs from "node:fs/promises";
import path from "node:path";

const decompressHandlers = {
  zstd: (buffer, size) => {
    const out = zstdDecompress(buffer);
    if (BigInt(out.byteLength) !== size) {
      throw new Error(`zstd chunk decompressed to ${out.byteLength} bytes, expected ${size}`);
    }
    return out;
  },
};

function matches(expected, actual, where, errors) {
  if (errors.length > 20) return;
  if (expected === null || typeof expected !== "object") {
    const a = typeof actual === "bigint" ? actual.toString() : actual;
    const e = typeof actual === "bigint" ? String(expected) : expected;
    if (a !== e) errors.push(`${where}: expected ${JSON.stringify(e)}, decoded ${String(a)}`);
    return;
  }
  if (actual === null || typeof actual !== "object") {
    errors.push(`${where}: expected an object/array, decoded ${String(actual)}`);
    return;
  }
  if (Array.isArray(expected)) {
    if (actual.length !== expected.length) {
      errors.push(`${where}: expected ${expected.length} elements, decoded ${actual.length}`);
      return;
    }
    expected.forEach((e, i) => matches(e, actual[i], `${where}[${i}]`, errors));
    return;
  }
  for (const [key, e] of Object.entries(expected)) {
    if (!(key in actual)) {
      errors.push(`${where}.${key}: missing in the decoded message`);
      continue;
    }
    matches(e, actual[key], `${where}.${key}`, errors);
  }
}

async function validate(file, expected) {
  const errors = [];
  const bytes = new Uint8Array(await fs.readFile(file));

  // 1. Stream reader over every record.
  const stream = new McapStreamReader({ validateCrcs: true, decompressHandlers });
  stream.append(bytes);
  const streamed = [];
  let dataEndCrc;
  let chunks = 0;
  const channels = new Map();
  for (let record; (record = stream.nextRecord()); ) {
    if (record.type === "Message") {
      streamed.push(record);
    } else if (record.type === "DataEnd") {
      dataEndCrc = record.dataSectionCrc;
    } else if (record.type === "Channel") {
      channels.set(record.id, record);
    }
  }
  if (!stream.done()) errors.push("stream reader did not reach the footer and closing magic");

  // 2. Indexed reader (summary CRC is checked in Initialize).
  const handle = await fs.open(file, "r");
  let indexed;
  try {
    const reader = await McapIndexedReader.Initialize({
      readable: new FileHandleReadable(handle),
      decompressHandlers,
    });
    chunks = reader.chunkIndexes.length;
    const dataEndOffset = Number(reader.dataEndOffset);
    const computed = crc32(bytes.subarray(0, dataEndOffset));
    if (reader.dataSectionCrc === undefined || reader.dataSectionCrc === 0) {
      errors.push("Data End carries no data section CRC");
    } else if (computed !== reader.dataSectionCrc || computed !== dataEndCrc) {
      errors.push(`data section CRC: stored ${reader.dataSectionCrc}, computed ${computed}`);
    }
    // Chunk indexes must point at Chunk records of the stated length, message indexes at
    // Message Index records of the right channel.
    const view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
    for (const ci of reader.chunkIndexes) {
      const at = Number(ci.chunkStartOffset);
      if (bytes[at] !== 0x06 || BigInt(9) + view.getBigUint64(at + 1, true) !== ci.chunkLength) {
        errors.push(`chunk index -> byte ${at} is not a Chunk of length ${ci.chunkLength}`);
      }
      for (const [channelId, offset] of ci.messageIndexOffsets) {
        const o = Number(offset);
        if (bytes[o] !== 0x07 || view.getUint16(o + 9, true) !== channelId) {
          errors.push(`message index offset ${o} (channel ${channelId}) is not its Message Index`);
        }
      }
    }
    indexed = [];
    for await (const m of reader.readMessages({ validateCrcs: true })) indexed.push(m);
    const stats = reader.statistics;
    if (!stats) {
      errors.push("no Statistics record");
    } else {
      if (Number(stats.messageCount) !== indexed.length)
        errors.push(`Statistics.messageCount ${stats.messageCount} != ${indexed.length} indexed`);
      if (stats.chunkCount !== chunks)
        errors.push(`Statistics.chunkCount ${stats.chunkCount} != ${chunks} chunk indexes`);
      for (const [id, count] of stats.channelMessageCounts) {
        const n = indexed.filter((m) => m.channelId === id).length;
        if (Number(count) !== n) errors.push(`channel ${id}: Statistics says ${count}, indexed ${n}`);
      }
      if (indexed.length > 0) {
        const min = indexed.reduce((a, m) => (m.logTime < a ? m.logTime : a), indexed[0].logTime);
        const max = indexed.reduce((a, m) => (m.logTime > a ? m.logTime : a), indexed[0].logTime);
        if (stats.messageStartTime !== min || stats.messageEndTime !== max)
          errors.push("Statistics message start/end times do not match the messages");
      }
    }
    for (const [id, ch] of reader.channelsById) channels.set(id, ch);
    // Decode.
    const key = (m) => `${m.channelId}/${m.sequence}/${m.logTime}`;
    const streamedKeys = streamed.map(key).sort();
    const indexedKeys = indexed.map(key).sort();
    if (JSON.stringify(streamedKeys) !== JSON.stringify(indexedKeys)) {
      errors.push(`stream reader saw ${streamed.length} messages, indexed reader ${indexed.length}`);
    }
    const decoders = new Map();
    const decoded = new Map();  // topic/sequence -> {message, value}
    for (const m of indexed) {
      const channel = reader.channelsById.get(m.channelId);
      const schema = reader.schemasById.get(channel.schemaId);
      if (channel.messageEncoding !== "cdr" || !schema || schema.encoding !== "omgidl") {
        errors.push(`channel ${channel.topic}: encoding ${channel.messageEncoding}/${schema?.encoding}`);
        continue;
      }
      let decoder = decoders.get(schema.id);
      if (!decoder) {
        const text = new TextDecoder().decode(schema.data);
        decoder = new MessageReader(schema.name, parseIDL(text));
        decoders.set(schema.id, decoder);
      }
      const id = `${channel.topic}/${m.sequence}`;
      const mustFail = (expected.undecodable ?? []).includes(id);
      try {
        decoded.set(id, { message: m, value: decoder.readMessage(m.data) });
        if (mustFail) errors.push(`${id}: decoded, but it was written as an invalid payload`);
      } catch (e) {
        if (!mustFail) errors.push(`${channel.topic} #${m.sequence}: cannot decode: ${e.message}`);
      }
    }
    // Compare with expectations.
    if (expected.messages !== undefined && expected.messages !== indexed.length)
      errors.push(`expected ${expected.messages} messages, file has ${indexed.length}`);
    if (expected.min_chunks !== undefined && chunks < expected.min_chunks)
      errors.push(`expected at least ${expected.min_chunks} chunks, file has ${chunks}`);
    for (const [topic, want] of Object.entries(expected.channels ?? {})) {
      const ch = [...reader.channelsById.values()].find((c) => c.topic === topic);
      if (!ch) { errors.push(`no channel ${topic}`); continue; }
      const schema = reader.schemasById.get(ch.schemaId);
      if (want.schema !== undefined && schema?.name !== want.schema)
        errors.push(`${topic}: schema ${schema?.name}, expected ${want.schema}`);
      const n = indexed.filter((m) => m.channelId === ch.id).length;
      if (want.count !== undefined && n !== want.count) errors.push(`${topic}: ${n} messages, expected ${want.count}`);
      if (want.min_count !== undefined && n < want.min_count) errors.push(`${topic}: ${n} messages, expected >= ${want.min_count}`);
      for (const [k, v] of Object.entries(want.metadata ?? {})) {
        if (ch.metadata.get(k) !== v) errors.push(`${topic}: metadata ${k}=${ch.metadata.get(k)}, expected ${v}`);
      }
    }
    let compared = 0;
    for (const v of expected.values ?? []) {
      const got = decoded.get(`${v.topic}/${v.sequence}`);
      if (!got) {
        if (!v.optional) errors.push(`${v.topic} #${v.sequence}: not in the file`);
        continue;
      }
      if (v.log_time !== undefined && got.message.logTime.toString() !== v.log_time)
        errors.push(`${v.topic} #${v.sequence}: log time ${got.message.logTime}, expected ${v.log_time}`);
      if (v.publish_time !== undefined && got.message.publishTime.toString() !== v.publish_time)
        errors.push(`${v.topic} #${v.sequence}: publish time ${got.message.publishTime}, expected ${v.publish_time}`);
      matches(v.value, got.value, `${v.topic} #${v.sequence}`, errors);
      compared += 1;
    }
    if (errors.length === 0) {
      console.log(`OK ${path.basename(file)}: ${indexed.length} messages, ${chunks} chunks, ` +
                  `${channels.size} channels, ${compared} payloads decoded and compared`);
    }
  } catch (e) {
    errors.push(`indexed reader: ${e.message}`);
  } finally {
    await handle.close();
  }
  return errors;
}

const dir = process.argv[2];
if (!dir) {
  console.error("usage: node validate.mjs DIR (FILE.mcap + FILE.expected.json pairs)");
  process.exit(2);
}
const files = (await fs.readdir(dir)).filter((f) => f.endsWith(".mcap")).sort();
let failed = 0;
let checked = 0;
for (const f of files) {
  const expectedPath = path.join(dir, f.replace(/\.mcap$/, ".expected.json"));
  let expected;
  try {
    expected = JSON.parse(await fs.readFile(expectedPath, "utf8"));
  } catch {
    continue;  // not a case file
  }
  checked += 1;
  let errors;
  try {
    errors = await validate(path.join(dir, f), expected);
  } catch (e) {
    errors = [`${e.message}`];
  }
  if (errors.length > 0) {
    failed += 1;
    console.log(`FAIL ${f}:`);
    for (const e of errors) console.log(`  ${e}`);
  }
}
if (checked === 0) {
  console.log(`FAIL: no FILE.mcap + FILE.expected.json pairs in ${dir}`);
  process.exit(1);
}
console.log(`${checked - failed}/${checked} files valid`);
process.exit(failed > 0 ? 1 : 0);
