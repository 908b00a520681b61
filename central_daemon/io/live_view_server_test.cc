#include "central_daemon/io/live_view_server.h"

#include <gtest/gtest.h>
#include <netinet/in.h>
#include <signal.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <sys/wait.h>
#include <unistd.h>

#include <boost/asio/executor_work_guard.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/post.hpp>
#include <boost/beast/core/buffers_to_string.hpp>
#include <boost/beast/core/flat_buffer.hpp>
#include <boost/beast/core/tcp_stream.hpp>
#include <boost/beast/http/read.hpp>
#include <boost/beast/http/string_body.hpp>
#include <boost/beast/http/write.hpp>
#include <boost/beast/websocket/stream.hpp>
#include <chrono>
#include <fstream>
#include <functional>
#include <future>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "central_daemon/io/live_view_http.h"

extern char** environ;

namespace lrfnet::daemon {
namespace {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace http = beast::http;
namespace websocket = beast::websocket;
using tcp = asio::ip::tcp;
using boost::system::error_code;
using namespace std::chrono_literals;
using Response = http::response<http::string_body>;
using Json = nlohmann::json;

// ---- clients (on their own io_context in the test thread, every operation with a deadline) ----

// Plain HTTP/1.1 over Beast, one connection, requests in turn.
class HttpClient {
 public:
  explicit HttpClient(std::uint16_t port) {
    stream_.expires_after(5s);
    stream_.async_connect(tcp::endpoint(asio::ip::make_address("127.0.0.1"), port),
                          [this](const error_code& ec) { ok_ = !ec; });
    Run();
  }
  bool ok() const { return ok_; }

  std::optional<Response> Send(
      http::verb method, const std::string& target,
      const std::vector<std::pair<std::string, std::string>>& headers = {}) {
    http::request<http::string_body> request(method, target, 11);
    request.set(http::field::host, "127.0.0.1");
    for (const auto& [name, value] : headers) request.set(name, value);
    request.prepare_payload();
    error_code ec;
    stream_.expires_after(5s);
    http::async_write(stream_, request, [&](const error_code& e, std::size_t) { ec = e; });
    Run();
    if (ec) return std::nullopt;
    http::response_parser<http::string_body> parser;
    parser.skip(method == http::verb::head);
    stream_.expires_after(5s);
    http::async_read(stream_, buffer_, parser, [&](const error_code& e, std::size_t) { ec = e; });
    Run();
    if (ec) return std::nullopt;
    return parser.release();
  }

 private:
  void Run() {
    ioc_.restart();
    ioc_.run();
  }
  asio::io_context ioc_;
  beast::tcp_stream stream_{ioc_};
  beast::flat_buffer buffer_;
  bool ok_ = false;
};

std::optional<Response> Request(std::uint16_t port, http::verb method, const std::string& target) {
  HttpClient client(port);
  if (!client.ok()) return std::nullopt;
  return client.Send(method, target);
}

class WsClient {
 public:
  // Connects and upgrades; `origin` is sent as the Origin header and `subprotocols` as
  // Sec-WebSocket-Protocol when set.
  bool Connect(std::uint16_t port, const std::optional<std::string>& origin = std::nullopt,
               const std::optional<std::string>& subprotocols = std::nullopt,
               const std::string& path = "/ws") {
    bool done = false, ok = false;
    beast::get_lowest_layer(ws_).expires_after(5s);
    beast::get_lowest_layer(ws_).async_connect(
        tcp::endpoint(asio::ip::make_address("127.0.0.1"), port), [&](const error_code& ec) {
          done = true;
          ok = !ec;
        });
    RunUntil(done);
    if (!ok) return false;
    beast::get_lowest_layer(ws_).expires_never();
    ws_.set_option(websocket::stream_base::timeout{5s, websocket::stream_base::none(), false});
    ws_.set_option(
        websocket::stream_base::decorator([origin, subprotocols](websocket::request_type& r) {
          if (origin) r.set(http::field::origin, *origin);
          if (subprotocols) r.set(http::field::sec_websocket_protocol, *subprotocols);
        }));
    ws_.read_message_max(64 << 20);
    done = false;
    const std::string host = "127.0.0.1:" + std::to_string(port);
    ws_.async_handshake(response_, host, path, [&](const error_code& ec) {
      done = true;
      ok = !ec;
    });
    RunUntil(done);
    return ok;
  }
  const websocket::response_type& handshake_response() const { return response_; }

  // The next text message, or nullopt when none arrives in time (a read still outstanding then
  // delivers to the next call) or the connection ended.
  std::optional<std::string> Read(std::chrono::milliseconds timeout = 3000ms) {
    if (!reading_) {
      reading_ = true;
      read_done_ = false;
      ws_.async_read(buffer_, [this](const error_code& e, std::size_t) {
        read_done_ = true;
        read_error_ = e;
      });
    }
    const auto end = std::chrono::steady_clock::now() + timeout;
    ioc_.restart();
    while (!read_done_ && std::chrono::steady_clock::now() < end) {
      ioc_.run_one_until(end);
      ioc_.restart();
    }
    if (!read_done_) return std::nullopt;
    reading_ = false;
    if (read_error_) return std::nullopt;
    std::string message = beast::buffers_to_string(buffer_.data());
    buffer_.consume(buffer_.size());
    last_text_ = ws_.got_text();
    return message;
  }
  bool last_was_text() const { return last_text_; }

  bool Write(const std::string& message, bool text = true) {
    bool done = false, ok = false;
    ws_.text(text);
    ws_.async_write(asio::buffer(message), [&](const error_code& ec, std::size_t) {
      done = true;
      ok = !ec;
    });
    RunUntil(done);
    return ok;
  }

