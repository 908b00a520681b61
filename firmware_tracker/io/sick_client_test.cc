#include "firmware_tracker/io/sick_client.h"

#include <gtest/gtest.h>
#include <spdlog/spdlog.h>

#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/write.hpp>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <new>
#include <string>
#include <thread>
#include <vector>

#include "firmware_tracker/cola/commands.h"
#include "firmware_tracker/cola/framer.h"
#include "firmware_tracker/cola/scan_telegram.h"

// Heap allocations made by the current thread (the zero-allocation test below reads it around the
// streaming path; the scripted device runs on another thread).
namespace {
thread_local std::uint64_t t_allocations = 0;
void* CountedAlloc(std::size_t n) {
  ++t_allocations;
  if (void* p = std::malloc(n == 0 ? 1 : n)) return p;
  throw std::bad_alloc();
}
}  // namespace
void* operator new(std::size_t n) { return CountedAlloc(n); }
void* operator new[](std::size_t n) { return CountedAlloc(n); }
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }

namespace lrfnet::io {
namespace {

namespace asio = boost::asio;
using asio::ip::tcp;
using std::chrono::milliseconds;

TEST(BackoffTest, GrowsByTheMultiplierUpToTheMaximum) {
  BackoffOptions options;
  options.initial = milliseconds(100);
  options.max = milliseconds(1000);
  options.multiplier = 2.0;
  options.jitter = 0.0;
  Backoff backoff(options, 1);
  std::vector<long> delays;
  for (int i = 0; i < 7; ++i) delays.push_back(static_cast<long>(backoff.Next().count()));
  EXPECT_EQ(delays, (std::vector<long>{100, 200, 400, 800, 1000, 1000, 1000}));
  backoff.Reset();
  EXPECT_EQ(backoff.Next(), milliseconds(100));
}

TEST(BackoffTest, JitterStaysWithinItsFractionAndIsSeeded) {
  BackoffOptions options;
  options.initial = milliseconds(1000);
  options.max = milliseconds(10'000);
  options.multiplier = 1.0;
  options.jitter = 0.25;
  Backoff a(options, 7);
  Backoff b(options, 7);
  Backoff c(options, 8);
  bool differs_from_other_seed = false;
  bool varies = false;
  milliseconds first = a.Next();
  EXPECT_EQ(first, b.Next());
  differs_from_other_seed |= first != c.Next();
  for (int i = 0; i < 50; ++i) {
    const milliseconds d = a.Next();
    EXPECT_EQ(d, b.Next());
    differs_from_other_seed |= d != c.Next();
    varies |= d != first;
    EXPECT_GE(d.count(), 750);
    EXPECT_LE(d.count(), 1250);
  }
  EXPECT_TRUE(varies);
  EXPECT_TRUE(differs_from_other_seed);
}

TEST(SickClientOptionsTest, ValidateNamesTheBadField) {
  SickClientOptions ok;
  ok.host = "127.0.0.1";
  EXPECT_FALSE(Validate(ok).has_value());

  SickClientOptions o = ok;
  o.host.clear();
  EXPECT_NE(Validate(o).value_or("").find("host"), std::string::npos);
  o = ok;
  o.port = 0;
  EXPECT_NE(Validate(o).value_or("").find("port"), std::string::npos);
  o = ok;
  o.reply_timeout = milliseconds(0);
  EXPECT_NE(Validate(o).value_or("").find("reply"), std::string::npos);
  o = ok;
  o.read_deadline_scan_periods = 0.5;
  EXPECT_NE(Validate(o).value_or("").find("read deadline"), std::string::npos);
  o = ok;
  o.backoff.max = milliseconds(1);
  EXPECT_NE(Validate(o).value_or("").find("backoff"), std::string::npos);
  o = ok;
  o.backoff.jitter = 1.0;
  EXPECT_NE(Validate(o).value_or("").find("jitter"), std::string::npos);
}

// A device that follows a script: answers every start-up command, then sends `scans` scan telegrams
// after sEN LMDscandata 1. Records the command names it received.
class ScriptedDevice {
 public:
  // `scans` scans of `points` DIST1 values each; all in one write after sEA LMDscandata, or
  // `interval` apart.
  // `busy_polls`: SCdevicestate answers busy (0) this often before ready (1); then `final_state`.
  ScriptedDevice(asio::io_context& io, int scans, std::uint16_t points = 4,
                 milliseconds interval = milliseconds(0), int busy_polls = 0,
                 std::uint8_t final_state = 1)
      : busy_polls_(busy_polls),
        final_state_(final_state),
        acceptor_(io, tcp::endpoint(asio::ip::make_address("127.0.0.1"), 0)),
        socket_(io),
        timer_(io),
        scans_(scans),
        points_(points),
        interval_(interval) {
    acceptor_.async_accept(socket_, [this](const boost::system::error_code& ec) {
      if (!ec) Read();
    });
  }
  std::uint16_t port() const { return acceptor_.local_endpoint().port(); }
  const std::vector<std::string>& commands() const { return commands_; }
  void Close() {
    boost::system::error_code ignored;
    acceptor_.close(ignored);
    socket_.close(ignored);
    timer_.cancel(ignored);
  }

 private:
  void Read() {
    socket_.async_read_some(asio::buffer(buffer_), [this](const boost::system::error_code& ec,
                                                          std::size_t n) {
      if (ec) return;
      framer_.FeedAll(
          {buffer_.data(), n}, [this](std::span<const std::uint8_t> payload) { Answer(payload); },
          [](const char*) {});
      Read();
    });
  }

  void Answer(std::span<const std::uint8_t> payload) {
    cola::TelegramHeader h;
    ASSERT_EQ(cola::ParseTelegramHeader(payload, &h), cola::HeaderStatus::kOk);
    commands_.emplace_back(h.name);
    std::vector<std::uint8_t> args;
    auto flex = [&args](const std::string& s) {
      args.push_back(0);
      args.push_back(static_cast<std::uint8_t>(s.size()));
      args.insert(args.end(), s.begin(), s.end());
    };
    cola::CommandType type = cola::CommandType::kMethodAnswer;
    if (h.name == "SetAccessMode" || h.name == "Run") {
      args = {1};
    } else if (h.name == "LMCstartmeas") {
      args = {0};
    } else if (h.name == "DeviceIdent") {
      type = cola::CommandType::kReadAnswer;
      flex("TestDevice");
      flex("1.2.3");
    } else if (h.name == "FirmwareVersion") {
      type = cola::CommandType::kReadAnswer;
      flex("V9.9");
    } else if (h.name == "SerialNumber") {
      type = cola::CommandType::kReadAnswer;
      flex("424242");
    } else if (h.name == "LMDscandatacfg" && h.type == cola::CommandType::kWrite) {
      type = cola::CommandType::kWriteAnswer;
      written_config_.assign(h.args.begin(), h.args.end());
    } else if (h.name == "LMDscandatacfg") {
      type = cola::CommandType::kReadAnswer;
      // What was written, but every second scan only: a device that changed the request.
      args = written_config_.empty()
                 ? std::vector<std::uint8_t>{1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1, 0, 1}
                 : written_config_;
      args[12] = 2;
    } else if (h.name == "LMPoutputRange") {
      type = cola::CommandType::kReadAnswer;
      // The LMS111 of the shared capture.
      args = {0x00, 0x01, 0x00, 0x00, 0x13, 0x88, 0xff, 0xf9, 0x22, 0x33, 0x00, 0x22, 0x55, 0x0d};
    } else if (h.name == "SCdevicestate") {
      type = cola::CommandType::kReadAnswer;
      args = {static_cast<std::uint8_t>(polls_++ < busy_polls_ ? 0 : final_state_)};
    } else if (h.name == "LMDscandata") {
      type = cola::CommandType::kEventAnswer;
      args = {1};
    }
    std::vector<std::uint8_t> reply(64 + args.size());
    reply.resize(cola::EncodeReply(type, h.name, args, reply));
    // One write per answer: the reply and the scans must not interleave with another write.
    auto out = std::make_shared<std::vector<std::uint8_t>>();
    AppendFrame(reply, out.get());
    if (h.name == "LMDscandata" && interval_.count() == 0) {
      for (int k = 0; k < scans_; ++k) AppendFrame(ScanPayload(k), out.get());
    }
    asio::async_write(socket_, asio::buffer(*out),
                      [out](const boost::system::error_code&, std::size_t) {});
    if (h.name == "LMDscandata" && interval_.count() > 0) SendPacedScan(0);
  }

  // Scans one at a time, `interval_` apart, as a device streams them.
  void SendPacedScan(int k) {
    if (k >= scans_) return;
    auto out = std::make_shared<std::vector<std::uint8_t>>();
    AppendFrame(ScanPayload(k), out.get());
    asio::async_write(socket_, asio::buffer(*out),
                      [this, out, k](const boost::system::error_code& ec, std::size_t) {
                        if (ec) return;
                        timer_.expires_after(interval_);
                        timer_.async_wait([this, k](const boost::system::error_code& tec) {
                          if (!tec) SendPacedScan(k + 1);
                        });
                      });
  }

  std::vector<std::uint8_t> ScanPayload(int k) {
    scan_->scan_frequency_raw = 2500;
    scan_->channels16.clear();
    cola::ScanChannel* dist = scan_->channels16.emplace_slot();
    std::memcpy(dist->name.data(), "DIST1", 5);
    dist->angle_step_raw = 1667;
    dist->count = points_;
    scan_->telegram_counter = static_cast<std::uint16_t>(100 + k);
    for (std::uint16_t i = 0; i < points_; ++i)
      dist->raw[i] = static_cast<std::uint16_t>(1000 * (k + 1) + i);
    std::vector<std::uint8_t> payload(cola::MaxEncodedSize(*scan_));
    payload.resize(cola::EncodeScanTelegram(*scan_, payload));
    return payload;
  }

  static void AppendFrame(std::span<const std::uint8_t> payload, std::vector<std::uint8_t>* out) {
    std::vector<std::uint8_t> frame(payload.size() + 9);
    frame.resize(cola::EncodeFrame(payload, frame));
    out->insert(out->end(), frame.begin(), frame.end());
  }

  int busy_polls_ = 0;
  std::uint8_t final_state_ = 1;
  int polls_ = 0;
  std::vector<std::uint8_t> written_config_;
  tcp::acceptor acceptor_;
  tcp::socket socket_;
  asio::steady_timer timer_;
  std::array<std::uint8_t, 2048> buffer_{};
  cola::Framer framer_;
  std::vector<std::string> commands_;
  int scans_ = 0;
  std::uint16_t points_ = 4;
  milliseconds interval_{0};
  std::unique_ptr<cola::ScanTelegram> scan_ = std::make_unique<cola::ScanTelegram>();
};

SickClientOptions FastOptions(std::uint16_t port) {
  SickClientOptions o;
  o.host = "127.0.0.1";
  o.port = port;
  o.connect_timeout = milliseconds(500);
  o.reply_timeout = milliseconds(500);
  o.first_scan_timeout = milliseconds(1000);
  o.backoff.initial = milliseconds(20);
  o.backoff.max = milliseconds(100);
  return o;
}

TEST(SickClientTest, RunsTheStartUpDialogueAndDeliversScansWithTheInjectedClock) {
  asio::io_context io;
  ScriptedDevice device(io, 3, 4, milliseconds(0), /*busy_polls=*/2);
  SickClientOptions options = FastOptions(device.port());
  options.configure_scan_data = true;
  options.ready_poll_interval = milliseconds(10);
  std::vector<std::uint16_t> counters;
  std::vector<common::UtcNs> times;
  std::vector<std::uint16_t> first_raw;
  common::UtcNs fake_now = 1'000'000'000;
  SickClient* client_ptr = nullptr;
  SickClient client(
      io, options,
      [&](const cola::ScanTelegram& scan, common::UtcNs t) {
        counters.push_back(scan.telegram_counter);
        times.push_back(t);
        first_raw.push_back(scan.channels16[0].raw[0]);
        if (counters.size() == 3) client_ptr->Stop();
      },
      [&] { return fake_now += 1000; });
  client_ptr = &client;
  client.Start();
  io.run_for(std::chrono::seconds(5));

  EXPECT_EQ(device.commands(),
            (std::vector<std::string>{"SetAccessMode", "DeviceIdent", "FirmwareVersion",
                                      "SerialNumber", "LMDscandatacfg", "LMDscandatacfg",
                                      "LMPoutputRange", "LMCstartmeas", "Run", "SCdevicestate",
                                      "SCdevicestate", "SCdevicestate", "LMDscandata"}));
  EXPECT_EQ(counters, (std::vector<std::uint16_t>{100, 101, 102}));
  EXPECT_EQ(first_raw, (std::vector<std::uint16_t>{1000, 2000, 3000}));
  ASSERT_EQ(times.size(), 3u);
  for (const common::UtcNs t : times) EXPECT_GT(t, 1'000'000'000);
  EXPECT_EQ(client.device_info().ident_name, "TestDevice");
  EXPECT_EQ(client.device_info().ident_version, "1.2.3");
  EXPECT_EQ(client.device_info().firmware_version, "V9.9");
  EXPECT_EQ(client.device_info().serial_number, "424242");
  // The scan configuration read back: the device answered every second scan.
  ASSERT_TRUE(client.device_info().scan_data_config.has_value());
  cola::ScanDataConfig expected = options.scan_data_config;
  expected.output_interval = 2;
  EXPECT_EQ(*client.device_info().scan_data_config, expected);
  EXPECT_EQ(client.counters().config_mismatches, 1u);
  ASSERT_TRUE(client.device_info().output_range.has_value());
  EXPECT_EQ(client.device_info().output_range->start_raw, -449997);
  EXPECT_EQ(client.device_info().output_range->stop_raw, 2249997);
  EXPECT_EQ(client.device_info().output_range->step_raw, 5000u);
  EXPECT_EQ(client.device_info().device_state, 1);
  EXPECT_EQ(client.counters().busy_polls, 2u);
  EXPECT_EQ(client.counters().connects, 1u);
  EXPECT_EQ(client.counters().scans, 3u);
  EXPECT_EQ(client.counters().sfa_replies, 0u);
  EXPECT_EQ(client.state(), SickClientState::kStopped);
}

TEST(SickClientTest, ADeviceThatStaysBusyOrReportsAnErrorFailsTheSession) {
  for (const std::uint8_t final_state : {std::uint8_t{0}, std::uint8_t{2}}) {
    asio::io_context io;
    ScriptedDevice device(io, 3, 4, milliseconds(0), /*busy_polls=*/1, final_state);
    SickClientOptions options = FastOptions(device.port());
    options.ready_poll_interval = milliseconds(10);
    options.ready_timeout = milliseconds(200);
    SickClient client(io, options, [](const cola::ScanTelegram&, common::UtcNs) {});
    client.Start();
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    while (client.counters().handshake_failures == 0 &&
           std::chrono::steady_clock::now() < deadline) {
      io.run_for(milliseconds(10));
    }
    EXPECT_EQ(client.counters().handshake_failures, 1u) << int{final_state};
    EXPECT_EQ(client.counters().scans, 0u);
    EXPECT_NE(client.last_failure().find(final_state == 2 ? "error state" : "still busy"),
              std::string::npos)
        << client.last_failure();
    if (final_state == 0) {
      EXPECT_GE(client.counters().busy_polls, 10u);
    }
    EXPECT_EQ(device.commands().back(), "SCdevicestate");
    client.Stop();
    device.Close();
    io.run_for(milliseconds(50));
  }
}

TEST(SickClientTest, StreamingAllocatesNothingPerScan) {
#ifdef LRFNET_CROSS_EMULATED_TESTS
  // The device runs on a second thread; the qemu-user of the cross test run (7.2) hangs in
  // pthread_create. The tracker itself runs on one thread; the host run covers this test.
  GTEST_SKIP() << "needs a second thread, which qemu-user does not start here";
#endif
  // LMS511-sized scans, 1 ms apart, so every read completes about one telegram: the per-scan path
  // runs hundreds of times after the warm-up.
  constexpr int kScans = 300;
  asio::io_context device_io;
  ScriptedDevice device(device_io, kScans, 1141, milliseconds(1));
  std::thread device_thread([&] { device_io.run(); });

  asio::io_context io;
  int scans = 0;
  std::uint64_t allocations_after_warm_up = 0;
  std::uint64_t allocations_at_end = 0;
  SickClient* client_ptr = nullptr;
  SickClient client(io, FastOptions(device.port()), [&](const cola::ScanTelegram&, common::UtcNs) {
    ++scans;
    if (scans == 20) allocations_after_warm_up = t_allocations;
    if (scans == kScans) {
      allocations_at_end = t_allocations;
      client_ptr->Stop();
    }
  });
  client_ptr = &client;
  client.Start();
  io.run_for(std::chrono::seconds(10));
  asio::post(device_io, [&] { device.Close(); });
  device_thread.join();

  ASSERT_EQ(scans, kScans);
  EXPECT_EQ(allocations_at_end - allocations_after_warm_up, 0u)
      << "heap allocations while streaming " << kScans - 20 << " scans";
}

TEST(SickClientTest, StopPostedToTheIoContextEndsRunWhileConnectingToNobody) {
  asio::io_context io;
  // Bound but not listening: connects are refused, and no other test can take the port meanwhile.
  tcp::socket reserved(io, tcp::endpoint(asio::ip::make_address("127.0.0.1"), 0));
  const std::uint16_t port = reserved.local_endpoint().port();
  SickClient client(io, FastOptions(port), nullptr);
  client.Start();
  asio::steady_timer stop_timer(io, milliseconds(300));
  stop_timer.async_wait(
      [&](const boost::system::error_code&) { asio::post(io, [&] { client.Stop(); }); });
  const auto start = std::chrono::steady_clock::now();
  io.run();  // returns only when the client has no pending work left
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(3));
  EXPECT_GE(client.counters().connect_failures, 2u);
  EXPECT_EQ(client.counters().connects, 0u);
  // Every failure but possibly the last (stopped during its backoff) was followed by a new attempt.
  EXPECT_GE(client.counters().reconnects + 1, client.counters().connect_failures);
  EXPECT_LE(client.counters().reconnects, client.counters().connect_failures);
  EXPECT_EQ(client.state(), SickClientState::kStopped);
  EXPECT_NE(client.last_failure().find("connect"), std::string::npos);
}

}  // namespace
}  // namespace lrfnet::io
