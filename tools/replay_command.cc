// lrfnet replay REC --to HOST:PORT [--speed X] [--max-gap-s S] [--udp-port P]

#include <spdlog/spdlog.h>

#include <array>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/udp.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/signal_set.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/program_options.hpp>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "central_daemon/app/auth_files.h"
#include "central_daemon/io/datagram_source.h"
#include "common/datagram_auth.h"
#include "common/host_port.h"
#include "tools/replay.h"
#include "tools/subcommands.h"

namespace lrfnet::tools {

namespace po = boost::program_options;
namespace asio = boost::asio;
using asio::ip::udp;

namespace {

struct ReplayCounters {
  std::uint64_t datagrams_sent = 0;
  std::uint64_t bytes_sent = 0;
  std::uint64_t send_errors = 0;
  std::uint64_t replies = 0;
  std::uint64_t refused = 0;  // --keys: not sent, they did not verify
};

// Sends the datagrams of a source to one endpoint on the schedule of ReplaySchedule, from one
// socket per recorded source (SenderSlots), and counts what comes back without processing it.
// Runs on one io_context thread; `done` is called once, after the last datagram or Stop().
class UdpReplayer {
 public:
  UdpReplayer(asio::io_context& io, daemon::DatagramSource& source, const udp::endpoint& target,
              const ReplayScheduleOptions& schedule, std::function<void()> done)
      : io_(io),
        source_(source),
        target_(target),
        schedule_(schedule),
        timer_(io),
        done_(std::move(done)) {}

  void Start() {
    start_ = std::chrono::steady_clock::now();
    SendDue();
  }

  // Stops at once (SIGINT): what was sent stays counted.
  void Stop() {
    interrupted_ = true;
    Finish();
  }

  const ReplayCounters& counters() const { return counters_; }
  const ReplaySchedule& schedule() const { return schedule_; }
  std::size_t senders() const { return slots_.slots_used(); }
  bool interrupted() const { return interrupted_; }
  // --keys: only what verifies with the sensor keys is sent (forged and repeated datagrams of
  // the recording stay behind).
  void set_verifier(daemon::DatagramVerifier* verifier) { verifier_ = verifier; }
  double elapsed_s() const { return std::chrono::duration<double>(end_ - start_).count(); }

 private:
  // Up to this many datagrams that are due are sent before the loop yields to the replies and
  // the signal handler (matters with --speed 0).
  static constexpr int kBurst = 64;
  static constexpr std::size_t kReplyBufferBytes = 2048;  // a Request is a few bytes
  static constexpr std::chrono::seconds kLongWait{5};

  struct Sender {
    explicit Sender(asio::io_context& io) : socket(io) {}
    udp::socket socket;
    udp::endpoint reply_from;
    std::array<std::uint8_t, kReplyBufferBytes> reply_buffer{};
  };

  void SendDue() {
    if (finished_) return;
    for (int n = 0; n < kBurst; ++n) {
      if (!have_pending_) {
        const daemon::SourceStatus status = source_.Next(&pending_);
        if (status != daemon::SourceStatus::kDatagram) {
          Finish();
          return;
        }
        have_pending_ = true;
        due_ = Due(schedule_.Next(pending_.receive_ns));
      }
      const auto now = std::chrono::steady_clock::now();
      if (due_ > now) {
        if (due_ - now > kLongWait)
          spdlog::info(
              "waiting {:.1f} s for the next datagram (a gap in the recording; "
              "--max-gap-s shortens gaps)",
              std::chrono::duration<double>(due_ - now).count());
        timer_.expires_at(due_);
        timer_.async_wait([this](const boost::system::error_code& ec) {
          if (!ec) SendDue();
        });
        return;
      }
      Send(pending_);
      have_pending_ = false;
    }
    asio::post(io_, [this] { SendDue(); });
  }

  // start_ + offset, saturating: an offset near the int64 limit (hostile receive times, a tiny
  // --speed) must not wrap around to the past.
  std::chrono::steady_clock::time_point Due(common::DurationNs offset_ns) const {
    const auto headroom = std::chrono::steady_clock::time_point::max() - start_;
    const std::chrono::nanoseconds offset(offset_ns);
    return offset >= headroom ? std::chrono::steady_clock::time_point::max() : start_ + offset;
  }

  void Send(const daemon::ReceivedDatagram& datagram) {
    if (verifier_ != nullptr) {
      const daemon::AuthResult r = verifier_->Verify(datagram.bytes, 0);
      if (!r.ok()) {
        ++counters_.refused;
        return;
      }
      verifier_->Commit(r);
    }
    Sender& sender = SenderFor(datagram.source);
    boost::system::error_code ec;
    if (!sender.socket.is_open()) {
      ec = boost::asio::error::bad_descriptor;
    } else {
      sender.socket.send_to(asio::buffer(datagram.bytes), target_, 0, ec);
    }
    if (ec) {
      if (counters_.send_errors++ == 0)
        spdlog::warn("send to {} failed: {} (further errors are only counted)",
                     target_.address().to_string(), ec.message());
      return;
    }
    ++counters_.datagrams_sent;
    counters_.bytes_sent += datagram.bytes.size();
  }

