#include "central_daemon/ingest/ingest.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>

#include "central_daemon/ingest/background_assembler.h"
#include "central_daemon/ingest/datagram_decoder.h"
#include "central_daemon/ingest/proto_convert.h"
#include "central_daemon/ingest/sequence_tracker.h"

namespace lrfnet::daemon {
namespace {

// The upper bound of every duration option: large enough for anything sensible, small enough that
// SecondsToNs cannot overflow.
constexpr double kMaxOptionSeconds = 1e9;

bool InRange(double v, double lo, double hi) { return std::isfinite(v) && v >= lo && v <= hi; }

// Minimum over the last 2.5 to 5 s (two buckets of 2.5 s): the minimum of (receive - sent) is the
// one-way latency without queueing plus the clock offset, and it follows a clock step within 5 s.
class RollingMinimum {
 public:
  static constexpr common::DurationNs kBucketNs = 2'500'000'000;

  void Add(common::UtcNs t_ns, double value) {
    if (!has_value_) {
      has_value_ = true;
      bucket_start_ns_ = t_ns;
      current_ = value;
      return;
    }
    const common::DurationNs age_ns = t_ns - bucket_start_ns_;
    if (age_ns >= kBucketNs) {
      previous_ = age_ns >= 2 * kBucketNs ? kNone : current_;
      current_ = value;
      bucket_start_ns_ = t_ns;
    } else {
      current_ = std::min(current_, value);
    }
  }
  double Value() const { return has_value_ ? std::min(current_, previous_) : 0.0; }

