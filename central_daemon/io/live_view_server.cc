#include "central_daemon/io/live_view_server.h"

#include <fcntl.h>

#include <algorithm>
#include <array>
#include <boost/asio/ip/address.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/beast/core/buffers_to_string.hpp>
#include <boost/beast/core/error.hpp>
#include <boost/beast/core/flat_buffer.hpp>
#include <boost/beast/core/tcp_stream.hpp>
#include <boost/beast/http/write.hpp>
#include <boost/beast/websocket/stream.hpp>
#include <chrono>
#include <deque>
#include <map>
#include <optional>
#include <unordered_set>
#include <utility>

#include "central_daemon/io/foxglove_protocol.h"
#include "central_daemon/io/live_view_http.h"

namespace lrfnet::daemon {
namespace {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
using tcp = asio::ip::tcp;
using boost::system::error_code;

// The daemon's children (if it ever starts any) must not keep its port open.
void CloseOnExec(int fd) { ::fcntl(fd, F_SETFD, ::fcntl(fd, F_GETFD) | FD_CLOEXEC); }

std::chrono::steady_clock::duration Seconds(double s) {
  return std::chrono::duration_cast<std::chrono::steady_clock::duration>(
      std::chrono::duration<double>(s));
}

// The peer left, or Stop() closed the socket: not a fault of the request.
bool IsConnectionGone(const error_code& ec) {
  return ec == asio::error::operation_aborted || ec == asio::error::connection_reset ||
         ec == asio::error::broken_pipe || ec == asio::error::eof ||
         ec == asio::error::bad_descriptor || ec == asio::error::not_connected;
}

class HttpSession;
class WsSession;

// The server's state, shared by the sessions (LiveViewServer::Impl is this, under a name the
// sessions may use).
struct Core : std::enable_shared_from_this<Core> {
  Core(asio::io_context& io_context, const LiveViewOptions& o)
      : options(o), acceptor(io_context), retry_timer(io_context) {}

  void Accept();
  void OnAccept(const error_code& ec, tcp::socket socket);
  void Refuse(tcp::socket socket);

  const LiveViewOptions options;
  tcp::acceptor acceptor;
  asio::steady_timer retry_timer;  // after an accept error (e.g. out of file descriptors)
  bool running = false;
  std::uint16_t port = 0;
  LiveViewCounters counters;
  // Shared by every client's send queue: a slow client holds at most this one and the one it is
  // being sent, never copies.
  std::shared_ptr<const std::string> latest;
  // Sessions register themselves for Stop() and Publish(); each is owned by its pending handlers.
  std::unordered_set<HttpSession*> http_sessions;
  std::unordered_set<WsSession*> ws_sessions;
  std::size_t ws_open = 0;
  // Foxglove channels, by id - 1, with their latest message.
  struct FoxgloveTopic {
    FoxgloveChannel channel;
    std::shared_ptr<const std::string> payload;
    std::uint64_t stamp_ns = 0;
  };
  std::vector<FoxgloveTopic> foxglove_topics;
  std::map<std::string, std::uint32_t, std::less<>> foxglove_ids;
  std::string session_id =
      std::to_string(std::chrono::system_clock::now().time_since_epoch().count());
};

// Does the upgrade come from a page allowed to open a Foxglove connection?
bool FoxgloveOriginAllowed(const HttpRequest& request, const LiveViewOptions& options) {
  if (SelectSubprotocol(request).empty()) return false;
  const auto it = request.find(http::field::origin);
  if (it == request.end()) return false;
  const std::string_view origin(it->value().data(), it->value().size());
  for (const std::string& allowed : options.foxglove_origins) {
    if (origin == allowed) return true;
  }
  return false;
}

class WsSession : public std::enable_shared_from_this<WsSession> {
 public:
  WsSession(std::shared_ptr<Core> impl, tcp::socket socket)
      : impl_(std::move(impl)), ws_(std::move(socket)) {
    impl_->ws_sessions.insert(this);
  }
  ~WsSession() {
    if (open_) --impl_->ws_open;
    impl_->ws_sessions.erase(this);
  }

