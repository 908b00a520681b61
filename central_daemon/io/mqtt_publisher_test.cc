#include "central_daemon/io/mqtt_publisher.h"

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <thread>

#include "tests/mosquitto_broker.h"
#include "tests/mqtt_subscriber.h"

namespace lrfnet::daemon {
namespace {

using lrfnet::testing::BrokerOptions;
using lrfnet::testing::MosquittoBroker;
using lrfnet::testing::MqttSubscriber;
using lrfnet::testing::Process;
using lrfnet::testing::ReceivedMessage;
using std::chrono::milliseconds;

#define REQUIRE_MOSQUITTO()                                                         \
  if (!lrfnet::testing::HaveBinary(lrfnet::testing::kMosquitto)) {                  \
    GTEST_SKIP() << "mosquitto is not installed (scripts/install_deps.sh adds it)"; \
  }

MqttOptions OptionsFor(std::uint16_t port) {
  MqttOptions o;
  o.host = "127.0.0.1";
  o.port = port;
  o.client_id = "lrfnet-test-" + std::to_string(::getpid());
  o.reconnect_min_s = 0.05;
  o.reconnect_max_s = 0.4;
  return o;
}

template <typename Predicate>
bool Eventually(Predicate done, milliseconds timeout = milliseconds(20'000)) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (std::chrono::steady_clock::now() < deadline) {
    if (done()) return true;
    std::this_thread::sleep_for(milliseconds(10));
  }
  return done();
}

TEST(MqttPublisherTest, DeliversEveryMessageInOrder) {
  REQUIRE_MOSQUITTO();
  MosquittoBroker broker;
  ASSERT_TRUE(broker.Start());
  MqttSubscriber subscriber(broker.port(), "test/#");
  ASSERT_TRUE(subscriber.WaitSubscribed());
  MqttPublisher publisher(OptionsFor(broker.port()));
  std::string error;
  ASSERT_TRUE(publisher.Start(&error)) << error;
  ASSERT_TRUE(publisher.WaitConnected(20.0)) << publisher.last_error();
  for (int i = 0; i < 500; ++i) publisher.Publish("test/n", std::to_string(i), 0, false);
  ASSERT_TRUE(publisher.Flush(20.0));
  ASSERT_TRUE(subscriber.WaitFor([](const auto& m) { return m.size() >= 500; }));
  const std::vector<ReceivedMessage> got = subscriber.messages();
  ASSERT_EQ(got.size(), 500u);
  for (int i = 0; i < 500; ++i)
    EXPECT_EQ(got[static_cast<std::size_t>(i)].payload, std::to_string(i));
  const MqttCounters c = publisher.counters();
  EXPECT_EQ(c.submitted, 500u);
  EXPECT_EQ(c.sent, 500u);
  EXPECT_EQ(c.dropped_queue_full + c.dropped_disconnected + c.lost_in_flight, 0u);
  EXPECT_EQ(c.connects, 1u);
}

TEST(MqttPublisherTest, ConnectsWhenTheBrokerComesAndAgainAfterARestart) {
  REQUIRE_MOSQUITTO();
  MosquittoBroker broker;
  MqttOptions options = OptionsFor(broker.port());
  options.will_topic = "test/status";
  options.will_payload = "offline";
  MqttPublisher publisher(options);
  std::string error;
  ASSERT_TRUE(publisher.Start(&error)) << error;
  // No broker yet: attempts fail (counted) and are repeated with backoff.
  ASSERT_TRUE(Eventually([&] { return publisher.counters().connect_failures >= 2; }));
  EXPECT_FALSE(publisher.connected());
  publisher.Publish("test/calibration", "v1", 1, true);
  for (int i = 0; i < 7; ++i) publisher.Publish("test/objects", "early", 0, false);
  EXPECT_EQ(publisher.counters().dropped_disconnected, 7u);

  ASSERT_TRUE(broker.Start());
  ASSERT_TRUE(publisher.WaitConnected(20.0)) << publisher.last_error();
  ASSERT_TRUE(publisher.Flush(20.0));
  {
    MqttSubscriber late(broker.port(), "test/#");
    ASSERT_TRUE(late.WaitFor([](const auto& m) { return !m.empty(); }));
    EXPECT_EQ(late.messages()[0].payload, "v1");  // the retained message, sent once connected
    EXPECT_TRUE(late.messages()[0].retained);
  }

  // The broker restarts without its store (persistence off).
  broker.Stop();
  ASSERT_TRUE(Eventually([&] { return !publisher.connected(); }));
  for (int i = 0; i < 20; ++i) publisher.Publish("test/objects", "lost", 0, false);
  publisher.Publish("test/calibration", "v2", 1, true);
  ASSERT_TRUE(broker.Start());
  ASSERT_TRUE(publisher.WaitConnected(20.0)) << publisher.last_error();
  MqttSubscriber subscriber(broker.port(), "test/#");
  ASSERT_TRUE(subscriber.WaitFor([](const auto& m) { return !m.empty(); }));
  EXPECT_EQ(subscriber.messages()[0].payload, "v2");
  for (int i = 0; i < 5; ++i) publisher.Publish("test/objects", "after", 0, false);
  ASSERT_TRUE(subscriber.WaitFor([](const auto& m) { return m.size() >= 6; }));
  EXPECT_EQ(subscriber.On("test/objects").size(), 5u);
  const MqttCounters c = publisher.counters();
  EXPECT_EQ(c.connects, 2u);
  EXPECT_EQ(c.disconnects, 1u);
  EXPECT_EQ(c.dropped_disconnected, 27u);
  EXPECT_EQ(c.lost_in_flight, 0u);
  EXPECT_EQ(c.submitted, c.sent + c.dropped_disconnected + c.dropped_queue_full + c.lost_in_flight +
                             c.retained_replaced + c.queued + c.in_flight);
}

// A broker that accepts the connection and then never reads or acknowledges again.
class StalledBroker {
 public:
  StalledBroker() {
    listen_fd_ = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    ::bind(listen_fd_, reinterpret_cast<sockaddr*>(&a), sizeof a);
    ::listen(listen_fd_, 1);
    socklen_t len = sizeof a;
    ::getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&a), &len);
    port_ = ntohs(a.sin_port);
    thread_ = std::thread([this] {
      client_fd_ = ::accept(listen_fd_, nullptr, nullptr);
      if (client_fd_ < 0) return;
      char connect_packet[256];
      ::recv(client_fd_, connect_packet, sizeof connect_packet, 0);
      const unsigned char connack[] = {0x20, 0x02, 0x00, 0x00};
      ::send(client_fd_, connack, sizeof connack, 0);
    });
  }
  ~StalledBroker() {
    ::shutdown(listen_fd_, SHUT_RDWR);
    thread_.join();
    if (client_fd_ >= 0) ::close(client_fd_);
    ::close(listen_fd_);
  }
  std::uint16_t port() const { return port_; }

