#pragma once
// Emulator and SickClient on one io_context over loopback, for the link integration tests.

#include <gtest/gtest.h>

#include <boost/asio/io_context.hpp>
#include <chrono>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "firmware_tracker/io/sick_client.h"
#include "tools/emulator.h"
#include "tools/scan_source.h"

namespace lrfnet::testing {

struct ReceivedScan {
  std::uint16_t telegram_counter = 0;
  std::uint16_t scan_counter = 0;
  std::uint32_t time_since_startup_us = 0;
  std::uint64_t dist1_raw_sum = 0;
  std::uint64_t connection = 0;  // SickClient connects counter when the scan arrived
  std::chrono::steady_clock::time_point at;
};

// Client options with deadlines short enough for tests but long enough not to fire on a busy 2-core
// machine during a healthy stream.
inline io::SickClientOptions TestClientOptions() {
  io::SickClientOptions o;
  o.host = "127.0.0.1";
  o.connect_timeout = std::chrono::milliseconds(1000);
  o.reply_timeout = std::chrono::milliseconds(1000);
  o.first_scan_timeout = std::chrono::milliseconds(2000);
  o.read_deadline_scan_periods = 25;  // 1 s at 25 Hz, 0.5 s at 50 Hz
  o.min_read_deadline = std::chrono::milliseconds(500);
  o.backoff.initial = std::chrono::milliseconds(20);
  o.backoff.max = std::chrono::milliseconds(200);
  o.ready_poll_interval = std::chrono::milliseconds(20);
  return o;
}

class LinkHarness {
 public:
  // Starts the emulator on a free loopback port and a client pointed at it. `on_scan` (optional)
  // sees every scan after it was recorded.
  LinkHarness(tools::EmulatorOptions emulator_options, std::unique_ptr<tools::ScanSource> source,
              io::SickClientOptions client_options = TestClientOptions(),
              std::function<void(const cola::ScanTelegram&)> on_scan = nullptr)
      : on_scan_(std::move(on_scan)) {
    emulator_options.port = 0;
    emulator_ = std::make_unique<tools::Emulator>(io_, emulator_options, std::move(source));
    std::string error;
    started_ = emulator_->Start(&error);
    EXPECT_TRUE(started_) << error;
    client_options.port = emulator_->port();
    client_ = std::make_unique<io::SickClient>(
        io_, client_options,
        [this](const cola::ScanTelegram& scan, common::UtcNs) { Record(scan); });
  }

  ~LinkHarness() { Shutdown(); }

  // Runs the io_context until done() is true or `timeout` passed. Returns done().
  bool RunUntil(const std::function<bool()>& done, std::chrono::milliseconds timeout) {
    if (!client_started_) {
      client_started_ = true;
      start_ = std::chrono::steady_clock::now();
      client_->Start();
    }
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (!done() && std::chrono::steady_clock::now() < deadline) {
      io_.run_for(std::chrono::milliseconds(5));
      if (io_.stopped()) io_.restart();
    }
    return done();
  }

  bool RunUntilScans(std::size_t n, std::chrono::milliseconds timeout) {
    return RunUntil([&] { return received_.size() >= n; }, timeout);
  }

  // Stops both ends and lets the io_context drain their cancelled handlers.
  void Shutdown() {
    if (client_) client_->Stop();
    if (emulator_) emulator_->Stop();
    io_.restart();
    io_.run_for(std::chrono::seconds(2));
  }

  bool started() const { return started_; }
  io::SickClient& client() { return *client_; }
  tools::Emulator& emulator() { return *emulator_; }
  const std::vector<ReceivedScan>& received() const { return received_; }
  std::chrono::steady_clock::time_point start_time() const { return start_; }
  std::vector<std::uint16_t> received_counters() const {
    std::vector<std::uint16_t> out;
    for (const ReceivedScan& r : received_) out.push_back(r.telegram_counter);
    return out;
  }

 private:
  void Record(const cola::ScanTelegram& scan) {
    ReceivedScan r;
    r.telegram_counter = scan.telegram_counter;
    r.scan_counter = scan.scan_counter;
    r.time_since_startup_us = scan.time_since_startup_us;
    if (const cola::ScanChannel* dist = scan.FindChannel("DIST1")) {
      for (std::size_t i = 0; i < dist->count; ++i) r.dist1_raw_sum += dist->raw[i];
    }
    r.connection = client_->counters().connects;
    r.at = std::chrono::steady_clock::now();
    received_.push_back(r);
    if (on_scan_) on_scan_(scan);
  }

  boost::asio::io_context io_;
  std::function<void(const cola::ScanTelegram&)> on_scan_;
  std::unique_ptr<tools::Emulator> emulator_;
  std::unique_ptr<io::SickClient> client_;
  std::vector<ReceivedScan> received_;
  bool started_ = false;
  bool client_started_ = false;
  std::chrono::steady_clock::time_point start_{};
};

// The client received exactly the scans the emulator wrote completely, in order: every connection's
// scans in full, except that the newest connection may still have scans in flight (a missing tail).
inline void ExpectNoLossNoDuplicates(const std::vector<std::vector<std::uint16_t>>& sent,
                                     const std::vector<std::uint16_t>& received) {
  std::vector<std::uint16_t> complete;  // all connections but the newest
  for (std::size_t c = 0; c + 1 < sent.size(); ++c)
    complete.insert(complete.end(), sent[c].begin(), sent[c].end());
  std::vector<std::uint16_t> all = complete;
  if (!sent.empty()) all.insert(all.end(), sent.back().begin(), sent.back().end());
  ASSERT_GE(received.size(), complete.size()) << "scans of closed connections were lost";
  ASSERT_LE(received.size(), all.size())
      << "the client received scans the emulator never completed";
  EXPECT_EQ(received, std::vector<std::uint16_t>(all.begin(),
                                                 all.begin() + static_cast<long>(received.size())));
}

}  // namespace lrfnet::testing
