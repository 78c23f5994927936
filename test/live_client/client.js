// The test client of the live view (test/test_live.py): the npm @foxglove/ws-protocol FoxgloveClient over the `ws`
// WebSocket, offering the client's own default subprotocol (FoxgloveClient.SUPPORTED_SUBPROTOCOL,
// "foxglove.websocket.v1"), as a third-party tool would. It subscribes to every channel advertised, decodes each
// message with the channel's advertised schema (ros2msg, parsed by @foxglove/rosmsg; CDR, read by
// @foxglove/rosmsg2-serialization) and, once each topic named on the command line has N messages, unsubscribes,
// closes and prints one JSON document on stdout:
//   {subprotocol, serverInfo, channels: [advertised channel], messages: {topic: [[timestamp ns (string), message]]}}
// Usage: node client.js ws://HOST:PORT N TOPIC[,TOPIC...]
// Exit status 1 with a message on stderr if the connection fails or closes first.
"use strict";
const { FoxgloveClient } = require("@foxglove/ws-protocol");
const { parse } = require("@foxglove/rosmsg");
const { MessageReader } = require("@foxglove/rosmsg2-serialization");
const WebSocket = require("ws");

const [url, nText, topicsText] = process.argv.slice(2);
const n = Number(nText);
const wanted = topicsText.split(",");

const ws = new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
const client = new FoxgloveClient({ ws });
const channels = new Map(); // channel id -> {channel, reader}
const subscriptions = new Map(); // subscription id -> topic
const messages = {};
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
  messages[topic].push([timestamp.toString(), reader.readMessage(data)]);
  if (!done && wanted.every((t) => (messages[t] ?? []).length >= n)) {
    done = true;
    for (const id of subscriptions.keys()) client.unsubscribe(id);
    const out = {
      subprotocol: ws.protocol,
      serverInfo,
      channels: [...channels.values()].map((c) => c.channel),
      messages,
    };
    process.stdout.write(JSON.stringify(out, plain) + "\n", () => {
      client.close();
      process.exit(0);
    });
  }
});
client.on("error", (error) => fail(`error: ${error?.message ?? error}`));
client.on("close", (event) => fail(`connection closed (code ${event?.code}) before ${n} messages on ${wanted}`));
