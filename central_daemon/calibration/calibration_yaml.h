#pragma once
// calibration.yaml (DESIGN.md "Poses"): writing a CalibrationResult, and reading the `sensors`
// poses of a calibration.yaml or of the simulator's truth.yaml, which share the format:
//
//   reference: "s1"                      # calibration only: the sensor fixed at the origin
//   sensors:
//     - {id: "s1", x_m: 0, y_m: 0, yaw_deg: 0, sigma_x_m: 0, sigma_y_m: 0, sigma_yaw_deg: 0}
//     - {id: "s7", calibrated: false}    # calibration only: not connected, no pose
//     - {id: "s2", x_m: 4, ..., radial_bias_m: -0.02, sigma_radial_bias_m: 0.004,
//        radial_bias_estimated: true}    # calibration only, where the joint refinement ran
//     - {id: "s3", ..., cov_xy_m2: 1e-5, cov_xyaw_m_deg: 2e-4, cov_yyaw_m_deg: -1e-4,
//        flag: "...", mount_looks_like_legs: true}   # calibration only
//
// x_m, y_m [m] and yaw_deg [deg, counter-clockwise] are world_from_sensor (common/geometry.h);
// sigma_x_m, sigma_y_m, sigma_yaw_deg and the cross terms cov_* (any absent: 0) its covariance
// (SensorPose::covariance; none of them: not given); flag and mount_looks_like_legs as
// SensorPose's;
// a calibration's world is the reference sensor's frame. radial_bias_m, sigma_radial_bias_m [m]
// and radial_bias_estimated (all three or none) are the joint refinement's shared radial bias of
// that sensor (types.h RadialBiasEstimate). quality.track_residual_rms_m is read too; other keys
// (method, the rest of quality, devices, targets, ...) are informative and ignored by the reader.

#include <cstdint>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "central_daemon/calibration/types.h"

namespace lrfnet::calib {

// Informative header fields (the caller knows the time and the input files; this code reads no
// clock).
struct YamlContext {
  std::string created_utc;          // e.g. "2024-05-01T12:00:00Z"; omitted when empty
  std::vector<std::string> inputs;  // the recordings / captures calibrated
  // The data of a live calibration (written as `input_window` when set): the datagrams received up
  // to received_until_ns (the daemon's receive clock, which its recording keeps), their frames
  // from scan time scan_from_ns on.
  std::optional<std::int64_t> received_until_ns = std::nullopt;
  std::optional<std::int64_t> scan_from_ns = std::nullopt;
};

// The whole file: a comment block explaining the fields, then method, reference, the context,
// `sensors` (poses printed with shortest round-trip precision, so reading gives the same doubles)
// and `quality` (per-edge status and residuals, joint refinement before/after, track residual,
// warnings, stage timings). The file always reads back with ParsePoseYaml: a calibrated sensor
// whose pose is not finite (or beyond kMaxPoseCoordinateM) is written as calibrated: false with a
// comment, and `reference` is only written when it names a sensor with a pose.
std::string CalibrationYaml(const CalibrationResult& result, const YamlContext& context);

struct PoseFile {
  std::optional<std::string> reference;                // `reference`, when the file has one
  std::vector<std::pair<std::string, Pose2>> sensors;  // in file order; yaw in (-pi, pi]
  std::vector<bool> calibrated;                        // parallel to sensors (absent: true)
  // Parallel to sensors as read (absent: nullopt); may be shorter in a PoseFile built by hand.
  std::vector<std::optional<RadialBiasEstimate>> radial_bias;
  // Parallel to sensors, like radial_bias: the pose's covariance (x, y, yaw; metres and radians)
  // where the file gives its sigmas (nullopt: it does not), the `flag` text ("" absent), and
  // mount_looks_like_legs (absent: false).
  std::vector<std::optional<Eigen::Matrix3d>> covariance;
  std::vector<std::string> flag;
  std::vector<bool> mount_looks_like_legs;
  // quality.track_residual_rms_m [m], when the file has it.
  std::optional<double> track_residual_rms_m;

  // Index of `id` in sensors, or nullopt.
  std::optional<std::size_t> Find(const std::string& id) const;
};

// The poses of a result as a PoseFile (what reading its calibration.yaml gives, without the
// round trip through text), e.g. to Evaluate it against a truth.
PoseFile PoseFileOf(const CalibrationResult& result);

// Bounds of what the reader accepts (a larger or stranger file is an error, not a crash).
inline constexpr std::size_t kMaxPoseFileBytes = 16u << 20;
inline constexpr double kMaxPoseCoordinateM = 1e7;
inline constexpr double kMaxPoseYawDeg = 1e6;
inline constexpr double kMaxRadialBiasM = 100.0;

// Parses the `sensors` list (and `reference`, quality.track_residual_rms_m). False with a one-line *error naming the file (if
// any), the line and the key for anything malformed: not YAML, no `sensors` list or an empty one,
// an entry without id, a duplicate id, a missing or non-numeric or non-finite or out-of-range
// x_m / y_m / yaw_deg of a calibrated sensor, a radial bias with one of its three keys missing or
// malformed (or a negative sigma_radial_bias_m), a negative sigma, a cross term beyond the
// product of its sigmas (a correlation above 1), a `calibrated` or mount_looks_like_legs that is
// not true/false, a `flag` that is not a string, a quality.track_residual_rms_m that is not a
// number >= 0, a
// `reference` that is not one of the calibrated sensors. *out is only written on success.
bool ParsePoseYaml(const std::string& text, PoseFile* out, std::string* error);
bool ReadPoseFile(const std::string& path, PoseFile* out, std::string* error);

}  // namespace lrfnet::calib