  void Start(HttpRequest request) {
    request_ = std::move(request);
    // The WebSocket stream keeps its own deadlines from here on.
    beast::get_lowest_layer(ws_).expires_never();
    websocket::stream_base::timeout timeouts{};
    timeouts.handshake_timeout = Seconds(impl_->options.idle_timeout_s);
    timeouts.idle_timeout = Seconds(impl_->options.websocket_idle_timeout_s);
    timeouts.keep_alive_pings = true;
    ws_.set_option(timeouts);
    // The subprotocol decides what this connection speaks: Foxglove, or the page's own JSON.
    subprotocol_ = SelectSubprotocol(request_);
    foxglove_ = !subprotocol_.empty();
    ws_.set_option(
        websocket::stream_base::decorator([protocol = subprotocol_](websocket::response_type& r) {
          r.set(http::field::server, "lrfnetd");
          if (!protocol.empty()) r.set(http::field::sec_websocket_protocol, protocol);
        }));
    // Clients send little (Foxglove: subscriptions); a large frame from one is an error, not a
    // buffer to grow.
    ws_.read_message_max(foxglove_ ? 65536 : 4096);
    ws_.async_accept(request_,
                     [self = shared_from_this()](const error_code& ec) { self->OnAccept(ec); });
  }

  bool foxglove() const { return foxglove_; }

  // Foxglove: a control message (never dropped).
  void SendControl(std::string text) {
    if (!open_ || !foxglove_) return;
    control_.push_back(std::make_shared<const std::string>(std::move(text)));
    Pump();
  }
  // Foxglove: a channel's message to the subscriptions of that channel; an unsent older one of the
  // same subscription is replaced.
  void SendChannel(std::uint32_t channel_id, std::uint64_t stamp_ns,
                   const std::shared_ptr<const std::string>& payload) {
    if (!open_ || !foxglove_) return;
    for (const auto& [subscription, channel] : subscriptions_) {
      if (channel != channel_id) continue;
      auto [it, inserted] = data_pending_.try_emplace(subscription);
      if (!inserted) ++impl_->counters.foxglove_messages_replaced;
      it->second = {stamp_ns, payload};
    }
    Pump();
  }

  void Send(const std::shared_ptr<const std::string>& message) {
    if (!open_ || foxglove_) return;
    if (writing_) {
      if (pending_) ++impl_->counters.messages_replaced;
      pending_ = message;
      return;
    }
    writing_ = message;
    ws_.text(true);
    ws_.async_write(
        asio::buffer(*writing_),
        [self = shared_from_this()](const error_code& ec, std::size_t) { self->OnWrite(ec); });
  }

  void Close() {
    MarkClosed();
    beast::get_lowest_layer(ws_).close();
  }

 private:
  void OnAccept(const error_code& ec) {
    if (ec) {
      // Beast has answered a malformed handshake with 400 already.
      if (ec == beast::error::timeout) {
        ++impl_->counters.timeouts;
      } else if (!IsConnectionGone(ec)) {
        ++impl_->counters.failed_handshakes;
      }
      return;
    }
    if (!impl_->running) return;
    request_ = {};
    open_ = true;
    ++impl_->ws_open;
    ++impl_->counters.websocket_clients;
    if (foxglove_) {
      ++impl_->counters.foxglove_clients;
      SendControl(FoxgloveServerInfo("lrfnetd", impl_->session_id));
      std::vector<FoxgloveChannel> channels;
      for (const Core::FoxgloveTopic& t : impl_->foxglove_topics) channels.push_back(t.channel);
      if (!channels.empty()) SendControl(FoxgloveAdvertise(channels));
    } else if (impl_->latest) {
      Send(impl_->latest);
    }
    Read();
  }

  // Foxglove: the next control message, else the next channel message, when nothing is being
  // written.
  void Pump() {
    if (!open_ || writing_) return;
    bool text = true;
    if (!control_.empty()) {
      writing_ = std::move(control_.front());
      control_.pop_front();
    } else if (!data_pending_.empty()) {
      const auto it = data_pending_.begin();
      writing_ = std::make_shared<const std::string>(
          FoxgloveMessageData(it->first, it->second.stamp_ns, *it->second.payload));
      data_pending_.erase(it);
      text = false;
      ++impl_->counters.foxglove_messages_sent;
    } else {
      return;
    }
    ws_.text(text);
    ws_.async_write(
        asio::buffer(*writing_),
        [self = shared_from_this()](const error_code& ec, std::size_t) { self->OnWrite(ec); });
  }

