#pragma once
// The daemon's ingest core (pure: no socket, no clock, no logging; time is passed in). Every
// received datagram goes through OnDatagram: it is verified against the sensor keys when keys are
// configured (datagram_verifier.h: before anything of its protobuf is read; a datagram refused
// there counts at its sensor only when that sensor is known already, never creates one, is no
// sign of life and changes no source address), decoded (libprotobuf-lite), validated, checked
// against its sensor's sequence state, turned into the value types of sensor_data.h and handed to
// the listener. An invalid datagram is counted per sensor and reason (or, when it names no valid
// sensor, per reason under "unattributed") and dropped; nothing in it can crash the ingest or make
// it allocate without bound:
// - datagrams larger than kMaxDatagramBytes are refused before parsing, so a parsed message is
//   bounded by 1400 bytes of input;
// - at most IngestOptions::max_sensors sensors are tracked; further sensor ids are refused;
// - a background snapshot in reassembly is bounded by max_background_beams.
//
// Sequence state per sensor (Datagram.sequence, +1 per datagram of a tracker session, from 0):
// a datagram whose sequence is below the highest seen and was not seen yet is "reordered" (still
// accepted); one seen before is a "duplicate" (dropped); sequence numbers skipped are "lost" once
// the window of reorder_window_datagrams has passed them (a late arrival inside the window undoes
// the loss). A new session_id is a restart: the sequence state starts again (counted). A sequence
// number further than max_sequence_jump ahead of the highest within one session is a reset
// (counted, state restarts at it).
//
// Choices within that contract:
// - Attribution: a datagram that parses and names a valid sensor id counts at that sensor, also
//   when it is rejected (a wrong version too); the sensor is created (SensorEvent kNew) unless
//   max_sensors is reached (kTooManySensors, unattributed). Everything rejected earlier counts in
//   IngestCounters::unattributed.
// - Order of checks: decoding and validation (datagram_decoder.h), then the background part against
//   the snapshot in reassembly (background_assembler.h), then the sequence state; so a datagram
//   rejected for its content is not "received" (its number counts as lost unless it arrives valid)
//   and only accepted datagrams move the sequence state.
// - Sequence: an arrival older than the window cannot be told from a duplicate: it is dropped and
//   counted as one. A number more than max_sequence_jump behind the highest is a reset too. A
//   session_id change is a restart whatever the order (a late datagram of the old session after a
//   restart would count as another restart; a tracker restart takes seconds, reordering does not).
// - Restart: the snapshot in reassembly is dropped (backgrounds_abandoned); SensorStatus keeps the
//   last info and background for the status, but requests ask for both again.
// - Silence: any attributed datagram is a sign of life (kBack), valid or not.
// - Requests: only for sensors with an accepted datagram in their current session (whose protocol
//   and session are known), not silent, lacking SensorInfo or a complete background of that
//   session; the first at once, then at most every request_interval_s.
//
// Not thread-safe: one ingest per thread (the daemon's io thread).

#include <array>
#include <cstddef>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "central_daemon/ingest/datagram_verifier.h"
#include "central_daemon/ingest/sensor_data.h"
#include "common/time.h"

