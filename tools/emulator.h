#pragma once
// A TCP server that behaves like a SICK scanner (Boost.Asio): one port speaks CoLa-B and CoLa-A
// (each request is answered in its own dialect), the SOPAS dialogue is a SopasDevice of the
// source's device family (sopas_device.h: every variable, method and event a driver uses, the
// login levels, the device state machine, field evaluation and I/O telegrams), and scans of a
// ScanSource go out at the source's pace, scaled by `speed`, while the device's state lets them:
// measuring (LMCstopmeas stops them), out of configuration mode, ready, and subscribed with
// `sEN LMDscandata 1` in either dialect.
//
// One client at a time: a new connection replaces the current one. The source keeps its position
// across connections (the device keeps measuring); counters and µs ticks are rewritten so they keep
// increasing when the source loops, and restart small after an injected device restart (decode ->
// modify -> encode).
//
// Fault injection (EmulatorFaults) lets tests and users check how a client survives a misbehaving
// device. The scan-count faults count per connection, so they fire again on every new connection;
// the sFA fault counts commands over the emulator's lifetime (so it can clear).
//
// Thread-safety: none; everything runs on the thread running the io_context. Read counters and the
// sent record on that thread or after run() returned.

#include <array>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/steady_timer.hpp>
#include <chrono>
#include <cstdint>
#include <deque>
#include <memory>
#include <optional>
#include <random>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "firmware_tracker/cola/scan_telegram.h"
#include "firmware_tracker/cola/sopas_framer.h"
#include "tools/scan_source.h"
#include "tools/sopas_device.h"

namespace lrfnet::tools {

struct EmulatorFaults {
  // After N complete scans on a connection: go silent (no scans, no replies) but keep the socket
  // open.
  std::uint32_t stall_after_scans = 0;
  // After N complete scans on a connection: send the first half of the next scan frame, then close.
  std::uint32_t close_mid_frame_after_scans = 0;
  // Before every N-th scan: a burst of garbage bytes and a frame with a wrong checksum.
  std::uint32_t garbage_every_scans = 0;
  // Answer this command name (e.g. "LMCstartmeas") with sFA...
  std::string sfa_command;
  // ...the first N times it is received (0: always).
  std::uint32_t sfa_times = 0;
  // After N complete scans on a connection: the device "reboots": the connection drops, the login
  // is lost and telegram counter, scan counter and µs ticks start again from small values.
  std::uint32_t restart_after_scans = 0;
};

struct EmulatorOptions {
  std::string bind_address = "127.0.0.1";
  std::uint16_t port = 2112;  // 0: any free port (see Emulator::port())
  double speed = 1.0;         // > 0; 2 = twice the recorded scan rate
  bool loop = false;          // restart the source at its end (counters and ticks keep increasing)
  std::uint64_t seed = 1;     // garbage bytes
  // The device family; nullopt: from the source's DeviceIdent name (FamilyFromDeviceName), and
  // LMS5xx when that names none.
  std::optional<DeviceFamily> family;
  // Seconds from `sMN Run` until the device reports ready; negative: the family's value.
  double ready_after_run_s = -1.0;
  EmulatorFaults faults;
};
std::optional<std::string> Validate(const EmulatorOptions& options);

struct EmulatorCounters {
  std::uint64_t connections = 0;
  std::uint64_t commands = 0;    // request telegrams received (SopasDevice counts them in detail)
  std::uint64_t bad_frames = 0;  // frames from the client that were rejected
  std::uint64_t sfa_sent = 0;    // sFA replies, the device's and the injected ones
  std::uint64_t scans_sent = 0;  // scan frames written completely
  std::uint64_t passes = 0;      // times the source was rewound (--loop)
  std::uint64_t garbage_bursts = 0;
  std::uint64_t stalls = 0;
  std::uint64_t mid_frame_closes = 0;
  std::uint64_t restarts = 0;
  std::uint64_t bytes_sent = 0;
};

class Emulator {
 public:
  Emulator(boost::asio::io_context& io, const EmulatorOptions& options,
           std::unique_ptr<ScanSource> source);
  ~Emulator();
  Emulator(const Emulator&) = delete;
  Emulator& operator=(const Emulator&) = delete;

