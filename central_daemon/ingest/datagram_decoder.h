#pragma once
// Decoding and validation of one received datagram (pure: bytes and the receive time in, the
// decoded message or a reason out; no clock, no logging).
//
// Checks, in this order (the first failure is the reason):
//   size (kEmpty, kOversize) -> protobuf parse (kMalformed) -> version (kVersion) -> sensor id
//   (kSensorId) -> payload kind (kUnexpectedKind for a Request, kUnknownKind for none or an
//   unknown field number) -> sent_ns (kTimestamp) -> the payload's fields:
// - TrackFrame: scan_start_ns (kTimestamp); scan_period_s finite (kNotFinite) and in (0, 1]
//   (kOutOfRange); part < part_count <= max_part_count (kPart); at most max_tracks_per_frame tracks
//   (kOutOfRange); per track: state TENTATIVE/CONFIRMED/COASTING, kind and shape known values
//   (kOutOfRange), every float finite (kNotFinite), size semi-axes and sigma in
//   [0, max_object_size_m] (kOutOfRange), exactly 10 covariance values (kCovariance),
//   |x|, |y| <= max_position_m and |vx|, |vy| <= max_speed_mps (kOutOfRange), covariance positive
//   semi-definite (kCovariance, see IsCovariancePsd).
// - BackgroundSnapshot: learned_until_ns (kTimestamp); angles finite (kNotFinite); angle_step_rad
//   != 0 and both angles within +-2 pi (kOutOfRange); beam_count in [1, max_background_beams]
//   (kOutOfRange); part < part_count <= max_part_count and first_beam + ranges <= beam_count
//   (kPart).
// - Health: floats and doubles finite (kNotFinite), clock_sync a known value (kOutOfRange).
// - SensorInfo: doubles finite (kNotFinite); model, serial, firmware and tracker_version at most
//   kMaxInfoStringBytes (kOutOfRange); kind and mount known values (kOutOfRange); the motion
//   model's values not negative (kOutOfRange). (The parser already
//   refuses strings that are not UTF-8: kMalformed.)
// Timestamps: see ValidationOptions (ingest.h); all arithmetic saturates, so no stamp overflows.
//
// Memory: the message is parsed into an arena whose first block belongs to the decoder, so decoding
// a valid datagram allocates nothing; hostile input that needs more (at most what 1400 bytes of
// protobuf can describe) gets blocks that the next Decode frees.
// Not thread-safe.

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>

#include "central_daemon/ingest/ingest.h"
#include "common/time.h"
#include "lrfnet.pb.h"

namespace lrfnet::daemon {

inline constexpr std::size_t kMaxSensorIdBytes = 32;
inline constexpr std::size_t kMaxInfoStringBytes = 64;
// Smallest eigenvalue a track's correlation matrix (the covariance scaled to a unit diagonal) may
// have: float rounding of a positive definite matrix stays far above it, a broken one does not.
inline constexpr double kCovariancePsdTolerance = 1e-5;
// |cov_ij| <= sqrt(cov_ii cov_jj) * (1 + kCovarianceCorrelationSlack)
inline constexpr double kCovarianceCorrelationSlack = 1e-3;

// [A-Za-z0-9_.-]{1,32}
bool IsValidSensorId(std::string_view id);

// The 10 upper-triangle values (xx, xy, xvx, xvy, yy, yvx, yvy, vxvx, vxvy, vyvy) form a positive
// semi-definite 4x4 matrix: exactly 10 finite values, no negative variance, no correlation above
// 1 + kCovarianceCorrelationSlack, and a Cholesky factorisation of the correlation matrix plus
// kCovariancePsdTolerance * I succeeds (its smallest eigenvalue is above -tolerance).
bool IsCovariancePsd(std::span<const float> upper_triangle);

struct DecodeStatus {
  RejectReason reason = RejectReason::kCount;  // kCount: decoded and valid
  // The message parsed and names a valid sensor id: a rejection is attributed to that sensor.
  bool attributed = false;
  bool ok() const { return reason == RejectReason::kCount; }
};

// Validates a parsed message (everything after the parse in the list above). On failure, *detail
// (when not null) is set to one line saying what was wrong.
RejectReason ValidateDatagram(const proto::Datagram& datagram, common::UtcNs receive_ns,
                              const ValidationOptions& options, std::string* detail);

class DatagramDecoder {
 public:
  // Precondition: Validate(options) is nullopt (checked; aborts otherwise).
  explicit DatagramDecoder(const ValidationOptions& options);
  ~DatagramDecoder();
  DatagramDecoder(const DatagramDecoder&) = delete;
  DatagramDecoder& operator=(const DatagramDecoder&) = delete;

  // Decodes and validates one datagram received at receive_ns (daemon clock).
  DecodeStatus Decode(std::span<const std::uint8_t> bytes, common::UtcNs receive_ns);

  // The message of the last Decode; meaningful when it parsed (ok() or attributed). Valid until the
  // next Decode.
  const proto::Datagram& datagram() const { return *message_; }
  // One line about the last rejection (empty after a valid datagram).
  const std::string& detail() const { return detail_; }

  // Precondition: Validate(options) is nullopt.
  void set_options(const ValidationOptions& options);
  const ValidationOptions& options() const { return options_; }

 private:
  static constexpr std::size_t kArenaBlockBytes = 64 * 1024;

  ValidationOptions options_;
  std::unique_ptr<std::array<char, kArenaBlockBytes>> arena_block_;
  std::unique_ptr<google::protobuf::Arena> arena_;
  proto::Datagram* message_ = nullptr;  // on arena_
  std::string detail_;
};

}  // namespace lrfnet::daemon