 private:
  static constexpr double kNone = std::numeric_limits<double>::infinity();
  bool has_value_ = false;
  common::UtcNs bucket_start_ns_ = 0;
  double current_ = kNone;
  double previous_ = kNone;
};

}  // namespace

const char* ToString(RejectReason reason) {
  switch (reason) {
    case RejectReason::kOversize:
      return "oversize";
    case RejectReason::kEmpty:
      return "empty";
    case RejectReason::kMalformed:
      return "malformed";
    case RejectReason::kVersion:
      return "version";
    case RejectReason::kSensorId:
      return "sensor_id";
    case RejectReason::kTooManySensors:
      return "too_many_sensors";
    case RejectReason::kUnknownKind:
      return "unknown_kind";
    case RejectReason::kUnexpectedKind:
      return "unexpected_kind";
    case RejectReason::kNotFinite:
      return "not_finite";
    case RejectReason::kCovariance:
      return "covariance";
    case RejectReason::kOutOfRange:
      return "out_of_range";
    case RejectReason::kPart:
      return "part";
    case RejectReason::kTimestamp:
      return "timestamp";
    case RejectReason::kDuplicate:
      return "duplicate";
    case RejectReason::kUnsigned:
      return "unsigned";
    case RejectReason::kAuthHeader:
      return "auth_header";
    case RejectReason::kUnknownSensor:
      return "unknown_sensor";
    case RejectReason::kWrongEpoch:
      return "wrong_epoch";
    case RejectReason::kWrongKey:
      return "wrong_key";
    case RejectReason::kReplayed:
      return "replayed";
    case RejectReason::kStale:
      return "stale";
    case RejectReason::kBadTag:
      return "bad_tag";
    case RejectReason::kEncrypted:
      return "encrypted";
    case RejectReason::kAuthMismatch:
      return "auth_mismatch";
    case RejectReason::kCount:
      break;
  }
  return "invalid";
}

const char* ToString(SensorEventKind kind) {
  switch (kind) {
    case SensorEventKind::kNew:
      return "new";
    case SensorEventKind::kRestart:
      return "restart";
    case SensorEventKind::kSequenceReset:
      return "sequence_reset";
    case SensorEventKind::kSilent:
      return "silent";
    case SensorEventKind::kBack:
      return "back";
  }
  return "invalid";
}

std::optional<std::string> Validate(const ValidationOptions& o) {
  if (!InRange(o.max_future_s, 0.0, kMaxOptionSeconds))
    return "validation.max_future_s must be in [0, 1e9] s";
  if (!InRange(o.max_stamp_age_s, 0.0, kMaxOptionSeconds))
    return "validation.max_stamp_age_s must be in [0, 1e9] s";
  if (!InRange(o.max_clock_offset_s, 0.0, kMaxOptionSeconds))
    return "validation.max_clock_offset_s must be in [0, 1e9] s (0: not checked)";
  if (!(std::isfinite(o.max_position_m) && o.max_position_m > 0.0))
    return "validation.max_position_m must be > 0";
  if (!(std::isfinite(o.max_speed_mps) && o.max_speed_mps > 0.0))
    return "validation.max_speed_mps must be > 0";
  if (!(std::isfinite(o.max_object_size_m) && o.max_object_size_m > 0.0))
    return "validation.max_object_size_m must be > 0";
  if (o.max_tracks_per_frame == 0) return "validation.max_tracks_per_frame must be >= 1";
  if (o.max_part_count == 0 || o.max_part_count > 65536)
    return "validation.max_part_count must be in [1, 65536]";
  if (o.max_background_beams == 0 || o.max_background_beams > (1u << 20))
    return "validation.max_background_beams must be in [1, 1048576]";
  return std::nullopt;
}

std::optional<std::string> Validate(const IngestOptions& o) {
  if (auto error = Validate(o.validation)) return error;
  if (auto error = Validate(o.auth)) return "auth." + *error;
  if (o.max_sensors == 0 || o.max_sensors > 1'000'000) return "max_sensors must be in [1, 1000000]";
  if (o.reorder_window_datagrams == 0 || o.reorder_window_datagrams > kMaxSequenceWindow)
    return "reorder_window_datagrams must be in [1, 65536]";
  if (o.max_sequence_jump < o.reorder_window_datagrams)
    return "max_sequence_jump must be >= reorder_window_datagrams";
  if (!(InRange(o.silent_after_s, 0.0, kMaxOptionSeconds) && o.silent_after_s > 0.0))
    return "silent_after_s must be in (0, 1e9] s";
  if (!(InRange(o.request_interval_s, 0.0, kMaxOptionSeconds) && o.request_interval_s > 0.0))
    return "request_interval_s must be in (0, 1e9] s";
  return std::nullopt;
}

struct Ingest::SensorState {
  SensorState(std::string_view id, const IngestOptions& o)
      : sequence(o.reorder_window_datagrams, o.max_sequence_jump),
        background(o.validation.max_background_beams, o.validation.max_part_count) {
    status.sensor_id.assign(id);
  }

