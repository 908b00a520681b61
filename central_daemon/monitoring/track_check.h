#pragma once
// Has a sensor moved? The track signal (pure), and the pose of one sensor from tracks with every
// other pose held fixed.
//
// The sensor's tracks (its own frame) are set against the tracks of the other placed sensors,
// brought into the world frame with their poses and taken together as one virtual sensor "the
// world" (W): the calibration's pairwise machinery (calib::Align with RTS smoothing onto one time
// grid, calib::AssociatePair, calib::FitMatches, calib::EstimatePair) then gives
// W_from_sensor = world_from_sensor directly, and its covariance. A person seen by several other
// sensors appears in W once per sensor; the one-to-one association takes the nearest and leaves
// the others unmatched. Each of W's positions is the body centre the measurement model
// (ingest/measurement_model.h) implies in its own sensor's frame, along that sensor's line of
// sight, with the model's uncertainty added to its covariance; W's samples then carry no model of
// their own. The sensor's own tracks keep their kind and go through the model as in the
// calibration (pairwise.h), the shared size correction included.
//
// CheckTracks (detection): the residuals of the sensor's tracks against W under its current pose,
// over the window given, summarised by the rigid correction that minimises them (FitMatches on the
// associated observations, Huber-weighted, so that a few wrong associations do not count):
//   correction = world_from_sensor(current)^-1 * world_from_sensor(fitted)
// in the sensor's frame (the convention of background_check.h: the sensor's new frame in its old
// one). A calibration leaves each sensor with a small correction of its own (its models of the
// object centres are not these; its poses carry their errors): `baseline`, the correction measured
// right after the pose was set, is what "nothing moved" looks like. The motion
// baseline^-1 * correction is tested against the fit's covariance without its sensor-bias part
// (chi^2 of the fitted pose minus current * baseline, (x_m, y_m, yaw_rad), 3 dof; the sensor's
// shared radial bias (calib::PairwiseOptions::sensor_bias) is a constant of its tracker, which
// the baseline, measured with the same bias, already holds; counted in the test, it would make
// a push along the lines of sight look smaller than it is): moved when chi^2 >= min_chi2, the
// motion is at least min_yaw_deg or min_translation_m and the fit's residual is at most
// max_fit_rms_m. Too few associated observations (min_matches) or too little spread of the
// sensor's matched positions (min_match_spread_m: one standing person fixes no rotation) is "not
// enough data", never "moved".
//
// EstimateFromTracks (correction): the same fit started from `initial` (e.g. the pose the
// background or the detection suggests); when that associates too little, the pairwise MSAC of
// the calibration (EstimatePair, eqs. 5-8 of Quenzel et al.) searches for the pose from scratch, so
// that a bump of 10 degrees or half a metre is found again.
//
// Pure and thread-safe (no shared state).

#include <Eigen/Core>
#include <cstddef>
#include <optional>
#include <string>
#include <vector>

#include "central_daemon/calibration/align.h"
#include "central_daemon/calibration/pairwise.h"
#include "central_daemon/ingest/sensor_data.h"
#include "common/geometry.h"

namespace lrfnet::monitoring {

using common::Pose2;
using daemon::TrackFrameData;

struct TrackCheckOptions {
  calib::AlignOptions align;
  // Association gate (refit_gate_m), the refit (Huber, model_sigma_m, view offsets, correlation of
  // grid steps) and, for EstimateFromTracks, the MSAC search and its acceptance.
  calib::PairwiseOptions pairwise = DefaultPairwise();
  // Tracks (the sensor's and the world's) that span less than this in the window (square root of
  // the largest eigenvalue of their positions' scatter) are left out: a box or a chair that the
  // trackers still see as foreground is seen from different sides by different sensors, and its
  // centres disagree by its size.
  double min_track_spread_m = 0.3;
  // A fit whose residual is larger than this (metres, rms) says nothing about a move: the
  // association failed.
  double max_fit_rms_m = 0.1;
  std::size_t min_matches = 60;     // associated observations (3 s of one person at 0.05 s)
  double min_match_spread_m = 0.5;  // of the sensor's matched positions (see pairwise.h)
  double min_yaw_deg = 0.5;
  double min_translation_m = 0.05;
  double min_chi2 = 25.0;

  static calib::PairwiseOptions DefaultPairwise();
};
std::optional<std::string> Validate(const TrackCheckOptions& options);

// A sensor's frames with its pose in the world.
struct PlacedFrames {
  std::string id;
  Pose2 world_from_sensor;
  const std::vector<TrackFrameData>* frames = nullptr;  // in scan order
};

struct TrackFit {
  bool enough = false;      // enough associated observations with enough spread
  bool moved = false;       // CheckTracks: the correction is large and significant
  std::string reason;       // a line for a person (why not enough, or the figures)
  Pose2 world_from_sensor;  // fitted (current when !enough)
  Pose2 correction;         // current^-1 * fitted, sensor frame (the baseline included)
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();  // of the fitted (x_m, y_m, yaw_rad)
  // Its part from the sensor's shared radial bias (left out of chi2, see above).
  Eigen::Matrix3d covariance_sensor_bias = Eigen::Matrix3d::Zero();
  double chi2 = 0.0;  // of the motion (covariance - covariance_sensor_bias)
  std::size_t matches = 0;
  double rms_m = 0.0;        // of the fit's residuals
  double spread_m = 0.0;     // of the sensor's matched positions
  bool from_search = false;  // EstimateFromTracks: found by the MSAC search
};

// `sensor`: the sensor's frames; `others`: the other placed sensors (not the sensor itself; sensors
// known to be misplaced left out by the caller). Precondition: Validate(options).
TrackFit CheckTracks(const std::vector<TrackFrameData>& sensor, const Pose2& world_from_sensor,
                     const std::vector<PlacedFrames>& others, const TrackCheckOptions& options,
                     const Pose2& baseline = Pose2::Identity());

// The fitted pose is what the tracks say (world_from_sensor); the sensor's pose in the
// calibration's terms is world_from_sensor * baseline^-1.
TrackFit EstimateFromTracks(const std::vector<TrackFrameData>& sensor, const Pose2& initial,
                            const std::vector<PlacedFrames>& others,
                            const TrackCheckOptions& options,
                            const Pose2& baseline = Pose2::Identity());

// The other sensors' frames as one recording in the world frame (positions, velocities and their
// covariance rotated and shifted by each pose; positions corrected by `model` and kinds as
// described above). Exposed for tests.
calib::SensorRecording WorldRecording(const std::vector<PlacedFrames>& others,
                                      const daemon::MeasurementModelOptions& model = {});

}  // namespace lrfnet::monitoring
