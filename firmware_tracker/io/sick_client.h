#pragma once
// Live link to a SICK scanner over TCP (CoLa-B, port 2112), built on Boost.Asio.
//
// A session is: connect -> sMN SetAccessMode -> sRN DeviceIdent -> sRN FirmwareVersion
// -> sRN SerialNumber [-> sWN LMDscandatacfg] -> sRN LMDscandatacfg -> sRN LMPoutputRange
// -> sMN LMCstartmeas -> sMN Run -> sRN SCdevicestate until the device reports ready
// -> sEN LMDscandata 1, each command waiting for its reply within `reply_timeout`, then streaming:
// received bytes go through cola::StreamDecoder (the same path the capture replay uses) and every
// decoded scan is handed to the scan callback with its receive time. The scan configuration read
// back (LMDscandatacfg, LMPoutputRange) is in device_info(); one that differs from what was
// written is logged and counted. After Run an LMS1xx or MRS1xxx is busy for a while (the MRS1104
// about 15 s): SCdevicestate is polled every `ready_poll_interval` until it says ready, for at most
// `ready_timeout` (SICK's driver waits 45 s); a device that reports its error state (2) fails the
// session.
//
// Failures never end the client: a refused or timed-out connect, a device that does not answer, an
// sFA to an essential command (LMCstartmeas, sEN LMDscandata), a closed connection or no scan
// within the read deadline close the session, are logged once with their reason and counted, and
// the client reconnects after an exponential backoff with jitter. sFA to the identification and
// configuration reads (DeviceIdent, FirmwareVersion, SerialNumber, LMDscandatacfg,
// LMPoutputRange, SCdevicestate), to SetAccessMode and to Run is logged and the session continues
// (not every device knows every variable). The decoder is Reset() on every new
// connection, so a device that rebooted (small telegram counters again) or a connection that broke
// mid-telegram starts a clean stream.
//
// Structure: a few Asio "actors" on one io_context: resolve/connect, the read loop, one deadline
// timer (connect deadline, reply deadline, then the read deadline) and the backoff timer.
//
// Thread-safety: none. Every member function, the scan callback and all handlers run on the thread
// that runs the io_context (construct it, call Start() and Stop() there, e.g. from an
// asio::signal_set handler or via asio::post). The io_context must be run by exactly one thread.
// Counters and device info are read on that thread too (or after io_context::run() returned).
//
// Allocation: the streaming path allocates nothing per scan (one read buffer, one decoder with one
// reused ScanTelegram, a deadline that is moved by storing a time point rather than re-arming the
// timer).

#include <array>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/steady_timer.hpp>
#include <chrono>
#include <cstdint>
#include <functional>
#include <optional>
#include <random>
#include <span>
#include <string>
#include <vector>

#include "common/time.h"
#include "firmware_tracker/cola/commands.h"
#include "firmware_tracker/cola/stream_decoder.h"

namespace lrfnet::io {

// Exponential backoff: the k-th delay after a reset is min(initial × multiplier^k, max), multiplied
// by a uniform factor in [1 − jitter, 1 + jitter] and capped at max again. Pure apart from its
// seeded RNG: the same seed gives the same delays (tests inject it through
// SickClientOptions::backoff_seed).
struct BackoffOptions {
  std::chrono::milliseconds initial{250};
  std::chrono::milliseconds max{10'000};
  double multiplier = 2.0;
  double jitter = 0.2;  // fraction of the nominal delay, in [0, 1)
};
std::optional<std::string> Validate(const BackoffOptions& options);

class Backoff {
 public:
  Backoff(const BackoffOptions& options, std::uint64_t seed);
  std::chrono::milliseconds Next();
  // After a healthy session: the next delay is `initial` again.
  void Reset() { attempt_ = 0; }
  int attempt() const { return attempt_; }

