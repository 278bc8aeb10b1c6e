// Test-only clients of poise's foxglove_bridge, written against the public packages Foxglove
// itself uses: @foxglove/ws-protocol (FoxgloveClient) over the `ws` WebSocket implementation, and
// @foxglove/omgidl-parser + @foxglove/omgidl-serialization to decode the advertised omgidl/cdr
// channels. The C++ tests (tests/foxglove/) run it and check what it prints.
//
//   node client.mjs decode URL OUT READY COUNT TIMEOUT_S TOPIC...
//       subscribes to TOPIC... once advertised (writes READY), decodes every message with the
//       channel's advertised schema, stops after COUNT messages per topic or TIMEOUT_S; OUT gets
//       one JSON line per message {topic, receive_ns, message} (64-bit integers as strings) and a
//       first line {serverInfo, channels (every advertisement), unadvertised (ids), statuses}.
//   node client.mjs malformed URL OUT
//       sends every kind of malformed client frame over a raw `ws` socket and records the server's
//       answers; then checks a good FoxgloveClient is still served. OUT: one JSON document.
//   node client.mjs stall URL OUT SECONDS READY
//       a good client subscribed to every channel, counting messages per topic per second, and a
//       stalled client (subscribed to every channel, its socket paused: it never reads again).
//   node client.mjs bench URL SECONDS
//       subscribes to every channel and prints messages/s and bytes/s.
import wsProtocol from "@foxglove/ws-protocol";
import { parseIDL } from "@foxglove/omgidl-parser";
import { MessageReader } from "@foxglove/omgidl-serialization";
import WebSocket from "ws";
import fs from "node:fs";

const { FoxgloveClient } = wsProtocol;
const [mode, url, ...args] = process.argv.slice(2);

/// JSON text of a decoded message: 64-bit integers (bigint) as strings, typed arrays (what the
/// omgidl reader gives for primitive arrays) as arrays.
function jsonSafe(value) {
  return JSON.stringify(value, (_k, v) =>
    typeof v === "bigint" ? v.toString() : ArrayBuffer.isView(v) && !(v instanceof DataView) ? Array.from(v) : v);
}

function decoderFor(channel) {
  if (channel.encoding === "cdr" && channel.schemaEncoding === "omgidl") {
    const reader = new MessageReader(channel.schemaName, parseIDL(channel.schema));
    return (view) => reader.readMessage(new Uint8Array(view.buffer, view.byteOffset, view.byteLength));
  }
  if (channel.encoding === "json") {
    const text = new TextDecoder();
    return (view) => JSON.parse(text.decode(view));
  }
  throw new Error(`channel ${channel.topic}: unexpected encoding ${channel.encoding}/${channel.schemaEncoding}`);
}

function connect() {
  return new FoxgloveClient({ ws: new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]) });
}

async function decode() {
  const [out, ready, countText, timeoutText, ...topics] = args;
  const count = Number(countText);
  const client = connect();
  const header = { serverInfo: null, channels: [], unadvertised: [], statuses: [] };
  const lines = [];
  const subs = new Map();  // subscription id -> {topic, decode}
  const counts = new Map(topics.map((t) => [t, 0]));
  let done;
  const finished = new Promise((resolve) => (done = resolve));
  client.on("serverInfo", (info) => (header.serverInfo = info));
  client.on("status", (s) => header.statuses.push(s));
  client.on("unadvertise", (ids) => header.unadvertised.push(...ids));
  client.on("error", (e) => header.statuses.push({ level: "client-error", message: String(e) }));
  client.on("advertise", (channels) => {
    for (const ch of channels) {
      header.channels.push(ch);
      if (topics.includes(ch.topic) && ![...subs.values()].some((s) => s.topic === ch.topic)) {
        const id = client.subscribe(ch.id);
        subs.set(id, { topic: ch.topic, decode: decoderFor(ch) });
      }
    }
    if (subs.size === topics.length) {
      fs.writeFileSync(ready, "subscribed\n");
    }
  });
  client.on("message", ({ subscriptionId, timestamp, data }) => {
    const sub = subs.get(subscriptionId);
    if (!sub) return;
    lines.push(jsonSafe({ topic: sub.topic, receive_ns: timestamp, message: sub.decode(data) }));
    counts.set(sub.topic, counts.get(sub.topic) + 1);
    if ([...counts.values()].every((n) => n >= count)) done();
  });
  const timer = setTimeout(done, Number(timeoutText) * 1000);
  await finished;
  clearTimeout(timer);
  client.close();
  fs.writeFileSync(out, [jsonSafe(header), ...lines].join("\n") + "\n");
}

/// Opens a raw ws socket with (or without) the subprotocol; resolves once open or refused.
function rawSocket(protocols, options = {}) {
  return new Promise((resolve) => {
    const ws = new WebSocket(url, protocols, options);
    const received = [];
    const state = { ws, received, open: false, closed: null, refused: null };
    ws.on("message", (data, isBinary) => received.push(isBinary ? { binary: data.length } : JSON.parse(data.toString())));
    ws.on("open", () => { state.open = true; resolve(state); });
    ws.on("unexpected-response", (_req, res) => { state.refused = res.statusCode; resolve(state); });
    ws.on("close", (code) => { state.closed = code; resolve(state); });
    ws.on("error", () => {});
  });
}

const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

