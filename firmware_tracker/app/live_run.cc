#include "firmware_tracker/app/live_run.h"

#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include <boost/asio/io_context.hpp>
#include <boost/asio/signal_set.hpp>
#include <boost/asio/steady_timer.hpp>
#include <chrono>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <memory>

#include "common/systemd_notify.h"
#include "firmware_tracker/app/outputs.h"
#include "firmware_tracker/app/run_setup.h"
#include "firmware_tracker/app/tracker_node.h"
#include "firmware_tracker/io/sick_client.h"
#include "firmware_tracker/io/system_clock.h"

namespace lrfnet::tracker {

namespace asio = boost::asio;

int RunLive(const TrackerConfig& config, const std::string& record_path, ScanLog& log) {
  Outputs outputs;
  if (auto e = outputs.Open(config, record_path, io::NowUtcNs())) {
    std::fprintf(stderr, "lrfnet-tracker: %s\n", e->c_str());
    return kExitFailure;
  }
  auto node = std::make_unique<TrackerNode>(config, RandomSessionId(), outputs.sink());
  io::ClockStatus clock_status = io::ReadClockStatus(config.clock_status);
  spdlog::info("gateway clock: {} (estimated error {:.3f} ms)", io::ToString(clock_status.sync),
               clock_status.esterror_s * 1e3);

  asio::io_context io;
  asio::signal_set signals(io, SIGINT, SIGTERM);
  asio::steady_timer timer(io);
  std::unique_ptr<io::SickClient> client;
  std::uint64_t ticks = 0;
  // Under systemd (Type=notify): ready at the first scan, watchdog from the scan path, so a link
  // that delivers no scans gets the tracker restarted.
  common::SystemdNotifier notifier(common::SystemdNotifier::ProcessEnvironment());
  if (!notifier.error().empty()) spdlog::warn("systemd notification: {}", notifier.error());
  bool ready = false;

  const auto link_health = [&] {
    LinkHealth link;
    const io::SickClientCounters& c = client->counters();
    link.bad_frames = c.bad_frames;
    link.decode_errors = client->decoder_counters().scan_decode_errors;
    link.reconnects = c.reconnects;
    link.send_errors = outputs.send_errors();
    return link;
  };
  std::function<void()> arm_timer = [&] {
    timer.expires_after(std::chrono::milliseconds(200));
    timer.async_wait([&](const boost::system::error_code& ec) {
      if (ec) return;
      ++ticks;
      outputs.ServeRequests(*node);
      if (ticks % 5 == 0) clock_status = io::ReadClockStatus(config.clock_status);
      node->OnTick(io::NowUtcNs(), link_health(), clock_status);
      if (ticks % 50 == 0) {
        const io::SickClientCounters& c = client->counters();
        spdlog::info("status: scans={} tracks={} reconnects={} bad_frames={} clock={} {}", c.scans,
                     node->pipeline().last_tracks().tracks.size(), c.reconnects, c.bad_frames,
                     io::ToString(clock_status.sync), NodeSummary(*node));
        notifier.Status(fmt::format("scans {}, tracks {}, reconnects {}, clock {}", c.scans,
                                    node->pipeline().last_tracks().tracks.size(), c.reconnects,
                                    io::ToString(clock_status.sync)));
      }
      arm_timer();
    });
  };

  io::SickClientOptions link = config.link;
  client = std::make_unique<io::SickClient>(
      io, link, [&](const cola::ScanTelegram& scan, common::UtcNs receive_time_ns) {
        const auto started = std::chrono::steady_clock::now();
        const io::SickDeviceInfo& d = client->device_info();
        node->SetDeviceIdentity(d.ident_name, d.serial_number, d.firmware_version);
        outputs.ServeRequests(*node);
        node->OnScan(scan, receive_time_ns, io::NowUtcNs());
        node->RecordScanCpu(ElapsedUs(started));
        node->OnTick(io::NowUtcNs(), link_health(), clock_status);
        if (!ready) {
          ready = true;
          notifier.Ready(fmt::format("streaming from {}:{}", link.host, link.port));
        }
        notifier.Watchdog(common::SteadyNowNs());
        if (!log.OnScan(config.sensor_id, scan, receive_time_ns, *node)) {
          client->Stop();
          timer.cancel();
          signals.cancel();
        }
      });
  signals.async_wait([&](const boost::system::error_code& ec, int signal_number) {
    if (ec) return;
    spdlog::info("signal {}: stopping", signal_number);
    notifier.Stopping();
    client->Stop();
    timer.cancel();
  });
  client->Start();
  arm_timer();
  io.run();

  const bool closed = outputs.Close();
  const io::SickClientCounters& c = client->counters();
  const io::SickDeviceInfo& d = client->device_info();
  fmt::print("device: sensor={} ident='{}' version='{}' firmware='{}' serial='{}'\n",
             config.sensor_id, d.ident_name, d.ident_version, d.firmware_version, d.serial_number);
  fmt::print(
      "summary: sensor={} mode=live scans={} connects={} connect_failures={} reconnects={} "
      "reply_timeouts={} read_timeouts={} sfa_replies={} handshake_failures={} disconnects={} "
      "bad_frames={} bytes={} {} {}{}\n",
      config.sensor_id, c.scans, c.connects, c.connect_failures, c.reconnects, c.reply_timeouts,
      c.read_timeouts, c.sfa_replies, c.handshake_failures, c.disconnects, c.bad_frames, c.bytes,
      DecoderSummary(client->decoder_counters()), NodeSummary(*node), outputs.Summary());
  std::fflush(stdout);
  return closed ? kExitOk : kExitFailure;
}

}  // namespace lrfnet::tracker