namespace lrfnet::daemon {

inline constexpr std::size_t kMaxDatagramBytes = 1400;

// Why a datagram was dropped. Names (ToString) are used in logs, the status JSON and tests.
enum class RejectReason : std::uint8_t {
  kOversize,        // "oversize": more than kMaxDatagramBytes
  kEmpty,           // "empty": zero bytes
  kMalformed,       // "malformed": not a protobuf Datagram
  kVersion,         // "version": protocol version unknown or unspecified
  kSensorId,        // "sensor_id": not [A-Za-z0-9_.-]{1,32}
  kTooManySensors,  // "too_many_sensors": max_sensors reached
  kUnknownKind,     // "unknown_kind": no payload or one this daemon does not know
  kUnexpectedKind,  // "unexpected_kind": a Request sent to the daemon
  kNotFinite,       // "not_finite": NaN or infinity in a float/double field
  kCovariance,      // "covariance": not 10 values or not positive semi-definite
  kOutOfRange,      // "out_of_range": position, speed, period, angle or count outside its bounds
  kPart,            // "part": part >= part_count, part_count 0 or above the bound, beams outside
  kTimestamp,       // "timestamp": outside the accepted window (see ValidationOptions)
  kDuplicate,       // "duplicate": sequence number already received in this session
  // Authentication (datagram_verifier.h says when each applies).
  kUnsigned,       // "unsigned": keys configured, datagram not sealed
  kAuthHeader,     // "auth_header": malformed envelope, or sealed for the other direction
  kUnknownSensor,  // "unknown_sensor": no key for the envelope's sensor id
  kWrongEpoch,     // "wrong_epoch": no key of that epoch, or an epoch older than the one in use
  kWrongKey,       // "wrong_key": sealed with another key (key id)
  kReplayed,       // "replayed": envelope counter accepted before
  kStale,          // "stale": counter older than the window or than the state stored at restart
  kBadTag,         // "bad_tag": forged or damaged
  kEncrypted,      // "encrypted": encrypted, and no keys to read it
  kAuthMismatch,   // "auth_mismatch": the Datagram names another sensor than its envelope
  kCount
};
inline constexpr std::size_t kRejectReasonCount = static_cast<std::size_t>(RejectReason::kCount);
const char* ToString(RejectReason reason);

struct ValidationOptions {
  // sent_ns must lie within [min_stamp_ns, receive_ns + max_future_s]; scan_start_ns and
  // learned_until_ns within [sent_ns - max_stamp_age_s, sent_ns + max_future_s].
  common::UtcNs min_stamp_ns = 946684800LL * 1000000000LL;  // 2000-01-01T00:00:00Z
  double max_future_s = 300.0;
  double max_stamp_age_s = 60.0;
  // When > 0: |sent_ns - receive_ns| above this is a timestamp error (strict live deployments;
  // 0 keeps replays of old captures acceptable).
  double max_clock_offset_s = 0.0;
  double max_position_m = 1000.0;  // |x|, |y| of a track
  double max_speed_mps = 100.0;    // |vx|, |vy|
  double max_object_size_m = 10.0;  // a track's size semi-axes and their sigma
  std::uint32_t max_tracks_per_frame = 256;
  std::uint32_t max_part_count = 64;
  std::uint32_t max_background_beams = 65536;
};
std::optional<std::string> Validate(const ValidationOptions& options);

struct IngestOptions {
  ValidationOptions validation;
  AuthOptions auth;  // keys: fixed for the ingest's life (Reconfigure keeps them)
  std::size_t max_sensors = 1024;
  std::uint32_t reorder_window_datagrams = 1024;  // <= 65536
  std::uint64_t max_sequence_jump = 1000000;
  double silent_after_s = 3.0;  // no datagram for this long: the sensor is reported silent
  // Requests (SensorInfo, background) are asked of a sensor that lacks them at most this often.
  double request_interval_s = 5.0;
};
std::optional<std::string> Validate(const IngestOptions& options);

struct SequenceCounters {
  std::uint64_t received = 0;    // accepted datagrams (duplicates not included)
  std::uint64_t lost = 0;        // skipped sequence numbers that did not arrive within the window
  std::uint64_t reordered = 0;   // arrived after a higher sequence number
  std::uint64_t duplicates = 0;  // also arrivals older than the window (dropped)
  std::uint64_t restarts = 0;    // session_id changes
  std::uint64_t resets = 0;      // sequence jumps within one session
};

struct SensorCounters {
  std::uint64_t datagrams = 0;  // every datagram attributed to this sensor, valid or not
  std::uint64_t bytes = 0;
  std::uint64_t track_frames = 0;
  std::uint64_t background_parts = 0;
  std::uint64_t health = 0;
  std::uint64_t sensor_info = 0;
  std::uint64_t backgrounds_completed = 0;
  // Replaced by a newer snapshot (or dropped by a restart) before all parts arrived.
  std::uint64_t backgrounds_abandoned = 0;
  std::uint64_t silent_periods = 0;
  std::uint64_t requests_sent = 0;
  std::array<std::uint64_t, kRejectReasonCount> rejected{};
  SequenceCounters sequence;
};

// What the daemon knows about one sensor (read-only view for status and tests).
struct SensorStatus {
  std::string sensor_id;
  std::string source;  // "ip:port" of its newest datagram
  std::uint64_t session_id = 0;
  common::UtcNs first_receive_ns = 0;
  common::UtcNs last_receive_ns = 0;
  bool silent = false;
  // Minimum of (receive_ns - sent_ns) over the last few seconds: network latency plus the clock
  // offset between the gateway and the daemon.
  double receive_minus_sent_s = 0.0;
  std::optional<SensorDescription> info;
  std::optional<SensorHealth> health;
  std::uint32_t background_snapshot_id = 0;  // of the newest complete background
  bool has_background = false;
  SensorCounters counters;
};

enum class SensorEventKind : std::uint8_t { kNew, kRestart, kSequenceReset, kSilent, kBack };
const char* ToString(SensorEventKind kind);
struct SensorEvent {
  SensorEventKind kind = SensorEventKind::kNew;
  std::string sensor_id;
  common::UtcNs time_ns = 0;  // receive clock
};

// Receives what the ingest accepted. Default implementations ignore it. Called synchronously from
// OnDatagram / OnTick; the references are valid during the call only (the ingest reuses them), and
// a listener must not call OnDatagram, OnTick or Reconfigure of the same ingest.
class IngestListener {
 public:
  virtual ~IngestListener() = default;
  virtual void OnTrackFrame(const std::string& /*sensor_id*/, const TrackFrameData& /*frame*/) {}
  virtual void OnBackground(const std::string& /*sensor_id*/,
                            const BackgroundScan& /*background*/) {}
  virtual void OnSensorInfo(const std::string& /*sensor_id*/, const SensorDescription& /*info*/) {}
  virtual void OnHealth(const std::string& /*sensor_id*/, const SensorHealth& /*health*/) {}
  virtual void OnSensorEvent(const SensorEvent& /*event*/) {}
};

// A request the daemon should send to a sensor's tracker (at its newest source address).
struct PendingRequest {
  std::string sensor_id;
  std::string source;  // "ip:port" or "[ipv6]:port"
  bool send_sensor_info = false;
  bool send_background = false;
};

struct IngestCounters {
  std::uint64_t datagrams = 0;
  std::uint64_t bytes = 0;
  std::uint64_t accepted = 0;
  std::uint64_t rejected = 0;
  std::uint64_t verified = 0;    // accepted, sealed and verified with the sensor's key
  std::uint64_t unverified = 0;  // accepted, sealed but read without keys (not verified)
  // Rejected datagrams that name no valid sensor (malformed, bad sensor id, too many sensors...).
  std::array<std::uint64_t, kRejectReasonCount> unattributed{};
};

// Result of one OnDatagram.
struct Disposition {
  bool accepted = false;
  RejectReason reason = RejectReason::kCount;  // when !accepted
  std::string sensor_id;                       // empty when unattributed
  std::string detail;  // when !accepted: one line saying what was wrong (for logs)
};

class DatagramDecoder;

class Ingest {
 public:
  // Precondition: Validate(options) is nullopt (checked; aborts otherwise). `listener` may be null
  // and must outlive the ingest.
  Ingest(const IngestOptions& options, IngestListener* listener);
  ~Ingest();
  Ingest(const Ingest&) = delete;
  Ingest& operator=(const Ingest&) = delete;

