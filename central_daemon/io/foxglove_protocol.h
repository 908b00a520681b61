#pragma once
// The Foxglove WebSocket protocol as the live view speaks it (pure: bytes <-> values, no socket).
// Subprotocols "foxglove.websocket.v1" and "foxglove.sdk.v1" (the name newer Foxglove clients
// offer; the same messages). What lrfnetd implements:
//   server -> client, text:   {"op":"serverInfo",...} on connect, {"op":"advertise","channels":
//                             [{id, topic, encoding:"json", schemaName, schema, schemaEncoding:
//                             "jsonschema"}]} on connect and when channels appear, {"op":"status"}
//                             for a client message that was refused
//   server -> client, binary: message data: opcode 0x01, uint32 LE subscription id, uint64 LE
//                             timestamp (ns), then the message (JSON text)
//   client -> server, text:   {"op":"subscribe","subscriptions":[{"id","channelId"}]},
//                             {"op":"unsubscribe","subscriptionIds":[...]}; other ops (parameters,
//                             services, client publishing: capabilities this server does not
//                             advertise) are answered with a status message and otherwise ignored
//   client -> server, binary: not supported (no clientPublish capability): refused with a status.

#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "central_daemon/io/live_view_http.h"

namespace lrfnet::daemon {

inline constexpr std::string_view kFoxgloveSubprotocol = "foxglove.websocket.v1";
inline constexpr std::string_view kFoxgloveSdkSubprotocol = "foxglove.sdk.v1";

// The subprotocol to answer an upgrade request with: the first Foxglove subprotocol among those
// the client offers (Sec-WebSocket-Protocol, comma-separated, in the client's order), or "" when
// it offers none (the live view's own JSON feed). Independent of whether the request is admitted.
std::string SelectSubprotocol(const HttpRequest& request);

struct FoxgloveChannel {
  std::uint32_t id = 0;
  std::string topic;
  std::string schema_name;  // e.g. "foxglove.SceneUpdate"
  std::string schema;       // JSON Schema text of the message (encoding "json")
};

std::string FoxgloveServerInfo(std::string_view name, std::string_view session_id);
std::string FoxgloveAdvertise(std::span<const FoxgloveChannel> channels);
// level: 0 info, 1 warning, 2 error.
std::string FoxgloveStatus(int level, std::string_view message);
// The binary message-data frame.
std::string FoxgloveMessageData(std::uint32_t subscription_id, std::uint64_t stamp_ns,
                                std::string_view payload);

// A client message, parsed within limits (at most kMaxFoxgloveSubscriptions per message).
inline constexpr std::size_t kMaxFoxgloveSubscriptions = 1024;
struct FoxgloveClientMessage {
  enum class Kind { kSubscribe, kUnsubscribe, kUnsupported, kBad };
  Kind kind = Kind::kBad;
  std::vector<std::pair<std::uint32_t, std::uint32_t>> subscribe;  // (subscription id, channel id)
  std::vector<std::uint32_t> unsubscribe;                          // subscription ids
  std::string op;                                                  // the op of kUnsupported
  std::string error;                                               // why, for kBad
};
FoxgloveClientMessage ParseFoxgloveClientMessage(std::string_view bytes, bool binary);

}  // namespace lrfnet::daemon