  Sender& SenderFor(const std::string& source) {
    const std::size_t slot = slots_.SlotFor(source);
    while (senders_.size() <= slot) {
      auto sender = std::make_unique<Sender>(io_);
      boost::system::error_code ec;
      sender->socket.open(target_.protocol(), ec);
      if (ec) {
        spdlog::warn("cannot open a UDP socket for source {}: {}", source, ec.message());
      } else {
        // Bound before the first send so that the reply receive below has a port to wait on.
        sender->socket.bind(udp::endpoint(target_.protocol(), 0), ec);
        if (ec) spdlog::warn("cannot bind a UDP socket for source {}: {}", source, ec.message());
        // Best effort: bursts at --speed 0 should not block on a small default buffer.
        boost::system::error_code ignored;
        sender->socket.set_option(asio::socket_base::send_buffer_size(1 << 20), ignored);
      }
      senders_.push_back(std::move(sender));
      if (senders_.back()->socket.is_open()) ReceiveReply(*senders_.back());
    }
    return *senders_[slot];
  }

  void ReceiveReply(Sender& sender) {
    sender.socket.async_receive_from(
        asio::buffer(sender.reply_buffer), sender.reply_from,
        [this, &sender](const boost::system::error_code& ec, std::size_t) {
          if (finished_ || ec == asio::error::operation_aborted) return;
          // Other errors (an ICMP "port unreachable" reported on the socket) are one-shot.
          if (!ec) ++counters_.replies;
          ReceiveReply(sender);
        });
  }

  void Finish() {
    if (finished_) return;
    finished_ = true;
    end_ = std::chrono::steady_clock::now();
    timer_.cancel();
    for (auto& sender : senders_) {
      if (!sender->socket.is_open()) continue;
      // Replies that are queued already are counted; nothing is waited for.
      boost::system::error_code ec;
      while (sender->socket.available(ec) > 0 && !ec) {
        sender->socket.receive_from(asio::buffer(sender->reply_buffer), sender->reply_from, 0, ec);
        if (!ec) ++counters_.replies;
      }
      sender->socket.close(ec);
    }
    done_();
  }