 private:
  void RunUntil(const bool& done) {
    ioc_.restart();
    while (!done && ioc_.run_one() > 0) {
    }
  }
  asio::io_context ioc_;
  websocket::stream<beast::tcp_stream> ws_{ioc_};
  websocket::response_type response_;
  beast::flat_buffer buffer_;
  bool reading_ = false, read_done_ = false, last_text_ = true;
  error_code read_error_;
};

// A bare socket for bytes no HTTP client would send.
class RawClient {
 public:
  explicit RawClient(std::uint16_t port, int receive_buffer_bytes = 0) {
    fd_ = ::socket(AF_INET, SOCK_STREAM, 0);
    if (receive_buffer_bytes > 0) {
      ::setsockopt(fd_, SOL_SOCKET, SO_RCVBUF, &receive_buffer_bytes, sizeof(receive_buffer_bytes));
    }
    timeval tv{3, 0};
    ::setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof(tv));
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    a.sin_port = htons(port);
    ok_ = ::connect(fd_, reinterpret_cast<sockaddr*>(&a), sizeof(a)) == 0;
  }
  ~RawClient() { Close(); }
  bool ok() const { return ok_; }
  bool Send(const std::string& bytes) {
    return ::send(fd_, bytes.data(), bytes.size(), MSG_NOSIGNAL) ==
           static_cast<ssize_t>(bytes.size());
  }
  void ShutdownWrite() { ::shutdown(fd_, SHUT_WR); }
  // Everything until the server closes (or 3 s without a byte).
  std::string ReadToEnd(bool* closed = nullptr) {
    std::string out;
    char buf[4096];
    while (true) {
      const ssize_t n = ::recv(fd_, buf, sizeof(buf), 0);
      if (n > 0) {
        out.append(buf, static_cast<std::size_t>(n));
        continue;
      }
      if (closed != nullptr) *closed = n == 0 || errno == ECONNRESET;
      return out;
    }
  }
  void Close() {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
  }

 private:
  int fd_ = -1;
  bool ok_ = false;
};

int StatusOf(const std::string& raw_response) {
  // "HTTP/1.1 400 Bad Request"
  if (raw_response.size() < 12 || raw_response.compare(0, 5, "HTTP/") != 0) return 0;
  return std::stoi(raw_response.substr(9, 3));
}

bool WaitFor(const std::function<bool()>& condition, std::chrono::milliseconds timeout = 3000ms) {
  const auto end = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < end) {
    if (condition()) return true;
    std::this_thread::sleep_for(5ms);
  }
  return condition();
}

// AddressSanitizer keeps freed memory in quarantine, so resident memory says nothing there.
#if defined(__SANITIZE_ADDRESS__)
constexpr bool kFreedMemoryReturns = false;
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
constexpr bool kFreedMemoryReturns = false;
#else
constexpr bool kFreedMemoryReturns = true;
#endif
#else
constexpr bool kFreedMemoryReturns = true;
#endif

std::size_t ResidentBytes() {
  std::ifstream statm("/proc/self/statm");
  std::size_t pages = 0, resident = 0;
  statm >> pages >> resident;
  return resident * static_cast<std::size_t>(::sysconf(_SC_PAGESIZE));
}

// ---- the server on its io_context in a thread of its own -------------------------------------

class LiveViewServerTest : public ::testing::Test {
 protected:
  static LiveViewOptions QuickOptions() {
    LiveViewOptions o;
    o.idle_timeout_s = 0.5;  // slow and idle clients are cut off quickly here
    return o;
  }

  void StartServer(const LiveViewOptions& options = QuickOptions()) {
    ASSERT_EQ(Validate(options), std::nullopt);
    server_ = std::make_unique<LiveViewServer>(io_, options);
    std::string error;
    ASSERT_TRUE(server_->Start(&error)) << error;
    ASSERT_NE(server_->port(), 0);
    port_ = server_->port();
    thread_ = std::thread([this] { io_.run(); });
  }

  // Runs f on the server's thread (the server is not thread-safe) and returns its result.
  template <typename F>
  auto OnIo(F f) {
    std::packaged_task<decltype(f())()> task(std::move(f));
    auto result = task.get_future();
    asio::post(io_, [&task] { task(); });
    return result.get();
  }
  void TearDown() override {
    if (!thread_.joinable()) return;
    OnIo([this] { server_->Stop(); });
    guard_.reset();
    thread_.join();
  }

  LiveViewCounters Counters() {
    return OnIo([this] { return server_->counters(); });
  }
  void Publish(std::string json) {
    OnIo([this, &json] { server_->Publish(std::move(json)); });
  }
  // The server still answers a well-behaved client.
  void ExpectServing() {
    const auto r = Request(port_, http::verb::get, "/");
    ASSERT_TRUE(r.has_value());
    EXPECT_EQ(r->result_int(), 200);
  }

  asio::io_context io_;
  asio::executor_work_guard<asio::io_context::executor_type> guard_{io_.get_executor()};
  std::unique_ptr<LiveViewServer> server_;
  std::uint16_t port_ = 0;
  std::thread thread_;
};

TEST(LiveViewOptionsTest, ValidateNamesTheBadValue) {
  EXPECT_EQ(Validate(LiveViewOptions{}), std::nullopt);
  LiveViewOptions o;
  o.bind_address = "";
  EXPECT_NE(Validate(o).value_or("").find("bind_address"), std::string::npos);
  o.bind_address = "local host";
  EXPECT_NE(Validate(o).value_or("").find("bind_address"), std::string::npos);
  o = {};
  o.max_clients = 0;
  EXPECT_NE(Validate(o).value_or("").find("max_clients"), std::string::npos);
  o = {};
  o.max_request_bytes = 10;
  EXPECT_NE(Validate(o).value_or("").find("max_request_bytes"), std::string::npos);
  o = {};
  o.idle_timeout_s = std::numeric_limits<double>::quiet_NaN();
  EXPECT_NE(Validate(o).value_or("").find("idle_timeout_s"), std::string::npos);
  o = {};
  o.websocket_idle_timeout_s = -1;
  EXPECT_NE(Validate(o).value_or("").find("websocket_idle_timeout_s"), std::string::npos);
}

TEST(LiveViewServerStartTest, HostNamesAndIpv6Work) {
  asio::io_context io;
  for (const char* address : {"localhost", "::1"}) {
    LiveViewOptions o;
    o.bind_address = address;
    LiveViewServer server(io, o);
    std::string error;
    EXPECT_TRUE(server.Start(&error)) << address << ": " << error;
    EXPECT_NE(server.port(), 0) << address;
  }
}

