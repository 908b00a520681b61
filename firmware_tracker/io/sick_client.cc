#include "firmware_tracker/io/sick_client.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <boost/asio/connect.hpp>
#include <boost/asio/write.hpp>
#include <cmath>
#include <cstdlib>
#include <utility>

#include "firmware_tracker/cola/framer.h"

namespace lrfnet::io {

namespace asio = boost::asio;
using asio::ip::tcp;
using SteadyClock = std::chrono::steady_clock;

std::optional<std::string> Validate(const BackoffOptions& options) {
  if (options.initial.count() <= 0) return "backoff initial delay must be > 0 ms";
  if (options.max < options.initial) return "backoff max delay must be >= the initial delay";
  if (!(options.multiplier >= 1.0) || !std::isfinite(options.multiplier)) {
    return "backoff multiplier must be >= 1";
  }
  if (!(options.jitter >= 0.0 && options.jitter < 1.0)) return "backoff jitter must be in [0, 1)";
  return std::nullopt;
}

Backoff::Backoff(const BackoffOptions& options, std::uint64_t seed)
    : options_(options), rng_(seed) {}

std::chrono::milliseconds Backoff::Next() {
  const double initial_ms = static_cast<double>(options_.initial.count());
  const double max_ms = static_cast<double>(options_.max.count());
  const double nominal_ms = std::min(max_ms, initial_ms * std::pow(options_.multiplier, attempt_));
  // Jitter spreads the reconnects of many gateways that lost the same switch at once.
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  const double jittered_ms =
      std::clamp(nominal_ms * (1.0 + options_.jitter * unit(rng_)), 1.0, max_ms);
  if (nominal_ms < max_ms) ++attempt_;
  return std::chrono::milliseconds(std::llround(jittered_ms));
}

std::optional<std::string> Validate(const SickClientOptions& options) {
  if (options.host.empty()) return "sensor host is empty";
  if (options.port == 0) return "sensor port must be 1..65535";
  if (options.connect_timeout.count() <= 0) return "connect timeout must be > 0 ms";
  if (options.reply_timeout.count() <= 0) return "reply timeout must be > 0 ms";
  if (options.first_scan_timeout.count() <= 0) return "first-scan timeout must be > 0 ms";
  if (!(options.read_deadline_scan_periods >= 1.0) ||
      !std::isfinite(options.read_deadline_scan_periods)) {
    return "read deadline must be >= 1 scan period";
  }
  if (options.min_read_deadline.count() <= 0) return "minimum read deadline must be > 0 ms";
  if (options.ready_poll_interval.count() <= 0) return "ready poll interval must be > 0 ms";
  if (options.ready_timeout.count() <= 0) return "ready timeout must be > 0 ms";
  if (auto e = Validate(options.backoff)) return e;
  if (options.read_buffer_bytes < 64 || options.read_buffer_bytes > (16u << 20)) {
    return "read buffer must be 64 B .. 16 MiB";
  }
  if (auto e = cola::Validate(options.framer)) return e;
  return std::nullopt;
}

const char* SickClientStateName(SickClientState s) {
  switch (s) {
    case SickClientState::kIdle:
      return "idle";
    case SickClientState::kConnecting:
      return "connecting";
    case SickClientState::kHandshake:
      return "handshake";
    case SickClientState::kStreaming:
      return "streaming";
    case SickClientState::kBackoff:
      return "backoff";
    case SickClientState::kStopped:
      return "stopped";
  }
  return "?";
}

common::UtcNs SystemUtcNow() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

// ---- listener: the decoder's callbacks, forwarded to the session state machine

void SickClient::Listener::OnScan(const cola::ScanTelegram& scan, common::UtcNs receive_time_ns) {
  client_->HandleScan(scan, receive_time_ns);
}
void SickClient::Listener::OnTelegram(const cola::TelegramHeader& header,
                                      std::span<const std::uint8_t> /*payload*/,
                                      common::UtcNs /*receive_time_ns*/) {
  client_->HandleTelegram(header);
}
void SickClient::Listener::OnError(const char* reason, common::UtcNs /*receive_time_ns*/) {
  client_->HandleBadFrame(reason);
}

// ---- construction

SickClient::SickClient(asio::io_context& io, const SickClientOptions& options, ScanCallback on_scan,
                       UtcClock clock)
    : options_(options),
      on_scan_(std::move(on_scan)),
      clock_(std::move(clock)),
      endpoint_text_(options.host + ":" + std::to_string(options.port)),
      resolver_(io),
      socket_(io),
      deadline_timer_(io),
      backoff_timer_(io),
      poll_timer_(io),
      decoder_(options.framer),
      read_buffer_(options.read_buffer_bytes),
      backoff_(options.backoff, options.backoff_seed) {
  if (auto error = Validate(options_)) {
    spdlog::critical("SickClient: invalid options: {}", *error);
    std::abort();
  }
  steps_ = {Step::kSetAccessMode, Step::kDeviceIdent, Step::kFirmwareVersion, Step::kSerialNumber};
  if (options_.configure_scan_data) steps_.push_back(Step::kScanDataConfig);
  steps_.insert(steps_.end(), {Step::kReadScanDataConfig, Step::kReadOutputRange,
                               Step::kStartMeasurement, Step::kRun});
  if (options_.wait_for_ready) steps_.push_back(Step::kWaitReady);
  steps_.push_back(Step::kEnableScanData);
}

SickClient::~SickClient() { Stop(); }

const char* SickClient::StepCommandName(Step s) const {
  switch (s) {
    case Step::kSetAccessMode:
      return "SetAccessMode";
    case Step::kDeviceIdent:
      return "DeviceIdent";
    case Step::kFirmwareVersion:
      return "FirmwareVersion";
    case Step::kSerialNumber:
      return "SerialNumber";
    case Step::kScanDataConfig:
    case Step::kReadScanDataConfig:
      return "LMDscandatacfg";
    case Step::kReadOutputRange:
      return "LMPoutputRange";
    case Step::kStartMeasurement:
      return "LMCstartmeas";
    case Step::kRun:
      return "Run";
    case Step::kWaitReady:
      return "SCdevicestate";
    case Step::kEnableScanData:
      return "LMDscandata";
  }
  return "?";
}

// Without LMCstartmeas the laser does not measure and without sEN LMDscandata nothing is sent: a
// session that lost either can never deliver a scan. Everything else only adds information or
// convenience.
bool SickClient::StepEssential(Step s) const {
  return s == Step::kStartMeasurement || s == Step::kEnableScanData;
}

cola::CommandType SickClient::StepReplyType(Step s) const {
  switch (s) {
    case Step::kSetAccessMode:
    case Step::kStartMeasurement:
    case Step::kRun:
      return cola::CommandType::kMethodAnswer;
    case Step::kDeviceIdent:
    case Step::kFirmwareVersion:
    case Step::kSerialNumber:
    case Step::kReadScanDataConfig:
    case Step::kReadOutputRange:
    case Step::kWaitReady:
      return cola::CommandType::kReadAnswer;
    case Step::kScanDataConfig:
      return cola::CommandType::kWriteAnswer;
    case Step::kEnableScanData:
      return cola::CommandType::kEventAnswer;
  }
  return cola::CommandType::kUnknown;
}

// ---- lifecycle

void SickClient::Start() {
  if (state_ != SickClientState::kIdle) return;
  spdlog::info("sick_client {}: connecting", endpoint_text_);
  Connect();
}

void SickClient::Stop() {
  if (state_ == SickClientState::kStopped) return;
  const bool was_running = state_ != SickClientState::kIdle;
  CloseSocket();
  state_ = SickClientState::kStopped;
  boost::system::error_code ignored;
  deadline_timer_.cancel(ignored);
  backoff_timer_.cancel(ignored);
  poll_timer_.cancel(ignored);
  if (was_running) spdlog::info("sick_client {}: stopped", endpoint_text_);
}

void SickClient::CloseSocket() {
  ++session_;
  deadline_kind_ = DeadlineKind::kNone;
  resolver_.cancel();
  boost::system::error_code ignored;
  if (socket_.is_open()) {
    socket_.shutdown(tcp::socket::shutdown_both, ignored);
    socket_.close(ignored);
  }
}

void SickClient::Fail(const std::string& reason) {
  if (state_ == SickClientState::kStopped || state_ == SickClientState::kBackoff) return;
  last_failure_ = reason;
  CloseSocket();
  const std::chrono::milliseconds delay = backoff_.Next();
  spdlog::warn("sick_client {}: {}; reconnecting in {} ms", endpoint_text_, reason, delay.count());
  state_ = SickClientState::kBackoff;
  backoff_timer_.expires_after(delay);
  const std::uint64_t session = session_;
  backoff_timer_.async_wait([this, session](const boost::system::error_code& ec) {
    if (ec || session != session_ || state_ != SickClientState::kBackoff) return;
    ++counters_.reconnects;
    Connect();
  });
}

void SickClient::Connect() {
  state_ = SickClientState::kConnecting;
  session_has_scan_ = false;
  bad_frame_logged_ = false;
  step_index_ = 0;
  ready_deadline_ = {};
  // A new connection is a new byte stream: a partial telegram of the previous one must not be glued
  // to it.
  decoder_.Reset();
  SetDeadline(options_.connect_timeout, DeadlineKind::kConnect);
  const std::uint64_t session = session_;
  auto on_connect = [this, session](const boost::system::error_code& cec) {
    if (session != session_) return;
    if (cec) {
      ++counters_.connect_failures;
      Fail("connect failed: " + cec.message());
      return;
    }
    OnConnected();
  };
  // Scanners are addressed by IP almost always: connect directly, without the resolver (whose
  // private thread is needless work on the gateway and does not start under qemu-user).
  boost::system::error_code parse_error;
  const asio::ip::address address = asio::ip::make_address(options_.host, parse_error);
  if (!parse_error) {
    socket_.async_connect(tcp::endpoint(address, options_.port), on_connect);
    return;
  }
  resolver_.async_resolve(
      options_.host, std::to_string(options_.port), tcp::resolver::numeric_service,
      [this, session, on_connect](const boost::system::error_code& ec,
                                  const tcp::resolver::results_type& results) {
        if (session != session_) return;
        if (ec) {
          ++counters_.connect_failures;
          Fail("cannot resolve " + options_.host + ": " + ec.message());
          return;
        }
        asio::async_connect(socket_, results,
                            [on_connect](const boost::system::error_code& cec,
                                         const tcp::endpoint&) { on_connect(cec); });
      });
}

void SickClient::OnConnected() {
  ++counters_.connects;
  boost::system::error_code ignored;
  // Start-up commands are tiny request/response pairs: do not let Nagle hold them back.
  socket_.set_option(tcp::no_delay(true), ignored);
  state_ = SickClientState::kHandshake;
  spdlog::info("sick_client {}: connected", endpoint_text_);
  StartRead();
  SendStep();
}

// ---- start-up dialogue

void SickClient::SendStep() {
  const Step step = steps_[step_index_];
  const std::span<std::uint8_t> out(tx_payload_);
  std::size_t n = 0;
  switch (step) {
    case Step::kSetAccessMode:
      n = cola::EncodeSetAccessMode(options_.access_level, options_.password_hash, out);
      break;
    case Step::kDeviceIdent:
    case Step::kFirmwareVersion:
    case Step::kSerialNumber:
    case Step::kReadScanDataConfig:
    case Step::kReadOutputRange:
      n = cola::EncodeReadVariable(StepCommandName(step), out);
      break;
    case Step::kWaitReady:
      if (ready_deadline_ == SteadyClock::time_point{}) {
        ready_deadline_ = SteadyClock::now() + options_.ready_timeout;
      }
      n = cola::EncodeReadVariable(StepCommandName(step), out);
      break;
    case Step::kScanDataConfig:
      n = cola::EncodeScanDataConfig(options_.scan_data_config, out);
      break;
    case Step::kStartMeasurement:
      n = cola::EncodeStartMeasurement(out);
      break;
    case Step::kRun:
      n = cola::EncodeRun(out);
      break;
    case Step::kEnableScanData:
      n = cola::EncodeScanDataEvent(true, out);
      break;
  }
  const std::size_t frame_bytes =
      n == 0 ? 0 : cola::EncodeFrame({tx_payload_.data(), n}, tx_frame_);
  if (frame_bytes == 0) {
    // Fixed command sizes: cannot happen unless the encoders change; fail loudly rather than hang.
    Fail(std::string("cannot encode ") + StepCommandName(step));
    return;
  }
  SetDeadline(options_.reply_timeout, DeadlineKind::kReply);
  const std::uint64_t session = session_;
  asio::async_write(socket_, asio::buffer(tx_frame_.data(), frame_bytes),
                    [this, session](const boost::system::error_code& ec, std::size_t) {
                      if (session != session_ || !ec) return;
                      ++counters_.disconnects;
                      Fail("write failed: " + ec.message());
                    });
}

void SickClient::NextStep() {
  ++step_index_;
  if (step_index_ < steps_.size()) {
    SendStep();
    return;
  }
  state_ = SickClientState::kStreaming;
  SetDeadline(options_.first_scan_timeout, DeadlineKind::kFirstScan);
  spdlog::info("sick_client {}: scan data enabled (device '{}' '{}', firmware '{}', serial '{}')",
               endpoint_text_, device_info_.ident_name, device_info_.ident_version,
               device_info_.firmware_version, device_info_.serial_number);
}

void SickClient::HandleTelegram(const cola::TelegramHeader& header) {
  if (state_ != SickClientState::kHandshake && state_ != SickClientState::kStreaming) return;
  if (header.type == cola::CommandType::kError) ++counters_.sfa_replies;
  if (state_ != SickClientState::kHandshake) {
    if (header.type == cola::CommandType::kError) {
      spdlog::warn("sick_client {}: unsolicited sFA {} ({}) while streaming", endpoint_text_,
                   header.error_code, cola::SopasErrorName(header.error_code));
    }
    return;  // events such as sSN LIDoutputstate / LFErec are not ours to interpret
  }
  const Step step = steps_[step_index_];
  if (header.type == cola::CommandType::kError) {
    // sFA carries no name: it answers the one command in flight.
    if (StepEssential(step)) {
      ++counters_.handshake_failures;
      Fail(fmt::format("{} refused with sFA {} ({})", StepCommandName(step), header.error_code,
                       cola::SopasErrorName(header.error_code)));
      return;
    }
    spdlog::warn("sick_client {}: {} answered sFA {} ({}); continuing", endpoint_text_,
                 StepCommandName(step), header.error_code, cola::SopasErrorName(header.error_code));
    NextStep();
    return;
  }
  if (header.type == StepReplyType(step) && header.name == StepCommandName(step)) {
    HandleStepReply(header);
  }
}

void SickClient::HandleStepReply(const cola::TelegramHeader& header) {
  const Step step = steps_[step_index_];
  std::uint8_t status = 0;
  const bool has_status = cola::DecodeFirstByte(header.args, &status);
  switch (step) {
    case Step::kSetAccessMode:
      // sAN SetAccessMode: 1 = level granted. Some devices stream without it, so carry on.
      if (!has_status || status != 1) {
        spdlog::warn("sick_client {}: SetAccessMode (level {}) refused; continuing", endpoint_text_,
                     static_cast<int>(options_.access_level));
      }
      break;
    case Step::kDeviceIdent: {
      cola::DeviceIdent ident;
      if (cola::DecodeDeviceIdent(header.args, &ident)) {
        device_info_.ident_name = std::string(ident.name);
        device_info_.ident_version = std::string(ident.version);
      } else {
        spdlog::warn("sick_client {}: undecodable DeviceIdent reply; continuing", endpoint_text_);
      }
      break;
    }
    case Step::kFirmwareVersion:
    case Step::kSerialNumber: {
      cola::FlexString text;
      if (cola::DecodeFlexString(header.args, &text)) {
        (step == Step::kFirmwareVersion ? device_info_.firmware_version
                                        : device_info_.serial_number) = std::string(text.text);
      } else {
        spdlog::warn("sick_client {}: undecodable {} reply; continuing", endpoint_text_,
                     StepCommandName(step));
      }
      break;
    }
    case Step::kScanDataConfig:
      break;
    case Step::kReadScanDataConfig: {
      cola::ScanDataConfig config;
      if (!cola::DecodeScanDataConfig(header.args, &config)) {
        spdlog::warn("sick_client {}: undecodable LMDscandatacfg reply; continuing",
                     endpoint_text_);
        break;
      }
      device_info_.scan_data_config = config;
      if (options_.configure_scan_data && !(config == options_.scan_data_config)) {
        ++counters_.config_mismatches;
        spdlog::warn(
            "sick_client {}: the device kept another scan data configuration than the "
            "one written (channels {}, remission {}, resolution {}, time {}, every {}. scan)",
            endpoint_text_, config.output_channel, config.remission, config.resolution, config.time,
            config.output_interval);
      }
      break;
    }
    case Step::kReadOutputRange: {
      cola::OutputRange range;
      if (cola::DecodeOutputRange(header.args, &range)) {
        device_info_.output_range = range;
      } else {
        spdlog::warn("sick_client {}: undecodable LMPoutputRange reply; continuing",
                     endpoint_text_);
      }
      break;
    }
    case Step::kWaitReady:
      if (!has_status) {
        spdlog::warn("sick_client {}: SCdevicestate without a value; continuing", endpoint_text_);
        break;
      }
      device_info_.device_state = status;
      if (status == 2) {
        ++counters_.handshake_failures;
        Fail("the device reports its error state (SCdevicestate 2)");
        return;
      }
      if (status != 1) {
        ++counters_.busy_polls;
        if (SteadyClock::now() + options_.ready_poll_interval > ready_deadline_) {
          ++counters_.handshake_failures;
          Fail(fmt::format("the device is still busy {} ms after Run (SCdevicestate {})",
                           options_.ready_timeout.count(), status));
          return;
        }
        // Poll again; the reply deadline does not run meanwhile.
        deadline_kind_ = DeadlineKind::kNone;
        poll_timer_.expires_after(options_.ready_poll_interval);
        const std::uint64_t session = session_;
        poll_timer_.async_wait([this, session](const boost::system::error_code& ec) {
          if (ec || session != session_ || state_ != SickClientState::kHandshake) return;
          SendStep();
        });
        return;
      }
      break;
    case Step::kStartMeasurement:
      // sAN LMCstartmeas: 0 = no error.
      if (!has_status || status != 0) {
        ++counters_.handshake_failures;
        Fail(fmt::format("LMCstartmeas answered error status {}", has_status ? status : -1));
        return;
      }
      break;
    case Step::kRun:
      if (!has_status || status != 1) {
        spdlog::warn("sick_client {}: Run answered status {}; continuing", endpoint_text_,
                     has_status ? status : -1);
      }
      break;
    case Step::kEnableScanData:
      // sEA LMDscandata: 1 = event enabled.
      if (!has_status || status != 1) {
        ++counters_.handshake_failures;
        Fail(fmt::format("sEN LMDscandata 1 answered state {}", has_status ? status : -1));
        return;
      }
      break;
  }
  NextStep();
}

// ---- streaming

void SickClient::StartRead() {
  const std::uint64_t session = session_;
  socket_.async_read_some(asio::buffer(read_buffer_),
                          [this, session](const boost::system::error_code& ec, std::size_t n) {
                            if (session != session_) return;
                            if (ec) {
                              ++counters_.disconnects;
                              Fail(ec == asio::error::eof
                                       ? std::string("device closed the connection")
                                       : "read failed: " + ec.message());
                              return;
                            }
                            counters_.bytes += n;
                            decoder_.Feed({read_buffer_.data(), n}, clock_(), listener_);
                            // A telegram in this chunk may have ended the session (essential sFA)
                            // or the callback stopped us.
                            if (session != session_) return;
                            StartRead();
                          });
}

std::chrono::steady_clock::duration SickClient::ScanReadDeadline(
    const cola::ScanTelegram& scan) const {
  if (scan.scan_frequency_raw == 0) return options_.first_scan_timeout;
  // Scan frequency field: 1/100 Hz, so one period is 100 / raw seconds.
  const double period_s = 100.0 / scan.scan_frequency_raw;
  const auto deadline = std::chrono::duration_cast<SteadyClock::duration>(
      std::chrono::duration<double>(period_s * options_.read_deadline_scan_periods));
  return std::max<SteadyClock::duration>(deadline, options_.min_read_deadline);
}

void SickClient::HandleScan(const cola::ScanTelegram& scan, common::UtcNs receive_time_ns) {
  if (state_ != SickClientState::kHandshake && state_ != SickClientState::kStreaming) return;
  ++counters_.scans;
  if (!session_has_scan_) {
    session_has_scan_ = true;
    backoff_.Reset();  // the session proved healthy: the next failure starts from the initial delay
    spdlog::info("sick_client {}: first scan (telegram counter {}, scan counter {}, {} Hz)",
                 endpoint_text_, scan.telegram_counter, scan.scan_counter,
                 scan.scan_frequency_hz());
  }
  // Scans that arrive during the start-up dialogue (a device still streaming to an earlier session)
  // are delivered but do not replace the reply deadline.
  if (state_ == SickClientState::kStreaming) {
    scan_deadline_ = ScanReadDeadline(scan);
    SetDeadline(scan_deadline_, DeadlineKind::kScan);
  }
  if (on_scan_) on_scan_(scan, receive_time_ns);
}

void SickClient::HandleBadFrame(const char* reason) {
  ++counters_.bad_frames;
  // One warning per session; a device that keeps sending garbage must not flood the log.
  if (!bad_frame_logged_) {
    bad_frame_logged_ = true;
    spdlog::warn("sick_client {}: bad frame: {} (further ones this session counted only)",
                 endpoint_text_, reason);
  } else {
    spdlog::debug("sick_client {}: bad frame: {}", endpoint_text_, reason);
  }
}

// ---- deadline actor
//
// One timer serves the connect, reply and read deadlines. Moving the deadline later only stores a
// time point; the timer re-arms itself when it fires early. So a scan costs a clock read, not a
// timer operation.

void SickClient::SetDeadline(SteadyClock::duration timeout, DeadlineKind kind) {
  deadline_ = SteadyClock::now() + timeout;
  deadline_kind_ = kind;
  if (!deadline_waiting_ || deadline_timer_.expiry() > deadline_) ArmDeadlineTimer();
}

void SickClient::ArmDeadlineTimer() {
  deadline_timer_.expires_at(deadline_);  // cancels a pending wait; its handler sees a stale id
  const std::uint64_t wait_id = ++deadline_wait_id_;
  deadline_waiting_ = true;
  deadline_timer_.async_wait(
      [this, wait_id](const boost::system::error_code&) { OnDeadlineTimer(wait_id); });
}

void SickClient::OnDeadlineTimer(std::uint64_t wait_id) {
  if (wait_id != deadline_wait_id_) return;
  deadline_waiting_ = false;
  if (state_ == SickClientState::kStopped || deadline_kind_ == DeadlineKind::kNone) return;
  if (SteadyClock::now() < deadline_) {
    ArmDeadlineTimer();
    return;
  }
  const DeadlineKind kind = deadline_kind_;
  deadline_kind_ = DeadlineKind::kNone;
  switch (kind) {
    case DeadlineKind::kNone:
      break;
    case DeadlineKind::kConnect:
      ++counters_.connect_failures;
      Fail(fmt::format("connect timed out after {} ms", options_.connect_timeout.count()));
      break;
    case DeadlineKind::kReply:
      ++counters_.reply_timeouts;
      Fail(fmt::format("no reply to {} within {} ms", StepCommandName(steps_[step_index_]),
                       options_.reply_timeout.count()));
      break;
    case DeadlineKind::kFirstScan:
      ++counters_.read_timeouts;
      Fail(fmt::format("no scan within {} ms after enabling scan data",
                       options_.first_scan_timeout.count()));
      break;
    case DeadlineKind::kScan:
      ++counters_.read_timeouts;
      Fail(fmt::format(
          "no scan for {} ms (read deadline)",
          std::chrono::duration_cast<std::chrono::milliseconds>(scan_deadline_).count()));
      break;
  }
}

}  // namespace lrfnet::io
