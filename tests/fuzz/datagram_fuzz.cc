// Fuzz target for the daemon's ingest: arbitrary bytes as a short stream of datagrams from the
// network into a fresh Ingest, so the decoder, the validation, the sequence state, background
// reassembly, silence and request scheduling all see hostile input together.
//
// Input format (datagram_seeds.cc writes the seeds in it): datagrams separated by the 4-byte
// marker kMarker; the byte after each marker is a control byte for the datagram after it. A
// datagram before the first marker has kDefaultControl (so an input without any marker is one
// datagram); an input starting with the marker has none before it. Control bits:
//   0-1: receive clock step before the datagram: +1 ms, +40 ms, +4 s (beyond silent_after_s) or
//        -1 s (a clock stepping back);
//   2:   OnTick after it;  3: TakeRequests after it;  4-5: which of four source addresses.
// Properties checked with __builtin_trap:
//   - every datagram is counted exactly once, accepted or rejected with a reason, and every
//     rejection once: unattributed or at exactly one sensor; at most max_sensors sensors;
//   - a disposition is consistent (accepted: a sensor id and no reason; rejected: a reason and a
//     detail line); an accepted datagram given again is a duplicate;
//   - what reaches the listener is valid: finite tracks within the bounds, positive semi-definite
//     covariances, parts within their counts, whole backgrounds within the beam bound; the
//     listener saw exactly as many frames and backgrounds as the counters say;
//   - requests go only to known, non-silent sensors and ask for something.

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <numeric>
#include <span>
#include <string>

#include "central_daemon/ingest/datagram_decoder.h"
#include "central_daemon/ingest/ingest.h"

namespace {

using lrfnet::daemon::BackgroundScan;
using lrfnet::daemon::Disposition;
using lrfnet::daemon::Ingest;
using lrfnet::daemon::IngestOptions;
using lrfnet::daemon::RejectReason;
using lrfnet::daemon::SensorEvent;
using lrfnet::daemon::SensorStatus;
using lrfnet::daemon::TrackFrameData;

// The same marker and control layout as in datagram_seeds.cc.
constexpr std::uint8_t kMarker[4] = {0xFF, 'L', 'R', 'F'};
constexpr std::uint8_t kDefaultControl = 0x0D;  // +40 ms, tick, requests, source 0
// Receive clock of the first datagram minus its step; the seeds are stamped just before it.
constexpr lrfnet::common::UtcNs kStartNs = 1'700'000'000'000'000'000;
constexpr const char* kSources[4] = {"10.0.0.3:5000", "10.0.0.4:5000", "[fe80::1]:40000",
                                     "127.0.0.1:1"};

IngestOptions FuzzOptions() {
  IngestOptions o;
  o.max_sensors = 4;  // small, so the table fills up
  o.reorder_window_datagrams = 64;
  o.max_sequence_jump = 1000;
  o.validation.max_part_count = 16;
  o.validation.max_background_beams = 8192;
  o.validation.max_tracks_per_frame = 32;
  return o;
}

void Check(bool ok) {
  if (!ok) __builtin_trap();
}

struct CheckingListener final : lrfnet::daemon::IngestListener {
  lrfnet::daemon::ValidationOptions limits;
  std::uint64_t frames = 0;
  std::uint64_t backgrounds = 0;

