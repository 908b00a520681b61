#include "central_daemon/monitoring/background_check.h"

#include <fmt/format.h>

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>

namespace lrfnet::monitoring {

namespace {

// A background as the polyline through its adjacent returns, for point-to-scene distances.
class Scene {
 public:
  Scene(const BackgroundScan& scan, double max_segment_length_m, double max_range_m)
      : first_(scan.first_angle_rad),
        step_(scan.angle_step_rad),
        max_segment_(max_segment_length_m) {
    if (calib::CheckBackground(scan)) return;
    points_.resize(scan.ranges_mm.size());
    valid_.assign(scan.ranges_mm.size(), 0);
    for (std::size_t i = 0; i < scan.ranges_mm.size(); ++i) {
      const double r = scan.ranges_mm[i] * 1e-3;
      if (scan.ranges_mm[i] == 0 || (max_range_m > 0 && r > max_range_m)) continue;
      const double a = first_ + static_cast<double>(i) * step_;
      points_[i] = Eigen::Vector2d(r * std::cos(a), r * std::sin(a));
      valid_[i] = 1;
    }
  }

  // Distance of p (this scene's frame) to the nearest segment or isolated point within `reach`
  // metres; +inf when none is that close.
  double Distance(const Eigen::Vector2d& p, double reach) const {
    const double n = static_cast<double>(points_.size());
    const double range = p.norm();
    if (points_.empty() || !(range > 1e-6) || !std::isfinite(range)) {
      return std::numeric_limits<double>::infinity();
    }
    // Beams whose rays pass within `reach` of p.
    const double half = std::asin(std::min(1.0, reach / range)) + std::abs(step_);
    const double center = (std::atan2(p.y(), p.x()) - first_) / step_;
    const double width = half / std::abs(step_) + 1.0;
    double best = std::numeric_limits<double>::infinity();
    // The bearing may lie a full turn away from the first beam.
    for (const double turn : {0.0, 2.0 * common::kPi / step_, -2.0 * common::kPi / step_}) {
      const double lo = std::max(0.0, std::floor(center + turn - width));
      const double hi = std::min(n - 1.0, std::ceil(center + turn + width));
      for (double k = lo; k <= hi; k += 1.0) {
        const auto i = static_cast<std::size_t>(k);
        if (!valid_[i]) continue;
        best = std::min(best, (p - points_[i]).norm());
        if (i + 1 < points_.size() && valid_[i + 1]) {
          const Eigen::Vector2d a = points_[i], b = points_[i + 1];
          const Eigen::Vector2d ab = b - a;
          const double length2 = ab.squaredNorm();
          if (length2 > 0 && length2 <= max_segment_ * max_segment_) {
            const double u = std::clamp((p - a).dot(ab) / length2, 0.0, 1.0);
            best = std::min(best, (p - (a + u * ab)).norm());
          }
        }
      }
    }
    return best;
  }

