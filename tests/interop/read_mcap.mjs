#!/usr/bin/env node
// Independent reader for meshphase MCAP recordings, built on the TypeScript reader
// @mcap/core (McapIndexedReader) from the npm registry.
//
// It shares no code with meshphase: it decodes the message payload from the layout
// documented in data_schemas/mcap.md (16-byte little-endian header: first_sample uint64,
// n_samples uint32, n_channels uint16, dtype uint8 (1 = float32, 2 = float64), version uint8;
// then n_channels * n_samples little-endian samples, channel-major).
//
// JSON channels (message encoding "json", e.g. meshphase's layout="foxglove"): each message is
// parsed with JSON.parse and listed per topic under "jsonTopics" (log times, the decoded
// messages), so the test can hold them against the recording and the channel's jsonschema.
//
// Usage: node read_mcap.mjs FILE.mcap [--start NS --end NS]
//   --start/--end: also run readMessages({startTime, endTime}) over that log-time range
//   (@mcap/core treats endTime as INCLUSIVE) and list the messages it returns.
// Prints one JSON document on stdout: header, schemas, channels, metadata records,
// statistics, and per topic the log times, first-sample indices, the samples (base64 of the
// little-endian bytes in sample order, their SHA-256, the first values decoded as numbers).
// Exits 1 with a message on stderr when the file cannot be read or a payload is malformed.

import { open } from "node:fs/promises";
import { createHash } from "node:crypto";
import { McapIndexedReader } from "@mcap/core";
import decompressLZ4 from "@foxglove/wasm-lz4";
import zstd from "@foxglove/wasm-zstd";

const HEADER_SIZE = 16;
const DTYPES = { 1: { name: "float32", size: 4 }, 2: { name: "float64", size: 8 } };

/** Minimal IReadable over a Node file handle (random access reads). */
class FileReadable {
  constructor(handle) {
    this.handle = handle;
  }
  async size() {
    return BigInt((await this.handle.stat()).size);
  }
  async read(offset, length) {
    const n = Number(length);
    const buf = new Uint8Array(n);
    const { bytesRead } = await this.handle.read(buf, 0, n, Number(offset));
    if (bytesRead !== n) {
      throw new Error(`short read: ${bytesRead} of ${n} bytes at offset ${offset}`);
    }
    return buf;
  }
}

function parseArgs(argv) {
  const args = { file: undefined, start: undefined, end: undefined };
  for (let i = 0; i < argv.length; i++) {
    const a = argv[i];
    if (a === "--start") args.start = BigInt(argv[++i]);
    else if (a === "--end") args.end = BigInt(argv[++i]);
    else if (args.file === undefined) args.file = a;
    else throw new Error(`unexpected argument ${a}`);
  }
  if (args.file === undefined) throw new Error("usage: node read_mcap.mjs FILE.mcap [--start NS --end NS]");
  if ((args.start === undefined) !== (args.end === undefined)) throw new Error("--start and --end go together");
  return args;
}

function decodeHeader(data, where) {
  if (data.byteLength < HEADER_SIZE) throw new Error(`${where}: payload of ${data.byteLength} bytes < header`);
  const dv = new DataView(data.buffer, data.byteOffset, data.byteLength);
  const h = {
    firstSample: dv.getBigUint64(0, true),
    nSamples: dv.getUint32(8, true),
    nChannels: dv.getUint16(12, true),
    dtype: dv.getUint8(14),
    version: dv.getUint8(15),
  };
  const dt = DTYPES[h.dtype];
  if (dt === undefined) throw new Error(`${where}: unknown dtype code ${h.dtype}`);
  if (h.version !== 1) throw new Error(`${where}: unknown layout version ${h.version}`);
  const want = HEADER_SIZE + h.nChannels * h.nSamples * dt.size;
  if (data.byteLength !== want) throw new Error(`${where}: ${data.byteLength} bytes, header says ${want}`);
  return { ...h, dt };
}

function numberOut(x) {
  return Number.isFinite(x) ? x : String(x); // JSON has no NaN / Infinity
}

