// A strict check of `sarctl view` with the client Foxglove's own tools use:
// @foxglove/ws-protocol's FoxgloveClient (offering its default subprotocol,
// `foxglove.websocket.v1`) over `ws`; every advertised `ros2msg` schema parsed
// by @foxglove/rosmsg `parse(text, { ros2: true })`, every channel
// subscribed, messages of the CDR channels decoded by
// @foxglove/rosmsg2-serialization, the JSON ones by JSON.parse, until each
// channel has `--count N` messages (default 20); with `--layout FILE`, every
// message path of the layout is looked up in the decoded messages.
//
// Usage: SAR_READERS_NODE=DIR node check_live.mjs [--layout FILE] [--count N] ws://ADDR
// Prints one JSON object: {"subprotocol", "channels", "schemas", "messages",
// "failures", "errors", "topics": {topic: count}, "layout": {path: status}}.
import { createRequire } from "node:module";
import { readFile } from "node:fs/promises";
import path from "node:path";

const dir = process.env.SAR_READERS_NODE;
const require = createRequire(path.join(path.resolve(dir ?? "."), "node_modules", "x.js"));
let FoxgloveClient, WebSocket, parse, MessageReader;
try {
  ({ FoxgloveClient } = require("@foxglove/ws-protocol"));
  WebSocket = require("ws");
  ({ parse } = require("@foxglove/rosmsg"));
  ({ MessageReader } = require("@foxglove/rosmsg2-serialization"));
} catch (e) {
  console.error(`missing npm package: ${e.message} (scripts/setup-test-readers.sh)`);
  process.exit(3);
}

const args = process.argv.slice(2);
const opt = (name, dflt) => {
  const i = args.indexOf(name);
  if (i < 0) return dflt;
  const v = args[i + 1];
  args.splice(i, 2);
  return v;
};
const layoutFile = opt("--layout", null);
const count = Number(opt("--count", "20"));
const url = args[0];

const out = {
  subprotocol: null, channels: 0, schemas: 0, messages: 0, failures: 0,
  errors: [], topics: {}, layout: {},
};
const fail = (what) => {
  out.failures += 1;
  if (out.errors.length < 20) out.errors.push(what);
};

const paths = [];
if (layoutFile) {
  const walk = (v) => {
    if (typeof v === "string") {
      if (v.startsWith("/")) paths.push(v);
    } else if (Array.isArray(v)) v.forEach(walk);
    else if (v && typeof v === "object") {
      // Keys too: the 3D panel's topics.
      Object.keys(v).forEach((k) => k.startsWith("/") && paths.push(k));
      Object.values(v).forEach(walk);
    }
  };
  walk(JSON.parse(await readFile(layoutFile, "utf8")));
}

function lookup(msg, rest) {
  let v = msg;
  const re = /\.([A-Za-z_][A-Za-z0-9_]*)|\[(\d+)\]/gy;
  let at = 0;
  while (at < rest.length) {
    re.lastIndex = at;
    const m = re.exec(rest);
    if (!m) return undefined;
    at = re.lastIndex;
    if (v === undefined || v === null) return undefined;
    v = m[1] !== undefined ? v[m[1]] : v[Number(m[2])];
  }
  return v;
}

const ws = new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
const client = new FoxgloveClient({ ws });
const channels = new Map(); // subscription id -> {topic, decode}
const samples = new Map(); // topic -> decoded messages
let done = false;

const finish = () => {
  if (done) return;
  done = true;
  const topics = new Set([...channels.values()].map((c) => c.topic));
  for (const p of [...new Set(paths)].sort()) {
    const topic = [...topics]
      .filter((t) => p === t || p.startsWith(t + ".") || p.startsWith(t + "["))
      .sort((a, b) => b.length - a.length)[0];
    if (!topic) {
      out.layout[p] = "no-channel";
      continue;
    }
    const rest = p.slice(topic.length);
    const s = samples.get(topic) ?? [];
    if (rest === "") out.layout[p] = "ok";
    else if (s.length === 0) out.layout[p] = "no-messages";
    else {
      const ok = s.every((m) => {
        const v = lookup(m, rest);
        return v !== undefined && v !== null && typeof v !== "object";
      });
      out.layout[p] = ok ? "ok" : "missing";
    }
  }
  process.stdout.write(JSON.stringify(out) + "\n");
  client.close();
  process.exit(0);
};

const timer = setTimeout(() => {
  fail("timeout: not every channel sent enough messages");
  finish();
}, 30000);

ws.on("open", () => {
  out.subprotocol = ws.protocol;
});
ws.on("unexpected-response", (_req, res) => {
  fail(`HTTP ${res.statusCode} to the upgrade`);
  clearTimeout(timer);
  finish();
});
client.on("error", (e) => fail(`client: ${e?.message ?? e}`));
client.on("advertise", (advertised) => {
  for (const ch of advertised) {
    out.channels += 1;
    let decode;
    if (ch.encoding === "cdr") {
      if (ch.schemaEncoding !== "ros2msg") fail(`${ch.topic}: schema encoding ${ch.schemaEncoding}`);
      try {
        const reader = new MessageReader(parse(ch.schema, { ros2: true }));
        out.schemas += 1;
        decode = (data) => reader.readMessage(data);
      } catch (e) {
        fail(`${ch.topic}: schema ${ch.schemaName}: ${e.message}`);
        continue;
      }
    } else if (ch.encoding === "json") {
      decode = (data) => JSON.parse(new TextDecoder().decode(data));
    } else {
      // The 3D scene (protobuf): counted, not decoded here.
      decode = () => undefined;
    }
    const id = client.subscribe(ch.id);
    channels.set(id, { topic: ch.topic, decode });
  }
});
client.on("message", ({ subscriptionId, data }) => {
  const ch = channels.get(subscriptionId);
  if (!ch) return;
  out.messages += 1;
  out.topics[ch.topic] = (out.topics[ch.topic] ?? 0) + 1;
  try {
    const m = ch.decode(new Uint8Array(data.buffer, data.byteOffset, data.byteLength));
    const s = samples.get(ch.topic) ?? [];
    if (m !== undefined && s.length < count) {
      s.push(m);
      samples.set(ch.topic, s);
    }
  } catch (e) {
    fail(`${ch.topic}: ${e.message}`);
  }
  // Every channel except the guard's events (only at transitions) has enough.
  const enough = [...channels.values()]
    .filter((c) => c.topic !== "/sar/guard/events")
    .every((c) => (out.topics[c.topic] ?? 0) >= count);
  if (enough && channels.size > 0) {
    clearTimeout(timer);
    finish();
  }
});
