// SickClient against a misbehaving device: it recovers from every fault and loses no scan that the
// device sent completely. The emulator serves the synthetic LMS511 source (25 Hz in the telegram,
// 10x faster on the wire), so these tests never need the shared data.

#include <gtest/gtest.h>

#include <boost/asio/ip/tcp.hpp>
#include <chrono>
#include <functional>
#include <list>
#include <memory>
#include <string>
#include <vector>

#include "tests/link_harness.h"

namespace lrfnet {
namespace {

namespace asio = boost::asio;
using asio::ip::tcp;
using std::chrono::milliseconds;
using std::chrono::seconds;

constexpr double kSpeed = 10.0;

std::unique_ptr<tools::ScanSource> Synthetic() {
  tools::SyntheticScanOptions options;
  options.model = "lms511";
  return tools::MakeSyntheticScanSource(options);
}

tools::EmulatorOptions WithFaults(const tools::EmulatorFaults& faults) {
  tools::EmulatorOptions o;
  o.speed = kSpeed;
  o.faults = faults;
  return o;
}

// A read deadline that a stalled device trips quickly: 5 periods of the telegram's 25 Hz = 200 ms.
io::SickClientOptions QuickDeadlineOptions() {
  io::SickClientOptions o = testing::TestClientOptions();
  o.read_deadline_scan_periods = 5;
  o.min_read_deadline = milliseconds(100);
  return o;
}

TEST(LinkFaultsTest, GarbageBetweenFramesIsCountedAndNoScanIsLost) {
  tools::EmulatorFaults faults;
  faults.garbage_every_scans = 5;
  testing::LinkHarness link(WithFaults(faults), Synthetic());
  ASSERT_TRUE(link.RunUntilScans(41, seconds(10)));
  link.Shutdown();

  const io::SickClientCounters& c = link.client().counters();
  EXPECT_GE(c.bad_frames, 8u);  // one frame with a bad checksum before every 5th scan
  EXPECT_GT(link.client().decoder_counters().framer.garbage_bytes, 0u);
  EXPECT_EQ(c.connects, 1u) << "garbage must not cost the connection";
  EXPECT_EQ(c.read_timeouts, 0u);
  const std::vector<std::uint16_t> received = link.received_counters();
  for (std::size_t i = 0; i < received.size(); ++i) ASSERT_EQ(received[i], i + 1);
  testing::ExpectNoLossNoDuplicates(link.emulator().sent_telegram_counters(), received);
}

TEST(LinkFaultsTest, StalledDeviceTripsTheReadDeadlineAndTheClientReconnects) {
  tools::EmulatorFaults faults;
  faults.stall_after_scans = 15;
  testing::LinkHarness link(WithFaults(faults), Synthetic(), QuickDeadlineOptions());
  ASSERT_TRUE(link.RunUntilScans(40, seconds(15)));
  link.Shutdown();

  const io::SickClientCounters& c = link.client().counters();
  EXPECT_GE(c.read_timeouts, 2u);
  EXPECT_GE(c.reconnects, 2u);
  EXPECT_GE(c.connects, 3u);
  EXPECT_GE(link.emulator().counters().stalls, 2u);
  // The device kept its position: counters continue across connections.
  const std::vector<std::uint16_t> received = link.received_counters();
  for (std::size_t i = 0; i < received.size(); ++i) ASSERT_EQ(received[i], i + 1);
  testing::ExpectNoLossNoDuplicates(link.emulator().sent_telegram_counters(), received);
}

TEST(LinkFaultsTest, ConnectionClosedMidFrameLosesOnlyTheBrokenScan) {
  tools::EmulatorFaults faults;
  faults.close_mid_frame_after_scans = 12;
  testing::LinkHarness link(WithFaults(faults), Synthetic());
  ASSERT_TRUE(link.RunUntilScans(40, seconds(15)));
  link.Shutdown();

  const io::SickClientCounters& c = link.client().counters();
  EXPECT_GE(c.disconnects, 2u);
  EXPECT_GE(c.reconnects, 2u);
  EXPECT_EQ(c.bad_frames, 0u)
      << "the half frame must be dropped with the connection, not glued to the next";
  const std::vector<std::uint16_t> received = link.received_counters();
  // Each connection: 12 scans, then the 13th breaks off.
  for (std::size_t i = 1; i < received.size(); ++i) {
    const int step = received[i] - received[i - 1];
    ASSERT_TRUE(step == 1 || (step == 2 && i % 12 == 0))
        << "at " << i << ": " << received[i - 1] << " -> " << received[i];
  }
  testing::ExpectNoLossNoDuplicates(link.emulator().sent_telegram_counters(), received);
}

TEST(LinkFaultsTest, SfaToStartMeasurementIsRetriedAfterTheBackoff) {
  tools::EmulatorFaults faults;
  faults.sfa_command = "LMCstartmeas";
  faults.sfa_times = 2;
  io::SickClientOptions options = testing::TestClientOptions();
  options.backoff.initial = milliseconds(100);
  options.backoff.multiplier = 2.0;
  options.backoff.jitter = 0.2;
  options.backoff.max = milliseconds(1000);
  testing::LinkHarness link(WithFaults(faults), Synthetic(), options);
  ASSERT_TRUE(link.RunUntilScans(20, seconds(10)));
  link.Shutdown();

  const io::SickClientCounters& c = link.client().counters();
  EXPECT_EQ(c.sfa_replies, 2u);
  EXPECT_EQ(c.handshake_failures, 2u);
  EXPECT_EQ(c.connects, 3u);
  EXPECT_EQ(c.reconnects, 2u);
  // Two backoffs, 100 ms and 200 ms nominal, at most 20 % shorter each.
  EXPECT_GE(link.received().front().at - link.start_time(), milliseconds(80 + 160));
  EXPECT_EQ(link.received().front().connection, 3u);
  testing::ExpectNoLossNoDuplicates(link.emulator().sent_telegram_counters(),
                                    link.received_counters());
}

TEST(LinkFaultsTest, SfaToIdentificationReadsDoesNotStopTheSession) {
  tools::EmulatorFaults faults;
  faults.sfa_command = "DeviceIdent";
  testing::LinkHarness link(WithFaults(faults), Synthetic());
  ASSERT_TRUE(link.RunUntilScans(10, seconds(10)));
  link.Shutdown();

  EXPECT_EQ(link.client().counters().sfa_replies, 1u);
  EXPECT_EQ(link.client().counters().connects, 1u);
  EXPECT_TRUE(link.client().device_info().ident_name.empty());
  EXPECT_EQ(link.client().device_info().firmware_version, "V1.80");
}

TEST(LinkFaultsTest, DeviceRestartWithSmallCountersIsFollowed) {
  tools::EmulatorFaults faults;
  faults.restart_after_scans = 20;
  testing::LinkHarness link(WithFaults(faults), Synthetic());
  ASSERT_TRUE(link.RunUntilScans(50, seconds(15)));
  link.Shutdown();

  EXPECT_GE(link.emulator().counters().restarts, 2u);
  EXPECT_GE(link.client().counters().reconnects, 2u);
  const std::vector<testing::ReceivedScan>& r = link.received();
  // After each restart the device counts from 1 again, with a tick of a freshly powered unit.
  for (std::size_t i = 0; i < r.size(); ++i) {
    EXPECT_EQ(r[i].telegram_counter, i % 20 + 1) << i;
    if (i >= 20 && i % 20 == 0) {
      EXPECT_LT(r[i].time_since_startup_us, 3'000'000u) << i;
    }
  }
  testing::ExpectNoLossNoDuplicates(link.emulator().sent_telegram_counters(),
                                    link.received_counters());
}

TEST(LinkFaultsTest, DeviceThatAcceptsButNeverAnswersTripsTheReplyDeadline) {
  asio::io_context io;
  tcp::acceptor acceptor(io, tcp::endpoint(asio::ip::make_address("127.0.0.1"), 0));
  std::list<tcp::socket> held;  // accepted and never answered (nor closed)
  std::function<void()> accept = [&] {
    acceptor.async_accept([&](const boost::system::error_code& ec, tcp::socket s) {
      if (ec) return;
      held.push_back(std::move(s));
      accept();
    });
  };
  accept();
  io::SickClientOptions options = testing::TestClientOptions();
  options.port = acceptor.local_endpoint().port();
  options.reply_timeout = milliseconds(100);
  io::SickClient client(io, options, nullptr);
  client.Start();
  io.run_for(milliseconds(700));

  const io::SickClientCounters& c = client.counters();
  EXPECT_GE(c.reply_timeouts, 2u);
  EXPECT_GE(c.connects, 2u);
  EXPECT_EQ(c.scans, 0u);
  EXPECT_GE(held.size(), 2u);
  EXPECT_NE(client.last_failure().find("SetAccessMode"), std::string::npos)
      << client.last_failure();
  client.Stop();
  acceptor.close();
  io.restart();
  io.run_for(seconds(1));
}

TEST(LinkFaultsTest, NothingListeningIsCountedAndRetriedWithBackoff) {
  asio::io_context io;
  // Bound but not listening: connects are refused, and no other test can take the port meanwhile.
  tcp::socket reserved(io, tcp::endpoint(asio::ip::make_address("127.0.0.1"), 0));
  const std::uint16_t port = reserved.local_endpoint().port();
  io::SickClientOptions options = testing::TestClientOptions();
  options.port = port;
  options.backoff.initial = milliseconds(50);
  options.backoff.max = milliseconds(100);
  options.backoff.jitter = 0.0;
  io::SickClient client(io, options, nullptr);
  client.Start();
  io.run_for(milliseconds(600));

  const io::SickClientCounters& c = client.counters();
  EXPECT_EQ(c.connects, 0u);
  EXPECT_GE(c.connect_failures, 3u);
  // 50 + 100 + 100 + ... ms of backoff in 600 ms: a client that does not wait would fail hundreds
  // of times.
  EXPECT_LE(c.connect_failures, 9u);
  EXPECT_TRUE(client.state() == io::SickClientState::kBackoff ||
              client.state() == io::SickClientState::kConnecting);
  EXPECT_NE(client.last_failure().find("refused"), std::string::npos) << client.last_failure();
  client.Stop();
  io.restart();
  io.run_for(seconds(1));
}

}  // namespace
}  // namespace lrfnet
