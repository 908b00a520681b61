#include "central_daemon/app/daemon.h"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>

#include "lrfnet.pb.h"

namespace lrfnet::daemon {
namespace {

constexpr std::size_t kMaxEvents = 1000;
constexpr std::size_t kMaxSensorsInStatus = 8;

double Seconds(common::DurationNs ns) { return static_cast<double>(ns) * 1e-9; }

// Receive minus send time: milliseconds on a synchronised network; hours or days for a replay of
// an old capture.
std::string OffsetText(double s) {
  const double a = std::abs(s);
  if (a < 1.0) return fmt::format("{:+.1f}ms", s * 1e3);
  if (a < 3600.0) return fmt::format("{:+.1f}s", s);
  if (a < 86400.0 * 3) return fmt::format("{:+.1f}h", s / 3600.0);
  return fmt::format("{:+.1f}d", s / 86400.0);
}

std::string ClockText(const SensorStatus& s) {
  const char* sync = s.health ? ToString(s.health->clock_sync) : "no-health";
  return fmt::format("clock {} rx-sent {}", sync, OffsetText(s.receive_minus_sent_s));
}

}  // namespace

std::optional<std::string> Validate(const DaemonOptions& o) {
  if (auto e = Validate(o.ingest)) return e;
  if (auto e = Validate(o.store)) return "store." + *e;
  return std::nullopt;
}

std::vector<std::uint8_t> EncodeRequestDatagram(const PendingRequest& request,
                                                std::uint64_t sequence, common::UtcNs sent_ns,
                                                std::uint64_t session_id) {
  proto::Datagram d;
  d.set_version(proto::PROTOCOL_VERSION_1);
  d.set_sensor_id(request.sensor_id);
  d.set_sequence(sequence);
  d.set_sent_ns(sent_ns);
  d.set_session_id(session_id);
  proto::Request* r = d.mutable_request();
  r->set_send_sensor_info(request.send_sensor_info);
  r->set_send_background(request.send_background);
  std::vector<std::uint8_t> bytes(d.ByteSizeLong());
  d.SerializeWithCachedSizesToArray(bytes.data());
  return bytes;
}

Daemon::Daemon(const DaemonOptions& options, RecordSink* recorder, RequestSink* requests,
               std::uint64_t session_id)
    : options_(options),
      recorder_(recorder),
      requests_(requests),
      session_id_(session_id),
      store_(options.store),
      ingest_(options.ingest, this) {
  if (auto e = Validate(options)) {
    std::fprintf(stderr, "Daemon: invalid options: %s\n", e->c_str());
    std::abort();
  }
}

void Daemon::OnDatagram(std::span<const std::uint8_t> datagram, std::string_view source,
                        common::UtcNs receive_ns) {
  // Recorded before anything can refuse it: the recording holds what arrived, for replay.
  if (recorder_ != nullptr) recorder_->Record(datagram, source, receive_ns);
  ingest_.OnDatagram(datagram, source, receive_ns);
}

void Daemon::OnTick(common::UtcNs now_ns) {
  ingest_.OnTick(now_ns);
  store_.Evict(now_ns);
  if (recorder_ != nullptr) recorder_->FlushIfDue(now_ns);
  // Taking a request counts it as sent: only take them when they can go out.
  if (!options_.send_requests || requests_ == nullptr) return;
  for (const PendingRequest& r : ingest_.TakeRequests(now_ns)) {
    const auto bytes = EncodeRequestDatagram(r, request_sequence_++, now_ns, session_id_);
    std::span<const std::uint8_t> out = bytes;
    std::array<std::uint8_t, kMaxDatagramBytes> sealed{};
    if (ingest_.authenticated()) {
      // Sealed with the sensor's key for the tracker direction; a sensor without a verified
      // datagram gets none (it cannot have asked for anything).
      const std::size_t n = ingest_.SealRequest(r.sensor_id, bytes, sealed);
      if (n == 0) {
        ++requests_dropped_;
        continue;
      }
      out = std::span<const std::uint8_t>(sealed).first(n);
    }
    if (requests_->SendTo(r.source, out)) {
      ++requests_sent_;
    } else {
      ++requests_dropped_;
    }
  }
}

void Daemon::Reconfigure(const DaemonOptions& options) {
  if (auto e = Validate(options)) {
    std::fprintf(stderr, "Daemon: invalid options: %s\n", e->c_str());
    std::abort();
  }
  options_ = options;
  ingest_.Reconfigure(options.ingest);
  store_.Reconfigure(options.store);
}

void Daemon::OnTrackFrame(const std::string& sensor_id, const TrackFrameData& frame) {
  store_.Add(sensor_id, frame);
  if (frame_listener_ != nullptr) frame_listener_->OnFrame(sensor_id, frame);
}

void Daemon::OnBackground(const std::string& sensor_id, const BackgroundScan& background) {
  store_.SetBackground(sensor_id, background);
}

void Daemon::OnSensorInfo(const std::string& sensor_id, const SensorDescription& info) {
  if (frame_listener_ != nullptr) frame_listener_->OnSensorInfo(sensor_id, info);
}

void Daemon::OnSensorEvent(const SensorEvent& event) {
  if (events_.size() >= kMaxEvents) events_.pop_front();
  events_.push_back(event);
}

std::vector<SensorEvent> Daemon::TakeEvents() {
  std::vector<SensorEvent> out(events_.begin(), events_.end());
  events_.clear();
  return out;
}

std::string Daemon::StatusLine(common::UtcNs now_ns) {
  const double interval_s =
      status_since_ns_ > 0 && now_ns > status_since_ns_ ? Seconds(now_ns - status_since_ns_) : 0.0;
  const IngestCounters& c = ingest_.counters();
  const std::vector<SensorStatus> sensors = ingest_.Sensors();

  struct Row {
    const SensorStatus* status;
    double rate;
    double loss;
  };
  std::vector<Row> rows;
  std::map<std::string, SensorMark, std::less<>> marks;
  std::uint64_t lost = 0, received = 0, lost_total = 0, reordered = 0, duplicates = 0;
  std::size_t silent = 0;
  for (const SensorStatus& s : sensors) {
    const SequenceCounters& q = s.counters.sequence;
    const auto found = status_marks_.find(s.sensor_id);
    const SensorMark before = found != status_marks_.end() ? found->second : SensorMark{};
    const std::uint64_t d_received = q.received - std::min(q.received, before.received);
    const std::uint64_t d_lost = q.lost - std::min(q.lost, before.lost);
    const std::uint64_t d_datagrams = s.counters.datagrams - std::min(s.counters.datagrams, before.datagrams);
    received += d_received;
    lost += d_lost;
    lost_total += q.lost;
    reordered += q.reordered;
    duplicates += q.duplicates;
    if (s.silent) ++silent;
    const double loss = d_received + d_lost > 0
                            ? static_cast<double>(d_lost) / static_cast<double>(d_received + d_lost)
                            : 0.0;
    rows.push_back({&s, interval_s > 0 ? static_cast<double>(d_datagrams) / interval_s : 0.0, loss});
    marks.emplace(s.sensor_id, SensorMark{s.counters.datagrams, q.received, q.lost});
  }
  const std::uint64_t d_datagrams = c.datagrams - status_counters_.datagrams;
  const std::uint64_t d_rejected = c.rejected - status_counters_.rejected;
  const double loss = received + lost > 0
                          ? static_cast<double>(lost) / static_cast<double>(received + lost)
                          : 0.0;
  std::string line = fmt::format(
      "{} sensors ({} silent) | {:.1f} datagrams/s, {} invalid | loss {:.2f}% ({} total), "
      "reordered {}, duplicates {} | store {} frames {:.1f} MiB",
      sensors.size(), silent, interval_s > 0 ? static_cast<double>(d_datagrams) / interval_s : 0.0,
      d_rejected, loss * 100.0, lost_total, reordered, duplicates, store_.frames(),
      static_cast<double>(store_.bytes_used()) / (1 << 20));

  // The sensors a person should look at first: silent ones, then the highest loss.
  std::stable_sort(rows.begin(), rows.end(), [](const Row& a, const Row& b) {
    if (a.status->silent != b.status->silent) return a.status->silent;
    return a.loss > b.loss;
  });
  const std::size_t shown = std::min(rows.size(), kMaxSensorsInStatus);
  for (std::size_t i = 0; i < shown; ++i) {
    const Row& r = rows[i];
    line += fmt::format(" | {}{} {:.1f}/s loss {:.2f}% {}", r.status->sensor_id,
                        r.status->silent ? " SILENT" : "", r.rate, r.loss * 100.0,
                        ClockText(*r.status));
  }
  if (rows.size() > shown) line += fmt::format(" | +{} more", rows.size() - shown);
  // Authentication: what was refused since the start, by reason (all sensors and unattributed).
  if (!ingest_.authenticated()) {
    line += " | UNAUTHENTICATED (no --keys)";
  } else {
    std::array<std::uint64_t, kRejectReasonCount> refused = c.unattributed;
    for (const SensorStatus& s : sensors) {
      for (std::size_t i = 0; i < kRejectReasonCount; ++i) refused[i] += s.counters.rejected[i];
    }
    std::string reasons;
    for (std::size_t i = static_cast<std::size_t>(RejectReason::kUnsigned); i < kRejectReasonCount;
         ++i) {
      if (refused[i] == 0) continue;
      reasons += fmt::format("{}{} {}", reasons.empty() ? "" : ", ",
                             ToString(static_cast<RejectReason>(i)), refused[i]);
    }
    line += fmt::format(" | auth: {} verified, refused {}", c.verified,
                        reasons.empty() ? "none" : reasons);
  }

  status_since_ns_ = now_ns;
  status_counters_ = c;
  status_marks_ = std::move(marks);
  return line;
}

}  // namespace lrfnet::daemon
