// lrfnet-tracker: the gateway program next to one SICK scanner.
//
//   lrfnet-tracker --sensor HOST[:PORT] --sensor-id ID   live, CoLa-B over TCP (SickClient)
//   lrfnet-tracker --replay CAPTURE --sensor-id ID       offline, a pcap/pcapng of the scanner's
//                                                        TCP stream, as fast as it can be read
//
// Both paths feed cola::StreamDecoder. For now every scan (or every N-th) is printed as one line;
// the tracking pipeline and the UDP uplink come later. SIGINT / SIGTERM stop cleanly and print the
// counters.

#include <spdlog/fmt/fmt.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <boost/asio/io_context.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/signal_set.hpp>
#include <boost/program_options.hpp>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <ctime>
#include <exception>
#include <iostream>
#include <memory>
#include <optional>
#include <string>

#include "common/time.h"
#include "firmware_tracker/cola/stream_decoder.h"
#include "firmware_tracker/io/capture_stream.h"
#include "firmware_tracker/io/sick_client.h"

namespace lrfnet::tracker {
namespace {

namespace asio = boost::asio;
namespace po = boost::program_options;

constexpr int kExitOk = 0;
constexpr int kExitFailure = 1;
constexpr int kExitUsage = 2;

int UsageError(const std::string& message) {
  std::fprintf(stderr, "lrfnet-tracker: %s (see lrfnet-tracker --help)\n", message.c_str());
  return kExitUsage;
}

struct HostPort {
  std::string host;
  std::uint16_t port = 2112;
};

// "HOST", "HOST:PORT", "[IPv6]" or "[IPv6]:PORT"; a bare IPv6 address (several colons) has no port.
std::optional<HostPort> ParseHostPort(const std::string& text, std::string* error) {
  HostPort out;
  std::string port_text;
  if (!text.empty() && text.front() == '[') {
    const auto close = text.find(']');
    if (close == std::string::npos) {
      *error = "--sensor: missing ']' in '" + text + "'";
      return std::nullopt;
    }
    out.host = text.substr(1, close - 1);
    if (close + 1 < text.size()) {
      if (text[close + 1] != ':') {
        *error = "--sensor: expected ':PORT' after ']' in '" + text + "'";
        return std::nullopt;
      }
      port_text = text.substr(close + 2);
    }
  } else if (text.find(':') != std::string::npos && text.find(':') == text.rfind(':')) {
    out.host = text.substr(0, text.find(':'));
    port_text = text.substr(text.find(':') + 1);
  } else {
    out.host = text;
  }
  if (out.host.empty()) {
    *error = "--sensor: empty host in '" + text + "'";
    return std::nullopt;
  }
  if (!port_text.empty() || text.back() == ':') {
    char* end = nullptr;
    const long port = std::strtol(port_text.c_str(), &end, 10);
    if (port_text.empty() || *end != '\0' || port < 1 || port > 65535) {
      *error = "--sensor: bad port '" + port_text + "' (1..65535)";
      return std::nullopt;
    }
    out.port = static_cast<std::uint16_t>(port);
  }
  return out;
}

// UTC as 2021-01-01T12:00:03.123456Z (µs: enough to tell scans 20 ms apart and short to read).
std::string FormatUtc(common::UtcNs t_ns) {
  const std::time_t seconds =
      static_cast<std::time_t>(t_ns / common::kNsPerS) - (t_ns % common::kNsPerS < 0 ? 1 : 0);
  const auto micros =
      static_cast<long>(((t_ns % common::kNsPerS) + common::kNsPerS) % common::kNsPerS / 1000);
  std::tm tm{};
  gmtime_r(&seconds, &tm);
  return fmt::format("{:04}-{:02}-{:02}T{:02}:{:02}:{:02}.{:06}Z", tm.tm_year + 1900, tm.tm_mon + 1,
                     tm.tm_mday, tm.tm_hour, tm.tm_min, tm.tm_sec, micros);
}

// Prints scans and decides when to stop; shared by the live and the replay path.
class ScanPrinter {
 public:
  ScanPrinter(std::string sensor_id, std::uint64_t print_every, std::uint64_t max_scans)
      : sensor_id_(std::move(sensor_id)), print_every_(print_every), max_scans_(max_scans) {}

  // Returns false once max_scans were seen (the caller stops).
  bool OnScan(const cola::ScanTelegram& scan, common::UtcNs receive_time_ns) {
    ++scans_;
    if ((scans_ - 1) % print_every_ == 0) {
      const cola::ScanChannel* dist = scan.FindChannel("DIST1");
      std::string first;
      if (dist != nullptr) {
        for (std::size_t i = 0; i < std::min<std::size_t>(3, dist->count); ++i) {
          first += fmt::format("{}{:.3f}", i == 0 ? "" : ", ", dist->RangeM(i));
        }
      }
      fmt::print("{} tc={} sc={} points={} rx={} first_m=[{}]\n", sensor_id_, scan.telegram_counter,
                 scan.scan_counter, dist != nullptr ? dist->count : 0, FormatUtc(receive_time_ns),
                 first);
      std::fflush(stdout);
    }
    return max_scans_ == 0 || scans_ < max_scans_;
  }
  std::uint64_t scans() const { return scans_; }

