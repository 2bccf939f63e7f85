// A Foxglove WebSocket client for the end-to-end tests (tests/e2e/foxglove.rs), built on Foxglove's own
// client library: FoxgloveClient from @foxglove/ws-protocol, over the `ws` package. The protocol (server info,
// channel advertisements, subscriptions, binary message frames, status replies) is handled by that library;
// this script only says what to subscribe to and prints what arrives, one JSON object per line on stdout.
//
// node client.mjs URL [--ticks N] [--events N] [--try-commands] [--timeout-ms MS]
//   --ticks N        subscribe to every /pavlov/ channel and stop after N /pavlov/ticks messages
//   --events N       also wait for N /pavlov/events messages
//   --spec-subprotocol  offer foxglove.websocket.v1 (the library's default) instead of foxglove.sdk.v1
//   --try-commands   once connected, try everything a Foxglove client could do beyond reading: advertise a
//                    channel and publish on it, get and set parameters, call a service; print the replies
//
// Exit code 0 after a clean stop, 1 on timeout, 2 when the connection failed or closed early.
import WebSocket from "ws";
import protocol from "@foxglove/ws-protocol";

const { FoxgloveClient } = protocol;

const args = process.argv.slice(2);
const url = args[0];
const option = (name, fallback) => {
  const i = args.indexOf(name);
  return i >= 0 ? Number(args[i + 1]) : fallback;
};
const ticksWanted = option("--ticks", 0);
const eventsWanted = option("--events", 0);
const timeoutMs = option("--timeout-ms", 30000);
const tryCommands = args.includes("--try-commands");
// The subprotocol offered: the SDK's name "foxglove.sdk.v1" unless --spec-subprotocol, which offers the
// library's own (the published spec's), FoxgloveClient.SUPPORTED_SUBPROTOCOL ("foxglove.websocket.v1").
const SUBPROTOCOL = args.includes("--spec-subprotocol")
  ? FoxgloveClient.SUPPORTED_SUBPROTOCOL
  : "foxglove.sdk.v1";

const out = (object) =>
  process.stdout.write(
    JSON.stringify(object, (_, v) => (typeof v === "bigint" ? v.toString() : v)) + "\n",
  );

const socket = new WebSocket(url, [SUBPROTOCOL]);
const client = new FoxgloveClient({ ws: socket });
const topics = new Map(); // subscription id → topic
const decoder = new TextDecoder();
let ticks = 0;
let events = 0;
let done = false;
let opened = false;
let signalsShown = 0;

const finish = (code) => {
  if (done) return;
  done = true;
  out({ event: "done", ticks, events });
  client.close();
  setTimeout(() => process.exit(code), 100);
};
const enough = () => ticks >= ticksWanted && events >= eventsWanted;

setTimeout(() => {
  out({ event: "timeout", ticks, events });
  finish(1);
}, timeoutMs);

client.on("open", () => {
  opened = true;
  out({ event: "open", protocol: socket.protocol });
});
client.on("error", (error) => out({ event: "error", message: String(error?.message ?? error) }));
client.on("close", (e) => {
  out({ event: "close", code: e?.code });
  if (!done) {
    done = true;
    setTimeout(() => process.exit(2), 50);
  }
});
client.on("serverInfo", (info) =>
  out({ event: "serverInfo", name: info.name, capabilities: info.capabilities }),
);
client.on("status", (s) => out({ event: "status", level: s.level, message: s.message }));
client.on("serviceCallFailure", (f) =>
  out({ event: "serviceCallFailure", serviceId: f.serviceId, message: f.message }),
);
client.on("parameterValues", (p) => out({ event: "parameterValues", parameters: p.parameters }));

client.on("advertise", (channels) => {
  for (const ch of channels) {
    out({
      event: "channel",
      topic: ch.topic,
      encoding: ch.encoding,
      schemaName: ch.schemaName,
      schemaEncoding: ch.schemaEncoding,
      schema: ch.schema,
    });
    if (ticksWanted > 0 && ch.topic.startsWith("/pavlov/")) {
      topics.set(client.subscribe(ch.id), ch.topic);
    }
  }
  out({ event: "subscribed", topics: [...topics.values()] });
  if (tryCommands) {
    const channelId = client.advertise({
      topic: "/pavlov/commands",
      encoding: "json",
      schemaName: "command",
    });
    client.sendMessage(channelId, new TextEncoder().encode(JSON.stringify({ cmd: "estop" })));
    client.getParameters(["alpha"], "get-1");
    client.setParameters([{ name: "alpha", value: 1 }], "set-1");
    client.sendServiceCallRequest({
      serviceId: 1,
      callId: 1,
      encoding: "json",
      data: new TextEncoder().encode(JSON.stringify({ cmd: "estop" })),
    });
    out({ event: "tried-commands" });
  }
  if (ticksWanted === 0 && !tryCommands) finish(0);
});

client.on("message", ({ subscriptionId, timestamp, data }) => {
  const topic = topics.get(subscriptionId);
  const text = decoder.decode(data);
  let message;
  try {
    message = JSON.parse(text);
  } catch (e) {
    out({ event: "bad-json", topic, message: String(e) });
    return;
  }
  if (topic === "/pavlov/ticks") {
    ticks += 1;
    if (ticks <= ticksWanted) {
      out({ event: "tick", seq: message.seq, t_ms: message.t_ms, log_time: timestamp, estop: message.estop });
    }
  } else if (topic === "/pavlov/events") {
    events += 1;
    out({ event: "message", topic, log_time: timestamp, message });
  } else if (topic === "/pavlov/signals") {
    if (signalsShown++ < 2) out({ event: "signals", seq: message.seq, keys: Object.keys(message), obs: message.obs, predictions: message.predictions });
  } else {
    out({ event: "message", topic, log_time: timestamp, message });
  }
  if (ticksWanted > 0 && enough()) finish(0);
});
