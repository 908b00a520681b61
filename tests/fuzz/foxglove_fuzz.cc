// Fuzz target for what a Foxglove client sends the live view (central_daemon/io/
// foxglove_protocol.h): arbitrary bytes as one WebSocket message, text or binary (first byte).
// Properties checked with __builtin_trap:
//   - a message is refused with a reason, or parsed within the limits (at most
//     kMaxFoxgloveSubscriptions entries, every id a uint32);
//   - parsing is deterministic;
//   - the answers the server builds from it (a status message naming the op or the reason, a
//     message-data frame) are well-formed: the status is JSON with "op":"status", the frame has
//     the opcode, the ids and the payload where the protocol puts them.

#include <cstddef>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>

#include "central_daemon/io/foxglove_protocol.h"

namespace {

using lrfnet::daemon::FoxgloveClientMessage;

void Check(bool ok) {
  if (!ok) __builtin_trap();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  const bool binary = (data[0] & 1) != 0;
  const std::string_view bytes(reinterpret_cast<const char*>(data + 1), size - 1);
  const FoxgloveClientMessage m = lrfnet::daemon::ParseFoxgloveClientMessage(bytes, binary);
  const FoxgloveClientMessage again = lrfnet::daemon::ParseFoxgloveClientMessage(bytes, binary);
  Check(m.kind == again.kind && m.subscribe == again.subscribe &&
        m.unsubscribe == again.unsubscribe);
  Check(m.subscribe.size() <= lrfnet::daemon::kMaxFoxgloveSubscriptions);
  Check(m.unsubscribe.size() <= lrfnet::daemon::kMaxFoxgloveSubscriptions);
  switch (m.kind) {
    case FoxgloveClientMessage::Kind::kBad:
      Check(!m.error.empty() && m.subscribe.empty() && m.unsubscribe.empty());
      break;
    case FoxgloveClientMessage::Kind::kUnsupported:
      Check(!m.op.empty() && m.op.size() <= 64);
      break;
    case FoxgloveClientMessage::Kind::kSubscribe:
    case FoxgloveClientMessage::Kind::kUnsubscribe:
      Check(!binary);
      break;
  }
  const std::string status = lrfnet::daemon::FoxgloveStatus(
      2, m.kind == FoxgloveClientMessage::Kind::kBad ? m.error : m.op);
  const nlohmann::json j = nlohmann::json::parse(status, nullptr, false);
  Check(j.is_object() && j["op"] == "status" && j["level"] == 2);
  for (const auto& [subscription, channel] : m.subscribe) {
    const std::string frame = lrfnet::daemon::FoxgloveMessageData(subscription, channel, bytes);
    Check(frame.size() == 13 + bytes.size() && frame[0] == 0x01);
    std::uint32_t id = 0;
    for (int i = 3; i >= 0; --i) id = (id << 8) | static_cast<std::uint8_t>(frame[1 + i]);
    Check(id == subscription);
    Check(std::string_view(frame).substr(13) == bytes);
  }
  return 0;
}