TEST(LiveViewServerStartTest, AddressInUseIsAnError) {
  asio::io_context io;
  LiveViewServer first(io, LiveViewOptions{});
  std::string error;
  ASSERT_TRUE(first.Start(&error)) << error;
  LiveViewOptions same;
  same.port = first.port();
  LiveViewServer second(io, same);
  EXPECT_FALSE(second.Start(&error));
  EXPECT_NE(error.find(std::to_string(first.port())), std::string::npos) << error;
}

TEST_F(LiveViewServerTest, ServesThePage) {
  StartServer();
  const auto r = Request(port_, http::verb::get, "/");
  ASSERT_TRUE(r.has_value());
  EXPECT_EQ(r->result_int(), 200);
  EXPECT_EQ((*r)[http::field::content_type], "text/html; charset=utf-8");
  EXPECT_EQ(r->body(), LiveViewPage());
  EXPECT_NE(r->body().find("<canvas"), std::string::npos);
  EXPECT_NE(r->body().find("/ws"), std::string::npos);
  // Self-contained: the page refers to nothing outside itself.
  EXPECT_EQ(r->body().find("http://"), std::string::npos);
  EXPECT_EQ(r->body().find("https://"), std::string::npos);
  EXPECT_NE((*r)["Content-Security-Policy"].find("default-src 'none'"), beast::string_view::npos);

  const auto head = Request(port_, http::verb::head, "/");
  ASSERT_TRUE(head.has_value());
  EXPECT_EQ(head->result_int(), 200);
  EXPECT_EQ((*head)[http::field::content_length], std::to_string(LiveViewPage().size()));
  EXPECT_TRUE(head->body().empty());
}

TEST_F(LiveViewServerTest, StateIs503BeforeTheFirstPublishAndTheJsonAfter) {
  StartServer();
  auto r = Request(port_, http::verb::get, "/state");
  ASSERT_TRUE(r.has_value());
  EXPECT_EQ(r->result_int(), 503);
  Publish(R"({"type":"state","n":1})");
  Publish(R"({"type":"state","n":2})");
  r = Request(port_, http::verb::get, "/state?nocache=1");
  ASSERT_TRUE(r.has_value());
  EXPECT_EQ(r->result_int(), 200);
  EXPECT_EQ((*r)[http::field::content_type], "application/json");
  EXPECT_EQ(r->body(), R"({"type":"state","n":2})");
}

TEST_F(LiveViewServerTest, UnknownPathsAndMethodsAreRefused) {
  StartServer();
  HttpClient client(port_);  // one keep-alive connection for all of them
  ASSERT_TRUE(client.ok());
  auto r = client.Send(http::verb::get, "/nothing-here");
  ASSERT_TRUE(r.has_value());
  EXPECT_EQ(r->result_int(), 404);
  r = client.Send(http::verb::post, "/");
  ASSERT_TRUE(r.has_value());
  EXPECT_EQ(r->result_int(), 405);
  EXPECT_EQ((*r)[http::field::allow], "GET, HEAD");
  r = client.Send(http::verb::delete_, "/state");
  ASSERT_TRUE(r.has_value());
  EXPECT_EQ(r->result_int(), 405);
  r = client.Send(http::verb::get, "/ws");
  ASSERT_TRUE(r.has_value());
  EXPECT_EQ(r->result_int(), 426);
  r = client.Send(http::verb::get, "/");
  ASSERT_TRUE(r.has_value());
  EXPECT_EQ(r->result_int(), 200);
  const LiveViewCounters c = Counters();
  EXPECT_EQ(c.http_requests, 5u);
  EXPECT_EQ(c.not_found, 1u);
  EXPECT_EQ(c.method_not_allowed, 2u);
  EXPECT_EQ(c.upgrade_required, 1u);
  EXPECT_EQ(c.bad_requests, 0u);
}

TEST_F(LiveViewServerTest, WebSocketGetsTheLatestOnConnectAndEveryPublish) {
  StartServer();
  WsClient early;
  ASSERT_TRUE(early.Connect(port_));
  ASSERT_TRUE(WaitFor([&] { return OnIo([&] { return server_->websocket_clients(); }) == 1; }));
  EXPECT_EQ(early.Read(200ms), std::nullopt);  // nothing published yet
  Publish("one");
  EXPECT_EQ(early.Read(), "one");
  Publish("two");
  EXPECT_EQ(early.Read(), "two");

  WsClient late;
  ASSERT_TRUE(late.Connect(port_, "http://127.0.0.1:" + std::to_string(port_)));
  EXPECT_EQ(late.Read(), "two");  // the newest, right away
  Publish("three");
  EXPECT_EQ(early.Read(), "three");
  EXPECT_EQ(late.Read(), "three");
  EXPECT_EQ(OnIo([&] { return server_->websocket_clients(); }), 2u);
  const LiveViewCounters c = Counters();
  EXPECT_EQ(c.websocket_clients, 2u);
  EXPECT_EQ(c.messages_sent, 5u);
  EXPECT_EQ(c.messages_replaced, 0u);
}

// ---- Foxglove WebSocket protocol ---------------------------------------------------------------

Json ParseJson(const std::optional<std::string>& text) {
  return text ? Json::parse(*text, nullptr, false) : Json();
}

FoxgloveChannelMessage Channel(const std::string& topic, const std::string& payload,
                               std::uint64_t stamp_ns) {
  return {topic, "lrfnet.Test", R"({"type":"object"})", payload, stamp_ns};
}

// The binary message-data frame: opcode 1, subscription id, stamp, payload.
struct DataFrame {
  std::uint32_t subscription = 0;
  std::uint64_t stamp_ns = 0;
  std::string payload;
};
std::optional<DataFrame> ParseFrame(const std::optional<std::string>& bytes) {
  if (!bytes || bytes->size() < 13 || (*bytes)[0] != 0x01) return std::nullopt;
  DataFrame f;
  for (int i = 3; i >= 0; --i)
    f.subscription = (f.subscription << 8) | static_cast<std::uint8_t>((*bytes)[1 + i]);
  for (int i = 7; i >= 0; --i)
    f.stamp_ns = (f.stamp_ns << 8) | static_cast<std::uint8_t>((*bytes)[5 + i]);
  f.payload = bytes->substr(13);
  return f;
}