async function main() {
  const args = parseArgs(process.argv.slice(2));
  await decompressLZ4.isLoaded;
  await zstd.isLoaded;
  const decompressHandlers = {
    lz4: (buffer, size) => new Uint8Array(decompressLZ4(buffer, Number(size))),
    zstd: (buffer, size) => new Uint8Array(zstd.decompress(buffer, Number(size))),
  };
  const handle = await open(args.file, "r");
  try {
    const reader = await McapIndexedReader.Initialize({
      readable: new FileReadable(handle),
      decompressHandlers,
    });
    const out = {
      header: { profile: reader.header.profile, library: reader.header.library },
      schemas: [],
      channels: [],
      metadata: [],
      statistics: null,
      topics: {},
      jsonTopics: {},
    };
    for (const s of reader.schemasById.values()) {
      const text = new TextDecoder().decode(s.data);
      let data = text;
      try {
        data = JSON.parse(text);
      } catch {
        // not JSON: keep the text
      }
      out.schemas.push({ id: s.id, name: s.name, encoding: s.encoding, data });
    }
    for (const c of reader.channelsById.values()) {
      out.channels.push({
        id: c.id,
        topic: c.topic,
        messageEncoding: c.messageEncoding,
        schemaId: c.schemaId,
        metadata: Object.fromEntries(c.metadata),
      });
    }
    for await (const m of reader.readMetadata()) {
      out.metadata.push({ name: m.name, metadata: Object.fromEntries(m.metadata) });
    }
    if (reader.statistics) {
      const st = reader.statistics;
      out.statistics = {
        messageCount: String(st.messageCount),
        messageStartTime: String(st.messageStartTime),
        messageEndTime: String(st.messageEndTime),
        chunkCount: st.chunkCount,
      };
    }

    // every message, in log-time order
    const perTopic = new Map();
    for await (const msg of reader.readMessages()) {
      const ch = reader.channelsById.get(msg.channelId);
      if (ch.messageEncoding === "json") {
        if (!(ch.topic in out.jsonTopics)) {
          const sc = reader.schemasById.get(ch.schemaId);
          out.jsonTopics[ch.topic] = {
            schemaName: sc ? sc.name : "",
            schemaEncoding: sc ? sc.encoding : "",
            logTimes: [],
            messages: [],
          };
        }
        const jt = out.jsonTopics[ch.topic];
        jt.logTimes.push(String(msg.logTime));
        jt.messages.push(JSON.parse(new TextDecoder().decode(msg.data)));
        continue;
      }
      if (ch.messageEncoding !== "meshphase-block") continue;
      const h = decodeHeader(msg.data, `${ch.topic} @ ${msg.logTime}`);
      if (!perTopic.has(ch.topic)) perTopic.set(ch.topic, []);
      perTopic.get(ch.topic).push({ logTime: msg.logTime, h, data: msg.data });
    }
    for (const [topic, msgs] of perTopic) {
      msgs.sort((a, b) => (a.h.firstSample < b.h.firstSample ? -1 : a.h.firstSample > b.h.firstSample ? 1 : 0));
      const dt = msgs[0].h.dt;
      let total = 0;
      let contiguous = true;
      let expect = 0n;
      for (const m of msgs) {
        if (m.h.firstSample !== expect) contiguous = false;
        expect = m.h.firstSample + BigInt(m.h.nSamples);
        total += m.h.nSamples * m.h.nChannels;
      }
      const bytes = Buffer.alloc(total * dt.size);
      let pos = 0;
      for (const m of msgs) {
        const body = m.data.subarray(HEADER_SIZE);
        bytes.set(body, pos);
        pos += body.byteLength;
      }
      const dv = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
      const head = [];
      let nNaN = 0;
      for (let i = 0; i < total; i++) {
        const x = dt.size === 8 ? dv.getFloat64(i * 8, true) : dv.getFloat32(i * 4, true);
        if (Number.isNaN(x)) nNaN++;
        if (i < 8) head.push(numberOut(x));
      }
      out.topics[topic] = {
        messages: msgs.length,
        dtype: dt.name,
        nSamples: total,
        contiguous,
        logTimes: msgs.map((m) => String(m.logTime)),
        firstSamples: msgs.map((m) => String(m.h.firstSample)),
        blockSizes: msgs.map((m) => m.h.nSamples),
        head,
        nNaN,
        sha256: createHash("sha256").update(bytes).digest("hex"),
        base64: bytes.toString("base64"),
      };
    }

    if (args.start !== undefined) {
      const got = [];
      for await (const msg of reader.readMessages({ startTime: args.start, endTime: args.end })) {
        const ch = reader.channelsById.get(msg.channelId);
        if (ch.messageEncoding !== "meshphase-block") continue;
        const h = decodeHeader(msg.data, `${ch.topic} @ ${msg.logTime}`);
        got.push({ topic: ch.topic, logTime: String(msg.logTime), firstSample: String(h.firstSample) });
      }
      out.window = { startTime: String(args.start), endTime: String(args.end), messages: got };
    }
    process.stdout.write(JSON.stringify(out) + "\n");
  } finally {
    await handle.close();
  }
}

main().catch((err) => {
  process.stderr.write(`read_mcap.mjs: ${err && err.stack ? err.stack : err}\n`);
  process.exit(1);
});
