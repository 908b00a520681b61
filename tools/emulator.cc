#include "tools/emulator.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <boost/asio/write.hpp>
#include <cmath>
#include <utility>

#include "common/byte_order.h"
#include "firmware_tracker/cola/commands.h"

namespace lrfnet::tools {

namespace asio = boost::asio;
using asio::ip::tcp;
using SteadyClock = std::chrono::steady_clock;

namespace {

// SOPAS error codes the injected sFA fault answers with (by request type, as a device refusing
// it would).
constexpr std::uint16_t kSopasMethodAccessDenied = 1;
constexpr std::uint16_t kSopasVariableUnknownIndex = 3;
constexpr std::uint16_t kSopasVariableWriteAccessDenied = 10;

// A subscribed device that is not ready yet is looked at again this often.
constexpr std::chrono::milliseconds kStatePollPeriod{20};

// After an injected restart the device counts from here (as a freshly powered unit: ticks a few
// seconds in).
constexpr std::uint32_t kRestartTickUs = 2'000'000;

constexpr std::size_t kGarbageBytes = 48;
constexpr std::size_t kFakeFramePayloadBytes = 16;

std::vector<std::uint8_t> Frame(std::span<const std::uint8_t> payload) {
  return cola::EncodeSopasFrame(cola::Dialect::kColaB, payload);
}

SopasDeviceOptions DeviceOptionsFor(const EmulatorOptions& options, const ScanSource& source) {
  SopasDeviceOptions o;
  o.identity = source.identity();
  // A DeviceIdent name ("LMS511-10100"), or the family a capture without one was recognised as
  // by its scan geometry ("LMS5xx").
  o.family = options.family.value_or(
      FamilyFromDeviceName(o.identity.name)
          .value_or(ParseDeviceFamily(o.identity.name).value_or(DeviceFamily::kLms5xx)));
  o.ready_after_run_s = options.ready_after_run_s;
  return o;
}

}  // namespace

std::optional<std::string> Validate(const EmulatorOptions& options) {
  boost::system::error_code ec;
  asio::ip::make_address(options.bind_address, ec);
  if (ec) return "bad bind address '" + options.bind_address + "'";
  if (!(options.speed > 0.0) || !std::isfinite(options.speed) || options.speed > 1e6) {
    return "speed must be > 0";
  }
  if (!(options.ready_after_run_s < 3600.0) || std::isnan(options.ready_after_run_s)) {
    return "ready delay after Run must be below 3600 s";
  }
  return std::nullopt;
}

Emulator::Emulator(asio::io_context& io, const EmulatorOptions& options,
                   std::unique_ptr<ScanSource> source)
    : options_(options),
      source_(std::move(source)),
      acceptor_(io),
      socket_(io),
      scan_timer_(io),
      state_timer_(io),
      epoch_(SteadyClock::now()),
      device_(DeviceOptionsFor(options, *source_)),
      scan_(std::make_unique<cola::ScanTelegram>()),
      rng_(options.seed) {}

Emulator::~Emulator() { Stop(); }

bool Emulator::Start(std::string* error) {
  if (auto e = Validate(options_)) {
    *error = *e;
    return false;
  }
  boost::system::error_code ec;
  const tcp::endpoint endpoint(asio::ip::make_address(options_.bind_address, ec), options_.port);
  const auto fail = [&](const char* what) {
    *error = std::string("cannot ") + what + " " + options_.bind_address + ":" +
             std::to_string(options_.port) + ": " + ec.message();
    boost::system::error_code ignored;
    acceptor_.close(ignored);
    return false;
  };
  if (acceptor_.open(endpoint.protocol(), ec)) return fail("open");
  acceptor_.set_option(tcp::acceptor::reuse_address(true), ec);
  if (acceptor_.bind(endpoint, ec)) return fail("bind");
  if (acceptor_.listen(asio::socket_base::max_listen_connections, ec)) return fail("listen on");
  port_ = acceptor_.local_endpoint(ec).port();
  spdlog::info("emulator: device '{}' ({}, CoLa-A and CoLa-B) listening on {}:{}",
               source_->identity().name, DeviceFamilyName(device_.family()), options_.bind_address,
               port_);
  Accept();
  return true;
}

void Emulator::Stop() {
  if (stopped_) return;
  stopped_ = true;
  boost::system::error_code ignored;
  acceptor_.close(ignored);
  if (socket_.is_open()) CloseConnection("emulator stopped");
  scan_timer_.cancel(ignored);
  state_timer_.cancel(ignored);
}

common::DurationNs Emulator::Now() const {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(SteadyClock::now() - epoch_).count();
}

// ---- connections

void Emulator::Accept() {
  acceptor_.async_accept([this](const boost::system::error_code& ec, tcp::socket socket) {
    if (stopped_) return;
    if (ec) {
      if (ec == asio::error::operation_aborted) return;
      spdlog::warn("emulator: accept failed: {}", ec.message());
    } else {
      OnAccepted(std::move(socket));
    }
    Accept();
  });
}

void Emulator::OnAccepted(tcp::socket socket) {
  if (socket_.is_open()) CloseConnection("replaced by a new client");
  socket_ = std::move(socket);
  boost::system::error_code ec;
  socket_.set_option(tcp::no_delay(true), ec);
  const auto peer = socket_.remote_endpoint(ec);
  ++counters_.connections;
  sent_.emplace_back();
  framer_.Reset();
  out_queue_.clear();
  writing_ = false;
  streaming_ = false;
  stalled_ = false;
  scan_due_ = false;
  scans_on_connection_ = 0;
  spdlog::info("emulator: client {}:{} connected (connection {})", peer.address().to_string(),
               peer.port(), counters_.connections);
  StartRead();
}

void Emulator::CloseConnection(const char* why) {
  ++connection_;
  StopStreaming();
  boost::system::error_code ignored_ec;
  state_timer_.cancel(ignored_ec);
  device_.OnDisconnect();
  out_queue_.clear();
  writing_ = false;
  boost::system::error_code ignored;
  if (socket_.is_open()) {
    socket_.shutdown(tcp::socket::shutdown_both, ignored);
    socket_.close(ignored);
    spdlog::info("emulator: connection closed: {}", why);
  }
}

void Emulator::StartRead() {
  const std::uint64_t connection = connection_;
  socket_.async_read_some(asio::buffer(read_buffer_), [this, connection](
                                                          const boost::system::error_code& ec,
                                                          std::size_t n) {
    if (stopped_ || connection != connection_) return;
    if (ec) {
      CloseConnection(ec == asio::error::eof ? "client closed the connection" : "read error");
      return;
    }
    if (stalled_) {
      StartRead();  // a stalled device reads nothing it answers, but must notice the client leaving
      return;
    }
    framer_.FeedAll(
        {read_buffer_.data(), n},
        [this, connection](cola::Dialect dialect, std::span<const std::uint8_t> payload) {
          if (connection == connection_) HandleCommand(dialect, payload);
        },
        [this](const char* reason) {
          ++counters_.bad_frames;
          spdlog::warn("emulator: bad frame from the client: {}", reason);
        });
    if (connection == connection_) StartRead();
  });
}

// ---- commands

void Emulator::HandleCommand(cola::Dialect dialect, std::span<const std::uint8_t> payload) {
  if (stalled_) return;
  ++counters_.commands;
  cola::TelegramHeader header;
  const bool parsed =
      cola::ParseSopasTelegram(dialect, payload, &header) == cola::HeaderStatus::kOk;
  if (parsed) {
    spdlog::debug("emulator: {} {} {}", cola::DialectName(dialect),
                  cola::CommandTypeName(header.type), header.name);
  }
  const EmulatorFaults& faults = options_.faults;
  if (parsed && !faults.sfa_command.empty() && header.name == faults.sfa_command &&
      (faults.sfa_times == 0 || sfa_fault_count_ < faults.sfa_times)) {
    ++sfa_fault_count_;
    spdlog::info("emulator: fault: answering {} {} with sFA", cola::CommandTypeName(header.type),
                 header.name);
    const std::uint16_t code = header.type == cola::CommandType::kRead ? kSopasVariableUnknownIndex
                               : header.type == cola::CommandType::kWrite
                                   ? kSopasVariableWriteAccessDenied
                                   : kSopasMethodAccessDenied;
    ++counters_.sfa_sent;
    SendOutputs({SopasOutput{dialect, cola::EncodeSopasError(dialect, code)}}, false);
    return;
  }
  const std::uint64_t sfa_before = device_.counters().sfa;
  const std::uint64_t reboots_before = device_.counters().reboots;
  std::vector<SopasOutput> outputs;
  device_.HandleRequest(dialect, payload, Now(), &outputs);
  counters_.sfa_sent += device_.counters().sfa - sfa_before;
  if (device_.counters().reboots != reboots_before) {
    // sMN mSCreboot: the reply goes out, then the device is gone until it has booted.
    ++counters_.restarts;
    rebase_ = Rebase::kRestart;
    SendOutputs(outputs, true);
    return;
  }
  SendOutputs(outputs, false);
  UpdateStreaming();
}

void Emulator::SendOutputs(const std::vector<SopasOutput>& outputs, bool close_after) {
  for (std::size_t i = 0; i < outputs.size(); ++i) {
    std::vector<std::uint8_t> frame =
        cola::EncodeSopasFrame(outputs[i].dialect, outputs[i].payload);
    if (frame.empty()) continue;
    Enqueue(OutItem{std::move(frame), -1, close_after && i + 1 == outputs.size()});
  }
}

void Emulator::UpdateStreaming() {
  if (!socket_.is_open() || stopped_) return;
  const common::DurationNs now = Now();
  if (device_.ScanOutputEnabled(now)) {
    StartStreaming();
    return;
  }
  StopStreaming();
  if (!device_.ScanSubscribed()) return;
  // Subscribed but busy (after Run): look again shortly; the device becomes ready on its own.
  state_timer_.expires_after(kStatePollPeriod);
  const std::uint64_t connection = connection_;
  state_timer_.async_wait([this, connection](const boost::system::error_code& ec) {
    if (ec || stopped_ || connection != connection_) return;
    UpdateStreaming();
  });
}

// ---- writing

void Emulator::Enqueue(OutItem item) {
  if (!socket_.is_open() || item.bytes.empty()) return;
  out_queue_.push_back(std::move(item));
  if (!writing_) WriteNext();
}

void Emulator::WriteNext() {
  if (out_queue_.empty()) {
    writing_ = false;
    return;
  }
  writing_ = true;
  const std::uint64_t connection = connection_;
  const std::size_t connection_index = sent_.size() - 1;
  const int scan_telegram_counter = out_queue_.front().scan_telegram_counter;
  asio::async_write(
      socket_, asio::buffer(out_queue_.front().bytes),
      [this, connection, connection_index, scan_telegram_counter](
          const boost::system::error_code& ec, std::size_t n) {
        // A frame that reached the socket was sent even if the connection ended before this handler
        // ran: the client may well have read it.
        if (!ec && scan_telegram_counter >= 0) {
          ++counters_.scans_sent;
          sent_[connection_index].push_back(static_cast<std::uint16_t>(scan_telegram_counter));
        }
        if (stopped_ || connection != connection_) return;
        if (ec) {
          CloseConnection("write error");
          return;
        }
        counters_.bytes_sent += n;
        OutItem done = std::move(out_queue_.front());
        out_queue_.pop_front();
        if (done.close_after) {
          CloseConnection("fault: closed in the middle of a scan frame");
          return;
        }
        if (!out_queue_.empty()) {
          WriteNext();
          return;
        }
        writing_ = false;
        if (scan_due_) SendScan();
      });
}

// ---- streaming

void Emulator::StartStreaming() {
  if (streaming_) return;
  streaming_ = true;
  stream_start_ = SteadyClock::now();
  stream_offset_ = std::chrono::nanoseconds(0);
  first_scan_of_stream_ = true;
  ScheduleNextScan();
}

void Emulator::StopStreaming() {
  streaming_ = false;
  scan_due_ = false;
  boost::system::error_code ignored;
  scan_timer_.cancel(ignored);
}

bool Emulator::PullScan(common::DurationNs* since_previous_ns) {
  if (source_->Next(scan_.get(), since_previous_ns)) return true;
  if (!options_.loop) return false;
  source_->Rewind();
  ++counters_.passes;
  if (rebase_ == Rebase::kNone) rebase_ = Rebase::kLoop;
  if (!source_->Next(scan_.get(), since_previous_ns)) return false;
  *since_previous_ns = source_->nominal_period_ns();
  return true;
}

void Emulator::ScheduleNextScan() {
  if (!streaming_ || stalled_ || exhausted_) return;
  if (!have_pending_scan_) {
    if (!PullScan(&pending_gap_ns_)) {
      exhausted_ = true;
      spdlog::info("emulator: end of the scan source after {} scans", counters_.scans_sent);
      return;
    }
    have_pending_scan_ = true;
  }
  if (!first_scan_of_stream_) {
    stream_offset_ += std::chrono::nanoseconds(
        std::llround(static_cast<double>(pending_gap_ns_) / options_.speed));
  }
  first_scan_of_stream_ = false;
  scan_timer_.expires_at(stream_start_ + stream_offset_);
  const std::uint64_t connection = connection_;
  scan_timer_.async_wait([this, connection](const boost::system::error_code& ec) {
    if (ec || stopped_ || connection != connection_ || !streaming_) return;
    OnScanTimer();
  });
}

void Emulator::OnScanTimer() {
  // Never queue more than one scan: a client that reads slowly gets scans late, as from a real
  // device's socket buffer, not an unbounded backlog.
  if (writing_) {
    scan_due_ = true;
    return;
  }
  SendScan();
}

void Emulator::ApplyRebase() {
  cola::ScanTelegram& scan = *scan_;
  if (rebase_ == Rebase::kLoop && have_last_) {
    const auto period_us =
        static_cast<std::uint32_t>(source_->nominal_period_ns() / common::kNsPerUs);
    telegram_counter_offset_ =
        static_cast<std::uint16_t>(last_telegram_counter_ + 1 - scan.telegram_counter);
    scan_counter_offset_ = static_cast<std::uint16_t>(last_scan_counter_ + 1 - scan.scan_counter);
    tick_offset_us_ = last_tick_us_ + period_us - scan.time_since_startup_us;
  } else if (rebase_ == Rebase::kRestart) {
    telegram_counter_offset_ = static_cast<std::uint16_t>(1 - scan.telegram_counter);
    scan_counter_offset_ = static_cast<std::uint16_t>(1 - scan.scan_counter);
    tick_offset_us_ = kRestartTickUs - scan.time_since_startup_us;
  }
  rebase_ = Rebase::kNone;
  // Modular arithmetic: the fields are uint16 / uint32 on the wire and wrap like the device's.
  scan.telegram_counter =
      static_cast<std::uint16_t>(scan.telegram_counter + telegram_counter_offset_);
  scan.scan_counter = static_cast<std::uint16_t>(scan.scan_counter + scan_counter_offset_);
  scan.time_since_startup_us += tick_offset_us_;
  scan.time_of_transmission_us += tick_offset_us_;
  have_last_ = true;
  last_telegram_counter_ = scan.telegram_counter;
  last_scan_counter_ = scan.scan_counter;
  last_tick_us_ = scan.time_since_startup_us;
}

std::vector<std::uint8_t> Emulator::GarbageBurst() {
  // Random bytes without 0x02 (so no false start sequence), then a frame with a wrong checksum: a
  // client's framer must skip the first and reject the second, and find the real frame that
  // follows.
  std::uniform_int_distribution<int> byte(0x03, 0xFF);
  std::vector<std::uint8_t> out;
  for (std::size_t i = 0; i < kGarbageBytes; ++i)
    out.push_back(static_cast<std::uint8_t>(byte(rng_)));
  std::vector<std::uint8_t> payload(kFakeFramePayloadBytes);
  for (auto& b : payload) b = static_cast<std::uint8_t>(byte(rng_));
  std::vector<std::uint8_t> frame = Frame(payload);
  frame.back() ^= 0x5A;
  out.insert(out.end(), frame.begin(), frame.end());
  return out;
}

void Emulator::SendScan() {
  scan_due_ = false;
  if (!streaming_ || stalled_ || !have_pending_scan_) return;
  const EmulatorFaults& faults = options_.faults;
  const std::uint32_t n = scans_on_connection_;
  if (faults.stall_after_scans != 0 && n == faults.stall_after_scans) {
    stalled_ = true;
    ++counters_.stalls;
    spdlog::info("emulator: fault: stalling after {} scans", n);
    return;
  }
  if (faults.restart_after_scans != 0 && n == faults.restart_after_scans) {
    ++counters_.restarts;
    rebase_ = Rebase::kRestart;
    spdlog::info("emulator: fault: device restart after {} scans", n);
    device_.Reboot(Now());
    CloseConnection("fault: device restart");
    return;
  }
  if (faults.garbage_every_scans != 0 && n != 0 && n % faults.garbage_every_scans == 0) {
    ++counters_.garbage_bursts;
    Enqueue(OutItem{GarbageBurst(), -1, false});
  }

  ApplyRebase();
  have_pending_scan_ = false;
  std::vector<SopasOutput> events;
  if (!device_.PrepareScan(scan_.get(), Now(), &events)) {
    // Not sent (output interval, filtered layer); field evaluation ran on it all the same.
    SendOutputs(events, false);
    ScheduleNextScan();
    return;
  }
  const SopasOutput encoded = device_.EncodeScan(*scan_);
  std::vector<std::uint8_t> frame = cola::EncodeSopasFrame(encoded.dialect, encoded.payload);
  if (frame.empty()) {
    spdlog::warn("emulator: scan {} cannot be encoded; skipped", scan_->telegram_counter);
    SendOutputs(events, false);
    ScheduleNextScan();
    return;
  }
  if (faults.close_mid_frame_after_scans != 0 && n == faults.close_mid_frame_after_scans) {
    ++counters_.mid_frame_closes;
    spdlog::info("emulator: fault: closing in the middle of scan {}", scan_->telegram_counter);
    frame.resize(frame.size() / 2);
    Enqueue(OutItem{std::move(frame), -1, true});
    return;
  }
  ++scans_on_connection_;
  Enqueue(OutItem{std::move(frame), scan_->telegram_counter, false});
  SendOutputs(events, false);
  ScheduleNextScan();
}

}  // namespace lrfnet::tools