 private:
  std::string sensor_id_;
  std::uint64_t print_every_;
  std::uint64_t max_scans_;
  std::uint64_t scans_ = 0;
};

std::string DecoderSummary(const cola::StreamCounters& c) {
  return fmt::format(
      "frames={} bad_checksums={} oversize_lengths={} garbage_bytes={} other_telegrams={} "
      "bad_headers={} scan_decode_errors={}",
      c.framer.frames, c.framer.bad_checksum, c.framer.oversize_length, c.framer.garbage_bytes,
      c.other_telegrams, c.bad_headers, c.scan_decode_errors);
}

int RunLive(const io::SickClientOptions& options, ScanPrinter& printer,
            const std::string& sensor_id) {
  asio::io_context io;
  asio::signal_set signals(io, SIGINT, SIGTERM);
  std::unique_ptr<io::SickClient> client;
  client = std::make_unique<io::SickClient>(
      io, options, [&](const cola::ScanTelegram& scan, common::UtcNs receive_time_ns) {
        if (!printer.OnScan(scan, receive_time_ns)) {
          client->Stop();
          signals.cancel();
        }
      });
  signals.async_wait([&](const boost::system::error_code& ec, int signal_number) {
    if (ec) return;
    spdlog::info("signal {}: stopping", signal_number);
    client->Stop();
  });
  client->Start();
  io.run();

  const io::SickClientCounters& c = client->counters();
  const io::SickDeviceInfo& d = client->device_info();
  fmt::print("device: sensor={} ident='{}' version='{}' firmware='{}' serial='{}'\n", sensor_id,
             d.ident_name, d.ident_version, d.firmware_version, d.serial_number);
  fmt::print(
      "summary: sensor={} mode=live scans={} connects={} connect_failures={} reconnects={} "
      "reply_timeouts={} read_timeouts={} sfa_replies={} handshake_failures={} disconnects={} "
      "bad_frames={} bytes={} {}\n",
      sensor_id, c.scans, c.connects, c.connect_failures, c.reconnects, c.reply_timeouts,
      c.read_timeouts, c.sfa_replies, c.handshake_failures, c.disconnects, c.bad_frames, c.bytes,
      DecoderSummary(client->decoder_counters()));
  std::fflush(stdout);
  return kExitOk;
}

// Replays a capture through the decoder in slices posted to the io_context, so a signal is handled
// between slices even for a large file.
class Replay : public cola::TelegramListener {
 public:
  Replay(asio::io_context& io, std::unique_ptr<io::CaptureStream> capture, ScanPrinter& printer)
      : io_(io), capture_(std::move(capture)), printer_(printer) {}

  void Start() {
    asio::post(io_, [this] { Slice(); });
  }
  void Stop() { stopped_ = true; }
  bool finished() const { return finished_; }
  const io::CaptureStream& capture() const { return *capture_; }
  cola::StreamCounters decoder_counters() const { return decoder_->counters(); }

  void OnScan(const cola::ScanTelegram& scan, common::UtcNs receive_time_ns) override {
    if (!stopped_ && !printer_.OnScan(scan, receive_time_ns)) stopped_ = true;
  }
  void OnError(const char* reason, common::UtcNs) override {
    spdlog::debug("replay: bad frame: {}", reason);
  }

  std::function<void()> on_done;

 private:
  void Slice() {
    constexpr int kChunksPerSlice = 256;
    io::StreamChunk chunk;
    for (int i = 0; i < kChunksPerSlice && !stopped_; ++i) {
      if (!capture_->Next(&chunk)) {
        finished_ = true;
        break;
      }
      if (chunk.discontinuity) decoder_->Reset();
      decoder_->Feed(chunk.bytes, chunk.receive_time_ns, *this);
    }
    if (stopped_ || finished_) {
      if (on_done) on_done();
      return;
    }
    asio::post(io_, [this] { Slice(); });
  }