TEST_F(LiveViewServerTest, FoxgloveClientGetsServerInfoChannelsAndWhatItSubscribedTo) {
  StartServer();
  OnIo([this] { server_->PublishFoxglove({Channel("/a", R"({"n":1})", 11)}); });
  WsClient fox;
  // Foxglove connects to "/" and offers its subprotocol.
  ASSERT_TRUE(fox.Connect(port_, std::nullopt, "foxglove.websocket.v1", "/"));
  EXPECT_EQ(fox.handshake_response()[http::field::sec_websocket_protocol], "foxglove.websocket.v1");
  const Json info = ParseJson(fox.Read());
  EXPECT_EQ(info["op"], "serverInfo");
  EXPECT_EQ(info["name"], "lrfnetd");
  const Json advertise = ParseJson(fox.Read());
  ASSERT_EQ(advertise["op"], "advertise");
  ASSERT_EQ(advertise["channels"].size(), 1u);
  EXPECT_EQ(advertise["channels"][0]["topic"], "/a");
  EXPECT_EQ(advertise["channels"][0]["encoding"], "json");
  EXPECT_EQ(advertise["channels"][0]["schemaEncoding"], "jsonschema");
  const std::uint32_t a = advertise["channels"][0]["id"].get<std::uint32_t>();
  // A channel that appears later is advertised then.
  OnIo([this] {
    server_->PublishFoxglove({Channel("/a", R"({"n":1})", 12), Channel("/b", "{}", 12)});
  });
  const Json later = ParseJson(fox.Read());
  ASSERT_EQ(later["channels"].size(), 1u);
  EXPECT_EQ(later["channels"][0]["topic"], "/b");
  // Subscribed: the latest message at once, then every new one; an unchanged one is not resent.
  ASSERT_TRUE(fox.Write(R"({"op":"subscribe","subscriptions":[{"id":42,"channelId":)" +
                        std::to_string(a) + "}]}"));
  auto frame = ParseFrame(fox.Read());
  ASSERT_TRUE(frame.has_value());
  EXPECT_FALSE(fox.last_was_text());
  EXPECT_EQ(frame->subscription, 42u);
  EXPECT_EQ(frame->stamp_ns, 11u);
  EXPECT_EQ(frame->payload, R"({"n":1})");
  OnIo([this] {
    server_->PublishFoxglove({Channel("/a", R"({"n":1})", 13), Channel("/b", "{\"x\":2}", 13)});
  });
  OnIo([this] {
    server_->PublishFoxglove({Channel("/a", R"({"n":2})", 14), Channel("/b", "{\"x\":3}", 14)});
  });
  frame = ParseFrame(fox.Read());
  ASSERT_TRUE(frame.has_value());
  EXPECT_EQ(frame->payload, R"({"n":2})");  // /b never: not subscribed
  EXPECT_EQ(fox.Read(200ms), std::nullopt);
  ASSERT_TRUE(fox.Write(R"({"op":"unsubscribe","subscriptionIds":[42]})"));
  // Client messages are handled in order: once the answer to a later one is here, the
  // unsubscription is done.
  ASSERT_TRUE(fox.Write(R"({"op":"getParameters","parameterNames":[]})"));
  EXPECT_EQ(ParseJson(fox.Read())["op"], "status");
  OnIo([this] { server_->PublishFoxglove({Channel("/a", R"({"n":3})", 15)}); });
  EXPECT_EQ(fox.Read(200ms), std::nullopt);
  // The page's own clients are not affected, and the JSON feed's clients get no Foxglove data.
  WsClient page;
  ASSERT_TRUE(page.Connect(port_));
  EXPECT_EQ(page.handshake_response().count(http::field::sec_websocket_protocol), 0u);
  Publish("state");
  EXPECT_EQ(page.Read(), "state");
  const LiveViewCounters c = Counters();
  EXPECT_EQ(c.foxglove_clients, 1u);
  EXPECT_EQ(c.foxglove_messages_sent, 2u);
}

TEST_F(LiveViewServerTest, HostileFoxgloveMessagesGetAStatusAndTheConnectionGoesOn) {
  StartServer();
  OnIo([this] { server_->PublishFoxglove({Channel("/a", "{}", 1)}); });
  WsClient fox;
  ASSERT_TRUE(fox.Connect(port_, std::nullopt, "x-unknown, foxglove.sdk.v1", "/ws"));
  EXPECT_EQ(fox.handshake_response()[http::field::sec_websocket_protocol], "foxglove.sdk.v1");
  ASSERT_EQ(ParseJson(fox.Read())["op"], "serverInfo");
  ASSERT_EQ(ParseJson(fox.Read())["op"], "advertise");
  for (const auto& [message, text] : std::vector<std::pair<std::string, bool>>{
           {"{not json", true},
           {R"({"op":""})", true},
           {R"({"op":"getParameters","parameterNames":[]})", true},
           {std::string("\x01\x00\x00\x00\x00zz", 7), false},
           {R"({"op":"subscribe","subscriptions":[{"id":1,"channelId":99}]})", true},
           {R"({"op":"subscribe","subscriptions":[{"id":-1,"channelId":1}]})", true}}) {
    ASSERT_TRUE(fox.Write(message, text));
    const Json status = ParseJson(fox.Read());
    EXPECT_EQ(status["op"], "status") << message;
    EXPECT_FALSE(status["message"].get<std::string>().empty());
  }
  EXPECT_EQ(Counters().foxglove_refused_messages, 6u);
  ASSERT_TRUE(fox.Write(R"({"op":"subscribe","subscriptions":[{"id":1,"channelId":1}]})"));
  ASSERT_TRUE(ParseFrame(fox.Read()).has_value());
  ExpectServing();
}

