// A Foxglove WebSocket client (@foxglove/ws-protocol over the ws package) as Foxglove connects:
//   node foxglove_client.mjs URL SUBPROTOCOL WAIT_TOPIC MIN_COUNT TIMEOUT_S
// It subscribes to every advertised channel (until every channel has sent a message and WAIT_TOPIC
// MIN_COUNT messages, or TIMEOUT_S), decodes each message with its advertised encoding
// (json) and validates it against the advertised JSON Schema and, for foxglove.* schemas, against
// Foxglove's own published JSON Schema (@foxglove/schemas). Prints one JSON summary on stdout:
// {subprotocol, serverInfo, channels: [{topic, schemaName}], counts: {topic: n},
//  last: {topic: message}, invalid: [...], errors: [...]}. Exit 0 when it ran (the caller judges).
import { createRequire } from "node:module";

// The packages' CommonJS builds (their ES module builds are not importable by node as they are).
const require = createRequire(import.meta.url);
const { FoxgloveClient } = require("@foxglove/ws-protocol");
const { WebSocket } = require("ws");
const Ajv = require("ajv");
const foxgloveSchemas = require("@foxglove/schemas/jsonschema");

const [url, subprotocol, waitTopic, minCountText, timeoutText] = process.argv.slice(2);
const minCount = Number(minCountText ?? "2");
const timeoutMs = Number(timeoutText ?? "20") * 1000;

const ajv = new Ajv({ allErrors: true, strict: false });
const official = new Map();
for (const [name, schema] of Object.entries(foxgloveSchemas)) official.set(`foxglove.${name}`, ajv.compile(schema));

const summary = { subprotocol: null, serverInfo: null, channels: [], counts: {}, last: {}, invalid: [], errors: [] };
const channels = new Map();
const subscriptions = new Map();
const decoder = new TextDecoder();

const ws = new WebSocket(url, [subprotocol]);
const client = new FoxgloveClient({ ws });
const finish = () => {
  summary.subprotocol = ws.protocol;
  process.stdout.write(JSON.stringify(summary) + "\n");
  try { client.close(); } catch (e) { /* closing anyway */ }
  process.exit(0);
};
const timer = setTimeout(finish, timeoutMs);

client.on("error", (e) => summary.errors.push(String(e && e.message ? e.message : e)));
client.on("close", () => { clearTimeout(timer); finish(); });
client.on("serverInfo", (info) => { summary.serverInfo = info; });
client.on("status", (s) => summary.errors.push(`status ${s.level}: ${s.message}`));
client.on("advertise", (list) => {
  for (const channel of list) {
    let advertised = null;
    try {
      advertised = ajv.compile(JSON.parse(channel.schema));
    } catch (e) {
      summary.invalid.push(`${channel.topic}: advertised schema does not compile: ${e.message}`);
    }
    channels.set(channel.id, { ...channel, advertised });
    summary.channels.push({ topic: channel.topic, schemaName: channel.schemaName, encoding: channel.encoding });
    subscriptions.set(client.subscribe(channel.id), channel.id);
  }
});
client.on("message", ({ subscriptionId, timestamp, data }) => {
  const channel = channels.get(subscriptions.get(subscriptionId));
  if (!channel) { summary.errors.push(`message for unknown subscription ${subscriptionId}`); return; }
  let message;
  try {
    message = JSON.parse(decoder.decode(data));
  } catch (e) {
    summary.invalid.push(`${channel.topic}: not JSON`);
    return;
  }
  if (channel.advertised && !channel.advertised(message)) {
    summary.invalid.push(`${channel.topic}: advertised schema: ${ajv.errorsText(channel.advertised.errors)}`);
  }
  const check = official.get(channel.schemaName);
  if (check && !check(message)) {
    summary.invalid.push(`${channel.topic}: ${channel.schemaName}: ${ajv.errorsText(check.errors)}`);
  }
  summary.counts[channel.topic] = (summary.counts[channel.topic] ?? 0) + 1;
  summary.last[channel.topic] = message;
  summary.last[channel.topic + "#timestamp"] = timestamp.toString();
  if (channels.size > 0 && [...channels.values()].every((c) => (summary.counts[c.topic] ?? 0) >= 1) &&
      (summary.counts[waitTopic] ?? 0) >= minCount) {
    clearTimeout(timer);
    finish();
  }
});
