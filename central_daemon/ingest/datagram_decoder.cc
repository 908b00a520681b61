#include "central_daemon/ingest/datagram_decoder.h"

#include <algorithm>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <numbers>

namespace lrfnet::daemon {
namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;

[[gnu::format(printf, 3, 4)]] RejectReason Fail(std::string* detail, RejectReason reason,
                                                const char* format, ...) {
  if (detail != nullptr) {
    char line[200];
    va_list args;
    va_start(args, format);
    std::vsnprintf(line, sizeof(line), format, args);
    va_end(args);
    detail->assign(line);
  }
  return reason;
}

// Wire stamps are arbitrary int64: bounds saturate instead of overflowing.
common::UtcNs SaturatingAdd(common::UtcNs a, common::DurationNs b) {
  common::UtcNs sum = 0;
  if (__builtin_add_overflow(a, b, &sum)) {
    return b > 0 ? std::numeric_limits<common::UtcNs>::max()
                 : std::numeric_limits<common::UtcNs>::min();
  }
  return sum;
}

double SecondsBetween(common::UtcNs later, common::UtcNs earlier) {
  return (static_cast<double>(later) - static_cast<double>(earlier)) * 1e-9;
}

long long Ll(std::int64_t v) { return static_cast<long long>(v); }

// A payload stamp (scan_start_ns, learned_until_ns) against the datagram's sent_ns.
RejectReason CheckPayloadStamp(const char* name, common::UtcNs stamp_ns, common::UtcNs sent_ns,
                               const ValidationOptions& o, std::string* detail) {
  const common::UtcNs earliest = SaturatingAdd(sent_ns, -common::SecondsToNs(o.max_stamp_age_s));
  const common::UtcNs latest = SaturatingAdd(sent_ns, common::SecondsToNs(o.max_future_s));
  if (stamp_ns < earliest) {
    return Fail(detail, RejectReason::kTimestamp, "%s %.3f s before sent_ns (at most %.3f s)", name,
                SecondsBetween(sent_ns, stamp_ns), o.max_stamp_age_s);
  }
  if (stamp_ns > latest) {
    return Fail(detail, RejectReason::kTimestamp, "%s %.3f s after sent_ns (at most %.3f s)", name,
                SecondsBetween(stamp_ns, sent_ns), o.max_future_s);
  }
  return RejectReason::kCount;
}

RejectReason CheckSentStamp(common::UtcNs sent_ns, common::UtcNs receive_ns,
                            const ValidationOptions& o, std::string* detail) {
  if (sent_ns < o.min_stamp_ns) {
    return Fail(detail, RejectReason::kTimestamp, "sent_ns %lld before min_stamp_ns %lld",
                Ll(sent_ns), Ll(o.min_stamp_ns));
  }
  if (sent_ns > SaturatingAdd(receive_ns, common::SecondsToNs(o.max_future_s))) {
    return Fail(detail, RejectReason::kTimestamp,
                "sent_ns %.3f s after the receive time (at most %.3f s)",
                SecondsBetween(sent_ns, receive_ns), o.max_future_s);
  }
  if (o.max_clock_offset_s > 0.0) {
    const double offset_s = SecondsBetween(sent_ns, receive_ns);
    if (std::fabs(offset_s) > o.max_clock_offset_s) {
      return Fail(detail, RejectReason::kTimestamp,
                  "sent_ns %.3f s from the receive time (at most %.3f s)", offset_s,
                  o.max_clock_offset_s);
    }
  }
  return RejectReason::kCount;
}

RejectReason CheckTrack(const proto::Track& t, int index, const ValidationOptions& o,
                        std::string* detail) {
  const int state = t.state();
  if (state < proto::TRACK_STATE_TENTATIVE || state > proto::TRACK_STATE_COASTING) {
    return Fail(detail, RejectReason::kOutOfRange, "track %d (id %u): unknown state %d", index,
                t.track_id(), state);
  }
  const int kind = t.kind();
  if (kind < proto::MEASUREMENT_KIND_UNSPECIFIED || kind > proto::MEASUREMENT_KIND_SHAPE_FIT) {
    return Fail(detail, RejectReason::kOutOfRange, "track %d (id %u): unknown kind %d", index,
                t.track_id(), kind);
  }
  const int shape = t.shape();
  if (shape < proto::OBJECT_SHAPE_UNSPECIFIED || shape > proto::OBJECT_SHAPE_BOX) {
    return Fail(detail, RejectReason::kOutOfRange, "track %d (id %u): unknown shape %d", index,
                t.track_id(), shape);
  }
  const bool covariance_finite = std::all_of(t.covariance().begin(), t.covariance().end(),
                                             [](float v) { return std::isfinite(v); });
  if (!std::isfinite(t.x_m()) || !std::isfinite(t.y_m()) || !std::isfinite(t.vx_mps()) ||
      !std::isfinite(t.vy_mps()) || !std::isfinite(t.ellipse_yaw_rad()) || !covariance_finite ||
      !std::isfinite(t.size_major_m()) || !std::isfinite(t.size_minor_m()) ||
      !std::isfinite(t.size_sigma_m())) {
    return Fail(detail, RejectReason::kNotFinite, "track %d (id %u): value not finite", index,
                t.track_id());
  }
  // Sizes: semi-axes of a person, a cart or a cylinder; negative or beyond a few metres is garbage.
  const auto bad_size = [&](float v) { return v < 0.0f || v > o.max_object_size_m; };
  if (bad_size(t.size_major_m()) || bad_size(t.size_minor_m()) || bad_size(t.size_sigma_m())) {
    return Fail(detail, RejectReason::kOutOfRange,
                "track %d (id %u): size (%g, %g ± %g) m outside [0, %g] m", index, t.track_id(),
                static_cast<double>(t.size_major_m()), static_cast<double>(t.size_minor_m()),
                static_cast<double>(t.size_sigma_m()), o.max_object_size_m);
  }
  if (t.covariance_size() != 10) {
    return Fail(detail, RejectReason::kCovariance,
                "track %d (id %u): %d covariance values (expected 10)", index, t.track_id(),
                t.covariance_size());
  }
  if (std::fabs(t.x_m()) > o.max_position_m || std::fabs(t.y_m()) > o.max_position_m) {
    return Fail(detail, RejectReason::kOutOfRange,
                "track %d (id %u): position (%g, %g) m beyond %g m", index, t.track_id(),
                static_cast<double>(t.x_m()), static_cast<double>(t.y_m()), o.max_position_m);
  }
  if (std::fabs(t.vx_mps()) > o.max_speed_mps || std::fabs(t.vy_mps()) > o.max_speed_mps) {
    return Fail(detail, RejectReason::kOutOfRange,
                "track %d (id %u): velocity (%g, %g) m/s beyond %g m/s", index, t.track_id(),
                static_cast<double>(t.vx_mps()), static_cast<double>(t.vy_mps()), o.max_speed_mps);
  }
  if (!IsCovariancePsd(std::span<const float>(t.covariance().data(), 10))) {
    return Fail(detail, RejectReason::kCovariance,
                "track %d (id %u): covariance not positive semi-definite", index, t.track_id());
  }
  return RejectReason::kCount;
}

RejectReason CheckTrackFrame(const proto::TrackFrame& f, common::UtcNs sent_ns,
                             const ValidationOptions& o, std::string* detail) {
  if (const RejectReason r =
          CheckPayloadStamp("scan_start_ns", f.scan_start_ns(), sent_ns, o, detail);
      r != RejectReason::kCount) {
    return r;
  }
  if (!std::isfinite(f.scan_period_s())) {
    return Fail(detail, RejectReason::kNotFinite, "scan_period_s not finite");
  }
  if (!(f.scan_period_s() > 0.0 && f.scan_period_s() <= 1.0)) {
    return Fail(detail, RejectReason::kOutOfRange, "scan_period_s %g outside (0, 1]",
                f.scan_period_s());
  }
  if (f.part_count() == 0 || f.part_count() > o.max_part_count || f.part() >= f.part_count()) {
    return Fail(detail, RejectReason::kPart, "track frame part %u of %u (at most %u parts)",
                f.part(), f.part_count(), o.max_part_count);
  }
  if (static_cast<std::uint64_t>(f.tracks_size()) > o.max_tracks_per_frame) {
    return Fail(detail, RejectReason::kOutOfRange, "%d tracks (at most %u)", f.tracks_size(),
                o.max_tracks_per_frame);
  }
  for (int i = 0; i < f.tracks_size(); ++i) {
    if (const RejectReason r = CheckTrack(f.tracks(i), i, o, detail); r != RejectReason::kCount) {
      return r;
    }
  }
  return RejectReason::kCount;
}

RejectReason CheckBackground(const proto::BackgroundSnapshot& b, common::UtcNs sent_ns,
                             const ValidationOptions& o, std::string* detail) {
  if (const RejectReason r =
          CheckPayloadStamp("learned_until_ns", b.learned_until_ns(), sent_ns, o, detail);
      r != RejectReason::kCount) {
    return r;
  }
  if (!std::isfinite(b.first_angle_rad()) || !std::isfinite(b.angle_step_rad())) {
    return Fail(detail, RejectReason::kNotFinite, "background angles not finite");
  }
  if (b.beam_count() == 0 || b.beam_count() > o.max_background_beams) {
    return Fail(detail, RejectReason::kOutOfRange, "background of %u beams (1 to %u)",
                b.beam_count(), o.max_background_beams);
  }
  // A 2D scanner covers at most one turn.
  if (b.angle_step_rad() == 0.0 || std::fabs(b.first_angle_rad()) > kTwoPi ||
      std::fabs(b.angle_step_rad()) * (b.beam_count() - 1) > kTwoPi + 1e-6) {
    return Fail(detail, RejectReason::kOutOfRange,
                "background angles first %g rad, step %g rad over %u beams", b.first_angle_rad(),
                b.angle_step_rad(), b.beam_count());
  }
  if (b.part_count() == 0 || b.part_count() > o.max_part_count || b.part() >= b.part_count()) {
    return Fail(detail, RejectReason::kPart, "background part %u of %u (at most %u parts)",
                b.part(), b.part_count(), o.max_part_count);
  }
  if (static_cast<std::uint64_t>(b.first_beam()) + static_cast<std::uint64_t>(b.ranges_mm_size()) >
      b.beam_count()) {
    return Fail(detail, RejectReason::kPart, "background beams %u + %d beyond beam_count %u",
                b.first_beam(), b.ranges_mm_size(), b.beam_count());
  }
  return RejectReason::kCount;
}

RejectReason CheckHealth(const proto::Health& h, std::string* detail) {
  if (!std::isfinite(h.scan_cpu_us_mean()) || !std::isfinite(h.scan_cpu_us_max()) ||
      !std::isfinite(h.clock_error_estimate_s()) || !std::isfinite(h.tick_offset_s()) ||
      !std::isfinite(h.tick_drift_ppm())) {
    return Fail(detail, RejectReason::kNotFinite, "health value not finite");
  }
  const int sync = h.clock_sync();
  if (sync < proto::CLOCK_SYNC_UNSPECIFIED || sync > proto::CLOCK_SYNC_REPLAY) {
    return Fail(detail, RejectReason::kOutOfRange, "health: unknown clock_sync %d", sync);
  }
  return RejectReason::kCount;
}

RejectReason CheckSensorInfo(const proto::SensorInfo& s, std::string* detail) {
  if (!std::isfinite(s.first_angle_rad()) || !std::isfinite(s.angle_step_rad()) ||
      !std::isfinite(s.fov_rad()) || !std::isfinite(s.scan_frequency_hz()) ||
      !std::isfinite(s.max_range_m())) {
    return Fail(detail, RejectReason::kNotFinite, "sensor info value not finite");
  }
  const std::size_t longest = std::max(
      {s.model().size(), s.serial().size(), s.firmware().size(), s.tracker_version().size()});
  if (longest > kMaxInfoStringBytes) {
    return Fail(detail, RejectReason::kOutOfRange, "sensor info string of %zu bytes (at most %zu)",
                longest, kMaxInfoStringBytes);
  }
  const int kind = s.kind();
  if (kind < proto::MEASUREMENT_KIND_UNSPECIFIED || kind > proto::MEASUREMENT_KIND_SHAPE_FIT) {
    return Fail(detail, RejectReason::kOutOfRange, "sensor info: unknown kind %d", kind);
  }
  const int mount = s.mount();
  if (mount < proto::MOUNT_HEIGHT_UNSPECIFIED || mount > proto::MOUNT_HEIGHT_LEGS) {
    return Fail(detail, RejectReason::kOutOfRange, "sensor info: unknown mount %d", mount);
  }
  if (!std::isfinite(s.accel_psd_m2ps3()) || !std::isfinite(s.max_speed_mps())) {
    return Fail(detail, RejectReason::kNotFinite, "sensor info value not finite");
  }
  if (s.accel_psd_m2ps3() < 0.0 || s.max_speed_mps() < 0.0) {
    return Fail(detail, RejectReason::kOutOfRange, "sensor info: negative motion model value");
  }
  return RejectReason::kCount;
}

}  // namespace