  void OnClientMessage() {
    const std::string bytes = beast::buffers_to_string(read_buffer_.data());
    const FoxgloveClientMessage m = ParseFoxgloveClientMessage(bytes, !ws_.got_text());
    switch (m.kind) {
      case FoxgloveClientMessage::Kind::kSubscribe:
        for (const auto& [subscription, channel] : m.subscribe) {
          if (channel == 0 || channel > impl_->foxglove_topics.size()) {
            ++impl_->counters.foxglove_refused_messages;
            SendControl(FoxgloveStatus(1, "subscribe: no channel " + std::to_string(channel)));
            continue;
          }
          subscriptions_[subscription] = channel;
          const Core::FoxgloveTopic& topic = impl_->foxglove_topics[channel - 1];
          if (topic.payload) {
            data_pending_[subscription] = {topic.stamp_ns, topic.payload};
          }
        }
        Pump();
        break;
      case FoxgloveClientMessage::Kind::kUnsubscribe:
        for (const std::uint32_t subscription : m.unsubscribe) {
          subscriptions_.erase(subscription);
          data_pending_.erase(subscription);
        }
        break;
      case FoxgloveClientMessage::Kind::kUnsupported:
        ++impl_->counters.foxglove_refused_messages;
        SendControl(FoxgloveStatus(1, "lrfnetd does not support '" + m.op + "'"));
        break;
      case FoxgloveClientMessage::Kind::kBad:
        ++impl_->counters.foxglove_refused_messages;
        SendControl(FoxgloveStatus(2, "malformed message: " + m.error));
        break;
    }
  }

  void Read() {
    ws_.async_read(read_buffer_, [self = shared_from_this()](const error_code& ec, std::size_t) {
      self->OnRead(ec);
    });
  }

  void OnRead(const error_code& ec) {
    if (ec) {
      if (ec == beast::error::timeout) ++impl_->counters.timeouts;
      Close();
      return;
    }
    if (foxglove_) OnClientMessage();
    read_buffer_.consume(read_buffer_.size());
    Read();
  }

  void OnWrite(const error_code& ec) {
    writing_.reset();
    if (ec) {
      Close();
      return;
    }
    ++impl_->counters.messages_sent;
    if (foxglove_) {
      Pump();
      return;
    }
    if (pending_) {
      const auto next = std::move(pending_);
      pending_.reset();
      Send(next);
    }
  }

  void MarkClosed() {
    if (open_) {
      open_ = false;
      --impl_->ws_open;
    }
    pending_.reset();
    control_.clear();
    data_pending_.clear();
  }

  std::shared_ptr<Core> impl_;
  websocket::stream<beast::tcp_stream> ws_;
  HttpRequest request_;  // the upgrade request, kept until the handshake is done
  beast::flat_buffer read_buffer_;
  bool open_ = false;
  std::shared_ptr<const std::string> writing_;  // the frame being written (keeps its bytes alive)
  std::shared_ptr<const std::string> pending_;  // at most one; a newer message replaces it
  // Foxglove.
  std::string subprotocol_;
  bool foxglove_ = false;
  std::map<std::uint32_t, std::uint32_t> subscriptions_;  // subscription id -> channel id
  std::deque<std::shared_ptr<const std::string>> control_;
  struct PendingData {
    std::uint64_t stamp_ns = 0;
    std::shared_ptr<const std::string> payload;
  };
  std::map<std::uint32_t, PendingData> data_pending_;  // by subscription id
};

class HttpSession : public std::enable_shared_from_this<HttpSession> {
 public:
  HttpSession(std::shared_ptr<Core> impl, tcp::socket socket)
      : impl_(std::move(impl)), stream_(std::move(socket)) {
    impl_->http_sessions.insert(this);
    unparsed_.reserve(RequestBufferBytes(impl_->options.max_request_bytes));
  }
  ~HttpSession() { impl_->http_sessions.erase(this); }

  void Start() { NextRequest(); }
  void Close() { stream_.close(); }