async function malformed() {
  const [out] = args;
  const result = { cases: [], huge: null, no_subprotocol: null, good: null };
  const raw = await rawSocket([FoxgloveClient.SUPPORTED_SUBPROTOCOL], { maxPayload: 0 });
  await sleep(300);
  const advertised = raw.received.filter((m) => m.op === "advertise").flatMap((m) => m.channels);
  const cases = [
    ["bad JSON", "{\"op\": \"subscribe\", "],
    ["not an object", "[1, 2, 3]"],
    ["no op", "{\"subscriptions\": []}"],
    ["op not a string", "{\"op\": 7}"],
    ["unknown op", "{\"op\": \"launchMissiles\"}"],
    ["unsupported op", "{\"op\": \"getParameters\", \"parameterNames\": []}"],
    ["subscriptions not an array", "{\"op\": \"subscribe\", \"subscriptions\": 5}"],
    ["subscription without ids", "{\"op\": \"subscribe\", \"subscriptions\": [{}]}"],
    ["negative ids", "{\"op\": \"subscribe\", \"subscriptions\": [{\"id\": -1, \"channelId\": -2}]}"],
    ["ids beyond 2^32", "{\"op\": \"subscribe\", \"subscriptions\": [{\"id\": 4294967296, \"channelId\": 1}]}"],
    ["unknown channel", "{\"op\": \"subscribe\", \"subscriptions\": [{\"id\": 1, \"channelId\": 999999}]}"],
    ["unsubscribe unknown", "{\"op\": \"unsubscribe\", \"subscriptionIds\": [\"x\"]}"],
    ["deep nesting", "[".repeat(20000) + "]".repeat(20000)],
    ["too large request", JSON.stringify({ op: "subscribe", pad: "x".repeat(200 * 1024) })],
    ["binary frame", Buffer.from([1, 0, 0, 0, 0, 42])],
  ];
  if (advertised.length > 0) {
    const ch = advertised[0].id;
    cases.push(["duplicate subscription id",
                JSON.stringify({ op: "subscribe", subscriptions: [{ id: 7, channelId: ch }, { id: 7, channelId: ch }] })]);
  }
  for (const [name, frame] of cases) {
    const before = raw.received.length;
    raw.ws.send(frame, { binary: Buffer.isBuffer(frame) });
    await sleep(150);
    const statuses = raw.received.slice(before).filter((m) => m.op === "status");
    result.cases.push({ name, statuses });
  }
  result.raw_still_open = raw.ws.readyState === WebSocket.OPEN;
  raw.ws.close();
  // A frame beyond the server's hard limit: the connection is closed with 1009 (message too big).
  const big = await rawSocket([FoxgloveClient.SUPPORTED_SUBPROTOCOL], { maxPayload: 0 });
  const closed = new Promise((resolve) => big.ws.on("close", (code) => resolve(code)));
  big.ws.send("x".repeat(8 * 1024 * 1024));
  result.huge = await Promise.race([closed, sleep(5000).then(() => "not closed")]);
  // A client that does not offer the subprotocol is refused at the handshake.
  const plain = await rawSocket([]);
  result.no_subprotocol = { refused: plain.refused, open: plain.open };
  if (plain.open) plain.ws.close();
  // And the server still serves a good client.
  const client = connect();
  const good = { serverInfo: null, channels: 0, messages: 0 };
  client.on("serverInfo", (info) => (good.serverInfo = info));
  client.on("advertise", (channels) => {
    good.channels += channels.length;
    for (const ch of channels) client.subscribe(ch.id);
  });
  client.on("message", () => (good.messages += 1));
  await sleep(2000);
  client.close();
  result.good = good;
  fs.writeFileSync(out, jsonSafe(result) + "\n");
}

async function stall() {
  const [out, secondsText, ready] = args;
  const seconds = Number(secondsText);
  // The stalled client: subscribes to everything advertised, then never reads again.
  const stalled = await rawSocket([FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
  await sleep(500);
  const channels = stalled.received.filter((m) => m.op === "advertise").flatMap((m) => m.channels);
  stalled.ws.send(JSON.stringify({ op: "subscribe", subscriptions: channels.map((c, i) => ({ id: i, channelId: c.id })) }));
  await sleep(100);
  stalled.ws._socket.pause();
  // The good client: every channel, messages counted per topic and per second.
  const client = connect();
  const topics = new Map();
  const perSecond = {};
  const start = Date.now();
  client.on("advertise", (list) => {
    for (const ch of list) topics.set(client.subscribe(ch.id), ch.topic);
    fs.writeFileSync(ready, "subscribed\n");
  });
  client.on("message", ({ subscriptionId }) => {
    const topic = topics.get(subscriptionId);
    const s = Math.floor((Date.now() - start) / 1000);
    perSecond[topic] ??= [];
    perSecond[topic][s] = (perSecond[topic][s] ?? 0) + 1;
  });
  await sleep(seconds * 1000);
  client.close();
  fs.writeFileSync(out, jsonSafe({ stalled_channels: channels.length, per_second: perSecond }) + "\n");
  process.exit(0);
}

async function bench() {
  const [secondsText] = args;
  const client = connect();
  let messages = 0;
  let bytes = 0;
  client.on("advertise", (list) => { for (const ch of list) client.subscribe(ch.id); });
  client.on("message", ({ data }) => { messages += 1; bytes += data.byteLength; });
  await sleep(Number(secondsText) * 1000);
  client.close();
  console.log(`client: ${(messages / Number(secondsText)).toFixed(0)} messages/s, ${(bytes / Number(secondsText) / 1024).toFixed(0)} KiB/s`);
}

const modes = { decode, malformed, stall, bench };
if (!modes[mode]) {
  console.error(`usage: client.mjs ${Object.keys(modes).join("|")} URL ...`);
  process.exit(2);
}
modes[mode]().catch((e) => { console.error(e); process.exit(1); });
