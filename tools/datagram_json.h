#pragma once
// `lrfnet dump` of datagram files (recordings, UDP captures): one JSON object per received
// datagram, and a summary of a whole file. The one place where the tools turn lrfnet.proto
// Datagrams into JSON.
//
// A line is nlohmann::json's compact dump (keys sorted, one line, invalid UTF-8 in strings replaced
// by U+FFFD):
//   receive_ns (int), source (string), size (bytes of the datagram), and when the bytes parse as
//   lrfnet.proto.Datagram: version, sensor_id, sequence, sent_ns, session_id, kind, and the payload
//   under its proto field name with every field of the message:
//     kind: "track_frame" | "background" | "health" | "sensor_info" | "request" | "none"
//     "track_frame": {scan_start_ns, scan_period_s, scan_counter, part, part_count,
//                     tracks: [{track_id, state, kind, x_m, y_m, vx_mps, vy_mps, covariance,
//                               age_scans, points, ellipse_yaw_rad, shape, size_major_m,
//                               size_minor_m, size_sigma_m}]}
//     "background": {snapshot_id, learned_until_ns, first_angle_rad, angle_step_rad, beam_count,
//                    part, part_count, first_beam, ranges_mm}
//     "health", "sensor_info", "request": all fields.
//   Field names exactly as in the proto (snake_case); enums by their proto value name
//   ("TRACK_STATE_CONFIRMED"), or the number when the value has no name (proto3 JSON mapping);
//   64-bit integers as JSON numbers (exact); floats with float precision (0.1f prints 0.1);
//   NaN and infinities as null. Fields at their default value are printed too.
// Bytes that do not parse: {"error": "not a lrfnet datagram", "receive_ns", "size", "source"}.
// A sealed datagram (common/datagram_auth.h) also has
//   "auth": {sensor_id, epoch, key_id, counter, encrypted, direction ("to_daemon" | "to_tracker"),
//            verified, and error (a reason name of the daemon's ingest) when it was refused}
// and its payload's fields when it could be read: with keys (a DatagramVerifier) only when it
// verifies (then the window refuses a repeated counter as "replayed"); without keys, a plain
// payload is shown unverified ("verified": false) and an encrypted one not at all
// ("error": "encrypted").
//
// Pure: no I/O besides the ostream a caller passes.

#include <cstdint>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <ostream>
#include <span>
#include <string>
#include <string_view>

#include "central_daemon/ingest/datagram_verifier.h"
#include "central_daemon/io/datagram_source.h"
#include "common/time.h"

namespace lrfnet::proto {
class Datagram;
}

namespace lrfnet::tools {

inline constexpr const char* kNotADatagram = "not a lrfnet datagram";

// "track_frame", "background", "health", "sensor_info", "request" or "none" (no payload set).
std::string_view DatagramKindName(const proto::Datagram& datagram);

// The datagram's fields (version, sensor_id, ..., kind, payload), without the receive fields.
nlohmann::json DatagramFieldsJson(const proto::Datagram& datagram);

// One received datagram as a JSON object (format above); `verifier` (may be null: no keys) checks
// sealed datagrams.
nlohmann::json DatagramJson(common::UtcNs receive_ns, std::string_view source,
                            std::span<const std::uint8_t> bytes,
                            daemon::DatagramVerifier* verifier = nullptr);
// The same as one line of text (no trailing newline).
std::string DatagramJsonLine(common::UtcNs receive_ns, std::string_view source,
                             std::span<const std::uint8_t> bytes,
                             daemon::DatagramVerifier* verifier = nullptr);

// Counts over the datagrams of a file. Distinct sensor ids are bounded by kMaxSummarySensors; the
// datagrams of further ids are counted in sensors_over_limit only.
inline constexpr std::size_t kMaxSummarySensors = 4096;

struct DatagramSummary {
  std::uint64_t datagrams = 0;
  std::uint64_t bytes = 0;
  std::uint64_t parse_errors = 0;                 // not a lrfnet datagram
  std::uint64_t sealed = 0;                       // in an envelope
  std::uint64_t verified = 0;                     // ... and verified with a key
  std::uint64_t auth_refused = 0;                 // ... and refused by the keys (or encrypted)
  std::optional<common::UtcNs> first_receive_ns;  // in file order
  std::optional<common::UtcNs> last_receive_ns;
  std::uint64_t receive_time_steps_back = 0;  // receive_ns smaller than the one before
  std::map<std::string, std::uint64_t> by_kind;
  std::map<std::string, std::map<std::string, std::uint64_t>> by_sensor_kind;  // sensor -> kind
  std::uint64_t sensors_over_limit = 0;

  void Add(common::UtcNs receive_ns, std::span<const std::uint8_t> bytes,
           daemon::DatagramVerifier* verifier = nullptr);
};

// The summary and the file's counters as one JSON object (one line, no trailing newline):
//   datagrams, bytes, parse_errors, sealed, verified, auth_refused, first_receive_ns,
//   last_receive_ns (null when empty), receive_time_steps_back, kinds {kind: n}, sensors
//   {sensor_id: {kind: n}}, sensors_over_limit, file {kind: "recording" | "capture", datagrams,
//   files, packets, malformed_packets, other_packets, and for recordings format_version,
//   created_ns, writer}, and error (the source's error line) when the file ended in an error.
std::string DatagramSummaryJson(const DatagramSummary& summary,
                                const daemon::DatagramSource& source);

// Reads `source` to its end: one line per datagram to `out` (nullptr: none), counted into
// *summary (nullptr: not counted). False with *error (one line) when the source ended in an error;
// the datagrams before it were written.
bool DumpDatagrams(daemon::DatagramSource& source, std::ostream* out, DatagramSummary* summary,
                   std::string* error, daemon::DatagramVerifier* verifier = nullptr);

}  // namespace lrfnet::tools