TEST_F(LiveViewServerTest, FoxgloveWebAppIsTheOnlyForeignOriginAllowed) {
  StartServer();
  WsClient app;
  EXPECT_TRUE(app.Connect(port_, "https://app.foxglove.dev", "foxglove.websocket.v1", "/"));
  WsClient evil;
  EXPECT_FALSE(evil.Connect(port_, "http://evil.example", "foxglove.websocket.v1", "/"));
  EXPECT_EQ(evil.handshake_response().result_int(), 403);
  // The Foxglove origin does not open the page's own feed.
  WsClient feed;
  EXPECT_FALSE(feed.Connect(port_, "https://app.foxglove.dev"));
}

TEST_F(LiveViewServerTest, WithATokenEveryRequestAndUpgradeNeedsIt) {
  LiveViewOptions options = QuickOptions();
  options.access_token = "9f86d081884c7d659a2feaa0c55ad015";
  StartServer(options);
  Publish(R"({"type":"state"})");
  std::size_t refused = 0;
  for (const std::string target :
       {"/", "/state", "/ws", "/nothing", "/?token=", "/?token=9f86d081",
        "/?token=9f86d081884c7d659a2feaa0c55ad016", "/?tok=9f86d081884c7d659a2feaa0c55ad015"}) {
    const auto r = Request(port_, http::verb::get, target);
    ASSERT_TRUE(r.has_value()) << target;
    EXPECT_EQ(r->result_int(), 401) << target;
    EXPECT_EQ(r->body().find("state"), std::string::npos) << "nothing of the state leaks";
    ++refused;
  }
  // The page and the state with the token, in the query or as a bearer token.
  auto page = Request(port_, http::verb::get, "/?token=9f86d081884c7d659a2feaa0c55ad015");
  ASSERT_TRUE(page.has_value());
  EXPECT_EQ(page->result_int(), 200);
  EXPECT_EQ(page->body(), LiveViewPage());
  EXPECT_EQ((*page)["Referrer-Policy"], "no-referrer");
  {
    HttpClient client(port_);
    ASSERT_TRUE(client.ok());
    const auto state = client.Send(http::verb::get, "/state",
                                   {{"Authorization", "Bearer 9f86d081884c7d659a2feaa0c55ad015"}});
    ASSERT_TRUE(state.has_value());
    EXPECT_EQ(state->result_int(), 200);
    EXPECT_EQ(state->body(), R"({"type":"state"})");
    const auto wrong = client.Send(http::verb::get, "/state", {{"Authorization", "Bearer nope"}});
    ASSERT_TRUE(wrong.has_value());
    EXPECT_EQ(wrong->result_int(), 401);
    ++refused;
  }
  const auto state =
      Request(port_, http::verb::get, "/state?x=1&token=9f86d081884c7d659a2feaa0c55ad015");
  ASSERT_TRUE(state.has_value());
  EXPECT_EQ(state->result_int(), 200);
  // The WebSocket: refused without the token, served with it.
  WsClient without;
  EXPECT_FALSE(without.Connect(port_));
  ++refused;
  WsClient with;
  ASSERT_TRUE(with.Connect(port_, std::nullopt, std::nullopt,
                           "/ws?token=9f86d081884c7d659a2feaa0c55ad015"));
  const auto message = with.Read();
  ASSERT_TRUE(message.has_value());
  EXPECT_EQ(*message, R"({"type":"state"})");
  // Foxglove's upgrade goes through the same admission.
  WsClient fox_without;
  EXPECT_FALSE(fox_without.Connect(port_, std::nullopt, "foxglove.websocket.v1", "/"));
  EXPECT_EQ(fox_without.handshake_response().result_int(), 401);
  ++refused;
  WsClient fox_with;
  EXPECT_TRUE(fox_with.Connect(port_, std::nullopt, "foxglove.websocket.v1",
                               "/?token=9f86d081884c7d659a2feaa0c55ad015"));
  EXPECT_TRUE(WaitFor([&] { return Counters().unauthorized == refused; }))
      << Counters().unauthorized << " of " << refused;
  EXPECT_EQ(Counters().websocket_clients, 2u);
}

TEST_F(LiveViewServerTest, WebSocketFromAnotherOriginIsRefused) {
  StartServer();
  WsClient foreign;
  EXPECT_FALSE(foreign.Connect(port_, "http://evil.example"));
  EXPECT_EQ(foreign.handshake_response().result_int(), 403);
  EXPECT_EQ(Counters().forbidden_origins, 1u);
  EXPECT_EQ(Counters().websocket_clients, 0u);
}

TEST_F(LiveViewServerTest, ClientThatStopsReadingDoesNotGrowMemory) {
  LiveViewOptions options = QuickOptions();
  options.websocket_idle_timeout_s = 60.0;  // long enough that the stuck client stays
  StartServer(options);
  WsClient stuck;  // connects, then never reads
  ASSERT_TRUE(stuck.Connect(port_));
  WsClient reader;
  ASSERT_TRUE(reader.Connect(port_));
  ASSERT_TRUE(WaitFor([&] { return OnIo([&] { return server_->websocket_clients(); }) == 2; }));

  // 64 messages of 1 MiB: far more than the socket buffers between server and client hold.
  constexpr int kMessages = 64;
  const std::size_t rss_before = ResidentBytes();
  for (int i = 0; i < kMessages; ++i) {
    std::string message(1 << 20, static_cast<char>('a' + i % 26));
    message.replace(0, std::to_string(i).size(), std::to_string(i));
    Publish(std::move(message));
    std::this_thread::sleep_for(2ms);
  }
  // Let the server write what the stuck client's buffers take.
  std::this_thread::sleep_for(200ms);
  const std::size_t rss_after = ResidentBytes();
  const LiveViewCounters c = Counters();
  // Of each publish to the stuck client: written, replaced, or the one pending/being written.
  EXPECT_GT(c.messages_replaced, kMessages / 2u);
  if (kFreedMemoryReturns) {
    EXPECT_LT(rss_after, rss_before + (24u << 20))
        << "resident memory grew by " << (rss_after - rss_before) / (1 << 20) << " MiB";
  }

  // The other client is served: it sees the newest message (older ones may be replaced for it
  // too, as it reads slower than the loop publishes).
  std::optional<std::string> last;
  while (auto m = reader.Read(300ms)) last = std::move(m);
  ASSERT_TRUE(last.has_value());
  EXPECT_EQ(last->substr(0, 2), std::to_string(kMessages - 1));
  ExpectServing();
}