 private:
  double first_, step_, max_segment_;
  std::vector<Eigen::Vector2d> points_;
  std::vector<unsigned char> valid_;
};

double Chi2(const Pose2& motion, const Eigen::Matrix3d& covariance) {
  const Eigen::Vector3d x(motion.x_m, motion.y_m, motion.yaw_rad);
  const Eigen::LDLT<Eigen::Matrix3d> ldlt(covariance);
  if (ldlt.info() != Eigen::Success || !ldlt.isPositive() ||
      covariance.diagonal().minCoeff() <= 0.0) {
    return 0.0;
  }
  const double chi2 = x.dot(ldlt.solve(x));
  return std::isfinite(chi2) && chi2 > 0 ? chi2 : 0.0;
}

}  // namespace

calib::IcpOptions BackgroundCheckOptions::DefaultIcp() {
  calib::IcpOptions o;
  // A sensor against itself: no calibration error to allow for, but a bump of up to ~0.5 m and
  // (from each start) a few degrees.
  o.initial_correspondence_m = 1.0;
  o.final_correspondence_m = 0.08;
  o.max_translation_change_m = 1.0;
  o.max_yaw_change_deg = 6.0;
  // Every converged result is a candidate; CheckBackgrounds decides.
  o.min_score_improvement = 0.0;
  return o;
}

const char* ToString(BackgroundVerdictKind kind) {
  switch (kind) {
    case BackgroundVerdictKind::kUnusable:
      return "unusable";
    case BackgroundVerdictKind::kUnchanged:
      return "unchanged";
    case BackgroundVerdictKind::kMoved:
      return "moved";
    case BackgroundVerdictKind::kSceneChanged:
      return "scene changed";
  }
  return "?";
}

std::optional<std::string> Validate(const BackgroundCheckOptions& o) {
  if (auto e = calib::Validate(o.icp)) return "icp." + *e;
  if (o.start_yaws_deg.empty() || o.start_yaws_deg.size() > 64) {
    return "start_yaws_deg: give 1 to 64 start yaws";
  }
  for (const double y : o.start_yaws_deg) {
    if (!(std::abs(y) <= 180.0)) return "start_yaws_deg: each in [-180, 180]";
  }
  const auto positive = [](double v, double hi) { return std::isfinite(v) && v > 0.0 && v <= hi; };
  const auto fraction = [](double v) { return std::isfinite(v) && v >= 0.0 && v <= 1.0; };
  if (!positive(o.inlier_distance_m, 1.0)) return "inlier_distance_m must be in (0, 1]";
  if (!positive(o.max_segment_length_m, 10.0)) return "max_segment_length_m must be in (0, 10]";
  if (o.min_points < 10) return "min_points must be >= 10";
  if (!fraction(o.min_inlier_fraction)) return "min_inlier_fraction must be in [0, 1]";
  if (!fraction(o.min_inlier_gain)) return "min_inlier_gain must be in [0, 1]";
  if (!fraction(o.min_changed_fraction)) return "min_changed_fraction must be in [0, 1]";
  if (!(std::isfinite(o.min_yaw_deg) && o.min_yaw_deg >= 0.0)) return "min_yaw_deg must be >= 0";
  if (!(std::isfinite(o.min_translation_m) && o.min_translation_m >= 0.0)) {
    return "min_translation_m must be >= 0";
  }
  if (!(std::isfinite(o.min_chi2) && o.min_chi2 >= 0.0)) return "min_chi2 must be >= 0";
  if (!fraction(o.small_move_min_inliers)) return "small_move_min_inliers must be in [0, 1]";
  if (o.min_changed_points < 3) return "min_changed_points must be >= 3";
  if (!fraction(o.min_changed_explained)) return "min_changed_explained must be in [0, 1]";
  if (!positive(o.unchanged_margin_m, 10.0)) return "unchanged_margin_m must be in (0, 10]";
  if (!fraction(o.min_unchanged_kept)) return "min_unchanged_kept must be in [0, 1]";
  if (!positive(o.covariance_inflation, 1e6)) return "covariance_inflation must be in (0, 1e6]";
  return std::nullopt;
}

double InlierFraction(const BackgroundScan& reference, const std::vector<Eigen::Vector2d>& points,
                      const Pose2& reference_from_current, double distance_m,
                      double max_segment_length_m, double max_range_m) {
  if (points.empty()) return 0.0;
  const Scene scene(reference, max_segment_length_m, max_range_m);
  std::size_t inliers = 0;
  for (const Eigen::Vector2d& p : points) {
    if (scene.Distance(reference_from_current * p, distance_m) <= distance_m) ++inliers;
  }
  return static_cast<double>(inliers) / static_cast<double>(points.size());
}

namespace {

struct Candidate {
  bool found = false;
  calib::IcpResult icp;
  double share = -1.0;  // of the scored points on the scene under icp.s_from_r
};

// The ICP of `current` onto `reference` from every start; the result that puts most of `scored`
// on the scene wins (ties keep the earlier start).
template <typename Share>
Candidate BestMotion(const BackgroundScan& reference, const BackgroundScan& current,
                     const std::vector<Pose2>& starts, const calib::IcpOptions& icp_options,
                     const Share& share_of) {
  Candidate best;
  for (const Pose2& start : starts) {
    // r = the new snapshot, s = the reference: s_from_r = reference_from_current.
    const calib::IcpResult icp =
        calib::RefineWithBackgrounds(current, reference, start, icp_options);
    if (!icp.applied) continue;
    const double share = share_of(icp.s_from_r);
    if (share > best.share + 1e-9) {
      best.found = true;
      best.icp = icp;
      best.share = share;
    }
  }
  return best;
}

}  // namespace

BackgroundVerdict CheckBackgrounds(const BackgroundScan& reference, const BackgroundScan& current,
                                   const BackgroundCheckOptions& options, const Pose2& expected) {
  if (auto e = Validate(options)) {
    std::fprintf(stderr, "CheckBackgrounds: invalid options: %s\n", e->c_str());
    std::abort();
  }
  BackgroundVerdict v;
  if (auto e = calib::CheckBackground(reference)) {
    v.reason = "reference snapshot: " + *e;
    return v;
  }
  if (auto e = calib::CheckBackground(current)) {
    v.reason = "new snapshot: " + *e;
    return v;
  }
  if (current.ranges_mm.size() != reference.ranges_mm.size() ||
      std::abs(current.first_angle_rad - reference.first_angle_rad) > 1e-6 ||
      std::abs(current.angle_step_rad - reference.angle_step_rad) > 1e-9) {
    v.reason = "the scan geometry changed (another device or configuration)";
    return v;
  }
  const double max_range_m = options.icp.max_range_m;
  const std::vector<Eigen::Vector2d> points = calib::BackgroundPoints(current, max_range_m);
  const std::size_t reference_points = calib::BackgroundPoints(reference, max_range_m).size();
  v.points = points.size();
  if (points.size() < options.min_points || reference_points < options.min_points) {
    v.reason = fmt::format("too few returns ({} new, {} in the reference; {} needed)",
                           points.size(), reference_points, options.min_points);
    return v;
  }
  const Scene scene(reference, options.max_segment_length_m, max_range_m);
  const double tau = options.inlier_distance_m;
  const auto share_within = [&](const std::vector<Eigen::Vector2d>& ps, const Pose2& pose,
                                double distance_m) {
    if (ps.empty()) return 0.0;
    std::size_t n = 0;
    for (const Eigen::Vector2d& p : ps) {
      if (scene.Distance(pose * p, distance_m) <= distance_m) ++n;
    }
    return static_cast<double>(n) / static_cast<double>(ps.size());
  };
  v.reference_from_current = expected;
  v.inliers_before = share_within(points, expected, tau);

  std::vector<Pose2> starts;
  for (const double yaw_deg : options.start_yaws_deg) {
    starts.push_back(expected * Pose2{0.0, 0.0, common::DegToRad(yaw_deg)});
  }
  const Pose2 from_expected = expected.inverse();
  const auto large = [&](const Pose2& pose) {
    const Pose2 m = from_expected * pose;
    return std::abs(common::RadToDeg(m.yaw_rad)) >= options.min_yaw_deg ||
           std::hypot(m.x_m, m.y_m) >= options.min_translation_m;
  };
  // chi^2 of the motion since the expectation, (x, y, yaw) of the pose against its covariance.
  const auto chi2_of = [&](const Pose2& pose, const Eigen::Matrix3d& covariance) {
    return Chi2(Pose2{pose.x_m - expected.x_m, pose.y_m - expected.y_m,
                      common::AngleDiff(pose.yaw_rad, expected.yaw_rad)},
                covariance);
  };
  const auto motion_text = [&](const Pose2& pose, double chi2) {
    const Pose2 m = from_expected * pose;
    return fmt::format("{:.2f} deg, {:.3f} m (chi2 {:.0f})", common::RadToDeg(m.yaw_rad),
                       std::hypot(m.x_m, m.y_m), chi2);
  };

  // Stage 1: the whole scene.
  const Candidate whole = BestMotion(reference, current, starts, options.icp,
                                     [&](const Pose2& m) { return share_within(points, m, tau); });
  // The expectation itself competes: a motion that puts fewer points on the scene is no motion.
  const bool better = whole.found && whole.share >= v.inliers_before;
  if (whole.found) {
    v.fit_found = true;
    v.fit_reference_from_current = whole.icp.s_from_r;
    v.fit_covariance = whole.icp.covariance * options.covariance_inflation;
    v.fit_share = whole.share;
  }
  v.inliers_after = better ? whole.share : v.inliers_before;
  if (better) {
    v.reference_from_current = whole.icp.s_from_r;
    v.covariance = whole.icp.covariance * options.covariance_inflation;
    v.degenerate_directions = whole.icp.degenerate_directions;
    v.chi2 = chi2_of(v.reference_from_current, v.covariance);
  }
  v.motion = from_expected * v.reference_from_current;
  const std::string shares = fmt::format(
      "{:.0f}% of {} points on the reference scene as they are, {:.0f}% after the motion",
      100.0 * v.inliers_before, v.points, 100.0 * v.inliers_after);
  // Most of the scene agrees again under one motion, where it did not before; or (a small move,
  // most points within inlier_distance_m either way) the motion fits the whole scene at least as
  // well and is far beyond the ICP's uncertainty.
  const bool together =
      v.inliers_after >= options.min_inlier_fraction &&
      (v.inliers_after - v.inliers_before >= options.min_inlier_gain ||
       (v.inliers_after >= options.small_move_min_inliers && v.inliers_after >= v.inliers_before));
  if (better && large(v.reference_from_current) && v.chi2 >= options.min_chi2 && together) {
    v.kind = BackgroundVerdictKind::kMoved;
    v.reason = "the whole scene moved together by " +
               motion_text(v.reference_from_current, v.chi2) + ": " + shares;
    return v;
  }

  // Stage 2: the changed part alone. A tracker's background follows a moved sensor beam by beam
  // (a farther return replaces the background within seconds, a nearer one only after it stayed
  // long): the first snapshots after a move hold the old background on most beams and the new
  // scene on the beams that changed. If the sensor moved, those points fit the reference scene
  // under one motion that constrains every direction, and that motion keeps the unchanged points
  // within the trackers' background margin; points of a cart or moved furniture fit the scene
  // under no such motion.
  BackgroundScan changed = current;
  std::vector<Eigen::Vector2d> changed_points, unchanged_points;
  for (std::size_t i = 0; i < changed.ranges_mm.size(); ++i) {
    const double r = changed.ranges_mm[i] * 1e-3;
    if (changed.ranges_mm[i] == 0 || (max_range_m > 0 && r > max_range_m)) {
      changed.ranges_mm[i] = 0;
      continue;
    }
    const double a = changed.first_angle_rad + static_cast<double>(i) * changed.angle_step_rad;
    const Eigen::Vector2d p(r * std::cos(a), r * std::sin(a));
    if (scene.Distance(expected * p, tau) <= tau) {
      changed.ranges_mm[i] = 0;
      unchanged_points.push_back(p);
    } else {
      changed_points.push_back(p);
    }
  }
  v.changed_points = changed_points.size();
  if (changed_points.size() >= options.min_changed_points) {
    calib::IcpOptions icp = options.icp;
    icp.min_correspondences = std::min(icp.min_correspondences, options.min_changed_points);
    const Candidate part = BestMotion(reference, changed, starts, icp, [&](const Pose2& m) {
      return share_within(changed_points, m, tau);
    });
    if (part.found) {
      const Pose2& m = part.icp.s_from_r;
      const Eigen::Matrix3d covariance = part.icp.covariance * options.covariance_inflation;
      const double chi2 = chi2_of(m, covariance);
      const double kept = share_within(unchanged_points, m, options.unchanged_margin_m);
      if (large(m) && chi2 >= options.min_chi2 && part.share >= options.min_changed_explained &&
          kept >= options.min_unchanged_kept) {
        v.kind = BackgroundVerdictKind::kMoved;
        v.partial = true;
        v.reference_from_current = m;
        v.motion = from_expected * m;
        v.covariance = covariance;
        v.chi2 = chi2;
        v.degenerate_directions = part.icp.degenerate_directions;
        v.inliers_after = share_within(points, m, tau);
        v.reason = fmt::format(
            "the changed part of the scene ({} points, {:.0f}% on the reference scene after the "
            "motion) moved together by {}, the rest ({:.0f}%) within {:.2f} m",
            changed_points.size(), 100.0 * part.share, motion_text(m, chi2), 100.0 * kept,
            options.unchanged_margin_m);
        return v;
      }
    }
  }
  if (1.0 - v.inliers_before >= options.min_changed_fraction) {
    v.kind = BackgroundVerdictKind::kSceneChanged;
    v.reason = "part of the scene changed, no common motion: " + shares;
  } else {
    v.kind = BackgroundVerdictKind::kUnchanged;
    v.reason = shares;
  }
  return v;
}

}  // namespace lrfnet::monitoring
