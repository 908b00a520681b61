#include "firmware_tracker/app/outputs.h"

#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include <cstdio>
#include <span>

#include "common/datagram_auth.h"
#include "common/host_port.h"
#include "common/key_file.h"
#include "firmware_tracker/io/system_clock.h"

#ifndef LRFNET_VERSION
#define LRFNET_VERSION "unknown"
#endif

namespace lrfnet::tracker {

using common::ParseHostPort;

std::optional<std::string> Outputs::Open(const TrackerConfig& config,
                                         const std::string& record_path, common::UtcNs created_ns) {
  std::optional<auth::SensorKeys> keys;
  if (!config.key_file.empty()) {
    auth::KeyFile key;
    if (!auth::Init()) return "--key: libsodium cannot be initialised";
    if (auto e = auth::LoadSensorKey(config.key_file, config.sensor_id, &key)) return "--key " + *e;
    keys = auth::DeriveSensorKeys(key.key, key.epoch);
    // Sealed before both outputs. The counter starts at the wall clock's now (also in replay), so
    // it is beyond every counter of an earlier start of this sensor (datagram_auth.h).
    auth::SealerOptions sealer;
    sealer.sensor_id = config.sensor_id;
    sealer.keys = *keys;
    sealer.encrypt = config.encrypt;
    auth::RandomBytes(std::span(reinterpret_cast<std::uint8_t*>(&sealer.salt), sizeof sealer.salt));
    sealer.first_counter = static_cast<std::uint64_t>(io::NowUtcNs());
    sealing_ = std::make_unique<io::SealingSink>(sealer, fanout_);
    spdlog::info("datagrams sealed with the key of {} (epoch {}){}", config.sensor_id, key.epoch,
                 config.encrypt ? ", content encrypted" : "");
  }
  if (!config.uplink_address.empty()) {
    std::string error;
    const auto endpoint = ParseHostPort(config.uplink_address, "--uplink", 0, &error);
    if (!endpoint) return error;
    io::UdpUplinkOptions options;
    options.host = endpoint->host;
    options.port = endpoint->port;
    options.sensor_id = config.sensor_id;
    options.keys = keys;
    if (auto e = io::Validate(options)) return "--uplink: " + *e;
    udp_ = std::make_unique<io::UdpUplink>(options);
    if (auto e = udp_->Open()) return "--uplink " + config.uplink_address + ": " + *e;
    (void)fanout_.Add(udp_.get());
  }
  if (!record_path.empty()) {
    io::RecordingWriterOptions options;
    options.path = record_path;
    options.writer = std::string("lrfnet-tracker ") + LRFNET_VERSION;
    options.source = io::TrackerRecordSource(config.sensor_id);
    if (auto e = io::Validate(options)) return "--out: " + *e;
    recording_ = std::make_unique<io::RecordingWriter>(options);
    if (auto e = recording_->Open(created_ns)) return "--out " + record_path + ": " + *e;
    (void)fanout_.Add(recording_.get());
  }
  return std::nullopt;
}

io::DatagramSink& Outputs::sink() {
  if (sealing_) return *sealing_;
  return fanout_;
}

void Outputs::ServeRequests(TrackerNode& node) {
  if (!udp_) return;
  udp_->Poll();
  const io::PendingRequests requests = udp_->TakeRequests();
  if (requests.send_sensor_info) node.RequestSensorInfo();
  if (requests.send_background) node.RequestBackground();
}

std::uint64_t Outputs::send_errors() const {
  return (udp_ ? udp_->counters().send_errors : 0) +
         (recording_ ? recording_->counters().write_errors : 0);
}

bool Outputs::Close() {
  if (!recording_) return true;
  if (auto e = recording_->Close()) {
    std::fprintf(stderr, "lrfnet-tracker: recording: %s\n", e->c_str());
    return false;
  }
  return true;
}

std::string Outputs::Summary() const {
  std::string out;
  if (udp_) {
    const io::UdpUplinkCounters& c = udp_->counters();
    out += fmt::format(" udp_sent={} udp_bytes={} udp_send_errors={} requests={}", c.datagrams_sent,
                       c.bytes_sent, c.send_errors, c.received);
    const io::RequestDecoderCounters& r = udp_->request_counters();
    std::uint64_t refused = 0;
    for (const std::uint64_t n : r.rejected) refused += n;
    out += fmt::format(" requests_accepted={} requests_refused={}", r.accepted, refused);
  }
  if (recording_) {
    const io::RecordingCounters& c = recording_->counters();
    out += fmt::format(" recorded={} recording_bytes={} write_errors={}", c.entries_written,
                       c.bytes_written, c.write_errors);
  }
  return out;
}

}  // namespace lrfnet::tracker
