// lrfnet-tracker: the gateway program next to one SICK scanner.
//
//   lrfnet-tracker --sensor HOST[:PORT] --sensor-id ID --uplink HOST:PORT   live: CoLa-B over TCP in,
//                                                                           tracks over UDP out
//   lrfnet-tracker --replay CAPTURE --sensor-id ID --out REC                offline: a pcap/pcapng of
//                                                                           the scanner's TCP stream
//                                                                           in, a recording out
//   lrfnet-tracker --print-config                                           the documented defaults
//
// Both modes feed cola::StreamDecoder and one TrackerNode (clock mapping, tracking, datagrams);
// --uplink and --out may be combined in either mode. SIGINT / SIGTERM stop cleanly (the recording
// is flushed and closed) and print the counters.

#include <spdlog/fmt/fmt.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <boost/asio/io_context.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/signal_set.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/program_options.hpp>
#include <chrono>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <ctime>
#include <exception>
#include <fstream>
#include <functional>
#include <iostream>
#include <memory>
#include <optional>
#include <random>
#include <sstream>
#include <string>

#include "common/capture/capture_stream.h"
#include "common/datagram_auth.h"
#include "common/host_port.h"
#include "common/key_file.h"
#include "common/systemd_notify.h"
#include "common/time.h"
#include "firmware_tracker/app/config.h"
#include "firmware_tracker/app/live_run.h"
#include "firmware_tracker/app/outputs.h"
#include "firmware_tracker/app/run_report.h"
#include "firmware_tracker/app/run_setup.h"
#include "firmware_tracker/app/tracker_node.h"
#include "firmware_tracker/cola/commands.h"
#include "firmware_tracker/cola/stream_decoder.h"
#include "firmware_tracker/io/datagram_encoder.h"
#include "firmware_tracker/io/recording_writer.h"
#include "firmware_tracker/io/sealing_sink.h"
#include "firmware_tracker/io/sick_client.h"
#include "firmware_tracker/io/system_clock.h"
#include "firmware_tracker/io/udp_uplink.h"

#ifndef LRFNET_VERSION
#define LRFNET_VERSION "unknown"
#endif