  // One datagram as received from `source` ("ip:port") at `receive_ns` (daemon clock).
  Disposition OnDatagram(std::span<const std::uint8_t> bytes, std::string_view source,
                         common::UtcNs receive_ns);
  // Silence detection and request scheduling; call every few hundred milliseconds with the
  // receive clock (or with the recording's receive times offline).
  void OnTick(common::UtcNs now_ns);
  // Requests due since the last call (a sensor without SensorInfo or background, at most every
  // request_interval_s). Counted as sent when taken.
  std::vector<PendingRequest> TakeRequests(common::UtcNs now_ns);

  // Replaces the options that may change at run time (validation, silence, request interval);
  // max_sensors and the reorder window keep their values. Precondition: Validate(options).
  void Reconfigure(const IngestOptions& options);

  // Keys configured: every datagram must be sealed.
  bool authenticated() const;
  // The verifier's state to store across restarts, and to restore at start; auth_changes() grows
  // with every accepted sealed datagram.
  std::vector<StoredAuthState> AuthState() const;
  void RestoreAuthState(const std::vector<StoredAuthState>& state);
  std::uint64_t auth_changes() const;
  // Seals a Request for `sensor_id` (see DatagramVerifier::SealRequest); 0 when it cannot.
  std::size_t SealRequest(std::string_view sensor_id, std::span<const std::uint8_t> payload,
                          std::span<std::uint8_t> out);

  std::vector<SensorStatus> Sensors() const;  // sorted by sensor id
  std::optional<SensorStatus> Sensor(std::string_view sensor_id) const;
  const IngestCounters& counters() const { return counters_; }

 private:
  struct SensorState;
  IngestOptions options_;
  IngestListener* listener_;
  std::map<std::string, std::unique_ptr<SensorState>, std::less<>> sensors_;
  IngestCounters counters_;

  Disposition Reject(RejectReason reason, SensorState* sensor, std::string_view detail);
  SensorState* FindOrAdd(std::string_view sensor_id, common::UtcNs receive_ns);
  void Emit(SensorEventKind kind, const std::string& sensor_id, common::UtcNs time_ns);
  SensorStatus StatusOf(const SensorState& sensor) const;

  Disposition RejectUnverified(RejectReason reason, std::string_view sensor_id,
                               const std::string& detail, std::string_view source);

  std::unique_ptr<DatagramDecoder> decoder_;
  std::unique_ptr<DatagramVerifier> verifier_;
  TrackFrameData frame_;       // reused for every track frame handed to the listener
  BackgroundScan background_;  // filled when a snapshot completes
};

}  // namespace lrfnet::daemon