 private:
  BackoffOptions options_;
  std::mt19937_64 rng_;
  int attempt_ = 0;
};

struct SickClientOptions {
  std::string host;
  std::uint16_t port = 2112;
  // SetAccessMode level and password hash (defaults: authorized client, the published default
  // hash).
  cola::AccessLevel access_level = cola::AccessLevel::kAuthorizedClient;
  std::uint32_t password_hash = cola::kAuthorizedClientPasswordHash;
  // Resolve + TCP connect must finish within this.
  std::chrono::milliseconds connect_timeout{3000};
  // Each start-up command must be answered within this.
  std::chrono::milliseconds reply_timeout{2000};
  // After sEN LMDscandata was accepted, the first scan must arrive within this.
  std::chrono::milliseconds first_scan_timeout{5000};
  // Then: no scan for this many scan periods (period from the telegram's scan frequency field) ->
  // the session is considered dead and the client reconnects. Never shorter than min_read_deadline.
  double read_deadline_scan_periods = 10.0;
  std::chrono::milliseconds min_read_deadline{100};
  BackoffOptions backoff;
  std::uint64_t backoff_seed = 0x5eed;
  // Send sWN LMDscandatacfg with `scan_data_config` before starting the measurement (off: keep the
  // device's stored configuration). A refusal is logged and the session continues.
  bool configure_scan_data = false;
  cola::ScanDataConfig scan_data_config;
  // After Run: poll SCdevicestate until the device is ready (off: enable the scans at once).
  bool wait_for_ready = true;
  std::chrono::milliseconds ready_poll_interval{250};
  std::chrono::milliseconds ready_timeout{45'000};
  // Size of the one read buffer (bytes per read call).
  std::size_t read_buffer_bytes = 16 * 1024;
  cola::FramerOptions framer;
};
std::optional<std::string> Validate(const SickClientOptions& options);

struct SickClientCounters {
  std::uint64_t connects = 0;          // TCP connections established
  std::uint64_t connect_failures = 0;  // resolve / connect errors and connect timeouts
  std::uint64_t reconnects = 0;        // connection attempts after a failed or lost session
  std::uint64_t reply_timeouts = 0;    // a start-up command not answered within reply_timeout
  std::uint64_t read_timeouts = 0;     // no scan within the read deadline (or first_scan_timeout)
  std::uint64_t sfa_replies = 0;       // sFA error telegrams received
  std::uint64_t handshake_failures =
      0;                          // an essential start-up command refused (sFA or error status)
  std::uint64_t disconnects = 0;  // connection closed by the device or a socket error
  std::uint64_t bad_frames = 0;   // frames or telegrams the decoder rejected
  std::uint64_t busy_polls = 0;   // SCdevicestate answered busy while waiting for ready
  std::uint64_t config_mismatches = 0;  // LMDscandatacfg read back differs from what was written
  std::uint64_t scans = 0;              // scans delivered to the callback
  std::uint64_t bytes = 0;              // bytes received
};

// What the device said about itself during the start-up dialogue (empty where it answered sFA).
struct SickDeviceInfo {
  std::string ident_name;     // DeviceIdent, e.g. "LMS511-10100"
  std::string ident_version;  // DeviceIdent version string
  std::string firmware_version;
  std::string serial_number;
  // The scan configuration read back (nullopt where the device refused the read).
  std::optional<cola::ScanDataConfig> scan_data_config;  // LMDscandatacfg
  std::optional<cola::OutputRange> output_range;         // LMPoutputRange
  int device_state = -1;  // last SCdevicestate: 0 busy, 1 ready, 2 error; -1 not read
};

enum class SickClientState {
  kIdle,        // before Start()
  kConnecting,  // resolving / connecting
  kHandshake,   // start-up commands
  kStreaming,   // sEN LMDscandata accepted; scans flow
  kBackoff,     // waiting before the next connection attempt
  kStopped,
};
const char* SickClientStateName(SickClientState s);

// UTC now in ns; the default reads std::chrono::system_clock.
using UtcClock = std::function<common::UtcNs()>;
common::UtcNs SystemUtcNow();

class SickClient {
 public:
  // `scan` is valid only during the call; `receive_time_ns` is the clock reading of the read that
  // completed the telegram. The callback may call Stop().
  using ScanCallback =
      std::function<void(const cola::ScanTelegram& scan, common::UtcNs receive_time_ns)>;

  // `options` must pass Validate (checked: aborts otherwise).
  SickClient(boost::asio::io_context& io, const SickClientOptions& options, ScanCallback on_scan,
             UtcClock clock = SystemUtcNow);
  // Destroy after Stop() once io_context::run() has returned (or with the io_context): pending
  // handlers refer to this object.
  ~SickClient();
  SickClient(const SickClient&) = delete;
  SickClient& operator=(const SickClient&) = delete;