bool IsValidSensorId(std::string_view id) {
  if (id.empty() || id.size() > kMaxSensorIdBytes) return false;
  return std::all_of(id.begin(), id.end(), [](char c) {
    return (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_' ||
           c == '.' || c == '-';
  });
}

bool IsCovariancePsd(std::span<const float> upper_triangle) {
  if (upper_triangle.size() != 10) return false;
  double a[4][4];
  std::size_t k = 0;
  for (int r = 0; r < 4; ++r) {
    for (int c = r; c < 4; ++c) {
      const double v = upper_triangle[k++];
      if (!std::isfinite(v)) return false;
      a[r][c] = a[c][r] = v;
    }
  }
  for (int i = 0; i < 4; ++i) {
    if (a[i][i] < 0.0) return false;
  }
  for (int i = 0; i < 4; ++i) {
    for (int j = i + 1; j < 4; ++j) {
      if (std::fabs(a[i][j]) > std::sqrt(a[i][i] * a[j][j]) * (1.0 + kCovarianceCorrelationSlack))
        return false;
    }
  }
  // Scaled to a unit diagonal the tolerance is independent of the units (m^2 against m^2/s^2) and
  // of the magnitude. A zero variance has zero covariances (checked above): its row is a unit row.
  double scale[4];
  for (int i = 0; i < 4; ++i) scale[i] = a[i][i] > 0.0 ? 1.0 / std::sqrt(a[i][i]) : 0.0;
  double c[4][4];
  for (int i = 0; i < 4; ++i) {
    for (int j = 0; j < 4; ++j) c[i][j] = a[i][j] * scale[i] * scale[j];
    c[i][i] = 1.0 + kCovariancePsdTolerance;
  }
  // Cholesky of C + tolerance * I: it succeeds exactly when C's smallest eigenvalue is above
  // -tolerance.
  double l[4][4] = {};
  for (int j = 0; j < 4; ++j) {
    double d = c[j][j];
    for (int m = 0; m < j; ++m) d -= l[j][m] * l[j][m];
    if (!(d > 0.0)) return false;
    l[j][j] = std::sqrt(d);
    for (int i = j + 1; i < 4; ++i) {
      double s = c[i][j];
      for (int m = 0; m < j; ++m) s -= l[i][m] * l[j][m];
      l[i][j] = s / l[j][j];
    }
  }
  return true;
}

RejectReason ValidateDatagram(const proto::Datagram& d, common::UtcNs receive_ns,
                              const ValidationOptions& o, std::string* detail) {
  if (d.version() != proto::PROTOCOL_VERSION_1) {
    return Fail(detail, RejectReason::kVersion, "protocol version %d (expected 1)",
                static_cast<int>(d.version()));
  }
  if (!IsValidSensorId(d.sensor_id())) {
    return Fail(detail, RejectReason::kSensorId,
                "sensor id of %zu bytes is not [A-Za-z0-9_.-]{1,32}", d.sensor_id().size());
  }
  switch (d.payload_case()) {
    case proto::Datagram::kTrackFrame:
    case proto::Datagram::kBackground:
    case proto::Datagram::kHealth:
    case proto::Datagram::kSensorInfo:
      break;
    case proto::Datagram::kRequest:
      return Fail(detail, RejectReason::kUnexpectedKind, "a request (sent to trackers only)");
    default:
      return Fail(detail, RejectReason::kUnknownKind, "no payload this daemon knows");
  }
  if (const RejectReason r = CheckSentStamp(d.sent_ns(), receive_ns, o, detail);
      r != RejectReason::kCount) {
    return r;
  }
  switch (d.payload_case()) {
    case proto::Datagram::kTrackFrame:
      return CheckTrackFrame(d.track_frame(), d.sent_ns(), o, detail);
    case proto::Datagram::kBackground:
      return CheckBackground(d.background(), d.sent_ns(), o, detail);
    case proto::Datagram::kHealth:
      return CheckHealth(d.health(), detail);
    default:
      return CheckSensorInfo(d.sensor_info(), detail);
  }
}

DatagramDecoder::DatagramDecoder(const ValidationOptions& options)
    : arena_block_(std::make_unique<std::array<char, kArenaBlockBytes>>()) {
  set_options(options);
  google::protobuf::ArenaOptions arena_options;
  arena_options.initial_block = arena_block_->data();
  arena_options.initial_block_size = arena_block_->size();
  arena_ = std::make_unique<google::protobuf::Arena>(arena_options);
  message_ = google::protobuf::Arena::CreateMessage<proto::Datagram>(arena_.get());
}

DatagramDecoder::~DatagramDecoder() = default;

void DatagramDecoder::set_options(const ValidationOptions& options) {
  if (const auto error = Validate(options)) {
    std::fprintf(stderr, "DatagramDecoder: invalid options: %s\n", error->c_str());
    std::abort();
  }
  options_ = options;
}

DecodeStatus DatagramDecoder::Decode(std::span<const std::uint8_t> bytes,
                                     common::UtcNs receive_ns) {
  DecodeStatus status;
  detail_.clear();
  if (bytes.empty()) {
    status.reason = Fail(&detail_, RejectReason::kEmpty, "0 bytes");
    return status;
  }
  if (bytes.size() > kMaxDatagramBytes) {
    status.reason = Fail(&detail_, RejectReason::kOversize, "%zu bytes (at most %zu)", bytes.size(),
                         kMaxDatagramBytes);
    return status;
  }
  // Everything the previous message held goes at once; the first block stays for this one.
  arena_->Reset();
  message_ = google::protobuf::Arena::CreateMessage<proto::Datagram>(arena_.get());
  bool parsed = false;
  {
    // libprotobuf logs every string that is not UTF-8 to stderr; hostile input would flood it.
    // The reason is counted instead.
    const google::protobuf::LogSilencer silence;
    parsed = message_->ParseFromArray(bytes.data(), static_cast<int>(bytes.size()));
  }
  if (!parsed) {
    status.reason =
        Fail(&detail_, RejectReason::kMalformed, "%zu bytes are not a Datagram", bytes.size());
    return status;
  }
  status.attributed = IsValidSensorId(message_->sensor_id());
  status.reason = ValidateDatagram(*message_, receive_ns, options_, &detail_);
  return status;
}

}  // namespace lrfnet::daemon
