#pragma once
// Test helpers for the ingest: real datagrams made by the tracker's encoder (what trackers send)
// and hostile ones made with libprotobuf. Test-only (links lrfnet_uplink and lrfnet_proto).

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "central_daemon/ingest/ingest.h"
#include "common/time.h"
#include "firmware_tracker/io/datagram_encoder.h"
#include "lrfnet.pb.h"

namespace lrfnet::daemon::testing {

using Bytes = std::vector<std::uint8_t>;

// The daemon's receive clock in the tests; trackers send at kT0 - 2 ms unless a test says so.
inline constexpr common::UtcNs kT0 = 1'700'000'000'000'000'000;
inline constexpr common::DurationNs kMs = common::kNsPerMs;
inline constexpr common::DurationNs kS = common::kNsPerS;

// Background geometry of an LMS5xx at 1/24 deg (-95 deg to 95 deg at 4561 beams).
inline constexpr double kBackgroundFirstAngleRad = -1.65806;
inline constexpr double kBackgroundStepRad = 0.000727;

inline std::span<const std::uint8_t> View(const Bytes& b) { return {b.data(), b.size()}; }

inline Bytes Serialize(const proto::Datagram& d) {
  const std::string s = d.SerializeAsString();
  return Bytes(s.begin(), s.end());
}

// A track with distinct values everywhere; its covariance is positive definite.
inline tracking::TrackReport MakeTrack(std::uint32_t i) {
  tracking::TrackReport t;
  t.track_id = 100 + i;
  t.state = i % 3 == 0   ? tracking::TrackState::kTentative
            : i % 3 == 1 ? tracking::TrackState::kConfirmed
                         : tracking::TrackState::kCoasting;
  t.kind =
      i % 2 == 0 ? tracking::MeasurementKind::kEllipse : tracking::MeasurementKind::kCenterOfMass;
  t.x_m = 1.25 + 0.5 * i;
  t.y_m = -2.0 + 0.25 * i;
  t.vx_mps = 0.1 * i;
  t.vy_mps = -0.7;
  Eigen::Matrix4d a;
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) a(r, c) = 0.01 * ((r + 1) * (c + 2) % 7) + (r == c ? 0.05 : 0.0);
  }
  t.covariance = a * a.transpose() + 1e-3 * Eigen::Matrix4d::Identity() * (1 + i);
  t.age_scans = 3 * i + 1;
  t.points = 10 + i;
  t.ellipse_yaw_rad = 0.1 * i - 0.3;
  return t;
}

// One tracker session: encodes with the tracker's DatagramEncoder and collects the bytes.
class FakeTracker final : public io::DatagramSink {
 public:
  FakeTracker(const std::string& sensor_id, std::uint64_t session_id)
      : encoder_(io::DatagramEncoderOptions{sensor_id, session_id}) {}

  void Send(std::span<const std::uint8_t> datagram, common::UtcNs) override {
    out_.emplace_back(datagram.begin(), datagram.end());
  }

  // A scan with `tracks` tracks (MakeTrack(0..tracks-1)): ceil(tracks / 14) parts, at least one.
  std::vector<Bytes> Tracks(std::size_t tracks, common::UtcNs sent_ns,
                            std::uint32_t scan_counter = 7) {
    tracking::ScanTracks scan;
    scan.scan_start_ns = sent_ns - 30 * kMs;
    scan.scan_period_s = 0.04;
    scan.scan_counter = scan_counter;
    for (std::uint32_t i = 0; i < tracks; ++i) (void)scan.tracks.push_back(MakeTrack(i));
    encoder_.EncodeTracks(scan, sent_ns, *this);
    return Take();
  }
  // A background of `beams` beams: ranges 1.000 m + 1 mm per beam, every 13th free (0).
  std::vector<Bytes> Background(std::size_t beams, common::UtcNs sent_ns) {
    std::vector<float> ranges(beams);
    for (std::size_t i = 0; i < beams; ++i)
      ranges[i] = i % 13 == 0 ? 0.0f : 1.0f + 0.001f * static_cast<float>(i);
    io::BackgroundSnapshotView view;
    view.learned_until_ns = sent_ns - 500 * kMs;
    view.first_angle_rad = kBackgroundFirstAngleRad;
    view.angle_step_rad = kBackgroundStepRad;
    view.range_m = ranges;
    encoder_.EncodeBackground(view, sent_ns, *this);
    return Take();
  }
  Bytes Health(common::UtcNs sent_ns) {
    io::HealthReport h;
    h.scans = 1234;
    h.bad_frames = 2;
    h.decode_errors = 3;
    h.reconnects = 4;
    h.dropped_tracks = 5;
    h.datagrams_sent = 6789;
    h.send_errors = 7;
    h.scan_cpu_us_mean = 812.5f;
    h.scan_cpu_us_max = 2048.25f;
    h.clock_sync = io::ClockSync::kSynchronized;
    h.clock_error_estimate_s = 0.0015f;
    h.tick_offset_s = 1234.5678;
    h.tick_drift_ppm = -12.5;
    h.device_restarts = 1;
    encoder_.EncodeHealth(h, sent_ns, *this);
    return TakeOne();
  }
  Bytes Info(common::UtcNs sent_ns) {
    io::SensorInfoReport r;
    r.model = "TiM781S";
    r.serial = "18090362";
    r.firmware = "V2.10";
    r.first_angle_rad = -2.35619;
    r.angle_step_rad = 0.00581776;
    r.beam_count = 811;
    r.fov_rad = 4.71239;
    r.scan_frequency_hz = 15.0;
    r.max_range_m = 25.0;
    r.tracker_version = "lrfnet-tracker 0.1.0";
    r.kind = tracking::MeasurementKind::kEllipse;
    encoder_.EncodeSensorInfo(r, sent_ns, *this);
    return TakeOne();
  }
  std::uint64_t next_sequence() const { return encoder_.next_sequence(); }

 private:
  std::vector<Bytes> Take() {
    std::vector<Bytes> out;
    out.swap(out_);
    return out;
  }
  Bytes TakeOne() {
    std::vector<Bytes> all = Take();
    return all.empty() ? Bytes{} : all.front();
  }

  io::DatagramEncoder encoder_;
  std::vector<Bytes> out_;
};

// Remembers everything the ingest hands on.
struct RecordingListener final : IngestListener {
  std::vector<std::pair<std::string, TrackFrameData>> frames;
  std::vector<std::pair<std::string, BackgroundScan>> backgrounds;
  std::vector<std::pair<std::string, SensorDescription>> infos;
  std::vector<std::pair<std::string, SensorHealth>> healths;
  std::vector<SensorEvent> events;

  void OnTrackFrame(const std::string& id, const TrackFrameData& f) override {
    frames.emplace_back(id, f);
  }
  void OnBackground(const std::string& id, const BackgroundScan& b) override {
    backgrounds.emplace_back(id, b);
  }
  void OnSensorInfo(const std::string& id, const SensorDescription& i) override {
    infos.emplace_back(id, i);
  }
  void OnHealth(const std::string& id, const SensorHealth& h) override {
    healths.emplace_back(id, h);
  }
  void OnSensorEvent(const SensorEvent& e) override { events.push_back(e); }

  std::size_t Count(SensorEventKind kind) const {
    std::size_t n = 0;
    for (const SensorEvent& e : events) n += e.kind == kind ? 1 : 0;
    return n;
  }
};

}  // namespace lrfnet::daemon::testing