  void OnTrackFrame(const std::string& id, const TrackFrameData& f) override {
    ++frames;
    Check(!id.empty());
    Check(f.part < f.part_count && f.part_count <= limits.max_part_count);
    Check(f.tracks.size() <= limits.max_tracks_per_frame);
    Check(f.scan_period_s > 0.0 && f.scan_period_s <= 1.0);
    for (const auto& t : f.tracks) {
      Check(std::isfinite(t.x_m) && std::isfinite(t.y_m) && std::isfinite(t.vx_mps) &&
            std::isfinite(t.vy_mps) && std::isfinite(t.ellipse_yaw_rad));
      Check(std::fabs(t.x_m) <= limits.max_position_m && std::fabs(t.y_m) <= limits.max_position_m);
      Check(std::fabs(t.vx_mps) <= limits.max_speed_mps &&
            std::fabs(t.vy_mps) <= limits.max_speed_mps);
      Check(lrfnet::daemon::IsCovariancePsd(t.covariance));
    }
  }
  void OnBackground(const std::string& id, const BackgroundScan& b) override {
    ++backgrounds;
    Check(!id.empty());
    Check(!b.ranges_mm.empty() && b.ranges_mm.size() <= limits.max_background_beams);
    Check(std::isfinite(b.first_angle_rad) && std::isfinite(b.angle_step_rad) &&
          b.angle_step_rad != 0.0);
  }
  void OnSensorEvent(const SensorEvent& e) override { Check(!e.sensor_id.empty()); }
};

std::uint64_t Sum(const std::array<std::uint64_t, lrfnet::daemon::kRejectReasonCount>& a) {
  return std::accumulate(a.begin(), a.end(), std::uint64_t{0});
}

const std::uint8_t* FindMarker(const std::uint8_t* from, const std::uint8_t* end) {
  for (const std::uint8_t* p = from; end - p >= static_cast<std::ptrdiff_t>(sizeof(kMarker)); ++p) {
    if (std::memcmp(p, kMarker, sizeof(kMarker)) == 0) return p;
  }
  return end;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const IngestOptions options = FuzzOptions();
  CheckingListener listener;
  listener.limits = options.validation;
  Ingest ingest(options, &listener);

  const std::uint8_t* const end = data + size;
  const std::uint8_t* chunk = data;
  std::uint8_t control = kDefaultControl;
  if (FindMarker(data, end) == data && size > 0) {
    chunk = data + sizeof(kMarker);
    if (chunk < end) control = *chunk++;
  }
  lrfnet::common::UtcNs now_ns = kStartNs;
  std::uint64_t calls = 0;
  while (true) {
    const std::uint8_t* const next = FindMarker(chunk, end);
    switch (control & 3) {
      case 0:
        now_ns += 1'000'000;
        break;
      case 1:
        now_ns += 40'000'000;
        break;
      case 2:
        now_ns += 4'000'000'000;
        break;
      default:
        now_ns -= 1'000'000'000;
        break;
    }
    const std::span<const std::uint8_t> bytes(chunk, static_cast<std::size_t>(next - chunk));
    const char* source = kSources[(control >> 4) & 3];
    const Disposition d = ingest.OnDatagram(bytes, source, now_ns);
    ++calls;
    if (d.accepted) {
      Check(d.reason == RejectReason::kCount && !d.sensor_id.empty() && d.detail.empty());
      Check(!bytes.empty() && bytes.size() <= lrfnet::daemon::kMaxDatagramBytes);
      const Disposition again = ingest.OnDatagram(bytes, source, now_ns);
      ++calls;
      Check(!again.accepted && again.reason == RejectReason::kDuplicate &&
            again.sensor_id == d.sensor_id);
    } else {
      Check(d.reason < RejectReason::kCount && !d.detail.empty());
    }
    if (control & 4) ingest.OnTick(now_ns);
    if (control & 8) {
      for (const auto& r : ingest.TakeRequests(now_ns)) {
        const auto s = ingest.Sensor(r.sensor_id);
        Check(s.has_value() && !s->silent && r.source == s->source);
        Check(r.send_sensor_info || r.send_background);
      }
    }
    if (next == end) break;
    chunk = next + sizeof(kMarker);
    control = kDefaultControl;
    if (chunk < end) control = *chunk++;
  }

  const auto& c = ingest.counters();
  Check(c.datagrams == calls);
  Check(c.accepted + c.rejected == c.datagrams);
  const auto sensors = ingest.Sensors();
  Check(sensors.size() <= options.max_sensors);
  std::uint64_t rejected = Sum(c.unattributed), datagrams = Sum(c.unattributed);
  std::uint64_t frames = 0, backgrounds = 0, received = 0;
  for (const SensorStatus& s : sensors) {
    rejected += Sum(s.counters.rejected);
    datagrams += s.counters.datagrams;
    received += s.counters.sequence.received;
    frames += s.counters.track_frames;
    backgrounds += s.counters.backgrounds_completed;
    Check(s.counters.datagrams == s.counters.sequence.received + Sum(s.counters.rejected));
    Check(s.counters.rejected[static_cast<std::size_t>(RejectReason::kDuplicate)] ==
          s.counters.sequence.duplicates);
    Check(std::isfinite(s.receive_minus_sent_s));
  }
  Check(rejected == c.rejected);
  Check(datagrams == c.datagrams);
  Check(received == c.accepted);
  Check(frames == listener.frames && backgrounds == listener.backgrounds);
  return 0;
}
