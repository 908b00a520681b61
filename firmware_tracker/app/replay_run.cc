#include "firmware_tracker/app/replay_run.h"

#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include <boost/asio/io_context.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/signal_set.hpp>
#include <boost/asio/steady_timer.hpp>
#include <chrono>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <memory>
#include <span>
#include <utility>

#include "firmware_tracker/app/outputs.h"
#include "firmware_tracker/app/run_setup.h"
#include "firmware_tracker/app/tracker_node.h"
#include "firmware_tracker/cola/commands.h"
#include "firmware_tracker/cola/stream_decoder.h"
#include "firmware_tracker/io/system_clock.h"

namespace lrfnet::tracker {

namespace {

namespace asio = boost::asio;

// Replays a capture through the decoder and the node in slices posted to the io_context, so a
// signal is handled between slices even for a large file. Runs as fast as it can; every time is
// the capture's.
class Replay : public cola::TelegramListener {
 public:
  Replay(asio::io_context& io, std::unique_ptr<capture::CaptureStream> capture, TrackerNode& node,
         Outputs& outputs, ScanLog& log, const TrackerConfig& config)
      : io_(io),
        capture_(std::move(capture)),
        node_(node),
        outputs_(outputs),
        log_(log),
        config_(config) {
    clock_.sync = io::ClockSync::kReplay;
  }

  void Start() {
    asio::post(io_, [this] { Slice(); });
  }
  void Stop() {
    stopped_ = true;
    timer_.cancel();
    if (has_pending_ && on_done) {
      has_pending_ = false;
      on_done();
    }
  }
  // Packet times scaled by 1/speed (0: as fast as possible).
  void SetSpeed(double speed) { speed_ = speed; }
  const capture::CaptureStream& capture() const { return *capture_; }
  cola::StreamCounters decoder_counters() const { return decoder_->counters(); }

  void OnScan(const cola::ScanTelegram& scan, common::UtcNs receive_time_ns) override {
    if (stopped_) return;
    const auto started = std::chrono::steady_clock::now();
    outputs_.ServeRequests(node_);
    node_.OnScan(scan, receive_time_ns, receive_time_ns);
    node_.RecordScanCpu(ElapsedUs(started));
    node_.OnTick(receive_time_ns, Link(), clock_);
    if (!log_.OnScan(config_.sensor_id, scan, receive_time_ns, node_)) stopped_ = true;
  }

  // Identity from the device's replies in the capture (when the capture holds the start-up).
  void OnTelegram(const cola::TelegramHeader& header, std::span<const std::uint8_t>,
                  common::UtcNs) override {
    if (header.type != cola::CommandType::kReadAnswer) return;
    cola::FlexString text;
    if (header.name == "DeviceIdent") {
      cola::DeviceIdent ident;
      if (cola::DecodeDeviceIdent(header.args, &ident)) model_ = std::string(ident.name);
    } else if (header.name == "FirmwareVersion" && cola::DecodeFlexString(header.args, &text)) {
      firmware_ = std::string(text.text);
    } else if (header.name == "SerialNumber" && cola::DecodeFlexString(header.args, &text)) {
      serial_ = std::string(text.text);
    } else {
      return;
    }
    node_.SetDeviceIdentity(model_, serial_, firmware_);
  }
  void OnError(const char* reason, common::UtcNs) override {
    spdlog::debug("replay: bad frame: {}", reason);
  }

  std::function<void()> on_done;

 private:
  LinkHealth Link() const {
    LinkHealth link;
    const cola::StreamCounters c = decoder_->counters();
    link.bad_frames = c.framer.bad_checksum + c.framer.oversize_length;
    link.decode_errors = c.scan_decode_errors + c.bad_headers;
    link.send_errors = outputs_.send_errors();
    return link;
  }

  void Slice() {
    constexpr int kChunksPerSlice = 256;
    bool finished = false;
    for (int i = 0; i < kChunksPerSlice && !stopped_; ++i) {
      if (!has_pending_ && !capture_->Next(&pending_)) {
        finished = true;
        break;
      }
      has_pending_ = true;
      if (speed_ > 0.0 && WaitFor(pending_.receive_time_ns)) return;
      has_pending_ = false;
      if (pending_.discontinuity) decoder_->Reset();
      decoder_->Feed(pending_.bytes, pending_.receive_time_ns, *this);
    }
    if (stopped_ || finished) {
      if (on_done) on_done();
      return;
    }
    asio::post(io_, [this] { Slice(); });
  }