TEST_F(LiveViewServerTest, GarbageGets400AndTheServerGoesOn) {
  StartServer();
  RawClient c(port_);
  ASSERT_TRUE(c.ok());
  ASSERT_TRUE(
      c.Send(std::string("\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03 hello\r\n\r\n", 22)));
  bool closed = false;
  EXPECT_EQ(StatusOf(c.ReadToEnd(&closed)), 400);
  EXPECT_TRUE(closed);
  EXPECT_EQ(Counters().bad_requests, 1u);
  ExpectServing();
}

TEST_F(LiveViewServerTest, TruncatedRequestGets400) {
  StartServer();
  RawClient c(port_);
  ASSERT_TRUE(c.ok());
  ASSERT_TRUE(c.Send("POST /state HTTP/1.1\r\nHost: x\r\nContent-Length: 100\r\n\r\nonly a part"));
  c.ShutdownWrite();
  bool closed = false;
  EXPECT_EQ(StatusOf(c.ReadToEnd(&closed)), 400);
  EXPECT_TRUE(closed);
  EXPECT_EQ(Counters().bad_requests, 1u);
  ExpectServing();
}

TEST_F(LiveViewServerTest, HeaderOverTheLimitGets400) {
  StartServer();
  RawClient c(port_);
  ASSERT_TRUE(c.ok());
  ASSERT_TRUE(
      c.Send("GET / HTTP/1.1\r\nHost: x\r\nX-Big: " + std::string(20000, 'a') + "\r\n\r\n"));
  bool closed = false;
  const std::string response = c.ReadToEnd(&closed);
  EXPECT_EQ(StatusOf(response), 400) << response.substr(0, 200);
  EXPECT_TRUE(closed);
  EXPECT_EQ(Counters().bad_requests, 1u);
  ExpectServing();
}

// A header a little over the limit, whose first part arrives alone: Beast parses that part at
// once and applies its own limit to the rest only.
std::string SlightlyLongHeader() {
  return "GET / HTTP/1.1\r\nHost: x\r\nX-Big: " + std::string(8192, 'a') + "\r\n\r\n";
}

TEST_F(LiveViewServerTest, HeaderOverTheLimitInTwoReadsGets400) {
  StartServer();  // max_request_bytes = 8192
  RawClient c(port_);
  ASSERT_TRUE(c.ok());
  const std::string header = SlightlyLongHeader();
  ASSERT_TRUE(c.Send(header.substr(0, 40)));
  std::this_thread::sleep_for(50ms);
  ASSERT_TRUE(c.Send(header.substr(40)));
  bool closed = false;
  const std::string response = c.ReadToEnd(&closed);
  EXPECT_EQ(StatusOf(response), 400) << response.substr(0, 200);
  EXPECT_NE(response.find("header"), std::string::npos) << response;
  EXPECT_TRUE(closed);
  EXPECT_EQ(Counters().bad_requests, 1u);
  EXPECT_EQ(Counters().http_requests, 0u);
  ExpectServing();
}

TEST_F(LiveViewServerTest, HugeContentLengthGets400BeforeAnyBodyIsRead) {
  StartServer();
  RawClient c(port_);
  ASSERT_TRUE(c.ok());
  // Some of the announced body follows; the server answers without waiting for (or storing) it.
  ASSERT_TRUE(c.Send("POST / HTTP/1.1\r\nHost: x\r\nContent-Length: 100000000000\r\n\r\n" +
                     std::string(64 * 1024, 'x')));
  bool closed = false;
  EXPECT_EQ(StatusOf(c.ReadToEnd(&closed)), 400);
  EXPECT_TRUE(closed);
  EXPECT_EQ(Counters().bad_requests, 1u);
  ExpectServing();
}

TEST_F(LiveViewServerTest, SlowlorisIsCutOffAtTheIdleTimeout) {
  StartServer();  // idle_timeout_s = 0.5
  RawClient slow(port_);
  ASSERT_TRUE(slow.ok());
  ASSERT_TRUE(slow.Send("GET / HTTP/1.1\r\nHost: x\r\n"));
  const auto start = std::chrono::steady_clock::now();
  bool cut_off = false;
  // A header line every 100 ms, for at most 3 s: the request never completes.
  for (int i = 0; i < 30 && !cut_off; ++i) {
    std::this_thread::sleep_for(100ms);
    cut_off = !slow.Send("X-Slow-" + std::to_string(i) + ": still here\r\n");
    if (i == 2) ExpectServing();  // others are served meanwhile
  }
  if (!cut_off) {
    bool closed = false;
    slow.ReadToEnd(&closed);
    cut_off = closed;
  }
  const double after_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  EXPECT_TRUE(cut_off);
  EXPECT_LT(after_s, 2.0);
  EXPECT_TRUE(WaitFor([&] { return Counters().timeouts == 1u; }));

  // A connection that says nothing is closed too, but counted as idle, not as an attack.
  RawClient idle(port_);
  ASSERT_TRUE(idle.ok());
  bool closed = false;
  EXPECT_EQ(idle.ReadToEnd(&closed), "");
  EXPECT_TRUE(closed);
  EXPECT_TRUE(WaitFor([&] { return Counters().idle_closed >= 1u; }));
  EXPECT_EQ(Counters().timeouts, 1u);
  ExpectServing();
}

