#include "central_daemon/io/foxglove_protocol.h"

#include <boost/beast/http/field.hpp>
#include <cstring>
#include <nlohmann/json.hpp>

namespace lrfnet::daemon {
namespace {

using Json = nlohmann::json;

std::string Dump(const Json& j) { return j.dump(-1, ' ', false, Json::error_handler_t::replace); }

std::string_view Trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t')) s.remove_suffix(1);
  return s;
}

// A uint32 field, or nullopt.
std::optional<std::uint32_t> U32(const Json& object, const char* key) {
  const auto it = object.find(key);
  if (it == object.end() || !it->is_number_unsigned()) return std::nullopt;
  const std::uint64_t v = it->get<std::uint64_t>();
  if (v > 0xffffffffu) return std::nullopt;
  return static_cast<std::uint32_t>(v);
}

}  // namespace

std::string SelectSubprotocol(const HttpRequest& request) {
  for (auto it = request.find(boost::beast::http::field::sec_websocket_protocol);
       it != request.end() && it->name() == boost::beast::http::field::sec_websocket_protocol;
       ++it) {
    std::string_view list(it->value().data(), it->value().size());
    while (!list.empty()) {
      const std::size_t comma = list.find(',');
      const std::string_view token = Trim(list.substr(0, comma));
      if (token == kFoxgloveSubprotocol || token == kFoxgloveSdkSubprotocol)
        return std::string(token);
      if (comma == std::string_view::npos) break;
      list.remove_prefix(comma + 1);
    }
  }
  return "";
}

std::string FoxgloveServerInfo(std::string_view name, std::string_view session_id) {
  Json j;
  j["op"] = "serverInfo";
  j["name"] = name;
  j["capabilities"] = Json::array();
  j["supportedEncodings"] = Json::array();
  j["metadata"] = Json::object();
  j["sessionId"] = session_id;
  return Dump(j);
}

std::string FoxgloveAdvertise(std::span<const FoxgloveChannel> channels) {
  Json list = Json::array();
  for (const FoxgloveChannel& c : channels) {
    list.push_back({{"id", c.id},
                    {"topic", c.topic},
                    {"encoding", "json"},
                    {"schemaName", c.schema_name},
                    {"schema", c.schema},
                    {"schemaEncoding", "jsonschema"}});
  }
  return Dump(Json{{"op", "advertise"}, {"channels", std::move(list)}});
}

std::string FoxgloveStatus(int level, std::string_view message) {
  return Dump(Json{{"op", "status"}, {"level", level}, {"message", message}});
}

std::string FoxgloveMessageData(std::uint32_t subscription_id, std::uint64_t stamp_ns,
                                std::string_view payload) {
  std::string out(1 + 4 + 8 + payload.size(), '\0');
  out[0] = 0x01;
  for (int i = 0; i < 4; ++i)
    out[static_cast<std::size_t>(1 + i)] = static_cast<char>((subscription_id >> (8 * i)) & 0xff);
  for (int i = 0; i < 8; ++i)
    out[static_cast<std::size_t>(5 + i)] = static_cast<char>((stamp_ns >> (8 * i)) & 0xff);
  std::memcpy(out.data() + 13, payload.data(), payload.size());
  return out;
}

FoxgloveClientMessage ParseFoxgloveClientMessage(std::string_view bytes, bool binary) {
  FoxgloveClientMessage m;
  if (binary) {
    m.kind = FoxgloveClientMessage::Kind::kUnsupported;
    m.op = bytes.empty() ? "binary"
                         : "binary opcode " + std::to_string(static_cast<unsigned char>(bytes[0]));
    return m;
  }
  const Json j = Json::parse(bytes.begin(), bytes.end(), nullptr, /*allow_exceptions=*/false);
  if (j.is_discarded()) {
    m.error = "not JSON";
    return m;
  }
  if (!j.is_object() || !j.contains("op") || !j["op"].is_string()) {
    m.error = "expected an object with \"op\"";
    return m;
  }
  const std::string op = j["op"].get<std::string>();
  if (op.empty()) {
    m.error = "\"op\" is empty";
    return m;
  }
  if (op == "subscribe") {
    const auto it = j.find("subscriptions");
    if (it == j.end() || !it->is_array()) {
      m.error = "subscribe: expected \"subscriptions\": [...]";
      return m;
    }
    if (it->size() > kMaxFoxgloveSubscriptions) {
      m.error = "subscribe: too many subscriptions in one message";
      return m;
    }
    for (const Json& s : *it) {
      const auto id = s.is_object() ? U32(s, "id") : std::nullopt;
      const auto channel = s.is_object() ? U32(s, "channelId") : std::nullopt;
      if (!id || !channel) {
        m.error = "subscribe: each subscription needs uint32 \"id\" and \"channelId\"";
        m.subscribe.clear();
        return m;
      }
      m.subscribe.emplace_back(*id, *channel);
    }
    m.kind = FoxgloveClientMessage::Kind::kSubscribe;
    return m;
  }
  if (op == "unsubscribe") {
    const auto it = j.find("subscriptionIds");
    if (it == j.end() || !it->is_array() || it->size() > kMaxFoxgloveSubscriptions) {
      m.error = "unsubscribe: expected \"subscriptionIds\": [...]";
      return m;
    }
    for (const Json& s : *it) {
      if (!s.is_number_unsigned() || s.get<std::uint64_t>() > 0xffffffffu) {
        m.error = "unsubscribe: subscription ids are uint32";
        m.unsubscribe.clear();
        return m;
      }
      m.unsubscribe.push_back(static_cast<std::uint32_t>(s.get<std::uint64_t>()));
    }
    m.kind = FoxgloveClientMessage::Kind::kUnsubscribe;
    return m;
  }
  m.kind = FoxgloveClientMessage::Kind::kUnsupported;
  m.op = op.substr(0, 64);
  return m;
}

}  // namespace lrfnet::daemon