  // --speed: the capture's packet times, scaled by 1/speed, against a steady clock from the first
  // packet on. True when a timer was set to resume at the packet's time.
  bool WaitFor(common::UtcNs capture_ns) {
    const auto now = std::chrono::steady_clock::now();
    if (!paced_) {
      paced_ = true;
      first_capture_ns_ = capture_ns;
      first_steady_ = now;
    }
    // A capture whose clock steps backwards is replayed without waiting until it catches up.
    const double offset_s = static_cast<double>(capture_ns - first_capture_ns_) * 1e-9 / speed_;
    const auto due =
        first_steady_ + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                            std::chrono::duration<double>(offset_s));
    if (due <= now) return false;
    timer_.expires_at(due);
    timer_.async_wait([this](const boost::system::error_code& ec) {
      if (!ec) Slice();
    });
    return true;
  }

  asio::io_context& io_;
  asio::steady_timer timer_{io_};
  double speed_ = 0.0;
  capture::StreamChunk pending_;
  bool has_pending_ = false;
  bool paced_ = false;
  common::UtcNs first_capture_ns_ = 0;
  std::chrono::steady_clock::time_point first_steady_;
  std::unique_ptr<capture::CaptureStream> capture_;
  std::unique_ptr<cola::StreamDecoder> decoder_ = std::make_unique<cola::StreamDecoder>();
  TrackerNode& node_;
  Outputs& outputs_;
  ScanLog& log_;
  const TrackerConfig& config_;
  io::ClockStatus clock_;
  std::string model_;
  std::string serial_;
  std::string firmware_;
  bool stopped_ = false;
};

}  // namespace

int RunReplay(const TrackerConfig& config, const std::string& path,
              const capture::CaptureStreamOptions& options, const std::string& record_path,
              double speed, ScanLog& log) {
  std::string error;
  std::unique_ptr<capture::CaptureStream> capture =
      capture::CaptureStream::Open(path, options, &error);
  if (!capture) {
    std::fprintf(stderr, "lrfnet-tracker: %s\n", error.c_str());
    return kExitFailure;
  }
  Outputs outputs;
  if (auto e = outputs.Open(config, record_path, io::NowUtcNs())) {
    std::fprintf(stderr, "lrfnet-tracker: %s\n", e->c_str());
    return kExitFailure;
  }
  auto node = std::make_unique<TrackerNode>(config, RandomSessionId(), outputs.sink());

  asio::io_context io;
  asio::signal_set signals(io, SIGINT, SIGTERM);
  Replay replay(io, std::move(capture), *node, outputs, log, config);
  replay.on_done = [&] { signals.cancel(); };
  signals.async_wait([&](const boost::system::error_code& ec, int signal_number) {
    if (ec) return;
    spdlog::info("signal {}: stopping", signal_number);
    replay.Stop();
  });
  replay.SetSpeed(speed);
  replay.Start();
  io.run();

  const bool closed = outputs.Close();
  const capture::CaptureCounters& c = replay.capture().counters();
  fmt::print(
      "summary: sensor={} mode=replay scans={} packets={} stream_packets={} malformed_packets={} "
      "retransmitted_bytes={} gaps={} gap_bytes={} {} {}{}\n",
      config.sensor_id, log.scans(), c.packets, c.stream_packets, c.malformed_packets,
      c.retransmitted_bytes, c.gaps, c.gap_bytes, DecoderSummary(replay.decoder_counters()),
      NodeSummary(*node), outputs.Summary());
  std::fflush(stdout);
  if (!replay.capture().error().empty()) {
    std::fprintf(stderr, "lrfnet-tracker: %s\n", replay.capture().error().c_str());
    return kExitFailure;
  }
  return closed ? kExitOk : kExitFailure;
}

}  // namespace lrfnet::tracker
