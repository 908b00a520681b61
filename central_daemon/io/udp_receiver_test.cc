#include "central_daemon/io/udp_receiver.h"

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include <boost/asio/io_context.hpp>
#include <boost/asio/steady_timer.hpp>
#include <chrono>
#include <string>
#include <vector>

namespace lrfnet::daemon {
namespace {

namespace asio = boost::asio;

common::UtcNs Now() {
  timespec ts{};
  ::clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<common::UtcNs>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

// A plain sender socket on loopback.
class Sender {
 public:
  explicit Sender(int family) : family_(family) {
    fd_ = ::socket(family, SOCK_DGRAM, 0);
    if (family == AF_INET) {
      sockaddr_in a{};
      a.sin_family = AF_INET;
      a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
      ok_ = fd_ >= 0 && ::bind(fd_, reinterpret_cast<sockaddr*>(&a), sizeof(a)) == 0;
    } else {
      sockaddr_in6 a{};
      a.sin6_family = AF_INET6;
      a.sin6_addr = in6addr_loopback;
      ok_ = fd_ >= 0 && ::bind(fd_, reinterpret_cast<sockaddr*>(&a), sizeof(a)) == 0;
    }
    timeval tv{2, 0};
    if (fd_ >= 0) ::setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof(tv));
  }
  ~Sender() {
    if (fd_ >= 0) ::close(fd_);
  }
  bool ok() const { return ok_; }
  std::uint16_t port() const {
    sockaddr_storage a{};
    socklen_t n = sizeof(a);
    ::getsockname(fd_, reinterpret_cast<sockaddr*>(&a), &n);
    return ntohs(a.ss_family == AF_INET ? reinterpret_cast<sockaddr_in&>(a).sin_port
                                        : reinterpret_cast<sockaddr_in6&>(a).sin6_port);
  }
  bool SendTo(std::uint16_t port, const std::vector<std::uint8_t>& bytes) {
    if (family_ == AF_INET) {
      sockaddr_in a{};
      a.sin_family = AF_INET;
      a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
      a.sin_port = htons(port);
      return ::sendto(fd_, bytes.data(), bytes.size(), 0, reinterpret_cast<sockaddr*>(&a),
                      sizeof(a)) == static_cast<ssize_t>(bytes.size());
    }
    sockaddr_in6 a{};
    a.sin6_family = AF_INET6;
    a.sin6_addr = in6addr_loopback;
    a.sin6_port = htons(port);
    return ::sendto(fd_, bytes.data(), bytes.size(), 0, reinterpret_cast<sockaddr*>(&a),
                    sizeof(a)) == static_cast<ssize_t>(bytes.size());
  }
  std::vector<std::uint8_t> Receive() {
    std::vector<std::uint8_t> buffer(2048);
    const ssize_t n = ::recv(fd_, buffer.data(), buffer.size(), 0);
    buffer.resize(n > 0 ? static_cast<std::size_t>(n) : 0);
    return buffer;
  }

 private:
  int family_;
  int fd_ = -1;
  bool ok_ = false;
};

struct Received {
  std::vector<std::uint8_t> bytes;
  std::string source;
  common::UtcNs receive_ns;
};

// Runs the io_context until `count` datagrams arrived or 5 s passed.
void RunUntil(asio::io_context& io, const std::vector<Received>& got, std::size_t count) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (got.size() < count && std::chrono::steady_clock::now() < deadline) {
    io.run_for(std::chrono::milliseconds(20));
    io.restart();
  }
}

std::vector<std::uint8_t> Payload(std::size_t size, std::uint8_t seed) {
  std::vector<std::uint8_t> p(size);
  for (std::size_t i = 0; i < size; ++i) p[i] = static_cast<std::uint8_t>(seed + i * 7);
  return p;
}

// A receiver on `address`, any free port, that collects what arrives into `got`.
struct CollectingReceiver {
  asio::io_context io;
  std::vector<Received> got;
  UdpReceiver receiver;
  explicit CollectingReceiver(const std::string& address, std::size_t batch_datagrams = 64)
      : receiver(io, Options(address, batch_datagrams),
                 [this](auto bytes, const std::string& source, auto t) {
                   got.push_back({{bytes.begin(), bytes.end()}, source, t});
                 }) {}
  static UdpReceiverOptions Options(const std::string& address, std::size_t batch_datagrams) {
    UdpReceiverOptions options;
    options.address = address;
    options.port = 0;
    options.batch_datagrams = batch_datagrams;
    return options;
  }
  void RunUntil(std::size_t count) { lrfnet::daemon::RunUntil(io, got, count); }
};

TEST(UdpReceiverTest, ReceivesEveryDatagramOfTwoSendersInOrderWithSourceAndTime) {
  CollectingReceiver loop("127.0.0.1", 16);
  UdpReceiver& receiver = loop.receiver;
  std::vector<Received>& got = loop.got;
  ASSERT_EQ(receiver.Open(), std::nullopt);
  EXPECT_GE(receiver.receive_buffer_bytes(), 65536);
  EXPECT_EQ(receiver.local_address(), "127.0.0.1:" + std::to_string(receiver.local_port()));
  Sender a(AF_INET), b(AF_INET);
  ASSERT_TRUE(a.ok() && b.ok());
  const common::UtcNs before = Now();
  constexpr int kEach = 300;
  for (int i = 0; i < kEach; ++i) {
    ASSERT_TRUE(a.SendTo(receiver.local_port(), Payload(100 + i, 1)));
    ASSERT_TRUE(b.SendTo(receiver.local_port(), Payload(1400, static_cast<std::uint8_t>(i))));
  }
  loop.RunUntil(2 * kEach);
  const common::UtcNs after = Now();
  ASSERT_EQ(got.size(), 2u * kEach);
  const std::string source_a = "127.0.0.1:" + std::to_string(a.port());
  const std::string source_b = "127.0.0.1:" + std::to_string(b.port());
  int next_a = 0, next_b = 0;
  for (const Received& r : got) {
    EXPECT_GE(r.receive_ns, before);
    EXPECT_LE(r.receive_ns, after);
    if (r.source == source_a) {
      EXPECT_EQ(r.bytes, Payload(100 + next_a, 1));
      ++next_a;
    } else {
      ASSERT_EQ(r.source, source_b);
      EXPECT_EQ(r.bytes, Payload(1400, static_cast<std::uint8_t>(next_b)));
      ++next_b;
    }
  }
  EXPECT_EQ(next_a, kEach);
  EXPECT_EQ(receiver.counters().datagrams, 2u * kEach);
  // Batching: fewer receive calls than datagrams.
  EXPECT_LT(receiver.counters().batches, 2u * kEach);
  EXPECT_EQ(receiver.counters().kernel_drops, 0u);
}

TEST(UdpReceiverTest, LargeDatagramArrivesWhole) {
  CollectingReceiver loop("127.0.0.1");
  UdpReceiver& receiver = loop.receiver;
  std::vector<Received>& got = loop.got;
  ASSERT_EQ(receiver.Open(), std::nullopt);
  Sender a(AF_INET);
  ASSERT_TRUE(a.SendTo(receiver.local_port(), Payload(60000, 3)));
  loop.RunUntil(1);
  ASSERT_EQ(got.size(), 1u);
  EXPECT_EQ(got[0].bytes, Payload(60000, 3));
  EXPECT_EQ(receiver.counters().truncated, 0u);
}

TEST(UdpReceiverTest, RepliesReachTheSenderAndUnknownDestinationsAreCounted) {
  CollectingReceiver loop("127.0.0.1");
  UdpReceiver& receiver = loop.receiver;
  std::vector<Received>& got = loop.got;
  ASSERT_EQ(receiver.Open(), std::nullopt);
  Sender a(AF_INET);
  ASSERT_TRUE(a.SendTo(receiver.local_port(), Payload(10, 0)));
  loop.RunUntil(1);
  ASSERT_EQ(got.size(), 1u);
  ASSERT_TRUE(receiver.SendTo(got[0].source, Payload(20, 9)));
  EXPECT_EQ(a.Receive(), Payload(20, 9));
  EXPECT_FALSE(receiver.SendTo("127.0.0.1:1", Payload(20, 9)));
  EXPECT_EQ(receiver.counters().unknown_destinations, 1u);
  EXPECT_EQ(receiver.counters().sent, 1u);
}

TEST(UdpReceiverTest, Ipv6AndDualStack) {
  CollectingReceiver loop("::");
  UdpReceiver& receiver = loop.receiver;
  std::vector<Received>& got = loop.got;
  if (auto e = receiver.Open()) GTEST_SKIP() << "no IPv6 here: " << *e;
  Sender v6(AF_INET6);
  if (!v6.ok()) GTEST_SKIP() << "no IPv6 loopback here";
  Sender v4(AF_INET);
  ASSERT_TRUE(v6.SendTo(receiver.local_port(), Payload(50, 1)));
  ASSERT_TRUE(v4.SendTo(receiver.local_port(), Payload(60, 2)));
  loop.RunUntil(2);
  ASSERT_EQ(got.size(), 2u);
  EXPECT_EQ(got[0].source, "[::1]:" + std::to_string(v6.port()));
  // An IPv4 tracker on a dual-stack socket appears with its IPv4 address.
  EXPECT_EQ(got[1].source, "127.0.0.1:" + std::to_string(v4.port()));
  ASSERT_TRUE(receiver.SendTo(got[1].source, Payload(5, 5)));
  EXPECT_EQ(v4.Receive(), Payload(5, 5));
}

TEST(UdpReceiverTest, BadAddressOrOptionsAreOneLineErrors) {
  asio::io_context io;
  UdpReceiverOptions options;
  options.address = "no-such-host.invalid";
  UdpReceiver receiver(io, options, [](auto, const std::string&, auto) {});
  const auto error = receiver.Open();
  ASSERT_TRUE(error.has_value());
  EXPECT_NE(error->find("no-such-host.invalid"), std::string::npos);
  options.receive_buffer_bytes = 1000;
  EXPECT_TRUE(Validate(options).has_value());
}

TEST(UdpReceiverTest, HandlerMayCloseTheReceiver) {
  asio::io_context io;
  int calls = 0;
  UdpReceiverOptions options;
  options.address = "127.0.0.1";
  options.port = 0;
  std::unique_ptr<UdpReceiver> receiver;
  receiver = std::make_unique<UdpReceiver>(io, options, [&](auto, const std::string&, auto) {
    ++calls;
    receiver->Close();
  });
  ASSERT_EQ(receiver->Open(), std::nullopt);
  Sender a(AF_INET);
  for (int i = 0; i < 5; ++i) ASSERT_TRUE(a.SendTo(receiver->local_port(), Payload(10, 0)));
  ::usleep(20000);
  io.run_for(std::chrono::milliseconds(100));
  EXPECT_EQ(calls, 1);
}

}  // namespace
}  // namespace lrfnet::daemon
