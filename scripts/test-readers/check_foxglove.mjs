// A strict check of MCAP recordings with the parsers Foxglove and Lichtblick
// use: @mcap/core's indexed reader (zstd by @mcap/support), every `ros2msg`
// schema parsed by @foxglove/rosmsg `parse(text, { ros2: true })`, every
// message decoded by @foxglove/rosmsg2-serialization's MessageReader. With
// `--layout FILE`, every message path of the Foxglove layout whose topic is in
// a file (`/topic.field.sub[0]`) is looked up in that topic's decoded
// messages.
//
// Usage: SAR_READERS_NODE=DIR node check_foxglove.mjs [--layout FILE] FILE.mcap...
//   (DIR: target/test-readers/node, made by scripts/setup-test-readers.sh)
// Prints one JSON object: {"files": [{"path", "profile", "schemas",
// "channels", "messages", "failures", "errors": [...], "topics": {topic:
// count}, "layout": {path: "ok" | "missing" | "no-channel" | "no-messages"}}]}.
// Exit 0 when it ran (the caller checks the failures), 3 when the packages
// are missing.
import { createRequire } from "node:module";
import { open, readFile } from "node:fs/promises";
import path from "node:path";

const dir = process.env.SAR_READERS_NODE;
if (!dir) {
  console.error("SAR_READERS_NODE is not set (scripts/setup-test-readers.sh)");
  process.exit(3);
}
let McapIndexedReader, loadDecompressHandlers, parse, MessageReader;
try {
  const require = createRequire(path.join(path.resolve(dir), "node_modules", "x.js"));
  ({ McapIndexedReader } = require("@mcap/core"));
  ({ loadDecompressHandlers } = require("@mcap/support"));
  ({ parse } = require("@foxglove/rosmsg"));
  ({ MessageReader } = require("@foxglove/rosmsg2-serialization"));
} catch (e) {
  console.error(`missing npm package: ${e.message} (scripts/setup-test-readers.sh)`);
  process.exit(3);
}

/// Message paths of a Foxglove layout: every string value that starts with a
/// topic ("/..."), and every key that does (the 3D panel's topics).
function layoutPaths(layout) {
  const out = new Set();
  const walk = (v) => {
    if (typeof v === "string") {
      if (v.startsWith("/")) out.add(v);
    } else if (Array.isArray(v)) {
      v.forEach(walk);
    } else if (v && typeof v === "object") {
      Object.keys(v).forEach((k) => k.startsWith("/") && out.add(k));
      Object.values(v).forEach(walk);
    }
  };
  walk(layout);
  return [...out].sort();
}

/// The value at `rest` (".a.b[0]") of a decoded message, or undefined.
function lookup(msg, rest) {
  let v = msg;
  const re = /\.([A-Za-z_][A-Za-z0-9_]*)|\[(\d+)\]/gy;
  let m;
  let at = 0;
  while (at < rest.length) {
    re.lastIndex = at;
    m = re.exec(rest);
    if (!m) return undefined;
    at = re.lastIndex;
    if (v === undefined || v === null) return undefined;
    v = m[1] !== undefined ? v[m[1]] : v[Number(m[2])];
  }
  return v;
}

async function check(file, paths) {
  const out = {
    path: file, profile: null, schemas: 0, channels: 0, messages: 0, failures: 0,
    errors: [], topics: {}, layout: {},
  };
  const fail = (what) => {
    out.failures += 1;
    if (out.errors.length < 20) out.errors.push(what);
  };
  let handle;
  try {
    handle = await open(file, "r");
    const size = BigInt((await handle.stat()).size);
    const readable = {
      size: async () => size,
      read: async (offset, length) => {
        const buf = new Uint8Array(Number(length));
        const { bytesRead } = await handle.read(buf, 0, Number(length), Number(offset));
        if (bytesRead !== Number(length)) throw new Error(`short read at ${offset}`);
        return buf;
      },
    };
    const reader = await McapIndexedReader.Initialize({
      readable,
      decompressHandlers: await loadDecompressHandlers(),
    });
    out.profile = reader.header.profile;
    const readers = new Map();
    const samples = new Map();
    for (const [id, schema] of reader.schemasById) {
      out.schemas += 1;
      if (schema.encoding !== "ros2msg") {
        fail(`schema ${schema.name}: encoding ${schema.encoding}`);
        continue;
      }
      try {
        const defs = parse(new TextDecoder().decode(schema.data), { ros2: true });
        readers.set(id, new MessageReader(defs));
      } catch (e) {
        fail(`schema ${schema.name}: ${e.message}`);
      }
    }
    for (const channel of reader.channelsById.values()) {
      out.channels += 1;
      if (channel.messageEncoding !== "cdr") {
        fail(`${channel.topic}: message encoding ${channel.messageEncoding}`);
      }
      if (!channel.metadata.get("offered_qos_profiles")) {
        fail(`${channel.topic}: no offered_qos_profiles`);
      }
    }
    for await (const message of reader.readMessages()) {
      out.messages += 1;
      const channel = reader.channelsById.get(message.channelId);
      out.topics[channel.topic] = (out.topics[channel.topic] ?? 0) + 1;
      const r = readers.get(channel.schemaId);
      if (!r) {
        fail(`${channel.topic}: no parsed schema`);
        continue;
      }
      try {
        const decoded = r.readMessage(message.data);
        const s = samples.get(channel.topic) ?? [];
        if (s.length < 50) {
          s.push(decoded);
          samples.set(channel.topic, s);
        }
      } catch (e) {
        fail(`${channel.topic}: message ${message.sequence}: ${e.message}`);
      }
    }
    const topics = new Set([...reader.channelsById.values()].map((c) => c.topic));
    for (const p of paths) {
      // The longest channel topic that prefixes the path.
      const topic = [...topics]
        .filter((t) => p === t || p.startsWith(t + ".") || p.startsWith(t + "["))
        .sort((a, b) => b.length - a.length)[0];
      if (!topic) {
        out.layout[p] = "no-channel";
        continue;
      }
      const rest = p.slice(topic.length);
      const s = samples.get(topic) ?? [];
      if (rest === "") {
        out.layout[p] = "ok";
      } else if (s.length === 0) {
        out.layout[p] = "no-messages";
      } else {
        const ok = s.every((m) => {
          const v = lookup(m, rest);
          return v !== undefined && v !== null && typeof v !== "object";
        });
        out.layout[p] = ok ? "ok" : "missing";
      }
    }
  } catch (e) {
    fail(`open: ${e.message}`);
  } finally {
    await handle?.close();
  }
  return out;
}

const args = process.argv.slice(2);
let paths = [];
const li = args.indexOf("--layout");
if (li >= 0) {
  paths = layoutPaths(JSON.parse(await readFile(args[li + 1], "utf8")));
  args.splice(li, 2);
}
const files = [];
for (const f of args) files.push(await check(f, paths));
process.stdout.write(JSON.stringify({ files }) + "\n");
