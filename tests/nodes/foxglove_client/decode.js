// Decodes recorded ROS 2 messages with Foxglove's own decoders, as its app reads an MCAP file.
//
// stdin: JSON lines {"topic", "schemaName", "schema" (ros2msg text), "data" (base64 CDR)};
// stdout: one JSON line per input, {"topic", "trailingBytes", "data"} (BigInts as numbers), or
// {"topic", "error"} when a message does not decode. tests/record/test_foxglove_decode.py.
"use strict";

const readline = require("readline");
const { parse } = require("@foxglove/rosmsg");
const { MessageReader } = require("@foxglove/rosmsg2-serialization");

const readers = new Map(); // schema text -> MessageReader

function plain(_key, value) {
  if (typeof value === "bigint") return Number(value);
  if (ArrayBuffer.isView(value)) return Array.from(value); // typed arrays: plain lists
  return value;
}

const lines = readline.createInterface({ input: process.stdin });
lines.on("line", (line) => {
  if (!line.trim()) return;
  const item = JSON.parse(line);
  try {
    let reader = readers.get(item.schema);
    if (reader === undefined) {
      reader = new MessageReader(parse(item.schema, { ros2: true }));
      readers.set(item.schema, reader);
    }
    const data = reader.readMessage(Buffer.from(item.data, "base64"));
    process.stdout.write(JSON.stringify({ topic: item.topic,
      trailingBytes: reader.lastReadHadTrailingBytes(), data }, plain) + "\n");
  } catch (err) {
    process.stdout.write(JSON.stringify({ topic: item.topic, error: err.message }) + "\n");
  }
});
