// An outside viewer of a live run: Foxglove's own WebSocket protocol client (npm
// @foxglove/ws-protocol, over the `ws` package) subscribes to every channel the server advertises
// and decodes each message with the schema the server sent (protobuf: the FileDescriptorSet of
// the channel, with protobufjs; json: JSON.parse). Used by tests/tests/foxglove.rs.
//
//   node foxglove_client.mjs ws://HOST:PORT [SECONDS]
//
// Runs until the server closes the connection (the run ended) or SECONDS (default 120) pass, then
// prints one JSON object: the advertised channels (topic, encoding, schema name), message counts
// per topic, every /tf transform (log time, frame, translation), every /agent/{i}/plot message,
// the entity ids seen per scene topic, and the /log lines.

import wsProtocol from "@foxglove/ws-protocol";
import protobuf from "protobufjs";
import descriptor from "protobufjs/ext/descriptor/index.js";
import WebSocket from "ws";

const { FoxgloveClient } = wsProtocol;

const [url, secondsArg] = process.argv.slice(2);
if (!url) {
  console.error("usage: node foxglove_client.mjs ws://HOST:PORT [SECONDS]");
  process.exit(2);
}
const seconds = Number(secondsArg ?? 120);

// The Foxglove SDK's server refuses a client that offers only foxglove.websocket.v1.
const ws = new WebSocket(url, ["foxglove.sdk.v1", FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
const client = new FoxgloveClient({ ws });

const channels = new Map(); // channel id -> {topic, encoding, schemaName, decode}
const subscriptions = new Map(); // subscription id -> channel id
const report = {
  subprotocol: null,
  server: null,
  channels: [],
  counts: {},
  tf: [],
  plots: [],
  entities: {},
  logs: [],
  errors: [],
};

function protobufDecoder(schemaName, schemaBase64) {
  const bytes = Buffer.from(schemaBase64, "base64");
  const set = descriptor.FileDescriptorSet.decode(bytes);
  const root = protobuf.Root.fromDescriptor(set);
  const type = root.lookupType(schemaName);
  return (data) =>
    type.toObject(type.decode(data), { longs: Number, enums: Number, defaults: true });
}

client.on("open", () => {
  report.subprotocol = ws.protocol;
});
client.on("serverInfo", (info) => {
  report.server = { name: info.name, capabilities: info.capabilities };
});
client.on("error", (e) => report.errors.push(String(e?.message ?? e)));
client.on("advertise", (list) => {
  for (const ch of list) {
    let decode;
    try {
      if (ch.encoding === "protobuf") {
        decode = protobufDecoder(ch.schemaName, ch.schema);
      } else if (ch.encoding === "json") {
        const text = new TextDecoder();
        decode = (data) => JSON.parse(text.decode(data));
      } else {
        report.errors.push(`${ch.topic}: unknown encoding ${ch.encoding}`);
        continue;
      }
    } catch (e) {
      report.errors.push(`${ch.topic}: cannot load schema ${ch.schemaName}: ${e}`);
      continue;
    }
    channels.set(ch.id, { topic: ch.topic, encoding: ch.encoding, schemaName: ch.schemaName, decode });
    report.channels.push({ topic: ch.topic, encoding: ch.encoding, schemaName: ch.schemaName });
    subscriptions.set(client.subscribe(ch.id), ch.id);
  }
});
client.on("message", ({ subscriptionId, timestamp, data }) => {
  const ch = channels.get(subscriptions.get(subscriptionId));
  if (!ch) return;
  const bytes = new Uint8Array(data.buffer, data.byteOffset, data.byteLength);
  let msg;
  try {
    msg = ch.decode(bytes);
  } catch (e) {
    report.errors.push(`${ch.topic}: cannot decode: ${e}`);
    return;
  }
  report.counts[ch.topic] = (report.counts[ch.topic] ?? 0) + 1;
  const logTimeNs = Number(timestamp);
  if (ch.topic === "/tf") {
    for (const t of msg.transforms) {
      // Field names as the schema spells them (protobufjs keeps them from the descriptor);
      // timestamps are google.protobuf.Timestamp.
      report.tf.push({
        log_time_ns: logTimeNs,
        stamp_ns: Number(t.timestamp.seconds) * 1e9 + Number(t.timestamp.nanos),
        parent: t.parent_frame_id,
        child: t.child_frame_id,
        translation: [t.translation.x, t.translation.y, t.translation.z],
        rotation: [t.rotation.x, t.rotation.y, t.rotation.z, t.rotation.w],
      });
    }
  } else if (ch.topic.startsWith("/agent/") && ch.topic.endsWith("/plot")) {
    report.plots.push({ log_time_ns: logTimeNs, ...msg });
  } else if (ch.topic.startsWith("/scene/")) {
    const ids = (report.entities[ch.topic] ??= []);
    for (const e of msg.entities) if (!ids.includes(e.id)) ids.push(e.id);
  } else if (ch.topic === "/log") {
    report.logs.push({ log_time_ns: logTimeNs, level: msg.level, message: msg.message });
  }
});

let done = false;
function finish() {
  if (done) return;
  done = true;
  // Exit once the whole report is written (a pipe takes it in pieces).
  process.stdout.write(JSON.stringify(report) + "\n", () => process.exit(0));
}
client.on("close", finish);
setTimeout(() => {
  report.errors.push(`timeout after ${seconds} s`);
  try {
    client.close();
  } catch {}
  finish();
}, seconds * 1000).unref();
