// The test client of the live view (test/test_live.py): the npm @foxglove/ws-protocol FoxgloveClient over the `ws`
// WebSocket, offering the client's own default subprotocol (FoxgloveClient.SUPPORTED_SUBPROTOCOL,
// "foxglove.websocket.v1"), as a third-party tool would. It subscribes to every channel advertised, decodes each
// message with the channel's advertised schema (ros2msg, parsed by @foxglove/rosmsg; CDR, read by
// @foxglove/rosmsg2-serialization) and, once each topic named on the command line has N messages, unsubscribes,
// closes and prints one JSON document on stdout:
//   {subprotocol, serverInfo, channels: [advertised channel], messages: {topic: [[timestamp ns (string), message]]},
//    scripts: {LAYOUT: [output]}}
// where, for each Foxglove layout file given, `scripts` holds what its user script (TypeScript, compiled by
// `typescript` as the app does) returned, fed the decoded messages of its input topics in the order received.
// Usage: node client.js ws://HOST:PORT N TOPIC[,TOPIC...] [LAYOUT.json ...]
// Exit status 1 with a message on stderr if the connection fails or closes first.
"use strict";
const { FoxgloveClient } = require("@foxglove/ws-protocol");
const { parse } = require("@foxglove/rosmsg");
const { MessageReader } = require("@foxglove/rosmsg2-serialization");
const fs = require("fs");
const ts = require("typescript");
const WebSocket = require("ws");

const [url, nText, topicsText, ...layouts] = process.argv.slice(2);
const n = Number(nText);
const wanted = topicsText.split(",");

const ws = new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
const client = new FoxgloveClient({ ws });
const channels = new Map(); // channel id -> {channel, reader}
const subscriptions = new Map(); // subscription id -> topic
const messages = {};
const received = []; // [topic, message] in the order received
let serverInfo;
let done = false;

// JSON of a decoded message: typed arrays as arrays, 64-bit integers as strings
const plain = (_key, value) => {
  if (typeof value === "bigint") return value.toString();
  if (ArrayBuffer.isView(value)) return Array.from(value);
  return value;
};

const fail = (text) => {
  if (done) return;
  done = true;
  process.stderr.write(`client: ${text}\n`);
  process.exit(1);
};

// the user scripts of a layout file run over the messages received: their outputs, in order
function runScripts(path) {
  const layout = JSON.parse(fs.readFileSync(path, "utf8"));
  const outputs = [];
  for (const node of Object.values(layout.userNodes ?? {})) {
    const js = ts.transpileModule(node.sourceCode, {
      compilerOptions: { module: ts.ModuleKind.CommonJS, target: ts.ScriptTarget.ES2020 },
    }).outputText;
    const mod = { exports: {} };
    new Function("module", "exports", js)(mod, mod.exports);
    const { inputs, default: script } = mod.exports;
    for (const [topic, message] of received) {
      if (!inputs.includes(topic)) continue;
      const out = script({ topic, message });
      if (out !== undefined) outputs.push(out);
    }
  }
  return outputs;
}

client.on("serverInfo", (info) => {
  serverInfo = info;
});
client.on("advertise", (advertised) => {
  for (const channel of advertised) {
    if (channel.encoding !== "cdr" || channel.schemaEncoding !== "ros2msg") {
      fail(`${channel.topic}: encoding ${channel.encoding}, schema ${channel.schemaEncoding}; want cdr, ros2msg`);
      return;
    }
    const reader = new MessageReader(parse(channel.schema, { ros2: true }));
    channels.set(channel.id, { channel, reader });
    messages[channel.topic] ??= [];
    subscriptions.set(client.subscribe(channel.id), channel.topic);
  }
});
client.on("message", ({ subscriptionId, timestamp, data }) => {
  const topic = subscriptions.get(subscriptionId);
  const { reader } = [...channels.values()].find((c) => c.channel.topic === topic);
  const message = reader.readMessage(data);
  messages[topic].push([timestamp.toString(), message]);
  received.push([topic, message]);
  if (!done && wanted.every((t) => (messages[t] ?? []).length >= n)) {
    done = true;
    for (const id of subscriptions.keys()) client.unsubscribe(id);
    const out = {
      subprotocol: ws.protocol,
      serverInfo,
      channels: [...channels.values()].map((c) => c.channel),
      messages,
      scripts: Object.fromEntries(layouts.map((path) => [path, runScripts(path)])),
    };
    process.stdout.write(JSON.stringify(out, plain) + "\n", () => {
      client.close();
      process.exit(0);
    });
  }
});
client.on("error", (error) => fail(`error: ${error?.message ?? error}`));
client.on("close", (event) => fail(`connection closed (code ${event?.code}) before ${n} messages on ${wanted}`));