  // Binds and starts accepting. False with *error set (one line) when the address cannot be bound.
  bool Start(std::string* error);
  // Closes the listener and the client connection and cancels all timers. Idempotent.
  void Stop();

  std::uint16_t port() const { return port_; }
  const EmulatorCounters& counters() const { return counters_; }
  const SopasDeviceCounters& device_counters() const { return device_.counters(); }
  const SopasDevice& device() const { return device_; }
  const cola::SopasFramerCounters& framer_counters() const { return framer_.counters(); }
  // Telegram counters (as sent) of the scan frames written completely, one list per accepted
  // connection.
  const std::vector<std::vector<std::uint16_t>>& sent_telegram_counters() const { return sent_; }
  // The source ended (no loop) and every scan was handed to the socket.
  bool exhausted() const { return exhausted_; }

 private:
  struct OutItem {
    std::vector<std::uint8_t> bytes;
    int scan_telegram_counter = -1;  // >= 0: a complete scan frame
    bool close_after = false;
  };
  enum class Rebase { kNone, kLoop, kRestart };

  void Accept();
  void OnAccepted(boost::asio::ip::tcp::socket socket);
  void CloseConnection(const char* why);
  void StartRead();
  void HandleCommand(cola::Dialect dialect, std::span<const std::uint8_t> payload);
  void SendOutputs(const std::vector<SopasOutput>& outputs, bool close_after);
  void UpdateStreaming();
  common::DurationNs Now() const;
  void Enqueue(OutItem item);
  void WriteNext();
  void StartStreaming();
  void StopStreaming();
  void ScheduleNextScan();
  void OnScanTimer();
  void SendScan();
  bool PullScan(common::DurationNs* since_previous_ns);
  void ApplyRebase();
  std::vector<std::uint8_t> GarbageBurst();

  EmulatorOptions options_;
  std::unique_ptr<ScanSource> source_;

  boost::asio::ip::tcp::acceptor acceptor_;
  boost::asio::ip::tcp::socket socket_;
  boost::asio::steady_timer scan_timer_;
  boost::asio::steady_timer state_timer_;  // re-checks a subscribed device that is not ready yet
  std::chrono::steady_clock::time_point epoch_;
  SopasDevice device_;
  std::uint16_t port_ = 0;
  bool stopped_ = false;

  // Per connection.
  std::uint64_t connection_ =
      0;  // bumped when a connection ends: handlers of older ones are ignored
  cola::SopasFramer framer_;
  std::array<std::uint8_t, 4096> read_buffer_{};
  std::deque<OutItem> out_queue_;
  bool writing_ = false;
  bool streaming_ = false;
  bool stalled_ = false;
  bool scan_due_ = false;  // the timer fired while a scan was still being written
  std::uint32_t scans_on_connection_ = 0;

  // Stream timing: scan i is due at stream_start_ + (sum of gaps up to i) / speed.
  std::chrono::steady_clock::time_point stream_start_{};
  std::chrono::nanoseconds stream_offset_{0};
  bool first_scan_of_stream_ = false;  // goes out right after sEA LMDscandata 1

  // The device's state across connections.
  std::unique_ptr<cola::ScanTelegram> scan_;  // ~100 kB: on the heap
  bool have_pending_scan_ = false;            // scan_ holds a pulled scan not sent yet
  common::DurationNs pending_gap_ns_ = 0;
  bool exhausted_ = false;
  std::uint32_t sfa_fault_count_ = 0;
  Rebase rebase_ = Rebase::kNone;
  std::uint16_t telegram_counter_offset_ = 0;
  std::uint16_t scan_counter_offset_ = 0;
  std::uint32_t tick_offset_us_ = 0;
  bool have_last_ = false;
  std::uint16_t last_telegram_counter_ = 0;
  std::uint16_t last_scan_counter_ = 0;
  std::uint32_t last_tick_us_ = 0;

  std::mt19937_64 rng_;
  EmulatorCounters counters_;
  std::vector<std::vector<std::uint16_t>> sent_;
};

}  // namespace lrfnet::tools
