#include "central_daemon/app/stats_json.h"

namespace lrfnet::daemon {
namespace {

nlohmann::json Reasons(const std::array<std::uint64_t, kRejectReasonCount>& counts) {
  nlohmann::json j = nlohmann::json::object();
  for (std::size_t i = 0; i < kRejectReasonCount; ++i) {
    if (counts[i] > 0) j[ToString(static_cast<RejectReason>(i))] = counts[i];
  }
  return j;
}

}  // namespace

nlohmann::json StatsJson(const Ingest& ingest, const TrackStore& store) {
  const IngestCounters& c = ingest.counters();
  nlohmann::json j;
  j["datagrams"] = c.datagrams;
  j["bytes"] = c.bytes;
  j["accepted"] = c.accepted;
  j["rejected"] = c.rejected;
  j["unattributed"] = Reasons(c.unattributed);
  j["authenticated"] = ingest.authenticated();
  j["verified"] = c.verified;
  j["unverified"] = c.unverified;
  j["store"] = {{"frames", store.frames()},
                {"bytes_used", store.bytes_used()},
                {"frames_added", store.counters().frames_added},
                {"parts_merged", store.counters().parts_merged},
                {"late_inserts", store.counters().late_inserts},
                {"evicted_by_age", store.counters().evicted_by_age},
                {"evicted_by_memory", store.counters().evicted_by_memory}};
  std::map<std::string, SensorStoreInfo> stored;
  for (const SensorStoreInfo& s : store.Sensors()) stored[s.sensor_id] = s;
  nlohmann::json sensors = nlohmann::json::array();
  for (const SensorStatus& s : ingest.Sensors()) {
    const SensorCounters& k = s.counters;
    nlohmann::json e;
    e["sensor_id"] = s.sensor_id;
    e["source"] = s.source;
    e["session_id"] = s.session_id;
    e["silent"] = s.silent;
    e["first_receive_ns"] = s.first_receive_ns;
    e["last_receive_ns"] = s.last_receive_ns;
    e["receive_minus_sent_s"] = s.receive_minus_sent_s;
    e["datagrams"] = k.datagrams;
    e["bytes"] = k.bytes;
    e["track_frames"] = k.track_frames;
    e["background_parts"] = k.background_parts;
    e["health"] = k.health;
    e["sensor_info"] = k.sensor_info;
    e["backgrounds_completed"] = k.backgrounds_completed;
    e["backgrounds_abandoned"] = k.backgrounds_abandoned;
    e["silent_periods"] = k.silent_periods;
    e["requests_sent"] = k.requests_sent;
    e["rejected"] = Reasons(k.rejected);
    e["sequence"] = {{"received", k.sequence.received},   {"lost", k.sequence.lost},
                     {"reordered", k.sequence.reordered}, {"duplicates", k.sequence.duplicates},
                     {"restarts", k.sequence.restarts},   {"resets", k.sequence.resets}};
    e["has_background"] = s.has_background;
    if (s.info) {
      e["info"] = {{"model", s.info->model},
                   {"serial", s.info->serial},
                   {"firmware", s.info->firmware},
                   {"beam_count", s.info->beam_count},
                   {"scan_frequency_hz", s.info->scan_frequency_hz},
                   {"tracker_version", s.info->tracker_version}};
    }
    if (s.health) {
      e["clock_sync"] = ToString(s.health->clock_sync);
      e["clock_error_estimate_s"] = s.health->clock_error_estimate_s;
      e["tracker_scans"] = s.health->scans;
    }
    const auto it = stored.find(s.sensor_id);
    if (it != stored.end()) {
      e["stored_frames"] = it->second.frames;
      e["stored_tracks"] = it->second.tracks;
      e["first_scan_ns"] = it->second.first_scan_ns;
      e["last_scan_ns"] = it->second.last_scan_ns;
    }
    sensors.push_back(std::move(e));
  }
  j["sensors"] = std::move(sensors);
  return j;
}

nlohmann::json ReceiverJson(const UdpReceiverCounters& c) {
  return {{"datagrams", c.datagrams},         {"bytes", c.bytes},
          {"batches", c.batches},             {"receive_errors", c.receive_errors},
          {"truncated", c.truncated},         {"kernel_drops", c.kernel_drops},
          {"sent", c.sent},                   {"send_errors", c.send_errors},
          {"unknown_destinations", c.unknown_destinations}};
}

nlohmann::json RecordingJson(const RecordingWriterCounters& c) {
  return {{"entries", c.entries},
          {"entries_written", c.entries_written},
          {"bytes_written", c.bytes_written},
          {"files", c.files},
          {"flushes", c.flushes},
          {"write_errors", c.write_errors},
          {"dropped_entries", c.dropped_entries}};
}

}  // namespace lrfnet::daemon