 private:
  void NextRequest() {
    reader_.emplace(impl_->options.max_request_bytes);
    // One deadline for the whole request, so a client that sends a byte now and then (slowloris)
    // is cut off as surely as a silent one.
    stream_.expires_after(Seconds(impl_->options.idle_timeout_s));
    Parse();
  }

  // Parses what is buffered (a pipelined request may be there already), else reads more.
  void Parse() {
    if (!unparsed_.empty()) {
      const RequestReader::Result r = reader_->Feed(unparsed_);
      unparsed_.erase(0, r.consumed);
      if (r.status == RequestReader::Status::kBad) {
        BadRequest(reader_->error());
        return;
      }
      if (r.status == RequestReader::Status::kComplete) {
        OnRequest(reader_->Take());
        return;
      }
    }
    const std::size_t have = unparsed_.size();
    if (have >= RequestBufferBytes(impl_->options.max_request_bytes)) {
      BadRequest("request too large");  // RequestReader refuses this first; kept as a guard
      return;
    }
    unparsed_.resize(RequestBufferBytes(impl_->options.max_request_bytes));
    stream_.async_read_some(asio::buffer(unparsed_.data() + have, unparsed_.size() - have),
                            [self = shared_from_this(), have](const error_code& ec, std::size_t n) {
                              self->unparsed_.resize(have + n);
                              self->OnRead(ec);
                            });
  }

  void OnRead(const error_code& ec) {
    if (!ec) {
      Parse();
      return;
    }
    if (ec == beast::error::timeout) {
      if (reader_->request_bytes() > 0 || !unparsed_.empty()) {
        ++impl_->counters.timeouts;
      } else {
        ++impl_->counters.idle_closed;
      }
      return;  // the stream is closed already
    }
    if (ec == asio::error::eof) {
      if (reader_->EndOfStream() == RequestReader::Status::kBad || !unparsed_.empty()) {
        BadRequest(reader_->error().empty() ? "connection closed in the middle of a request"
                                            : reader_->error());
      } else {
        Shutdown();
      }
    }
    // Otherwise reset by the peer, or Stop().
  }

  // Malformed, truncated or over a limit: say so and close.
  void BadRequest(const std::string& reason) {
    ++impl_->counters.bad_requests;
    Respond(BadRequestResponse(reason));
  }

  void OnRequest(HttpRequest request) {
    ++impl_->counters.http_requests;
    // Admission before routing: no page, state or upgrade of any kind without the token.
    if (AdmitRequest(request, impl_->options.access_token) != Admission::kAdmitted) {
      ++impl_->counters.unauthorized;
      Respond(UnauthorizedResponse(request));
      return;
    }
    const LiveViewRoute route = RouteOf(request);
    switch (route) {
      case LiveViewRoute::kWebSocket:
        if (!impl_->running) return;
        std::make_shared<WsSession>(impl_, stream_.release_socket())->Start(std::move(request));
        return;
      case LiveViewRoute::kNotFound:
        ++impl_->counters.not_found;
        break;
      case LiveViewRoute::kMethodNotAllowed:
        ++impl_->counters.method_not_allowed;
        break;
      case LiveViewRoute::kForbiddenOrigin:
        if (FoxgloveOriginAllowed(request, impl_->options)) {
          if (!impl_->running) return;
          std::make_shared<WsSession>(impl_, stream_.release_socket())->Start(std::move(request));
          return;
        }
        ++impl_->counters.forbidden_origins;
        break;
      case LiveViewRoute::kUpgradeRequired:
        ++impl_->counters.upgrade_required;
        break;
      case LiveViewRoute::kPage:
      case LiveViewRoute::kState:
        break;
    }
    Respond(RespondTo(request, route, impl_->latest.get()));
  }

  void Respond(HttpResponse response) {
    response_.emplace(std::move(response));
    // A client that does not take the response is cut off like a slow request.
    stream_.expires_after(Seconds(impl_->options.idle_timeout_s));
    http::async_write(
        stream_, *response_,
        [self = shared_from_this()](const error_code& ec, std::size_t) { self->OnWrite(ec); });
  }

