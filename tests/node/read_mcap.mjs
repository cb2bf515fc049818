#!/usr/bin/env node
// Reads an MCAP log with the TypeScript reader (@mcap/core, Foxglove's own implementation) and
// prints what it saw as one JSON object on stdout, for tests/planner/shore/test_mcap_node.py to compare with
// what executive/recorder.py wrote. An independent reader: none of the Python mcap package.
//
//   node read_mcap.mjs [--stream] [--messages] [--piece BYTES] LOG.mcap
//
// Default: McapIndexedReader (needs the footer, summary and indexes; validates the summary CRC,
// every chunk's CRC and every attachment's CRC). --stream: McapStreamReader fed the file in
// pieces of --piece bytes (default 65536), for a file a killed writer left without a footer:
// it reports the complete messages it got before the cut (`done` false, `bytes_remaining` the
// unparsed tail). --messages adds every message (raw JSON text and parsed payload).
//
// Times (nanoseconds) are strings: they do not fit a JSON number. Exit status 1 with a line on
// stderr when the reader refuses the file, 2 for a usage error.

import { open } from "node:fs/promises";
import { createHash } from "node:crypto";

import { McapIndexedReader, McapStreamReader, LIBRARY_IDENTIFIER } from "@mcap/core";
import zstd from "@foxglove/wasm-zstd";

const USAGE = "usage: node read_mcap.mjs [--stream] [--messages] [--piece BYTES] LOG.mcap";

function parseArgs(argv) {
  const opts = { stream: false, messages: false, piece: 65536, path: undefined };
  for (let i = 0; i < argv.length; i++) {
    const a = argv[i];
    if (a === "--stream") opts.stream = true;
    else if (a === "--messages") opts.messages = true;
    else if (a === "--piece") {
      opts.piece = Number(argv[++i]);
      if (!Number.isInteger(opts.piece) || opts.piece <= 0) usage(`--piece: expected a positive integer`);
    } else if (a.startsWith("--")) usage(`unknown option ${a}`);
    else if (opts.path === undefined) opts.path = a;
    else usage(`one log at a time; got ${opts.path} and ${a}`);
  }
  if (opts.path === undefined) usage("no log given");
  return opts;
}

function usage(message) {
  process.stderr.write(`read_mcap: ${message}\n${USAGE}\n`);
  process.exit(2);
}

// @mcap/core decompresses nothing itself; ZSTD (the recorder's compression) through Facebook's
// zstd compiled to WebAssembly, as @mcap/support's loadDecompressHandlers does it.
async function decompressHandlers() {
  await zstd.isLoaded;
  return { zstd: (buffer, size) => new Uint8Array(zstd.decompress(buffer, Number(size))) };
}

// Random access to the file for McapIndexedReader (the IReadable interface): it reads the
// footer, the summary and then only the chunks it needs.
function fileReadable(handle, size) {
  return {
    size: async () => BigInt(size),
    read: async (offset, length) => {
      if (offset + length > BigInt(size)) {
        throw new Error(`read past the end: ${offset}+${length} > ${size}`);
      }
      const buf = new Uint8Array(Number(length));
      let done = 0;
      while (done < buf.length) {
        const { bytesRead } = await handle.read(buf, done, buf.length - done, Number(offset) + done);
        if (bytesRead === 0) throw new Error(`short read at ${Number(offset) + done}`);
        done += bytesRead;
      }
      return buf;
    },
  };
}

const utf8 = new TextDecoder("utf-8", { fatal: true });

// What both readers report, built record by record.
class Report {
  constructor(mode, withMessages) {
    this.withMessages = withMessages;
    this.out = {
      reader: LIBRARY_IDENTIFIER,
      mode,
      header: null,
      schemas: {}, // by topic: {name, encoding, schema (parsed JSON schema)}
      channels: {}, // by topic: {message_encoding, metadata}
      counts: {}, // messages per topic
      message_count: 0,
      first_log_time: null,
      last_log_time: null,
      metadata: [], // {name, metadata} in file order
      attachments: [], // {name, media_type, log_time, create_time, size, sha256}
    };
    if (withMessages) this.out.messages = [];
    this.schemasById = new Map();
    this.channelsById = new Map();
  }

  header(h) {
    this.out.header = { profile: h.profile, library: h.library };
  }

  schema(s) {
    this.schemasById.set(s.id, s);
  }

  channel(c) {
    this.channelsById.set(c.id, c);
    const schema = this.schemasById.get(c.schemaId);
    if (schema === undefined) throw new Error(`channel ${c.id} (${c.topic}) names unknown schema ${c.schemaId}`);
    this.out.channels[c.topic] = { message_encoding: c.messageEncoding, metadata: Object.fromEntries(c.metadata) };
    this.out.schemas[c.topic] = {
      name: schema.name,
      encoding: schema.encoding,
      schema: schema.encoding === "jsonschema" ? JSON.parse(utf8.decode(schema.data)) : null,
    };
  }