TEST_F(LiveViewServerTest, BrokenUpgradeIsCounted) {
  StartServer();
  RawClient c(port_);
  ASSERT_TRUE(c.ok());
  // An upgrade without Sec-WebSocket-Key: the handshake refuses it.
  ASSERT_TRUE(
      c.Send("GET /ws HTTP/1.1\r\nHost: x\r\nConnection: Upgrade\r\nUpgrade: websocket\r\n"
             "Sec-WebSocket-Version: 13\r\n\r\n"));
  bool closed = false;
  EXPECT_EQ(StatusOf(c.ReadToEnd(&closed)), 400);
  EXPECT_TRUE(WaitFor([&] { return Counters().failed_handshakes == 1u; }));
  EXPECT_EQ(Counters().websocket_clients, 0u);
  ExpectServing();
}

TEST_F(LiveViewServerTest, ConnectionsOverMaxClientsAreRefused) {
  LiveViewOptions options = QuickOptions();
  options.max_clients = 2;
  options.idle_timeout_s = 5.0;  // the two holders must not time out during the test
  StartServer(options);
  RawClient a(port_), b(port_);
  ASSERT_TRUE(a.ok() && b.ok());
  ASSERT_TRUE(WaitFor([&] { return OnIo([&] { return server_->connections(); }) == 2u; }));
  RawClient refused(port_);
  ASSERT_TRUE(refused.ok());
  bool closed = false;
  const std::string response = refused.ReadToEnd(&closed);
  EXPECT_EQ(StatusOf(response), 503) << response;
  EXPECT_TRUE(closed);
  EXPECT_EQ(Counters().refused_connections, 1u);

  a.Close();
  ASSERT_TRUE(WaitFor([&] { return OnIo([&] { return server_->connections(); }) == 1u; }));
  ExpectServing();
}

TEST_F(LiveViewServerTest, StopLetsTheIoContextFinish) {
  StartServer();
  WsClient ws;
  ASSERT_TRUE(ws.Connect(port_));
  RawClient idle(port_);
  ASSERT_TRUE(idle.ok());
  RawClient half(port_);
  ASSERT_TRUE(half.ok());
  ASSERT_TRUE(half.Send("GET / HTTP/1.1\r\n"));
  ASSERT_TRUE(WaitFor([&] { return OnIo([&] { return server_->connections(); }) == 3u; }));
  Publish("x");

  const auto start = std::chrono::steady_clock::now();
  OnIo([this] { server_->Stop(); });
  guard_.reset();
  thread_.join();  // io.run() returned: nothing of the server is left in the io_context
  EXPECT_LT(std::chrono::steady_clock::now() - start, 1s);
  EXPECT_EQ(server_->connections(), 0u);
  EXPECT_EQ(server_->websocket_clients(), 0u);
  bool closed = false;
  idle.ReadToEnd(&closed);
  EXPECT_TRUE(closed);
}

// A child process started while the server runs (the daemon's, or chromium in the browser test).
pid_t StartChild() {
  pid_t child = -1;
  char sleep_bin[] = "/bin/sleep";
  char sleep_arg[] = "5";
  char* argv[] = {sleep_bin, sleep_arg, nullptr};
  EXPECT_EQ(posix_spawn(&child, "/bin/sleep", nullptr, nullptr, argv, environ), 0);
  return child;
}

void EndChild(pid_t child) {
  if (child <= 0) return;
  ::kill(child, SIGKILL);
  ::waitpid(child, nullptr, 0);
}

TEST_F(LiveViewServerTest, ChildProcessesDoNotKeepThePort) {
  StartServer();
  const pid_t child = StartChild();  // sleeps 5 s
  OnIo([this] { server_->Stop(); });
  // The port is free again at once, or within moments (the kernel may release it a little after
  // close() when a child was started meanwhile): not only when the child ends.
  bool restarted = false;
  std::string error;
  const auto end = std::chrono::steady_clock::now() + 1s;
  while (!restarted && std::chrono::steady_clock::now() < end) {
    restarted = OnIo([this, &error] {
      LiveViewOptions same = QuickOptions();
      same.port = port_;
      LiveViewServer again(io_, same);
      const bool ok = again.Start(&error);
      again.Stop();
      return ok;
    });
    if (!restarted) std::this_thread::sleep_for(10ms);
  }
  EndChild(child);
  EXPECT_TRUE(restarted) << error;
}

TEST_F(LiveViewServerTest, ChildProcessesDoNotKeepConnectionsOpen) {
  StartServer();
  RawClient client(port_);
  ASSERT_TRUE(client.ok());
  ASSERT_TRUE(WaitFor([&] { return OnIo([&] { return server_->connections(); }) == 1u; }));
  const pid_t child = StartChild();
  OnIo([this] { server_->Stop(); });
  bool closed = false;
  client.ReadToEnd(&closed);  // the end comes only when no process holds the server's socket
  EndChild(child);
  EXPECT_TRUE(closed);
}

// ---- the request handling without sockets ------------------------------------------------------

TEST(LiveViewHttpTest, ParseRequestReportsCompleteNeedMoreAndBad) {
  ParsedRequest p =
      ParseRequest("GET /state?x=1 HTTP/1.1\r\nHost: a\r\n\r\nGET / HTTP/1.1\r\n", 8192);
  ASSERT_EQ(p.status, RequestReader::Status::kComplete);
  EXPECT_EQ(p.consumed, std::string_view("GET /state?x=1 HTTP/1.1\r\nHost: a\r\n\r\n").size());
  EXPECT_EQ(RouteOf(p.request), LiveViewRoute::kState);
  EXPECT_EQ(ParseRequest("GET / HTTP/1.1\r\nHost: a\r\n", 8192).status,
            RequestReader::Status::kNeedMore);
  p = ParseRequest("GET / HTTP/1.1\r\nContent-Length: 9000\r\n\r\n", 8192);
  EXPECT_EQ(p.status, RequestReader::Status::kBad);
  EXPECT_FALSE(p.error.empty());
  EXPECT_EQ(ParseRequest("\x01\x02garbage\r\n\r\n", 8192).status, RequestReader::Status::kBad);
  EXPECT_EQ(ParseRequest("GET / HTTP/1.1\r\nX: " + std::string(9000, 'a'), 8192).status,
            RequestReader::Status::kBad);
}