  void OnWrite(const error_code& ec) {
    if (ec) {
      if (ec == beast::error::timeout) ++impl_->counters.timeouts;
      return;
    }
    const bool close = response_->need_eof();
    response_.reset();
    if (close) {
      Linger();
    } else {
      NextRequest();
    }
  }

  // Closing a socket with unread bytes makes the kernel send a reset, which can destroy the 400
  // still on its way (the client sent a body we refused to read). So: half-close, then read and
  // drop what comes for a short while.
  void Linger() {
    error_code ignored;
    stream_.socket().shutdown(tcp::socket::shutdown_send, ignored);
    stream_.expires_after(Seconds(std::min(1.0, impl_->options.idle_timeout_s)));
    DrainSome();
  }
  void DrainSome() {
    stream_.async_read_some(asio::buffer(drain_),
                            [self = shared_from_this()](const error_code& ec, std::size_t) {
                              if (ec) {
                                self->stream_.close();
                                return;
                              }
                              self->DrainSome();
                            });
  }

  void Shutdown() {
    error_code ignored;
    stream_.socket().shutdown(tcp::socket::shutdown_send, ignored);
    stream_.close();
  }

  std::shared_ptr<Core> impl_;
  beast::tcp_stream stream_;
  std::string unparsed_;  // read, not yet parsed: at most RequestBufferBytes
  std::optional<RequestReader> reader_;
  std::optional<HttpResponse> response_;
  std::array<char, 1024> drain_{};
};

}  // namespace

struct LiveViewServer::Impl : Core {
  using Core::Core;
};

void Core::Accept() {
  acceptor.async_accept([self = shared_from_this()](const error_code& ec, tcp::socket socket) {
    self->OnAccept(ec, std::move(socket));
  });
}

void Core::OnAccept(const error_code& ec, tcp::socket socket) {
  if (!running) return;
  if (ec) {
    // Out of descriptors or a connection aborted before it was taken: try again shortly rather
    // than spin.
    retry_timer.expires_after(std::chrono::milliseconds(100));
    retry_timer.async_wait([self = shared_from_this()](const error_code& wait_ec) {
      if (!wait_ec && self->running) self->Accept();
    });
    return;
  }
  CloseOnExec(socket.native_handle());
  if (http_sessions.size() + ws_sessions.size() >= options.max_clients) {
    Refuse(std::move(socket));
  } else {
    std::make_shared<HttpSession>(shared_from_this(), std::move(socket))->Start();
  }
  Accept();
}

void Core::Refuse(tcp::socket socket) {
  ++counters.refused_connections;
  // Best effort and without waiting: a fresh socket's send buffer takes the short answer whole.
  error_code ignored;
  socket.non_blocking(true, ignored);
  const std::string_view busy = BusyResponseBytes();
  socket.write_some(asio::buffer(busy.data(), busy.size()), ignored);
  socket.shutdown(tcp::socket::shutdown_both, ignored);
  socket.close(ignored);
}

std::optional<std::string> Validate(const LiveViewOptions& options) {
  if (options.bind_address.empty() ||
      options.bind_address.find_first_of(" \t\r\n") != std::string::npos) {
    return "live view: bind_address '" + options.bind_address +
           "' is not an address or a host name";
  }
  if (options.max_clients < 1 || options.max_clients > 10000) {
    return "live view: max_clients must be in 1..10000";
  }
  if (options.max_request_bytes < 512 || options.max_request_bytes > (1u << 20)) {
    return "live view: max_request_bytes must be in 512..1048576";
  }
  if (!(options.idle_timeout_s > 0.0 && options.idle_timeout_s <= 86400.0)) {
    return "live view: idle_timeout_s must be in (0, 86400]";
  }
  if (!(options.websocket_idle_timeout_s > 0.0 && options.websocket_idle_timeout_s <= 86400.0)) {
    return "live view: websocket_idle_timeout_s must be in (0, 86400]";
  }
  return std::nullopt;
}

LiveViewServer::LiveViewServer(asio::io_context& io, const LiveViewOptions& options)
    : impl_(std::make_shared<Impl>(io, options)) {}

LiveViewServer::~LiveViewServer() { Stop(); }

bool LiveViewServer::Start(std::string* error) {
  error_code ec;
  tcp::endpoint endpoint(asio::ip::make_address(impl_->options.bind_address, ec),
                         impl_->options.port);
  if (ec) {  // a host name: its first address
    tcp::resolver resolver(impl_->acceptor.get_executor());
    const auto found =
        resolver.resolve(impl_->options.bind_address, std::to_string(impl_->options.port),
                         tcp::resolver::passive | tcp::resolver::numeric_service, ec);
    if (!ec && found.empty()) ec = asio::error::host_not_found;
    if (!ec) endpoint = found.begin()->endpoint();
  }
  const auto fail = [&](const char* what) {
    if (error != nullptr) {
      *error = std::string("live view: ") + what + " " + impl_->options.bind_address + ":" +
               std::to_string(impl_->options.port) + ": " + ec.message();
    }
    error_code ignored;
    impl_->acceptor.close(ignored);
    return false;
  };
  if (ec) return fail("cannot resolve");
  if (impl_->acceptor.open(endpoint.protocol(), ec)) return fail("cannot open");
  CloseOnExec(impl_->acceptor.native_handle());
  if (impl_->acceptor.set_option(asio::socket_base::reuse_address(true), ec)) {
    return fail("cannot set SO_REUSEADDR on");
  }
  if (impl_->acceptor.bind(endpoint, ec)) return fail("cannot bind");
  if (impl_->acceptor.listen(asio::socket_base::max_listen_connections, ec)) {
    return fail("cannot listen on");
  }
  impl_->port = impl_->acceptor.local_endpoint(ec).port();
  impl_->running = true;
  impl_->Accept();
  return true;
}

void LiveViewServer::Stop() {
  impl_->running = false;
  error_code ignored;
  impl_->acceptor.close(ignored);
  impl_->retry_timer.cancel();
  // Closing only cancels: the sessions leave their sets when their handlers have run.
  for (HttpSession* s : impl_->http_sessions) s->Close();
  for (WsSession* s : impl_->ws_sessions) s->Close();
}

std::uint16_t LiveViewServer::port() const { return impl_->port; }

void LiveViewServer::Publish(std::string json) {
  impl_->latest = std::make_shared<const std::string>(std::move(json));
  for (WsSession* s : impl_->ws_sessions) s->Send(impl_->latest);
}

void LiveViewServer::PublishFoxglove(std::vector<FoxgloveChannelMessage> messages) {
  std::vector<FoxgloveChannel> advertise;
  std::vector<std::uint32_t> changed;
  for (FoxgloveChannelMessage& m : messages) {
    auto it = impl_->foxglove_ids.find(m.topic);
    if (it == impl_->foxglove_ids.end()) {
      Core::FoxgloveTopic topic;
      topic.channel.id = static_cast<std::uint32_t>(impl_->foxglove_topics.size() + 1);
      topic.channel.topic = m.topic;
      topic.channel.schema_name = m.schema_name;
      topic.channel.schema = m.schema;
      impl_->foxglove_topics.push_back(std::move(topic));
      it = impl_->foxglove_ids.emplace(m.topic, impl_->foxglove_topics.back().channel.id).first;
      advertise.push_back(impl_->foxglove_topics.back().channel);
    }
    Core::FoxgloveTopic& topic = impl_->foxglove_topics[it->second - 1];
    if (topic.payload && *topic.payload == m.payload) continue;
    topic.payload = std::make_shared<const std::string>(std::move(m.payload));
    topic.stamp_ns = m.stamp_ns;
    changed.push_back(it->second);
  }
  for (WsSession* s : impl_->ws_sessions) {
    if (!s->foxglove()) continue;
    if (!advertise.empty()) s->SendControl(FoxgloveAdvertise(advertise));
    for (const std::uint32_t id : changed) {
      const Core::FoxgloveTopic& t = impl_->foxglove_topics[id - 1];
      s->SendChannel(id, t.stamp_ns, t.payload);
    }
  }
}

std::size_t LiveViewServer::websocket_clients() const { return impl_->ws_open; }

std::size_t LiveViewServer::connections() const {
  return impl_->http_sessions.size() + impl_->ws_sessions.size();
}

const LiveViewCounters& LiveViewServer::counters() const { return impl_->counters; }

}  // namespace lrfnet::daemon