  message(m) {
    const channel = this.channelsById.get(m.channelId);
    if (channel === undefined) throw new Error(`message on unknown channel ${m.channelId}`);
    const o = this.out;
    o.counts[channel.topic] = (o.counts[channel.topic] ?? 0) + 1;
    o.message_count += 1;
    const t = m.logTime;
    if (o.first_log_time === null || t < BigInt(o.first_log_time)) o.first_log_time = String(t);
    if (o.last_log_time === null || t > BigInt(o.last_log_time)) o.last_log_time = String(t);
    if (!this.withMessages) return;
    const text = utf8.decode(m.data);
    o.messages.push({
      topic: channel.topic,
      sequence: m.sequence,
      log_time: String(m.logTime),
      publish_time: String(m.publishTime),
      text,
      payload: channel.messageEncoding === "json" ? JSON.parse(text) : null,
    });
  }

  metadata(m) {
    this.out.metadata.push({ name: m.name, metadata: Object.fromEntries(m.metadata) });
  }

  attachment(a) {
    this.out.attachments.push({
      name: a.name,
      media_type: a.mediaType,
      log_time: String(a.logTime),
      create_time: String(a.createTime),
      size: a.data.byteLength,
      sha256: createHash("sha256").update(a.data).digest("hex"),
    });
  }
}

async function readIndexed(path, withMessages) {
  const handle = await open(path, "r");
  try {
    const { size } = await handle.stat();
    const reader = await McapIndexedReader.Initialize({
      readable: fileReadable(handle, size),
      decompressHandlers: await decompressHandlers(),
    });
    const report = new Report("indexed", withMessages);
    report.header(reader.header);
    for (const s of reader.schemasById.values()) report.schema(s);
    for (const c of reader.channelsById.values()) report.channel(c);
    for await (const m of reader.readMessages({ validateCrcs: true })) report.message(m);
    for await (const m of reader.readMetadata()) report.metadata(m);
    for await (const a of reader.readAttachments({ validateCrcs: true })) report.attachment(a);
    const out = report.out;
    // Per topic through the message indexes (readMessages with a topic filter), to check them.
    out.indexed_counts = {};
    for (const c of reader.channelsById.values()) {
      let n = 0;
      for await (const _ of reader.readMessages({ topics: [c.topic] })) n += 1;
      out.indexed_counts[c.topic] = n;
    }
    const st = reader.statistics;
    out.statistics = st === undefined ? null : {
      message_count: String(st.messageCount),
      schema_count: st.schemaCount,
      channel_count: st.channelCount,
      attachment_count: st.attachmentCount,
      metadata_count: st.metadataCount,
      chunk_count: st.chunkCount,
      message_start_time: String(st.messageStartTime),
      message_end_time: String(st.messageEndTime),
      channel_message_counts: Object.fromEntries(
        [...st.channelMessageCounts].map(([id, n]) => [reader.channelsById.get(id)?.topic ?? String(id), String(n)])),
    };
    out.chunk_indexes = reader.chunkIndexes.map((ci) => ({
      compression: ci.compression,
      message_start_time: String(ci.messageStartTime),
      message_end_time: String(ci.messageEndTime),
      compressed_size: String(ci.compressedSize),
      uncompressed_size: String(ci.uncompressedSize),
    }));
    out.attachment_index_names = reader.attachmentIndexes.map((ai) => ai.name);
    out.metadata_index_names = reader.metadataIndexes.map((mi) => mi.name);
    out.data_section_crc = reader.dataSectionCrc ?? null;
    return out;
  } finally {
    await handle.close();
  }
}

async function readStream(path, withMessages, piece) {
  const reader = new McapStreamReader({ decompressHandlers: await decompressHandlers(), validateCrcs: true });
  const report = new Report("stream", withMessages);
  const records = {}; // record counts by type (chunk contents included)
  const handle = await open(path, "r");
  let fileBytes = 0;
  try {
    const buf = new Uint8Array(piece);
    for (;;) {
      const { bytesRead } = await handle.read(buf, 0, piece, null);
      if (bytesRead === 0) break;
      fileBytes += bytesRead;
      reader.append(buf.slice(0, bytesRead));
      for (let r; (r = reader.nextRecord()) !== undefined;) {
        records[r.type] = (records[r.type] ?? 0) + 1;
        switch (r.type) {
          case "Header": report.header(r); break;
          case "Schema": if (!report.schemasById.has(r.id)) report.schema(r); break;
          case "Channel": if (!report.channelsById.has(r.id)) report.channel(r); break;
          case "Message": report.message(r); break;
          case "Metadata": report.metadata(r); break;
          case "Attachment": report.attachment(r); break;
          default: break;
        }
      }
    }
  } finally {
    await handle.close();
  }
  const out = report.out;
  out.records = records;
  out.file_bytes = fileBytes;
  out.done = reader.done(); // a complete file: footer and closing magic parsed
  out.bytes_remaining = reader.bytesRemaining(); // the cut-off tail of a truncated file
  return out;
}

const opts = parseArgs(process.argv.slice(2));
try {
  const out = opts.stream
    ? await readStream(opts.path, opts.messages, opts.piece)
    : await readIndexed(opts.path, opts.messages);
  process.stdout.write(JSON.stringify(out) + "\n");
} catch (err) {
  process.stderr.write(`read_mcap: ${opts.path}: ${err?.message ?? err}\n`);
  process.exitCode = 1;
}