 private:
  int listen_fd_ = -1;
  int client_fd_ = -1;
  std::uint16_t port_ = 0;
  std::thread thread_;
};

TEST(MqttPublisherTest, APublisherWhoseBrokerStallsNeverBlocksAndCountsWhatItDrops) {
  StalledBroker broker;
  MqttOptions options = OptionsFor(broker.port());
  options.queue_messages = 20;
  options.max_in_flight = 5;
  MqttPublisher publisher(options);
  std::string error;
  ASSERT_TRUE(publisher.Start(&error)) << error;
  ASSERT_TRUE(publisher.WaitConnected(20.0)) << publisher.last_error();
  for (int i = 0; i < 5; ++i) publisher.Publish("test/q", "first", 1, false);
  // QoS 1 without PUBACKs: five stay in flight.
  ASSERT_TRUE(Eventually([&] { return publisher.counters().in_flight == 5; }));
  for (int i = 0; i < 100; ++i) publisher.Publish("test/q", std::string(100, 'x'), 1, false);
  const MqttCounters c = publisher.counters();
  EXPECT_EQ(c.queued, 20u);
  EXPECT_EQ(c.dropped_queue_full, 80u);
  EXPECT_EQ(c.sent, 0u);
  EXPECT_FALSE(publisher.Flush(0.2));
}

TEST(MqttPublisherTest, TlsWithUserAndPassword) {
  REQUIRE_MOSQUITTO();
  if (!lrfnet::testing::HaveBinary("/usr/bin/openssl")) GTEST_SKIP() << "openssl missing";
  MosquittoBroker broker(BrokerOptions{"daemon", "s3cret", true});
  ASSERT_TRUE(broker.Start()) << broker.log();
  MqttOptions options = OptionsFor(broker.port());
  options.tls = true;
  options.tls_ca_file = broker.ca_file();
  options.username = "daemon";
  {
    options.password = "wrong";
    MqttPublisher refused(options);
    std::string error;
    ASSERT_TRUE(refused.Start(&error)) << error;
    ASSERT_TRUE(Eventually([&] { return refused.counters().connect_failures >= 1; }));
    EXPECT_FALSE(refused.connected());
    EXPECT_NE(refused.last_error().find("not authorised"), std::string::npos)
        << refused.last_error();
  }
  {
    options.password = "s3cret";
    options.tls_ca_file = "/nonexistent/ca.crt";
    MqttPublisher bad_ca(options);
    std::string error;
    EXPECT_FALSE(bad_ca.Start(&error));
    EXPECT_NE(error.find("TLS"), std::string::npos) << error;
  }
  options.tls_ca_file = broker.ca_file();
  MqttPublisher publisher(options);
  std::string error;
  ASSERT_TRUE(publisher.Start(&error)) << error;
  ASSERT_TRUE(publisher.WaitConnected(20.0)) << publisher.last_error();
  publisher.Publish("test/tls", "over tls", 1, true);
  ASSERT_TRUE(publisher.Flush(20.0));
  EXPECT_EQ(publisher.counters().sent, 1u);  // acknowledged by the broker (QoS 1)
  // A second, independent client: mosquitto_sub over TLS with the same credentials.
  Process sub(lrfnet::testing::kMosquittoSub,
              {"-h", "127.0.0.1", "-p", std::to_string(broker.port()), "--cafile", broker.ca_file(),
               "-u", "daemon", "-P", "s3cret", "-t", "test/tls", "-C", "1", "-W", "20"});
  EXPECT_EQ(sub.Wait(milliseconds(30'000)), 0) << sub.err();
  EXPECT_EQ(sub.out(), "over tls\n");
}

}  // namespace
}  // namespace lrfnet::daemon