  asio::io_context& io_;
  std::unique_ptr<io::CaptureStream> capture_;
  std::unique_ptr<cola::StreamDecoder> decoder_ = std::make_unique<cola::StreamDecoder>();
  ScanPrinter& printer_;
  bool stopped_ = false;
  bool finished_ = false;
};

int RunReplay(const std::string& path, const io::CaptureStreamOptions& options,
              ScanPrinter& printer, const std::string& sensor_id) {
  std::string error;
  std::unique_ptr<io::CaptureStream> capture = io::CaptureStream::Open(path, options, &error);
  if (!capture) {
    std::fprintf(stderr, "lrfnet-tracker: %s\n", error.c_str());
    return kExitFailure;
  }
  asio::io_context io;
  asio::signal_set signals(io, SIGINT, SIGTERM);
  Replay replay(io, std::move(capture), printer);
  replay.on_done = [&] { signals.cancel(); };
  signals.async_wait([&](const boost::system::error_code& ec, int signal_number) {
    if (ec) return;
    spdlog::info("signal {}: stopping", signal_number);
    replay.Stop();
  });
  replay.Start();
  io.run();

  const io::CaptureCounters& c = replay.capture().counters();
  fmt::print(
      "summary: sensor={} mode=replay scans={} packets={} stream_packets={} malformed_packets={} "
      "retransmitted_bytes={} gaps={} gap_bytes={} {}\n",
      sensor_id, printer.scans(), c.packets, c.stream_packets, c.malformed_packets,
      c.retransmitted_bytes, c.gaps, c.gap_bytes, DecoderSummary(replay.decoder_counters()));
  std::fflush(stdout);
  if (!replay.capture().error().empty()) {
    std::fprintf(stderr, "lrfnet-tracker: %s\n", replay.capture().error().c_str());
    return kExitFailure;
  }
  return kExitOk;
}

int Run(int argc, char** argv) {
  po::options_description visible(
      "lrfnet-tracker --sensor HOST[:PORT] --sensor-id ID [options]\n"
      "lrfnet-tracker --replay CAPTURE --sensor-id ID [options]\n"
      "Reads a SICK scanner live (CoLa-B over TCP: log-in, device ident, start of measurement, "
      "scan stream;\n"
      "reconnects on failure) or a pcap/pcapng capture of its TCP stream, and prints the scans.\n"
      "Tracking and the UDP uplink (--uplink, --out) come with the tracking pipeline. Options",
      100, 50);
  std::string sensor;
  std::string replay;
  std::string sensor_id;
  long long print_every = 1;
  long long max_scans = 0;
  int capture_port = 2112;
  long long connect_timeout_ms = 3000;
  long long reply_timeout_ms = 2000;
  double read_deadline_periods = 10.0;
  std::string log_level = "info";
  visible.add_options()("help,h", "this help")(
      "sensor", po::value<std::string>(&sensor),
      "live: the scanner's address, HOST or HOST:PORT (port 2112)")(
      "replay", po::value<std::string>(&replay),
      "offline: a pcap/pcapng capture of the scanner's TCP stream")(
      "sensor-id", po::value<std::string>(&sensor_id), "name of this sensor in output (required)")(
      "print-every", po::value<long long>(&print_every)->default_value(1), "print every N-th scan")(
      "max-scans", po::value<long long>(&max_scans)->default_value(0),
      "stop after N scans (0: never)")("capture-port",
                                       po::value<int>(&capture_port)->default_value(2112),
                                       "replay: the scanner's TCP port in the capture")(
      "connect-timeout-ms", po::value<long long>(&connect_timeout_ms)->default_value(3000),
      "live: TCP connect deadline")("reply-timeout-ms",
                                    po::value<long long>(&reply_timeout_ms)->default_value(2000),
                                    "live: deadline for each start-up command's reply")(
      "read-deadline-periods", po::value<double>(&read_deadline_periods)->default_value(10.0),
      "live: reconnect when no scan arrived for this many scan periods")(
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
  if (sensor.empty() == replay.empty())
    return UsageError("give either --sensor HOST[:PORT] or --replay CAPTURE");
  if (sensor_id.empty()) return UsageError("--sensor-id is required");
  if (print_every < 1) return UsageError("--print-every must be >= 1");
  if (max_scans < 0) return UsageError("--max-scans must be >= 0");
  const spdlog::level::level_enum level = spdlog::level::from_str(log_level);
  if (level == spdlog::level::off && log_level != "off") {
    return UsageError("unknown --log-level '" + log_level + "'");
  }
  spdlog::set_default_logger(spdlog::stderr_color_mt("lrfnet-tracker"));
  spdlog::set_level(level);

  ScanPrinter printer(sensor_id, static_cast<std::uint64_t>(print_every),
                      static_cast<std::uint64_t>(max_scans));
  if (!replay.empty()) {
    io::CaptureStreamOptions options;
    if (capture_port < 1 || capture_port > 65535)
      return UsageError("--capture-port must be 1..65535");
    options.sensor_port = static_cast<std::uint16_t>(capture_port);
    if (auto e = io::Validate(options)) return UsageError(*e);
    return RunReplay(replay, options, printer, sensor_id);
  }

  std::string error;
  const std::optional<HostPort> endpoint = ParseHostPort(sensor, &error);
  if (!endpoint) return UsageError(error);
  io::SickClientOptions options;
  options.host = endpoint->host;
  options.port = endpoint->port;
  options.connect_timeout = std::chrono::milliseconds(connect_timeout_ms);
  options.reply_timeout = std::chrono::milliseconds(reply_timeout_ms);
  options.read_deadline_scan_periods = read_deadline_periods;
  if (auto e = io::Validate(options)) return UsageError(*e);
  return RunLive(options, printer, sensor_id);
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