  // Starts connecting. Call once.
  void Start();
  // Cancels every operation and timer and closes the socket; the io_context then runs out of work
  // from this client. Idempotent; the client cannot be restarted.
  void Stop();

  SickClientState state() const { return state_; }
  const SickClientCounters& counters() const { return counters_; }
  cola::StreamCounters decoder_counters() const { return decoder_.counters(); }
  const SickDeviceInfo& device_info() const { return device_info_; }
  // Reason of the last failure ("" if none yet), for status displays.
  const std::string& last_failure() const { return last_failure_; }

 private:
  enum class Step : std::uint8_t {
    kSetAccessMode,
    kDeviceIdent,
    kFirmwareVersion,
    kSerialNumber,
    kScanDataConfig,
    kReadScanDataConfig,
    kReadOutputRange,
    kStartMeasurement,
    kRun,
    kWaitReady,
    kEnableScanData,
  };
  enum class DeadlineKind : std::uint8_t { kNone, kConnect, kReply, kFirstScan, kScan };

  class Listener : public cola::TelegramListener {
   public:
    explicit Listener(SickClient* client) : client_(client) {}
    void OnScan(const cola::ScanTelegram& scan, common::UtcNs receive_time_ns) override;
    void OnTelegram(const cola::TelegramHeader& header, std::span<const std::uint8_t> payload,
                    common::UtcNs receive_time_ns) override;
    void OnError(const char* reason, common::UtcNs receive_time_ns) override;

   private:
    SickClient* client_;
  };

  void Connect();
  void OnConnected();
  void StartRead();
  void SendStep();
  void NextStep();
  void HandleScan(const cola::ScanTelegram& scan, common::UtcNs receive_time_ns);
  void HandleTelegram(const cola::TelegramHeader& header);
  void HandleStepReply(const cola::TelegramHeader& header);
  void HandleBadFrame(const char* reason);
  // Ends the session: logs `reason` once, closes the socket and schedules a reconnect after the
  // backoff.
  void Fail(const std::string& reason);
  void CloseSocket();

  void SetDeadline(std::chrono::steady_clock::duration timeout, DeadlineKind kind);
  void ArmDeadlineTimer();
  void OnDeadlineTimer(std::uint64_t wait_id);
  std::chrono::steady_clock::duration ScanReadDeadline(const cola::ScanTelegram& scan) const;

  const char* StepCommandName(Step s) const;
  bool StepEssential(Step s) const;
  cola::CommandType StepReplyType(Step s) const;

  SickClientOptions options_;
  ScanCallback on_scan_;
  UtcClock clock_;
  std::string endpoint_text_;  // "host:port" for log lines

  boost::asio::ip::tcp::resolver resolver_;
  boost::asio::ip::tcp::socket socket_;
  boost::asio::steady_timer deadline_timer_;
  boost::asio::steady_timer backoff_timer_;
  boost::asio::steady_timer poll_timer_;  // the next SCdevicestate poll

  cola::StreamDecoder decoder_;
  Listener listener_{this};
  std::vector<std::uint8_t> read_buffer_;       // allocated once
  std::array<std::uint8_t, 256> tx_payload_{};  // one start-up command at a time
  std::array<std::uint8_t, 256 + 9> tx_frame_{};

  std::vector<Step> steps_;  // this session's start-up dialogue (fixed after construction)
  std::size_t step_index_ = 0;

  SickClientState state_ = SickClientState::kIdle;
  std::uint64_t session_ =
      0;  // bumped whenever a session ends: handlers of older sessions are ignored
  bool session_has_scan_ = false;
  bool bad_frame_logged_ = false;
  std::chrono::steady_clock::time_point ready_deadline_{};  // kWaitReady gives up after this

  std::chrono::steady_clock::time_point deadline_{};
  DeadlineKind deadline_kind_ = DeadlineKind::kNone;
  std::chrono::steady_clock::duration scan_deadline_{};
  bool deadline_waiting_ = false;
  std::uint64_t deadline_wait_id_ = 0;

  Backoff backoff_;
  SickClientCounters counters_;
  SickDeviceInfo device_info_;
  std::string last_failure_;
};

}  // namespace lrfnet::io
