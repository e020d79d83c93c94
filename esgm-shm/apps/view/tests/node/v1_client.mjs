// An independent client of esgm-view, as Lichtblick and older Foxglove Studio connect:
// @foxglove/ws-protocol's FoxgloveClient over `ws`, asking for the spec's subprotocol
// (FoxgloveClient.SUPPORTED_SUBPROTOCOL, "foxglove.websocket.v1"). It subscribes to
// every channel advertised, decodes the first message of each topic named on the
// command line (JSON channels with JSON.parse, protobuf ones with protobufjs from the
// schema the server advertised), prints one JSON line per topic, and exits 0 once
// every topic has one; 1 on an error or after 20 s.
//
//   node v1_client.mjs ws://127.0.0.1:PORT /camera /robot
import wsProtocol from "@foxglove/ws-protocol";
import protobuf from "protobufjs";
import descriptor from "protobufjs/ext/descriptor/index.js";
import WebSocket from "ws";

const { FoxgloveClient } = wsProtocol;

const [url, ...topics] = process.argv.slice(2);
const wanted = new Set(topics);
const ws = new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
const client = new FoxgloveClient({ ws });
const bySubscription = new Map();
const fail = (why) => {
  console.error(`v1 client: ${why}`);
  process.exit(1);
};
setTimeout(() => fail(`timed out; still waiting for ${[...wanted].join(", ")}`), 20000);

ws.on("open", () => {
  if (ws.protocol !== FoxgloveClient.SUPPORTED_SUBPROTOCOL) {
    fail(`the server chose ${JSON.stringify(ws.protocol)}`);
  }
  console.log(JSON.stringify({ protocol: ws.protocol }));
});
client.on("error", (e) => fail(e?.message ?? String(e)));
client.on("serverInfo", (info) => console.log(JSON.stringify({ serverInfo: info.name })));
client.on("advertise", (channels) => {
  for (const channel of channels) {
    let decode;
    if (channel.encoding === "json") {
      const text = new TextDecoder();
      decode = (data) => JSON.parse(text.decode(data));
    } else if (channel.encoding === "protobuf") {
      const set = descriptor.FileDescriptorSet.decode(Buffer.from(channel.schema, "base64"));
      const type = protobuf.Root.fromDescriptor(set).lookupType(channel.schemaName);
      decode = (data) => {
        const m = type.toObject(type.decode(data), { longs: String, bytes: Array });
        // An image's pixels: their count and the first three bytes.
        if (Array.isArray(m.data)) {
          m.dataLength = m.data.length;
          m.data = m.data.slice(0, 3);
        }
        return m;
      };
    } else {
      fail(`channel ${channel.topic}: an encoding this client does not know: ${channel.encoding}`);
    }
    const id = client.subscribe(channel.id);
    bySubscription.set(id, { channel, decode });
  }
});
client.on("message", ({ subscriptionId, timestamp, data }) => {
  const sub = bySubscription.get(subscriptionId);
  if (!sub) fail(`a message for unknown subscription ${subscriptionId}`);
  const { channel, decode } = sub;
  if (!wanted.has(channel.topic)) return;
  const bytes = new Uint8Array(data.buffer, data.byteOffset, data.byteLength);
  console.log(JSON.stringify({
    topic: channel.topic,
    schemaName: channel.schemaName,
    encoding: channel.encoding,
    timestamp: timestamp.toString(),
    message: decode(bytes),
  }));
  wanted.delete(channel.topic);
  if (wanted.size === 0) {
    ws.close();
    process.exit(0);
  }
});
