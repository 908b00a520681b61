// Seeds for datagram_fuzz, in its input format (datagram_fuzz.cc: datagrams separated by a marker
// and a control byte): valid datagrams of every kind made by the tracker's encoder, whole scans and
// snapshots of several parts, sessions with loss, reordering, duplicates, restarts and silence, and
// hostile variants made with libprotobuf.

#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "central_daemon/ingest/ingest_test_util.h"
#include "lrfnet.pb.h"
#include "tests/fuzz/daemon_seeds.h"

namespace lrfnet::fuzz {
namespace {

using daemon::testing::Bytes;
using daemon::testing::FakeTracker;

// As in datagram_fuzz.cc.
constexpr std::uint8_t kMarker[4] = {0xFF, 'L', 'R', 'F'};
constexpr std::uint8_t kDefaultControl = 0x0D;  // +40 ms, tick, requests, source 0
constexpr std::uint8_t kStep1Ms = 0x00, kStep40Ms = 0x01, kStep4S = 0x02, kStepBack1S = 0x03;
constexpr std::uint8_t kTick = 0x04, kRequests = 0x08;
constexpr common::UtcNs kStartNs = 1'700'000'000'000'000'000;
constexpr common::DurationNs kMs = common::kNsPerMs;

// The receive time of the i-th datagram of a seed whose controls are all +40 ms; the trackers
// stamp their datagrams 1 ms before.
common::UtcNs SentNs(int i) { return kStartNs + (i + 1) * 40 * kMs - kMs; }

class Seed {
 public:
  // A datagram after a marker with `control` (the first needs none when control is the default).
  Seed& Add(const Bytes& datagram, std::uint8_t control = kDefaultControl) {
    if (!first_ || control != kDefaultControl || datagram.empty()) {
      bytes_.insert(bytes_.end(), std::begin(kMarker), std::end(kMarker));
      bytes_.push_back(control);
    }
    bytes_.insert(bytes_.end(), datagram.begin(), datagram.end());
    first_ = false;
    return *this;
  }
  Seed& Add(const std::vector<Bytes>& datagrams) {
    for (const Bytes& d : datagrams) Add(d);
    return *this;
  }
  const Bytes& bytes() const { return bytes_; }