  // counters.sequence, counters.backgrounds_abandoned and receive_minus_sent_s are filled in by
  // StatusOf from the parts below.
  SensorStatus status;
  SequenceTracker sequence;
  BackgroundAssembler background;
  RollingMinimum receive_minus_sent_s;
  // Per tracker session (status.session_id), known once a datagram of it was accepted.
  bool session_known = false;
  bool info_in_session = false;
  bool background_in_session = false;
  bool requested_in_session = false;
  common::UtcNs last_request_ns = 0;
};

Ingest::Ingest(const IngestOptions& options, IngestListener* listener)
    : options_(options), listener_(listener) {
  if (const auto error = Validate(options)) {
    std::fprintf(stderr, "Ingest: invalid options: %s\n", error->c_str());
    std::abort();
  }
  decoder_ = std::make_unique<DatagramDecoder>(options.validation);
  verifier_ = std::make_unique<DatagramVerifier>(options.auth);
}

Ingest::~Ingest() = default;

void Ingest::Reconfigure(const IngestOptions& options) {
  IngestOptions merged = options;
  merged.max_sensors = options_.max_sensors;
  merged.reorder_window_datagrams = options_.reorder_window_datagrams;
  merged.auth = options_.auth;
  if (const auto error = Validate(merged)) {
    std::fprintf(stderr, "Ingest::Reconfigure: invalid options: %s\n", error->c_str());
    std::abort();
  }
  options_ = merged;
  decoder_->set_options(options_.validation);
  for (auto& [id, sensor] : sensors_) {
    sensor->sequence.set_max_jump(options_.max_sequence_jump);
    sensor->background.set_limits(options_.validation.max_background_beams,
                                  options_.validation.max_part_count);
  }
}

void Ingest::Emit(SensorEventKind kind, const std::string& sensor_id, common::UtcNs time_ns) {
  if (listener_ == nullptr) return;
  SensorEvent event;
  event.kind = kind;
  event.sensor_id = sensor_id;
  event.time_ns = time_ns;
  listener_->OnSensorEvent(event);
}

Disposition Ingest::Reject(RejectReason reason, SensorState* sensor, std::string_view detail) {
  ++counters_.rejected;
  const auto index = static_cast<std::size_t>(reason);
  Disposition out;
  out.reason = reason;
  out.detail.assign(detail);
  if (sensor != nullptr) {
    ++sensor->status.counters.rejected[index];
    out.sensor_id = sensor->status.sensor_id;
  } else {
    ++counters_.unattributed[index];
  }
  return out;
}

Ingest::SensorState* Ingest::FindOrAdd(std::string_view sensor_id, common::UtcNs receive_ns) {
  if (const auto it = sensors_.find(sensor_id); it != sensors_.end()) return it->second.get();
  if (sensors_.size() >= options_.max_sensors) return nullptr;
  auto state = std::make_unique<SensorState>(sensor_id, options_);
  state->status.first_receive_ns = receive_ns;
  SensorState* sensor = state.get();
  sensors_.emplace(std::string(sensor_id), std::move(state));
  Emit(SensorEventKind::kNew, sensor->status.sensor_id, receive_ns);
  return sensor;
}

namespace {

RejectReason ReasonOf(AuthFailure failure) {
  switch (failure) {
    case AuthFailure::kUnsigned:
      return RejectReason::kUnsigned;
    case AuthFailure::kHeader:
      return RejectReason::kAuthHeader;
    case AuthFailure::kUnknownSensor:
      return RejectReason::kUnknownSensor;
    case AuthFailure::kWrongEpoch:
      return RejectReason::kWrongEpoch;
    case AuthFailure::kWrongKey:
      return RejectReason::kWrongKey;
    case AuthFailure::kAhead:
      return RejectReason::kTimestamp;
    case AuthFailure::kReplayed:
      return RejectReason::kReplayed;
    case AuthFailure::kStale:
      return RejectReason::kStale;
    case AuthFailure::kBadTag:
      return RejectReason::kBadTag;
    case AuthFailure::kEncrypted:
      return RejectReason::kEncrypted;
    case AuthFailure::kNone:
      break;
  }
  return RejectReason::kCount;
}

}  // namespace

Disposition Ingest::RejectUnverified(RejectReason reason, std::string_view sensor_id,
                                     const std::string& detail, std::string_view source) {
  // Counted at the envelope's sensor only when it is known already: a forged datagram must not
  // create sensors, count as a sign of life or change the address Requests go to.
  SensorState* sensor = nullptr;
  if (!sensor_id.empty()) {
    if (const auto it = sensors_.find(sensor_id); it != sensors_.end()) sensor = it->second.get();
  }
  if (sensor != nullptr) ++sensor->status.counters.datagrams;
  return Reject(reason, sensor, detail + " (from " + std::string(source) + ")");
}

Disposition Ingest::OnDatagram(std::span<const std::uint8_t> bytes, std::string_view source,
                               common::UtcNs receive_ns) {
  ++counters_.datagrams;
  counters_.bytes += bytes.size();
  // Verified before anything of the protobuf is read (sizes first: their reasons stay the same).
  AuthResult auth;
  auth.payload = bytes;
  if (!bytes.empty() && bytes.size() <= kMaxDatagramBytes) {
    auth = verifier_->Verify(bytes, receive_ns);
    if (!auth.ok())
      return RejectUnverified(ReasonOf(auth.failure), auth.sensor_id, auth.detail, source);
  }
  const DecodeStatus status = decoder_->Decode(auth.payload, receive_ns);
  if (!status.attributed) return Reject(status.reason, nullptr, decoder_->detail());

  const proto::Datagram& d = decoder_->datagram();
  if (auth.sealed && d.sensor_id() != auth.sensor_id) {
    return RejectUnverified(RejectReason::kAuthMismatch, auth.sensor_id,
                            "the datagram names sensor '" + d.sensor_id() + "'", source);
  }
  SensorState* sensor = FindOrAdd(d.sensor_id(), receive_ns);
  if (sensor == nullptr) {
    return Reject(RejectReason::kTooManySensors, nullptr, "the table of sensors is full");
  }
  SensorStatus& st = sensor->status;
  SensorCounters& c = st.counters;
  ++c.datagrams;
  c.bytes += bytes.size();
  st.last_receive_ns = receive_ns;
  st.source.assign(source);
  if (st.silent) {
    st.silent = false;
    Emit(SensorEventKind::kBack, st.sensor_id, receive_ns);
  }
  if (!status.ok()) return Reject(status.reason, sensor, decoder_->detail());

  // Checked before the sequence state learns the datagram, so a refused part counts nowhere else.
  BackgroundPart part;
  if (d.payload_case() == proto::Datagram::kBackground) {
    part = ToBackgroundPart(d);
    std::string detail;
    if (const auto reason = sensor->background.Check(part, &detail)) {
      return Reject(*reason, sensor, detail);
    }
  }

  switch (sensor->sequence.Observe(d.session_id(), d.sequence())) {
    case SequenceVerdict::kDuplicate: {
      char detail[96];
      const bool too_old =
          sensor->sequence.highest() - d.sequence() >= options_.reorder_window_datagrams;
      std::snprintf(detail, sizeof(detail), "sequence %llu %s",
                    static_cast<unsigned long long>(d.sequence()),
                    too_old ? "older than the reorder window" : "received already");
      return Reject(RejectReason::kDuplicate, sensor, detail);
    }
    case SequenceVerdict::kFirst:
      sensor->session_known = true;
      st.session_id = d.session_id();
      break;
    case SequenceVerdict::kRestart:
      st.session_id = d.session_id();
      sensor->info_in_session = false;
      sensor->background_in_session = false;
      sensor->requested_in_session = false;
      sensor->background.Reset();
      Emit(SensorEventKind::kRestart, st.sensor_id, receive_ns);
      break;
    case SequenceVerdict::kReset:
      Emit(SensorEventKind::kSequenceReset, st.sensor_id, receive_ns);
      break;
    case SequenceVerdict::kInOrder:
    case SequenceVerdict::kReordered:
      break;
  }
  common::DurationNs receive_minus_sent_ns = 0;
  if (__builtin_sub_overflow(receive_ns, d.sent_ns(), &receive_minus_sent_ns)) {
    receive_minus_sent_ns = std::numeric_limits<common::DurationNs>::min();  // not after validation
  }
  sensor->receive_minus_sent_s.Add(receive_ns, common::NsToSeconds(receive_minus_sent_ns));
  ++counters_.accepted;
  if (auth.sealed) {
    if (auth.verified) {
      verifier_->Commit(auth);
      ++counters_.verified;
    } else {
      ++counters_.unverified;
    }
  }

  switch (d.payload_case()) {
    case proto::Datagram::kTrackFrame:
      ++c.track_frames;
      ToTrackFrame(d, receive_ns, &frame_);
      if (listener_ != nullptr) listener_->OnTrackFrame(st.sensor_id, frame_);
      break;
    case proto::Datagram::kBackground:
      ++c.background_parts;
      if (sensor->background.Add(part, receive_ns, &background_) == AssembleOutcome::kCompleted) {
        ++c.backgrounds_completed;
        st.has_background = true;
        st.background_snapshot_id = background_.snapshot_id;
        sensor->background_in_session = true;
        if (listener_ != nullptr) listener_->OnBackground(st.sensor_id, background_);
      }
      break;
    case proto::Datagram::kHealth:
      ++c.health;
      st.health = ToSensorHealth(d, receive_ns);
      if (listener_ != nullptr) listener_->OnHealth(st.sensor_id, *st.health);
      break;
    case proto::Datagram::kSensorInfo:
      ++c.sensor_info;
      st.info = ToSensorDescription(d.sensor_info());
      sensor->info_in_session = true;
      if (listener_ != nullptr) listener_->OnSensorInfo(st.sensor_id, *st.info);
      break;
    default:  // refused by the decoder
      break;
  }
  Disposition out;
  out.accepted = true;
  out.sensor_id = st.sensor_id;
  return out;
}

void Ingest::OnTick(common::UtcNs now_ns) {
  const common::DurationNs silent_after_ns = common::SecondsToNs(options_.silent_after_s);
  for (auto& [id, sensor] : sensors_) {
    SensorStatus& st = sensor->status;
    if (st.silent || now_ns - st.last_receive_ns <= silent_after_ns) continue;
    st.silent = true;
    ++st.counters.silent_periods;
    Emit(SensorEventKind::kSilent, st.sensor_id, now_ns);
  }
}

std::vector<PendingRequest> Ingest::TakeRequests(common::UtcNs now_ns) {
  std::vector<PendingRequest> requests;
  const common::DurationNs interval_ns = common::SecondsToNs(options_.request_interval_s);
  for (auto& [id, sensor] : sensors_) {
    SensorState& s = *sensor;
    if (s.status.silent || !s.session_known) continue;
    const bool need_info = !s.info_in_session;
    const bool need_background = !s.background_in_session;
    if (!need_info && !need_background) continue;
    // A receive clock that went backwards (another recording) does not hold requests back.
    if (s.requested_in_session && now_ns >= s.last_request_ns &&
        now_ns - s.last_request_ns < interval_ns) {
      continue;
    }
    s.requested_in_session = true;
    s.last_request_ns = now_ns;
    ++s.status.counters.requests_sent;
    PendingRequest request;
    request.sensor_id = s.status.sensor_id;
    request.source = s.status.source;
    request.send_sensor_info = need_info;
    request.send_background = need_background;
    requests.push_back(std::move(request));
  }
  return requests;
}

SensorStatus Ingest::StatusOf(const SensorState& sensor) const {
  SensorStatus out = sensor.status;
  out.counters.sequence = sensor.sequence.counters();
  out.counters.backgrounds_abandoned = sensor.background.counters().abandoned;
  out.receive_minus_sent_s = sensor.receive_minus_sent_s.Value();
  return out;
}

bool Ingest::authenticated() const { return verifier_->enabled(); }

std::vector<StoredAuthState> Ingest::AuthState() const { return verifier_->State(); }

void Ingest::RestoreAuthState(const std::vector<StoredAuthState>& state) {
  verifier_->Restore(state);
}

std::uint64_t Ingest::auth_changes() const { return verifier_->changes(); }

std::size_t Ingest::SealRequest(std::string_view sensor_id, std::span<const std::uint8_t> payload,
                                std::span<std::uint8_t> out) {
  return verifier_->SealRequest(sensor_id, payload, out);
}

std::vector<SensorStatus> Ingest::Sensors() const {
  std::vector<SensorStatus> out;
  out.reserve(sensors_.size());
  for (const auto& [id, sensor] : sensors_) out.push_back(StatusOf(*sensor));
  return out;
}

std::optional<SensorStatus> Ingest::Sensor(std::string_view sensor_id) const {
  const auto it = sensors_.find(sensor_id);
  if (it == sensors_.end()) return std::nullopt;
  return StatusOf(*it->second);
}

}  // namespace lrfnet::daemon
