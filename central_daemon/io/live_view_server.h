#pragma once
// The live view's web server (Boost.Beast, on the daemon's io_context): plain HTTP/1.1 and
// WebSocket on one port.
//   GET /            the page (HTML + canvas + JavaScript, self-contained, no external resources)
//   GET /state       the latest published JSON message (application/json; 503 before the first)
//   GET /ws          WebSocket upgrade; the server then sends every published message as a text
//                    frame (the newest first on connect); what a client sends is read and ignored
//   GET / or /ws     WebSocket upgrade offering the subprotocol foxglove.websocket.v1 (or
//                    foxglove.sdk.v1): the Foxglove WebSocket protocol (foxglove_protocol.h) with
//                    the channels of PublishFoxglove; a client subscribes to the channels it wants
//   anything else    404; methods other than GET/HEAD: 405; malformed requests: 400 and the
//                    connection closed
// Admission: with an access token, every request (page, state, WebSocket, any upgrade) must carry
// it, else 401 (AdmitRequest in live_view_http.h, the one place that decides).
// Robustness: request header and body sizes are limited, idle and slow clients time out, at most
// max_clients connections are served (more are refused), and a WebSocket client that cannot keep
// up never queues more than one pending message (the newest replaces an unsent one). Every
// refusal is counted.
// Thread-safety: all functions are called on the io_context's thread.

#include <boost/asio/io_context.hpp>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace lrfnet::daemon {

struct LiveViewOptions {
  std::string bind_address = "127.0.0.1";  // IPv4 or IPv6 literal, or a host name
  std::uint16_t port = 0;                  // 0: any free port (see LiveViewServer::port())
  std::size_t max_clients = 32;
  // Required of every request when set (AdmitRequest, live_view_http.h); compared in constant time.
  std::string access_token;
  std::size_t max_request_bytes = 8192;
  double idle_timeout_s = 30.0;  // HTTP keep-alive and WebSocket handshake
  // A WebSocket client is pinged after half of this without data from it and dropped after all of
  // it (a browser answers pings by itself; a client that stopped reading does not).
  double websocket_idle_timeout_s = 60.0;
  // Pages of these origins may open a Foxglove connection although they are not served by this
  // host (the Foxglove web app); other cross-origin WebSockets are refused.
  std::vector<std::string> foxglove_origins = {"https://app.foxglove.dev"};
};
std::optional<std::string> Validate(const LiveViewOptions& options);

struct LiveViewCounters {
  std::uint64_t http_requests = 0;
  std::uint64_t bad_requests = 0;  // malformed or too large (400 / closed)
  std::uint64_t not_found = 0;
  std::uint64_t refused_connections = 0;  // over max_clients
  std::uint64_t websocket_clients = 0;    // accepted upgrades, total
  std::uint64_t messages_sent = 0;        // WebSocket frames written
  std::uint64_t messages_replaced = 0;    // a slow client's unsent message replaced by a newer one
  std::uint64_t timeouts = 0;             // a request, response or WebSocket that took too long
  std::uint64_t idle_closed = 0;          // keep-alive connections closed after idle_timeout_s
  std::uint64_t method_not_allowed = 0;   // 405
  std::uint64_t forbidden_origins = 0;    // WebSocket upgrades from another origin's page (403)
  std::uint64_t upgrade_required = 0;     // /ws without an upgrade (426)
  std::uint64_t failed_handshakes = 0;    // upgrade requests the WebSocket handshake refused
  std::uint64_t foxglove_clients = 0;     // WebSocket clients that chose a Foxglove subprotocol
  std::uint64_t foxglove_messages_sent = 0;      // message-data frames written
  std::uint64_t foxglove_messages_replaced = 0;  // a slow client's unsent channel message replaced
  std::uint64_t foxglove_refused_messages = 0;   // client messages malformed or not supported
  std::uint64_t unauthorized = 0;                // requests without the access token (401)
};

// One message of a Foxglove channel (JSON encoding). The channel is advertised the first time its
// topic is published; a message equal to the channel's previous one is not sent again.
struct FoxgloveChannelMessage {
  std::string topic;
  std::string schema_name;  // e.g. "foxglove.SceneUpdate"
  std::string schema;       // JSON Schema of the payload
  std::string payload;      // JSON text
  std::uint64_t stamp_ns = 0;
};

// The bytes of the page served at "/" (defined with the request handling, live_view_http.h).
const std::string& LiveViewPage();

class LiveViewServer {
 public:
  // Precondition: Validate(options).
  LiveViewServer(boost::asio::io_context& io, const LiveViewOptions& options);
  ~LiveViewServer();
  LiveViewServer(const LiveViewServer&) = delete;
  LiveViewServer& operator=(const LiveViewServer&) = delete;

  // Binds and starts accepting. False with *error on failure (address in use, ...).
  bool Start(std::string* error);
  // Closes the listener and every connection.
  void Stop();
  std::uint16_t port() const;

  // Makes `json` the latest message and sends it to every WebSocket client of the live view's own
  // feed.
  void Publish(std::string json);
  // Publishes to the Foxglove clients (see FoxgloveChannelMessage); a subscriber gets a channel's
  // latest message at once.
  void PublishFoxglove(std::vector<FoxgloveChannelMessage> messages);
  // Connected WebSocket clients (handshake done), and all open connections (HTTP included).
  std::size_t websocket_clients() const;
  std::size_t connections() const;
  const LiveViewCounters& counters() const;

 private:
  struct Impl;
  std::shared_ptr<Impl> impl_;
};

}  // namespace lrfnet::daemon