 private:
  Bytes bytes_;
  bool first_ = true;
};

void Write(const std::filesystem::path& dir, const std::string& name, const Bytes& bytes) {
  std::ofstream out(dir / name, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(bytes.data()),
            static_cast<std::streamsize>(bytes.size()));
}

Bytes Mutated(const Bytes& base, const std::function<void(proto::Datagram&)>& change) {
  proto::Datagram d;
  d.ParseFromArray(base.data(), static_cast<int>(base.size()));
  change(d);
  return daemon::testing::Serialize(d);
}

void WriteValid(const std::filesystem::path& dir) {
  FakeTracker t("gate-3", 7);
  Write(dir, "frame_3_tracks", t.Tracks(3, SentNs(0)).at(0));
  Write(dir, "frame_empty", t.Tracks(0, SentNs(0)).at(0));
  Write(dir, "health", t.Health(SentNs(0)));
  Write(dir, "sensor_info", t.Info(SentNs(0)));
  Write(dir, "background_1_part", t.Background(300, SentNs(0)).at(0));

  FakeTracker a("hall-north.lms511", 0xFEEDFACECAFEBEEFull);
  Write(dir, "frame_3_parts", Seed().Add(a.Tracks(30, SentNs(0))).bytes());

  std::vector<Bytes> parts = a.Background(2000, SentNs(0));  // 5 parts
  Seed shuffled;
  for (const std::size_t i : {3u, 0u, 4u, 1u, 2u}) shuffled.Add(parts.at(i), kStep1Ms);
  Write(dir, "background_5_parts_shuffled", shuffled.bytes());

  // A session as a tracker starts it: info, health, a background, scans; requests and ticks.
  FakeTracker s("tim-7", 99);
  Seed session;
  int i = 0;
  session.Add(s.Info(SentNs(i++)));
  session.Add(s.Health(SentNs(i++)));
  session.Add(s.Background(700, SentNs(i++)));
  for (int scan = 0; scan < 8; ++scan) session.Add(s.Tracks(5, SentNs(i++), scan));
  Write(dir, "session", session.bytes());
}

void WriteSequences(const std::filesystem::path& dir) {
  FakeTracker t("gate-3", 1);
  std::vector<Bytes> h;
  for (int i = 0; i < 10; ++i) h.push_back(t.Health(SentNs(i)));
  Seed loss;
  for (const int i : {0, 1, 3, 2, 2, 5, 9, 4, 0}) loss.Add(h[i], kStep40Ms | kTick);
  Write(dir, "loss_reorder_duplicate", loss.bytes());

  // A restart with a snapshot in reassembly; the new session asks for everything again.
  FakeTracker before("gate-3", 1), after("gate-3", 2);
  Seed restart;
  restart.Add(before.Info(SentNs(0)));
  restart.Add(before.Background(1000, SentNs(1)).at(0));
  restart.Add(after.Tracks(2, SentNs(2)));
  restart.Add(after.Health(SentNs(3)), kStep4S | kTick | kRequests);
  Write(dir, "restart", restart.bytes());

  // A sequence jump beyond max_sequence_jump (1000 in the target) and back.
  const Bytes first = t.Health(SentNs(0));
  Seed reset;
  reset.Add(first);
  reset.Add(Mutated(first, [](proto::Datagram& d) { d.set_sequence(5000); }));
  reset.Add(Mutated(first, [](proto::Datagram& d) { d.set_sequence(4990); }));
  reset.Add(Mutated(first, [](proto::Datagram& d) { d.set_sequence(3); }));
  Write(dir, "sequence_reset", reset.bytes());

  // Silence (+4 s with a tick), back, a clock stepping back, another source.
  FakeTracker q("gate-9", 5);
  Seed silence;
  silence.Add(q.Health(SentNs(0)));
  silence.Add(q.Health(SentNs(1)), kStep4S | kTick | kRequests);
  silence.Add(Bytes{0x00}, kStep4S | kTick);  // malformed, unattributed: still silent
  silence.Add(q.Health(SentNs(2)), kStep1Ms | kTick | kRequests | 0x20);
  silence.Add(q.Tracks(1, SentNs(3)).at(0), kStepBack1S | kTick | kRequests | 0x30);
  Write(dir, "silence_back_clock", silence.bytes());

  // More sensors than the target's table holds (4), interleaved, from different sources.
  Seed many;
  std::vector<std::unique_ptr<FakeTracker>> trackers;
  for (int k = 0; k < 6; ++k) {
    trackers.push_back(std::make_unique<FakeTracker>("s" + std::to_string(k), 10 + k));
  }
  for (int round = 0; round < 2; ++round) {
    for (int k = 0; k < 6; ++k) {
      many.Add(trackers[k]->Health(SentNs(round)),
               static_cast<std::uint8_t>(kStep1Ms | kRequests | ((k & 3) << 4)));
    }
  }
  Write(dir, "too_many_sensors", many.bytes());

  // Snapshot parts that do not fit together: another geometry, overlapping beams, a short last
  // part, then a newer snapshot abandoning the incomplete one.
  FakeTracker b("lms5", 3);
  const std::vector<Bytes> p = b.Background(1000, SentNs(0));  // 3 parts
  Seed inconsistent;
  inconsistent.Add(p[0]);
  inconsistent.Add(
      Mutated(p[1], [](proto::Datagram& d) { d.mutable_background()->set_beam_count(999); }));
  inconsistent.Add(
      Mutated(p[1], [](proto::Datagram& d) { d.mutable_background()->set_first_beam(100); }));
  inconsistent.Add(Mutated(
      p[2], [](proto::Datagram& d) { d.mutable_background()->mutable_ranges_mm()->RemoveLast(); }));
  inconsistent.Add(p[1]);
  inconsistent.Add(b.Background(1000, SentNs(1)));
  Write(dir, "background_inconsistent", inconsistent.bytes());
}

void WriteHostile(const std::filesystem::path& dir) {
  FakeTracker t("gate-3", 7);
  const Bytes frame = t.Tracks(3, SentNs(0)).at(0);
  const Bytes background = t.Background(300, SentNs(0)).at(0);
  const Bytes health = t.Health(SentNs(0));
  const Bytes info = t.Info(SentNs(0));
  using D = proto::Datagram;
  const auto track = [](D& d) { return d.mutable_track_frame()->mutable_tracks(1); };
  struct Case {
    const char* name;
    const Bytes* base;
    std::function<void(D&)> change;
  };
  const Case cases[] = {
      {"version_0", &health, [](D& d) { d.set_version(proto::PROTOCOL_VERSION_UNSPECIFIED); }},
      {"version_2", &frame, [](D& d) { d.set_version(static_cast<proto::ProtocolVersion>(2)); }},
      {"sensor_id_space", &health, [](D& d) { d.set_sensor_id("gate 3"); }},
      {"sensor_id_long", &health, [](D& d) { d.set_sensor_id(std::string(33, 'g')); }},
      {"request", &health, [](D& d) { d.mutable_request()->set_send_sensor_info(true); }},
      {"no_payload", &health, [](D& d) { d.clear_payload(); }},
      {"sent_before_2000", &health, [](D& d) { d.set_sent_ns(1); }},
      {"sent_far_future", &health,
       [](D& d) { d.set_sent_ns(std::numeric_limits<std::int64_t>::max()); }},
      {"scan_start_old", &frame,
       [](D& d) {
         d.mutable_track_frame()->set_scan_start_ns(std::numeric_limits<std::int64_t>::min());
       }},
      {"scan_period_zero", &frame, [](D& d) { d.mutable_track_frame()->set_scan_period_s(0.0); }},
      {"frame_part_beyond", &frame, [](D& d) { d.mutable_track_frame()->set_part(5); }},
      {"frame_part_count_zero", &frame, [](D& d) { d.mutable_track_frame()->set_part_count(0); }},
      {"track_nan", &frame,
       [track](D& d) { track(d)->set_x_m(std::numeric_limits<float>::quiet_NaN()); }},
      {"track_far", &frame, [track](D& d) { track(d)->set_y_m(1e6f); }},
      {"track_fast", &frame, [track](D& d) { track(d)->set_vx_mps(-500.0f); }},
      {"track_state_0", &frame,
       [track](D& d) { track(d)->set_state(proto::TRACK_STATE_UNSPECIFIED); }},
      {"covariance_9", &frame, [track](D& d) { track(d)->mutable_covariance()->RemoveLast(); }},
      {"covariance_indefinite", &frame,
       [track](D& d) {
         auto* c = track(d)->mutable_covariance();
         for (int k = 0; k < c->size(); ++k) c->Set(k, 0.0f);
         for (const int k : {0, 4, 7, 9}) c->Set(k, 1.0f);
         c->Set(1, 0.9f);   // xy
         c->Set(2, 0.9f);   // x vx
         c->Set(5, -0.9f);  // y vx
       }},
      {"background_beyond", &background, [](D& d) { d.mutable_background()->set_first_beam(1); }},
      {"background_step_zero", &background,
       [](D& d) { d.mutable_background()->set_angle_step_rad(0.0); }},
      {"background_huge", &background, [](D& d) { d.mutable_background()->set_beam_count(~0u); }},
      {"background_parts_huge", &background,
       [](D& d) { d.mutable_background()->set_part_count(~0u); }},
      {"health_nan", &health,
       [](D& d) {
         d.mutable_health()->set_scan_cpu_us_max(std::numeric_limits<float>::infinity());
       }},
      {"health_clock_9", &health,
       [](D& d) { d.mutable_health()->set_clock_sync(static_cast<proto::ClockSyncState>(9)); }},
      {"info_long_model", &info,
       [](D& d) { d.mutable_sensor_info()->set_model(std::string(100, 'M')); }},
  };
  for (const Case& c : cases)
    Write(dir, std::string("hostile_") + c.name, Mutated(*c.base, c.change));

  // Not protobuf, or not a Datagram.
  Write(dir, "hostile_empty", {});
  Bytes oversize = frame;
  oversize.resize(1401, 0x00);
  Write(dir, "hostile_oversize", oversize);
  Write(dir, "hostile_not_utf8_id", Bytes{0x08, 0x01, 0x12, 0x02, 0xc3, 0x28});
  Write(dir, "hostile_length_overrun", Bytes{0x08, 0x01, 0x12, 0x7f, 'g'});
  // An unknown field number (20) as the only payload.
  Bytes unknown = Mutated(health, [](D& d) { d.clear_payload(); });
  unknown.insert(unknown.end(), {0xA2, 0x01, 0x02, 0x08, 0x01});
  Write(dir, "hostile_unknown_payload", unknown);
  for (const std::size_t n : {std::size_t{1}, std::size_t{9}, frame.size() / 2, frame.size() - 1}) {
    Write(dir, "hostile_truncated_frame_" + std::to_string(n),
          Bytes(frame.begin(), frame.begin() + static_cast<std::ptrdiff_t>(n)));
  }
}

}  // namespace

void WriteDatagramSeeds(const std::string& dir) {
  const std::filesystem::path path(dir);
  std::filesystem::create_directories(path);
  WriteValid(path);
  WriteSequences(path);
  WriteHostile(path);
}

}  // namespace lrfnet::fuzz