namespace lrfnet::tracker {
namespace {

namespace asio = boost::asio;
namespace po = boost::program_options;

int UsageError(const std::string& message) {
  std::fprintf(stderr, "lrfnet-tracker: %s (see lrfnet-tracker --help)\n", message.c_str());
  return kExitUsage;
}

using common::HostPort;
using common::ParseHostPort;

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
    const auto due = first_steady_ + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
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

int Run(int argc, char** argv) {
  po::options_description visible(
      "lrfnet-tracker --sensor HOST[:PORT] --sensor-id ID --uplink HOST:PORT [options]\n"
      "lrfnet-tracker --replay CAPTURE --sensor-id ID --out REC [options]\n"
      "lrfnet-tracker --print-config\n"
      "Reads a SICK scanner live (CoLa-B over TCP; reconnects on failure) or a pcap/pcapng "
      "capture of\n"
      "its TCP stream, tracks the moving objects and sends track frames, background snapshots, "
      "health and\n"
      "sensor info as UDP datagrams (--uplink) and/or writes them to a recording (--out). "
      "Options",
      100, 50);
  std::string config_path;
  std::string sensor;
  std::string replay;
  std::string sensor_id;
  std::string uplink;
  std::string out;
  long long print_every = 0;
  long long max_scans = 0;
  double speed = 0.0;
  int capture_port = 2112;
  long long connect_timeout_ms = 0;
  long long reply_timeout_ms = 0;
  double read_deadline_periods = 0.0;
  std::string log_level = "info";
  visible.add_options()("help,h", "this help")(
      "print-config", "print every option with its default and documentation (YAML) and exit")(
      "config", po::value<std::string>(&config_path),
      "YAML config file (see --print-config); flags override it")(
      "sensor", po::value<std::string>(&sensor),
      "live: the scanner's address, HOST or HOST:PORT (port 2112)")(
      "replay", po::value<std::string>(&replay),
      "offline: a pcap/pcapng capture of the scanner's TCP stream")(
      "sensor-id", po::value<std::string>(&sensor_id),
      "name of this sensor in every datagram (required here or in the config)")(
      "uplink", po::value<std::string>(&uplink), "send datagrams over UDP to lrfnetd at HOST:PORT")(
      "out", po::value<std::string>(&out), "write the datagrams to this recording file")(
      "key", po::value<std::string>(),
      "seal every datagram with this sensor's key file (lrfnet keys derive) and serve only sealed "
      "Requests (auth.key)")("encrypt",
                             "also encrypt the datagrams' content (auth.encrypt; needs --key)")(
      "print-every", po::value<long long>(&print_every)->default_value(0),
      "print the tracks of every N-th scan (0: none)")(
      "speed", po::value<double>(&speed)->default_value(0.0),
      "replay: play the capture at this multiple of its recorded pace (1: real time; 0: as fast "
      "as possible)")("max-scans", po::value<long long>(&max_scans)->default_value(0),
                      "stop after N scans (0: never)")(
      "capture-port", po::value<int>(&capture_port)->default_value(2112),
      "replay: the scanner's TCP port in the capture")(
      "connect-timeout-ms", po::value<long long>(&connect_timeout_ms),
      "live: TCP connect deadline (link.connect_timeout_ms)")(
      "reply-timeout-ms", po::value<long long>(&reply_timeout_ms),
      "live: deadline for each start-up reply (link.reply_timeout_ms)")(
      "read-deadline-periods", po::value<double>(&read_deadline_periods),
      "live: reconnect after this many scan periods without a scan")(
      "log-level", po::value<std::string>(&log_level)->default_value("info"),
      "trace, debug, info, warn, error or off (stderr)");

  po::variables_map vm;
  try {
    po::store(po::command_line_parser(argc, argv).options(visible).run(), vm);
    po::notify(vm);
  } catch (const po::error& e) {
    return UsageError(e.what());
  }
  if (vm.count("help") != 0) {
    std::cout << visible << "\n";
    return kExitOk;
  }

  TrackerConfig config;
  if (!config_path.empty()) {
    std::ifstream file(config_path);
    if (!file) return UsageError("--config: cannot read '" + config_path + "'");
    std::stringstream text;
    text << file.rdbuf();
    if (auto e = LoadTrackerConfig(text.str(), config)) {
      return UsageError("--config " + config_path + ": " + *e);
    }
  }
  if (vm.count("print-config") != 0) {
    std::cout << PrintTrackerConfig(config);
    return kExitOk;
  }

  if (!sensor.empty()) config.sensor_address = sensor;
  if (!sensor_id.empty()) config.sensor_id = sensor_id;
  if (!uplink.empty()) config.uplink_address = uplink;
  if (vm.count("key") != 0) config.key_file = vm["key"].as<std::string>();
  if (vm.count("encrypt") != 0) config.encrypt = true;
  if (vm.count("connect-timeout-ms") != 0)
    config.link.connect_timeout = std::chrono::milliseconds(connect_timeout_ms);
  if (vm.count("reply-timeout-ms") != 0)
    config.link.reply_timeout = std::chrono::milliseconds(reply_timeout_ms);
  if (vm.count("read-deadline-periods") != 0)
    config.link.read_deadline_scan_periods = read_deadline_periods;

  if (replay.empty() && config.sensor_address.empty())
    return UsageError("give --sensor HOST[:PORT] (or sensor.address in the config) or --replay CAPTURE");
  if (!replay.empty() && !sensor.empty()) return UsageError("give either --sensor or --replay, not both");
  if (config.sensor_id.empty()) return UsageError("--sensor-id is required");
  if (print_every < 0) return UsageError("--print-every must be >= 0");
  if (max_scans < 0) return UsageError("--max-scans must be >= 0");
  if (!(speed >= 0.0 && speed <= 1e6)) return UsageError("--speed must be in [0, 1e6]");
  const spdlog::level::level_enum level = spdlog::level::from_str(log_level);
  if (level == spdlog::level::off && log_level != "off") {
    return UsageError("unknown --log-level '" + log_level + "'");
  }
  std::string error;
  if (replay.empty()) {
    const auto endpoint = ParseHostPort(config.sensor_address, "--sensor", 2112, &error);
    if (!endpoint) return UsageError(error);
    config.link.host = endpoint->host;
    config.link.port = endpoint->port;
  }
  if (!config.uplink_address.empty() &&
      !ParseHostPort(config.uplink_address, "--uplink", 0, &error)) {
    return UsageError(error);
  }
  if (auto e = Validate(config)) return UsageError(*e);
  spdlog::set_default_logger(spdlog::stderr_color_mt("lrfnet-tracker"));
  spdlog::set_level(level);

  ScanLog log(static_cast<std::uint64_t>(print_every), static_cast<std::uint64_t>(max_scans));
  if (!replay.empty()) {
    capture::CaptureStreamOptions options;
    if (capture_port < 1 || capture_port > 65535)
      return UsageError("--capture-port must be 1..65535");
    options.sensor_port = static_cast<std::uint16_t>(capture_port);
    if (auto e = capture::Validate(options)) return UsageError(*e);
    return RunReplay(config, replay, options, out, speed, log);
  }
  return RunLive(config, out, log);
}

}  // namespace
}  // namespace lrfnet::tracker

int main(int argc, char** argv) {
  try {
    return lrfnet::tracker::Run(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "lrfnet-tracker: %s\n", e.what());
    return 1;
  }
}
