#pragma once
// Has a sensor moved? The background signal (pure): a new background snapshot of a sensor against
// its reference snapshot (the one in place when its pose was last calibrated), with the
// point-to-line ICP of the calibration (calib::RefineWithBackgrounds, Censi) run sensor-to-itself.
//
// Frames: a snapshot is polar in its sensor's frame (icp.h). A sensor that moved sees the static
// scene from its new pose; the ICP aligns the new snapshot's points onto the reference's lines and
// gives reference_from_current: the sensor's new frame expressed in its old one, so that
//   world_from_sensor (new) = world_from_sensor (old) * reference_from_current.
//
// What tells a moved sensor from a moved cart (CheckBackgrounds):
//   before = the share of the new snapshot's points that lie on the reference scene (within
//            inlier_distance_m of its polyline) as they are;
//   after  = that share under the best motion the ICP finds (started from every start_yaws_deg,
//            the start with the most inliers wins).
// Stage 1, the whole static scene moving together is a pose change: after >= min_inlier_fraction
// and either after - before >= min_inlier_gain (most of the scene agrees again under one rigid
// motion, which a parked cart or moved furniture, a small part of the scene, cannot achieve) or,
// for a small move that leaves most points within inlier_distance_m anyway, after >=
// small_move_min_inliers and after >= before; and the motion is both large (>= min_yaw_deg or >=
// min_translation_m) and significant (chi^2 of (x, y, yaw) against the ICP covariance times
// covariance_inflation, >= min_chi2).
// Stage 2, the changed part: a tracker re-learns its background beam by beam, so the first
// snapshots after a move show the new scene only where beams changed. The points off the
// reference scene are aligned alone; if they fit it under one motion that constrains every
// direction (no degenerate direction), and that motion keeps the unchanged points within the
// trackers' background margin, the sensor moved (partial = true). A cart's or a moved cupboard's
// points fit the scene under no such motion.
// A scene in which at least min_changed_fraction of the points left the reference while no such
// motion exists changed by itself (furniture): kSceneChanged. Everything else is kUnchanged.
//
// Degenerate scenes (a corridor): the ICP keeps the start along a degenerate direction; the motion
// along it is unknown, and the chi^2 uses the covariance the ICP gives there (the change bound),
// so such a motion alone is never significant.
//
// Pure and thread-safe (no shared state).

#include <Eigen/Core>
#include <cstddef>
#include <optional>
#include <string>
#include <vector>

#include "central_daemon/calibration/icp.h"
#include "central_daemon/ingest/sensor_data.h"
#include "common/geometry.h"

namespace lrfnet::monitoring {

using common::Pose2;
using daemon::BackgroundScan;

struct BackgroundCheckOptions {
  // The ICP (icp.h); its acceptance tests are replaced by the ones below (a motion is kept when
  // the ICP converged with enough correspondences). Ranges beyond max_range_m are ignored.
  calib::IcpOptions icp = DefaultIcp();
  // The ICP runs from each of these yaws (degrees; a bump turns a sensor by up to ~10 degrees,
  // more than the ICP's correspondence window reaches at long range).
  std::vector<double> start_yaws_deg = {0.0, -3.0, 3.0, -6.0, 6.0, -10.0, 10.0, -15.0, 15.0};
  // A point lies on the scene when it is this close to the other snapshot's polyline [m].
  double inlier_distance_m = 0.05;
  // Adjacent beams farther apart than this do not form a surface of the polyline [m].
  double max_segment_length_m = 0.5;
  // Too few points with a return: nothing can be said (kUnusable).
  std::size_t min_points = 50;
  // A pose change (see the header comment).
  double min_inlier_fraction = 0.7;
  double min_inlier_gain = 0.08;
  double min_yaw_deg = 0.3;
  double min_translation_m = 0.03;
  double min_chi2 = 25.0;
  // The ICP covariance treats neighbouring beams as independent; their errors are not (icp.h).
  double covariance_inflation = 9.0;
  // The small-move rule: most points lie on the scene either way, the motion fits at least as
  // well and this share of the points lies on it.
  double small_move_min_inliers = 0.9;
  // Stage 2 (see the header comment): the points of the new snapshot that are off the reference
  // scene, when at least min_changed_points; of them at least min_changed_explained on the scene
  // under the motion, and at least min_unchanged_kept of the other points within
  // unchanged_margin_m (the trackers' background margin) of it.
  std::size_t min_changed_points = 20;
  double min_changed_explained = 0.8;
  double unchanged_margin_m = 0.15;
  double min_unchanged_kept = 0.7;
  // A scene change without a pose change.
  double min_changed_fraction = 0.05;

  static calib::IcpOptions DefaultIcp();
};
std::optional<std::string> Validate(const BackgroundCheckOptions& options);

enum class BackgroundVerdictKind { kUnusable, kUnchanged, kMoved, kSceneChanged };
const char* ToString(BackgroundVerdictKind kind);

struct BackgroundVerdict {
  BackgroundVerdictKind kind = BackgroundVerdictKind::kUnusable;
  std::string reason;  // kUnusable: why; else a line for a person
  // The best pose found (`expected` when none), and its covariance of (x_m, y_m, yaw_rad)
  // (inflated; see options); the motion since the expectation, expected^-1 * that pose.
  Pose2 reference_from_current;
  Pose2 motion;
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  double chi2 = 0.0;
  double inliers_before = 0.0;  // shares of the current snapshot's points (see above)
  double inliers_after = 0.0;
  std::size_t points = 0;          // of the current snapshot
  std::size_t changed_points = 0;  // of them off the reference scene (stage 2 ran when enough)
  int degenerate_directions = 0;
  // kMoved from the changed points alone (stage 2): the tracker has not yet re-learned the rest.
  bool partial = false;
  // The whole scene's ICP pose (stage 1) and its covariance (inflated), also where the expectation
  // kept more points within inlier_distance_m and so is the verdict's pose; fit_share of the
  // current snapshot's points on the reference scene under it. A count of points within
  // inlier_distance_m decides whether there was a motion; it cannot place a sensor to a tenth of a
  // degree (0.2 degrees move a point at 6 m by 2 cm, and a few stale or grazing points decide the
  // count), the ICP's least-squares pose can: where the sensor is, ask the fit.
  bool fit_found = false;
  Pose2 fit_reference_from_current;
  Eigen::Matrix3d fit_covariance = Eigen::Matrix3d::Zero();
  double fit_share = 0.0;
};

// Compares `current` with `reference` (both of the same sensor). `expected` is where the sensor is
// believed to be relative to the reference snapshot's frame (identity, or a motion corrected
// since): "before" is measured there, the ICP also starts from it (and from it turned by each
// start yaw), and a move is judged on expected^-1 * reference_from_current.
// Precondition: Validate(options).
BackgroundVerdict CheckBackgrounds(const BackgroundScan& reference, const BackgroundScan& current,
                                   const BackgroundCheckOptions& options,
                                   const Pose2& expected = Pose2::Identity());

// The share of `points` (current frame) that lie within distance_m of the reference scene after
// mapping them with reference_from_current (the polyline through adjacent reference beams closer
// than max_segment_length_m, and its isolated points). 0 for no points.
double InlierFraction(const BackgroundScan& reference, const std::vector<Eigen::Vector2d>& points,
                      const Pose2& reference_from_current, double distance_m,
                      double max_segment_length_m, double max_range_m);

}  // namespace lrfnet::monitoring