// Feeds `all` in pieces as the server does: what the reader did not use yet is offered again
// with the next piece. Returns the last status; *used counts the bytes the reader took.
RequestReader::Status FeedInPieces(RequestReader& reader, std::string_view all, std::size_t piece,
                                   std::size_t* used) {
  std::string unparsed;
  *used = 0;
  for (std::size_t offered = 0; offered < all.size();) {
    unparsed.append(all.substr(offered, piece));
    offered = std::min(all.size(), offered + piece);
    const RequestReader::Result r = reader.Feed(unparsed);
    unparsed.erase(0, r.consumed);
    *used += r.consumed;
    if (r.status != RequestReader::Status::kNeedMore) return r.status;
  }
  return RequestReader::Status::kNeedMore;
}

TEST(LiveViewHttpTest, HeaderLimitHoldsAcrossReads) {
  const std::string header = SlightlyLongHeader();
  ASSERT_GT(header.size(), 8192u);
  for (const std::size_t piece :
       {std::size_t{1}, std::size_t{40}, std::size_t{4096}, header.size()}) {
    RequestReader reader(8192);
    std::size_t used = 0;
    EXPECT_EQ(FeedInPieces(reader, header, piece, &used), RequestReader::Status::kBad) << piece;
    EXPECT_NE(reader.error().find("header"), std::string::npos) << reader.error();
  }
  // At the limit, in pieces, is fine.
  std::string fits = "GET / HTTP/1.1\r\nX: ";
  fits += std::string(8192 - fits.size() - 4, 'a') + "\r\n\r\n";
  ASSERT_EQ(fits.size(), 8192u);
  for (const std::size_t piece : {std::size_t{7}, std::size_t{40}, fits.size()}) {
    RequestReader reader(8192);
    std::size_t used = 0;
    EXPECT_EQ(FeedInPieces(reader, fits, piece, &used), RequestReader::Status::kComplete) << piece;
    EXPECT_EQ(used, fits.size());
  }
}

TEST(LiveViewHttpTest, TruncatedRequestIsBadAtTheEndOfTheStream) {
  RequestReader idle(1024);
  EXPECT_EQ(idle.EndOfStream(), RequestReader::Status::kNeedMore);
  RequestReader begun(1024);
  EXPECT_EQ(begun.Feed("GET / HTTP/1.1\r\nHo").status, RequestReader::Status::kNeedMore);
  EXPECT_EQ(begun.EndOfStream(), RequestReader::Status::kBad);
}

TEST(LiveViewHttpTest, OriginMustMatchTheHost) {
  const auto route = [](const char* origin, const char* host) {
    HttpRequest r(http::verb::get, "/ws", 11);
    if (host != nullptr) r.set(http::field::host, host);
    r.set(http::field::connection, "Upgrade");
    r.set(http::field::upgrade, "websocket");
    if (origin != nullptr) r.set(http::field::origin, origin);
    return RouteOf(r);
  };
  EXPECT_EQ(route(nullptr, "x:1"), LiveViewRoute::kWebSocket);
  EXPECT_EQ(route("http://x:1", "x:1"), LiveViewRoute::kWebSocket);
  EXPECT_EQ(route("HTTP://X:1", "x:1"), LiveViewRoute::kWebSocket);
  EXPECT_EQ(route("http://x:2", "x:1"), LiveViewRoute::kForbiddenOrigin);
  EXPECT_EQ(route("http://x:1.evil", "x:1"), LiveViewRoute::kForbiddenOrigin);
  EXPECT_EQ(route("null", "x:1"), LiveViewRoute::kForbiddenOrigin);
  EXPECT_EQ(route("http://x:1", nullptr), LiveViewRoute::kForbiddenOrigin);
}

TEST(LiveViewHttpTest, AdmissionWithoutATokenAdmitsEverythingAndWithOneOnlyTheToken) {
  const auto parse = [](const std::string& raw) {
    const ParsedRequest p = ParseRequest(raw, 8192);
    EXPECT_EQ(p.status, RequestReader::Status::kComplete) << raw;
    return p.request;
  };
  const HttpRequest plain = parse("GET /ws HTTP/1.1\r\nHost: h\r\n\r\n");
  EXPECT_EQ(AdmitRequest(plain, ""), Admission::kAdmitted);
  EXPECT_EQ(AdmitRequest(plain, "secret-token-0123"), Admission::kUnauthorized);
  EXPECT_EQ(AdmitRequest(parse("GET /x?a=b&token=secret-token-0123&c HTTP/1.1\r\nHost: h\r\n\r\n"),
                         "secret-token-0123"),
            Admission::kAdmitted);
  EXPECT_EQ(AdmitRequest(parse("GET /x?token=secret-token-0123x HTTP/1.1\r\nHost: h\r\n\r\n"),
                         "secret-token-0123"),
            Admission::kUnauthorized);
  EXPECT_EQ(AdmitRequest(parse("GET / HTTP/1.1\r\nHost: h\r\nAuthorization: bearer "
                               "secret-token-0123\r\n\r\n"),
                         "secret-token-0123"),
            Admission::kAdmitted);
  EXPECT_EQ(AdmitRequest(parse("GET / HTTP/1.1\r\nHost: h\r\nAuthorization: Basic "
                               "secret-token-0123\r\n\r\n"),
                         "secret-token-0123"),
            Admission::kUnauthorized);
  const HttpResponse r = UnauthorizedResponse(plain);
  EXPECT_EQ(r.result_int(), 401);
  EXPECT_FALSE(r.keep_alive());
}

TEST(LiveViewHttpTest, BusyResponseIsOneWellFormedResponse) {
  http::response_parser<http::string_body> parser;
  parser.eager(true);
  error_code ec;
  const std::string_view bytes = BusyResponseBytes();
  const std::size_t used = parser.put(asio::buffer(bytes.data(), bytes.size()), ec);
  EXPECT_FALSE(ec) << ec.message();
  EXPECT_TRUE(parser.is_done());
  EXPECT_EQ(used, bytes.size());
  EXPECT_EQ(parser.get().result_int(), 503);
}

}  // namespace
}  // namespace lrfnet::daemon