  asio::io_context& io_;
  daemon::DatagramSource& source_;
  udp::endpoint target_;
  ReplaySchedule schedule_;
  SenderSlots slots_;
  asio::steady_timer timer_;
  std::function<void()> done_;
  daemon::DatagramVerifier* verifier_ = nullptr;
  std::vector<std::unique_ptr<Sender>> senders_;
  daemon::ReceivedDatagram pending_;
  bool have_pending_ = false;
  std::chrono::steady_clock::time_point start_{};
  std::chrono::steady_clock::time_point end_{};
  std::chrono::steady_clock::time_point due_{};
  ReplayCounters counters_;
  bool finished_ = false;
  bool interrupted_ = false;
};

// The first address the resolver gives for `to`. nullopt with *error (one line) when none.
std::optional<udp::endpoint> Resolve(asio::io_context& io, const common::HostPort& to,
                                     std::string* error) {
  udp::resolver resolver(io);
  boost::system::error_code ec;
  const auto results =
      resolver.resolve(to.host, std::to_string(to.port), udp::resolver::numeric_service, ec);
  if (ec || results.empty()) {
    *error = "--to: cannot resolve '" + to.host + "': " + (ec ? ec.message() : "no address");
    return std::nullopt;
  }
  return results.begin()->endpoint();
}

}  // namespace

int RunReplay(int argc, char** argv) {
  po::options_description visible(
      "lrfnet replay REC --to HOST:PORT [options]\n"
      "Sends every datagram of a recording (with its rotation parts REC.1, REC.2, ...) or of a "
      "pcap/pcapng\ncapture of the UDP stream to HOST:PORT over UDP, exactly the recorded bytes, "
      "with the recorded\ntiming (receive times) scaled by 1/--speed. Every recorded sender gets "
      "a socket of its own (up to\n256), so the receiver sees distinct senders as it did live; "
      "replies (the daemon's Requests) are\ncounted, not answered. Prints one summary line at "
      "the end or on SIGINT/SIGTERM. Options",
      100, 50);
  std::string to;
  double speed = 1.0;
  double max_gap_s = 0.0;
  int udp_port = 0;
  std::string log_level = "info";
  visible.add_options()("help,h", "this help")(
      "to", po::value<std::string>(&to), "where to send: HOST:PORT, [IPv6]:PORT or NAME:PORT")(
      "speed", po::value<double>(&speed)->default_value(1.0),
      "timing factor: 2 = twice as fast, 0 = as fast as possible")(
      "max-gap-s", po::value<double>(&max_gap_s)->default_value(0.0),
      "shorten gaps longer than this many seconds of recording time to it (0 = off)")(
      "udp-port", po::value<int>(&udp_port)->default_value(0),
      "captures: only UDP datagrams to this port (0 = any)")(
      "keys", po::value<std::string>(),
      "send only the datagrams that verify with the sensor keys in this folder (without: every "
      "datagram as recorded, sealed ones stay sealed)")(
      "log-level", po::value<std::string>(&log_level)->default_value("info"),
      "trace, debug, info, warn, error or off (stderr)");
  po::variables_map vm;
  if (auto exit_code = ParseOptions("replay", argc, argv, visible, "recording", &vm))
    return *exit_code;
  if (vm.count("recording") == 0)
    return UsageError("replay", "missing REC (a recording or a pcap/pcapng capture)");
  if (to.empty()) return UsageError("replay", "missing --to HOST:PORT");
  std::string error;
  const auto target = common::ParseHostPort(to, "--to", 0, &error);
  if (!target) return UsageError("replay", error);
  ReplayScheduleOptions schedule;
  schedule.speed = speed;
  schedule.max_gap_s = max_gap_s;
  if (auto e = Validate(schedule)) return UsageError("replay", *e);
  if (udp_port < 0 || udp_port > 65535) return UsageError("replay", "--udp-port must be 0..65535");
  if (!SetUpLogging(log_level))
    return UsageError("replay", "unknown --log-level '" + log_level + "'");

  const std::string path = vm["recording"].as<std::string>();
  daemon::DatagramSourceOptions source_options;
  source_options.udp_port = static_cast<std::uint16_t>(udp_port);
  std::unique_ptr<daemon::DatagramSource> source =
      daemon::OpenDatagramFile(path, source_options, &error);
  if (!source) {
    std::fprintf(stderr, "lrfnet replay: %s\n", error.c_str());
    return kExitFailure;
  }

  asio::io_context io;
  const auto endpoint = Resolve(io, *target, &error);
  if (!endpoint) {
    std::fprintf(stderr, "lrfnet replay: %s\n", error.c_str());
    return kExitFailure;
  }

  std::unique_ptr<daemon::DatagramVerifier> verifier;
  if (vm.count("keys") != 0) {
    daemon::AuthOptions auth_options;
    if (!auth::Init()) return UsageError("replay", "--keys: libsodium cannot be initialised");
    if (auto e = daemon::LoadSensorKeys(vm["keys"].as<std::string>(), &auth_options))
      return UsageError("replay", "--keys " + *e);
    verifier = std::make_unique<daemon::DatagramVerifier>(auth_options);
  }

  asio::signal_set signals(io, SIGINT, SIGTERM);
  UdpReplayer replayer(io, *source, *endpoint, schedule, [&signals] {
    boost::system::error_code ignored;
    signals.cancel(ignored);
  });
  replayer.set_verifier(verifier.get());
  signals.async_wait([&replayer](const boost::system::error_code& ec, int) {
    if (!ec) replayer.Stop();
  });
  spdlog::info("replaying {} ({}) to {} port {} at speed {}{}", path,
               source->kind() == daemon::DatagramFileKind::kRecording ? "recording" : "capture",
               endpoint->address().to_string(), endpoint->port(), speed,
               speed == 0.0 ? " (as fast as possible)" : "");
  replayer.Start();
  io.run();

  const ReplayCounters& c = replayer.counters();
  std::printf(
      "summary: datagrams=%llu bytes=%llu send_errors=%llu replies=%llu elapsed_s=%.3f "
      "senders=%zu steps_back=%llu shortened_gaps=%llu refused=%llu interrupted=%s\n",
      static_cast<unsigned long long>(c.datagrams_sent),
      static_cast<unsigned long long>(c.bytes_sent), static_cast<unsigned long long>(c.send_errors),
      static_cast<unsigned long long>(c.replies), replayer.elapsed_s(), replayer.senders(),
      static_cast<unsigned long long>(replayer.schedule().steps_back()),
      static_cast<unsigned long long>(replayer.schedule().shortened_gaps()),
      static_cast<unsigned long long>(c.refused), replayer.interrupted() ? "yes" : "no");
  std::fflush(stdout);
  if (!replayer.interrupted() && !source->error().empty()) {
    std::fprintf(stderr, "lrfnet replay: %s\n", source->error().c_str());
    return kExitFailure;
  }
  return kExitOk;
}

}  // namespace lrfnet::tools
