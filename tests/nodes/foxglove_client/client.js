// A client of the Foxglove WebSocket protocol, as the Foxglove app is one: it connects to a
// server, reads the channels it advertises, subscribes to the topics it is given, decodes each
// message with the channel's own schema (ROS 2 .msg text, CDR payload) and prints one JSON line
// per event on stdout. tests/nodes/test_foxglove.py runs it and asserts on what it prints.
//
//   node client.js URL COUNT TIMEOUT_S [--try-publish] [--subprotocol=NAME] TOPIC[:COUNT]...
//
// Lines: {"op": "serverInfo", ...} once; {"op": "advertise", "topic", "encoding",
// "schemaName", "schemaEncoding"} per advertised channel; {"op": "message", "topic",
// "logTime", "trailingBytes", "data"} per message (at most COUNT per topic, or the topic's own); {"op": "status",
// "level", "message"} per status the server sends; {"op": "done", "complete"} last.
// With --try-publish the client also advertises a channel of its own and sends a message on it
// (what a read-only server must refuse). Exits 0 once every topic has COUNT messages (or, with
// --try-publish, also a status answer), 3 at TIMEOUT_S, 4 on a connection or decoding error.
"use strict";

const { FoxgloveClient } = require("@foxglove/ws-protocol");
const { parse } = require("@foxglove/rosmsg");
const { MessageReader } = require("@foxglove/rosmsg2-serialization");
const WebSocket = require("ws");

const args = process.argv.slice(2);
const url = args.shift();
const count = Number(args.shift());
const timeoutS = Number(args.shift());
const tryPublish = args[0] === "--try-publish";
if (tryPublish) args.shift();
// the subprotocol offered: foxglove-sdk's name by default, or the older ws-protocol name
const subprotocolArg = args[0] && args[0].startsWith("--subprotocol=") ? args.shift() : null;
const wanted = new Map(args.map((arg) => {
  const [topic, n] = arg.split(":");
  return [topic, n === undefined ? count : Number(n)];
}));

function emit(obj) {
  // int64/uint64 fields decode as BigInt, arrays of numbers as typed arrays
  process.stdout.write(JSON.stringify(obj, (_key, value) => {
    if (typeof value === "bigint") return value.toString();
    if (ArrayBuffer.isView(value)) return Array.from(value);
    return value;
  }) + "\n");
}

const received = new Map([...wanted.keys()].map((t) => [t, 0]));
const readers = new Map(); // subscription id -> {topic, reader}
let statusSeen = false;

function complete() {
  return [...received].every(([t, n]) => n >= wanted.get(t)) && (!tryPublish || statusSeen);
}

function finish(code) {
  emit({ op: "done", complete: complete() });
  client.close();
  // (stdout is a pipe: let it drain before the process ends)
  process.stdout.write("", () => process.exit(code));
}

// foxglove-sdk servers accept the subprotocol "foxglove.sdk.v1" (the Foxglove app's), the same
// protocol as ws-protocol's "foxglove.websocket.v1" under its new name (which the bridge's front
// also accepts)
const SUBPROTOCOL = subprotocolArg ? subprotocolArg.split("=")[1] : "foxglove.sdk.v1";
const client = new FoxgloveClient({ ws: new WebSocket(url, [SUBPROTOCOL]) });
const timer = setTimeout(() => finish(3), timeoutS * 1000);

client.on("error", (err) => {
  emit({ op: "error", message: String(err && err.message ? err.message : err) });
  clearTimeout(timer);
  finish(4);
});
client.on("serverInfo", (info) => {
  emit({ op: "serverInfo", name: info.name, capabilities: info.capabilities,
         supportedEncodings: info.supportedEncodings ?? null });
  if (tryPublish) {
    const id = client.advertise({ topic: "/biped/simulate_from_client", encoding: "cdr",
                                  schemaName: "std_msgs/msg/Empty", schema: "" });
    client.sendMessage(id, new Uint8Array([0, 1, 0, 0, 0, 0, 0, 0]));
  }
});
client.on("status", (status) => {
  statusSeen = true;
  emit({ op: "status", level: status.level, message: status.message });
  if (complete()) { clearTimeout(timer); finish(0); }
});
client.on("advertise", (channels) => {
  for (const ch of channels) {
    emit({ op: "advertise", topic: ch.topic, encoding: ch.encoding, schemaName: ch.schemaName,
           schemaEncoding: ch.schemaEncoding });
    if (!wanted.has(ch.topic)) continue;
    if (ch.encoding !== "cdr" || ch.schemaEncoding !== "ros2msg") {
      emit({ op: "error", message: `${ch.topic}: ${ch.encoding}/${ch.schemaEncoding}` });
      finish(4);
      return;
    }
    const reader = new MessageReader(parse(ch.schema, { ros2: true }));
    readers.set(client.subscribe(ch.id), { topic: ch.topic, reader });
  }
});
client.on("message", (event) => {
  const sub = readers.get(event.subscriptionId);
  if (sub === undefined || received.get(sub.topic) >= wanted.get(sub.topic)) return;
  let data;
  try {
    data = sub.reader.readMessage(event.data);
  } catch (err) {
    emit({ op: "error", message: `${sub.topic}: ${err.message}` });
    clearTimeout(timer);
    finish(4);
    return;
  }
  received.set(sub.topic, received.get(sub.topic) + 1);
  emit({ op: "message", topic: sub.topic, logTime: event.timestamp,
         trailingBytes: sub.reader.lastReadHadTrailingBytes(), data });
  if (complete()) { clearTimeout(timer); finish(0); }
});
