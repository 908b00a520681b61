#include "central_daemon/calibration/refine.h"

#include <ceres/ceres.h>

#include <Eigen/Cholesky>
#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <iomanip>
#include <limits>
#include <memory>
#include <numeric>
#include <optional>
#include <sstream>
#include <utility>

namespace lrfnet::calib {
namespace {

constexpr std::size_t kNone = static_cast<std::size_t>(-1);
// Bounds far beyond any real sample; they keep every product below finite overflow.
constexpr double kMaxModelValue = 100.0;
// The association gate shrinks by this factor per round down to association_gate_m.
constexpr double kGateShrink = 0.7;

// One valid track sample of a calibrated sensor at a used grid step, already whitened:
// z = CentreOf (the body centre at zero size correction), jd = CentrePerSizeCorrection,
// sqrt_info = L^-1 with L L^T = CentreCovariance + (sigma_per_m |z|)^2 I.
struct StepSample {
  std::size_t sensor = 0;
  std::size_t group = 0;  // the track (over all sensors): its own systematic offset
  Eigen::Vector2d z = Eigen::Vector2d::Zero();
  Eigen::Matrix2d jd = Eigen::Matrix2d::Zero();
  Eigen::Matrix2d sqrt_info = Eigen::Matrix2d::Identity();
  // The sample's shift for one standard deviation of its sensor's shared radial bias:
  // TrackSample::shared_bias_sigma_m along the line of sight (zero without sensor_bias).
  Eigen::Vector2d shared_bias = Eigen::Vector2d::Zero();
};

struct Observation {
  std::size_t sensor = 0;
  std::size_t group = 0;
  std::size_t object = 0;
  std::size_t sample = 0;  // index into the step's samples (identifies the association)
  Eigen::Vector2d z = Eigen::Vector2d::Zero();
  Eigen::Matrix2d jd = Eigen::Matrix2d::Zero();
  Eigen::Matrix2d sqrt_info = Eigen::Matrix2d::Identity();
  Eigen::Vector2d shared_bias = Eigen::Vector2d::Zero();
};

struct Association {
  std::vector<Observation> observations;
  std::vector<Eigen::Vector2d> objects;  // world positions
  std::vector<std::size_t> object_step;  // used-step index of each object (non-decreasing)

  bool SameGrouping(const Association& o) const {
    if (observations.size() != o.observations.size()) return false;
    for (std::size_t i = 0; i < observations.size(); ++i) {
      const Observation& a = observations[i];
      const Observation& b = o.observations[i];
      if (a.sample != b.sample || a.object != b.object ||
          object_step[a.object] != o.object_step[b.object]) {
        return false;
      }
    }
    return true;
  }

  std::size_t Steps() const {
    std::size_t steps = 0;
    for (std::size_t o = 0; o < object_step.size(); ++o) {
      if (o == 0 || object_step[o] != object_step[o - 1]) ++steps;
    }
    return steps;
  }
};

using PoseParams = std::array<double, 3>;  // x_m, y_m, yaw_rad of world_from_sensor
using SizeParams = std::array<double, 2>;  // d_major, d_minor

PoseParams ToParams(const Pose2& p) { return {p.x_m, p.y_m, p.yaw_rad}; }
Pose2 ToPose(const PoseParams& p) { return {p[0], p[1], common::NormalizeAngle(p[2])}; }

// e = R^T (o - t) - z - jd d, and its Jacobians with respect to the object, the pose (x, y, yaw)
// and the size correction d; unwhitened.
struct Linearization {
  Eigen::Vector2d e;
  Eigen::Matrix2d d_object;
  Eigen::Matrix<double, 2, 3> d_pose;
  Eigen::Matrix2d d_size;
};

// `c`, `s`: cos and sin of pose[2] (callers evaluating many observations of one sensor reuse them).
Linearization Linearize(const Eigen::Vector2d& z, const Eigen::Matrix2d& jd, const double* object,
                        const double* pose, double c, double s, const double* size) {
  const double dx = object[0] - pose[0], dy = object[1] - pose[1];
  Linearization l;
  l.e = Eigen::Vector2d(c * dx + s * dy, -s * dx + c * dy) - z -
        jd * Eigen::Vector2d(size[0], size[1]);
  l.d_object << c, s, -s, c;
  l.d_pose.leftCols<2>() = -l.d_object;
  l.d_pose.col(2) = Eigen::Vector2d(-s * dx + c * dy, -c * dx - s * dy);
  l.d_size = -jd;
  return l;
}

Linearization Linearize(const Eigen::Vector2d& z, const Eigen::Matrix2d& jd, const double* object,
                        const double* pose, const double* size) {
  return Linearize(z, jd, object, pose, std::cos(pose[2]), std::sin(pose[2]), size);
}

// cos and sin of every sensor's yaw.
std::vector<std::pair<double, double>> CosSin(const std::vector<PoseParams>& params) {
  std::vector<std::pair<double, double>> out(params.size());
  for (std::size_t s = 0; s < params.size(); ++s) {
    out[s] = {std::cos(params[s][2]), std::sin(params[s][2])};
  }
  return out;
}

// The whitened Jacobians of an observation's residual into Ceres' blocks (those requested): object
// (2), pose (3), the two components of the size correction (1 each).
void WhitenedJacobians(const Linearization& l, const Eigen::Matrix2d& sqrt_info,
                       double** jacobians) {
  if (jacobians[0] != nullptr) {
    Eigen::Map<Eigen::Matrix<double, 2, 2, Eigen::RowMajor>> j_object(jacobians[0]);
    j_object = sqrt_info * l.d_object;
  }
  if (jacobians[1] != nullptr) {
    Eigen::Map<Eigen::Matrix<double, 2, 3, Eigen::RowMajor>> j_pose(jacobians[1]);
    j_pose = sqrt_info * l.d_pose;
  }
  for (int k = 0; k < 2; ++k) {
    if (jacobians[2 + k] != nullptr) {
      Eigen::Map<Eigen::Vector2d> j_size(jacobians[2 + k]);
      j_size = sqrt_info * l.d_size.col(k);
    }
  }
}

// Whitened residual of one observation; parameter blocks: object (2), sensor pose (3), the two
// components of the size correction (1 each, so that either can be held). Where Quenzel et al.
// compare two sensors' observations by their Mahalanobis distance under the summed covariances
// (eq. 6), every observation here is compared with a common object position, so that any number
// of sensors share one object.
class ObservationCost final : public ceres::SizedCostFunction<2, 2, 3, 1, 1> {
 public:
  ObservationCost(const Eigen::Vector2d& z, const Eigen::Matrix2d& jd,
                  const Eigen::Matrix2d& sqrt_info)
      : z_(z), jd_(jd), sqrt_info_(sqrt_info) {}

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const double size[2] = {parameters[2][0], parameters[3][0]};
    const Linearization l = Linearize(z_, jd_, parameters[0], parameters[1], size);
    Eigen::Map<Eigen::Vector2d> r(residuals);
    r = sqrt_info_ * l.e;
    if (jacobians != nullptr) {
      WhitenedJacobians(l, sqrt_info_, jacobians);
    }
    return true;
  }

 private:
  Eigen::Vector2d z_;
  Eigen::Matrix2d jd_;
  Eigen::Matrix2d sqrt_info_;
};

// The same for an observation of a sensor whose shared radial bias is estimated: a fifth block,
// the bias' change beta (standard deviations of the prior) since it was last applied to z, moving
// the centre by beta * shared_bias.
class ObservationBiasCost final : public ceres::SizedCostFunction<2, 2, 3, 1, 1, 1> {
 public:
  ObservationBiasCost(const Eigen::Vector2d& z, const Eigen::Matrix2d& jd,
                      const Eigen::Matrix2d& sqrt_info, const Eigen::Vector2d& shared_bias)
      : z_(z), jd_(jd), sqrt_info_(sqrt_info), shared_bias_(shared_bias) {}

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const double size[2] = {parameters[2][0], parameters[3][0]};
    const Linearization l =
        Linearize(z_ + parameters[4][0] * shared_bias_, jd_, parameters[0], parameters[1], size);
    Eigen::Map<Eigen::Vector2d> r(residuals);
    r = sqrt_info_ * l.e;
    if (jacobians != nullptr) {
      WhitenedJacobians(l, sqrt_info_, jacobians);
      if (jacobians[4] != nullptr) {
        Eigen::Map<Eigen::Vector2d> j_bias(jacobians[4]);
        j_bias = -(sqrt_info_ * shared_bias_);
      }
    }
    return true;
  }

 private:
  Eigen::Vector2d z_;
  Eigen::Matrix2d jd_;
  Eigen::Matrix2d sqrt_info_;
  Eigen::Vector2d shared_bias_;
};

// The prior of a sensor's shared bias, N(0, 1) in standard deviations: (applied + beta) / 1.
class BiasPriorCost final : public ceres::SizedCostFunction<1, 1> {
 public:
  explicit BiasPriorCost(double applied) : applied_(applied) {}
  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    residuals[0] = applied_ + parameters[0][0];
    if (jacobians != nullptr && jacobians[0] != nullptr) jacobians[0][0] = 1.0;
    return true;
  }

 private:
  double applied_;
};

// The prior of one size-correction component: d / sigma.
class SizePriorCost final : public ceres::SizedCostFunction<1, 1> {
 public:
  explicit SizePriorCost(double sigma_m) : inv_sigma_(1.0 / sigma_m) {}
  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    residuals[0] = inv_sigma_ * parameters[0][0];
    if (jacobians != nullptr && jacobians[0] != nullptr) jacobians[0][0] = inv_sigma_;
    return true;
  }

 private:
  double inv_sigma_;
};

// A usable relative-pose constraint, whitened once.
struct Constraint {
  std::size_t r = 0, s = 0;
  Eigen::Vector3d measured = Eigen::Vector3d::Zero();  // x, y, yaw of s_from_r
  Eigen::Matrix3d sqrt_info = Eigen::Matrix3d::Identity();
};

// e = x(T_s^-1 T_r) - x(s_from_r) (yaw wrapped) and its Jacobians with respect to the poses of r
// and s; unwhitened.
struct ConstraintLinearization {
  Eigen::Vector3d e;
  Eigen::Matrix3d d_r;
  Eigen::Matrix3d d_s;
};

ConstraintLinearization LinearizeConstraint(const Eigen::Vector3d& measured, const double* pose_r,
                                            const double* pose_s) {
  const double c = std::cos(pose_s[2]), s = std::sin(pose_s[2]);
  const double dx = pose_r[0] - pose_s[0], dy = pose_r[1] - pose_s[1];
  ConstraintLinearization l;
  l.e = Eigen::Vector3d(c * dx + s * dy - measured.x(), -s * dx + c * dy - measured.y(),
                        common::NormalizeAngle(pose_r[2] - pose_s[2] - measured.z()));
  l.d_r << c, s, 0.0, -s, c, 0.0, 0.0, 0.0, 1.0;
  l.d_s << -c, -s, -s * dx + c * dy, s, -c, -c * dx - s * dy, 0.0, 0.0, -1.0;
  return l;
}

class ConstraintCost final : public ceres::SizedCostFunction<3, 3, 3> {
 public:
  ConstraintCost(const Eigen::Vector3d& measured, const Eigen::Matrix3d& sqrt_info)
      : measured_(measured), sqrt_info_(sqrt_info) {}

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const ConstraintLinearization l = LinearizeConstraint(measured_, parameters[0], parameters[1]);
    Eigen::Map<Eigen::Vector3d> r(residuals);
    r = sqrt_info_ * l.e;
    if (jacobians != nullptr) {
      if (jacobians[0] != nullptr) {
        Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> j_r(jacobians[0]);
        j_r = sqrt_info_ * l.d_r;
      }
      if (jacobians[1] != nullptr) {
        Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> j_s(jacobians[1]);
        j_s = sqrt_info_ * l.d_s;
      }
    }
    return true;
  }

 private:
  Eigen::Vector3d measured_;
  Eigen::Matrix3d sqrt_info_;
};

// The usable constraints between calibrated sensors; counts the others.
std::vector<Constraint> UsableConstraints(const std::vector<RelativePoseConstraint>& constraints,
                                          const std::vector<bool>& calibrated,
                                          std::size_t& rejected) {
  std::vector<Constraint> out;
  for (const RelativePoseConstraint& c : constraints) {
    const Eigen::Matrix3d& cov = c.covariance;
    const bool indices_ok = c.r < calibrated.size() && c.s < calibrated.size() && c.r != c.s &&
                            calibrated[c.r] && calibrated[c.s];
    const bool values_ok =
        std::isfinite(c.s_from_r.x_m) && std::isfinite(c.s_from_r.y_m) &&
        std::isfinite(c.s_from_r.yaw_rad) && cov.allFinite() &&
        (cov - cov.transpose()).cwiseAbs().maxCoeff() <= 1e-9 * (1.0 + cov.cwiseAbs().maxCoeff());
    const Eigen::LLT<Eigen::Matrix3d> llt(cov);
    if (!indices_ok || !values_ok || llt.info() != Eigen::Success ||
        llt.matrixL().toDenseMatrix().diagonal().minCoeff() <= 0.0) {
      ++rejected;
      continue;
    }
    Constraint u;
    u.r = c.r;
    u.s = c.s;
    u.measured = Eigen::Vector3d(c.s_from_r.x_m, c.s_from_r.y_m, c.s_from_r.yaw_rad);
    u.sqrt_info = llt.matrixL().solve(Eigen::Matrix3d::Identity());
    if (!u.sqrt_info.allFinite()) {
      ++rejected;
      continue;
    }
    out.push_back(u);
  }
  return out;
}

std::unique_ptr<ceres::LossFunction> MakeLoss(const JointRefineOptions& options) {
  switch (options.loss) {
    case RobustLoss::kHuber:
      return std::make_unique<ceres::HuberLoss>(options.loss_scale);
    case RobustLoss::kCauchy:
      return std::make_unique<ceres::CauchyLoss>(options.loss_scale);
    case RobustLoss::kNone:
      break;
  }
  return nullptr;
}

// rho(s), rho'(s) of the loss (the trivial loss when null).
std::pair<double, double> Rho(const ceres::LossFunction* loss, double squared_norm) {
  if (loss == nullptr) return {squared_norm, 1.0};
  double rho[3];
  loss->Evaluate(squared_norm, rho);
  return {rho[0], rho[1]};
}

bool IsFinite(const Pose2& p) {
  return std::isfinite(p.x_m) && std::isfinite(p.y_m) && std::isfinite(p.yaw_rad);
}

bool UsableModel(const TrackSample& x) {
  for (const float v : {x.bias_m, x.bias_per_major, x.bias_per_minor, x.bias_sigma_m,
                        x.model_sigma_m, x.shared_bias_sigma_m}) {
    if (!std::isfinite(v) || std::abs(v) > kMaxModelValue) return false;
  }
  return true;
}

// The valid samples of the calibrated sensors at every used step, whitened once. `groups`: the
// number of tracks (over all sensors) that gave samples.
std::vector<std::vector<StepSample>> CollectSamples(
    const AlignedTracks& tracks, const std::vector<bool>& calibrated, std::size_t stride,
    const JointRefineOptions& options, std::size_t& rejected, std::vector<double>& group_sigma) {
  const std::size_t used = tracks.steps == 0 ? 0 : (tracks.steps - 1) / stride + 1;
  std::vector<std::vector<StepSample>> per_step(used);
  group_sigma.clear();
  std::size_t groups = 0;
  for (std::size_t s = 0; s < tracks.sensors.size(); ++s) {
    if (!calibrated[s]) continue;
    for (const GridTrack& track : tracks.sensors[s].tracks) {
      if (track.first_step >= tracks.steps) continue;
      const std::size_t group = groups++;
      double range_sum = 0.0, range_count = 0.0;
      // First used step at or after the track's start; the grid end clips malformed tracks.
      std::size_t step = (track.first_step + stride - 1) / stride * stride;
      const std::size_t end = std::min(track.end_step(), tracks.steps);
      for (; step < end; step += stride) {
        const TrackSample& sample = track.At(step);
        const Eigen::Matrix2d& cov = sample.position_cov_m2;
        const double tolerance = 1e-9 * (1.0 + cov.cwiseAbs().maxCoeff());
        if (!sample.position_m.allFinite() || !cov.allFinite() || !UsableModel(sample) ||
            std::abs(cov(0, 1) - cov(1, 0)) > tolerance || cov(0, 0) < 0.0 || cov(1, 1) < 0.0 ||
            cov.determinant() < -tolerance * tolerance) {
          ++rejected;
          continue;
        }
        StepSample out;
        out.sensor = s;
        out.group = group;
        out.z = CentreOf(sample);
        out.jd = CentrePerSizeCorrection(sample);
        const double range_sigma = options.model_sigma_per_m * out.z.norm();
        const Eigen::Matrix2d total =
            CentreCovariance(sample) + range_sigma * range_sigma * Eigen::Matrix2d::Identity();
        const Eigen::LLT<Eigen::Matrix2d> llt(total);
        if (!out.z.allFinite() || llt.info() != Eigen::Success || total.determinant() <= 0.0) {
          ++rejected;
          continue;
        }
        out.sqrt_info = llt.matrixL().solve(Eigen::Matrix2d::Identity());
        if (options.sensor_bias) {
          out.shared_bias =
              static_cast<double>(sample.shared_bias_sigma_m) * LineOfSight(sample.position_m);
        }
        if (!out.sqrt_info.allFinite()) {
          ++rejected;
          continue;
        }
        per_step[step / stride].push_back(out);
        range_sum += out.z.norm();
        range_count += 1.0;
        group_sigma.resize(groups, options.segment_sigma_m);
        group_sigma[group] =
            options.segment_sigma_m + options.segment_sigma_per_m * range_sum / range_count;
      }
    }
  }
  group_sigma.resize(groups, options.segment_sigma_m);
  return per_step;
}

// The body centre an observation implies with the size correction d, sensor frame.
Eigen::Vector2d CentreWith(const StepSample& sample, const SizeParams& size) {
  return sample.z + sample.jd * Eigen::Vector2d(size[0], size[1]);
}

// Greedy agglomerative clustering at one step: candidate pairs of different sensors within the
// gate, nearest first; two clusters merge when they share no sensor and every cross pair is
// within the gate (complete linkage keeps two people walking side by side apart).
void AssociateStep(const std::vector<StepSample>& samples, std::size_t step_index,
                   const std::vector<Pose2>& poses, const SizeParams& size, double gate_m,
                   Association& out) {
  const std::size_t n = samples.size();
  if (n < 2) return;
  std::vector<Eigen::Vector2d> world(n);
  for (std::size_t i = 0; i < n; ++i)
    world[i] = poses[samples[i].sensor] * CentreWith(samples[i], size);

  // Sweep over x to find the candidate pairs without testing all n^2.
  std::vector<std::size_t> by_x(n);
  std::iota(by_x.begin(), by_x.end(), std::size_t{0});
  std::sort(by_x.begin(), by_x.end(),
            [&](std::size_t a, std::size_t b) { return world[a].x() < world[b].x(); });
  struct Pair {
    double d2;
    std::size_t i, j;
  };
  std::vector<Pair> pairs;
  const double gate2 = gate_m * gate_m;
  for (std::size_t a = 0; a < n; ++a) {
    const std::size_t i = by_x[a];
    for (std::size_t b = a + 1; b < n; ++b) {
      const std::size_t j = by_x[b];
      if (world[j].x() - world[i].x() > gate_m) break;
      if (samples[i].sensor == samples[j].sensor) continue;
      const double d2 = (world[i] - world[j]).squaredNorm();
      if (d2 <= gate2) pairs.push_back({d2, std::min(i, j), std::max(i, j)});
    }
  }
  if (pairs.empty()) return;
  std::sort(pairs.begin(), pairs.end(), [](const Pair& a, const Pair& b) {
    return a.d2 < b.d2 || (a.d2 == b.d2 && (a.i < b.i || (a.i == b.i && a.j < b.j)));
  });

  std::vector<std::size_t> cluster(n);
  std::iota(cluster.begin(), cluster.end(), std::size_t{0});
  std::vector<std::vector<std::size_t>> members(n);
  for (std::size_t i = 0; i < n; ++i) members[i] = {i};
  for (const Pair& p : pairs) {
    const std::size_t a = cluster[p.i], b = cluster[p.j];
    if (a == b) continue;
    bool compatible = true;
    for (std::size_t u : members[a]) {
      for (std::size_t v : members[b]) {
        if (samples[u].sensor == samples[v].sensor || (world[u] - world[v]).squaredNorm() > gate2) {
          compatible = false;
          break;
        }
      }
      if (!compatible) break;
    }
    if (!compatible) continue;
    for (std::size_t v : members[b]) cluster[v] = a;
    members[a].insert(members[a].end(), members[b].begin(), members[b].end());
    members[b].clear();
  }

  // Objects in the order of their first sample, observations in sample order: the same grouping
  // gives the same association whatever the merge order was.
  std::vector<std::size_t> order;
  for (std::size_t c = 0; c < n; ++c) {
    if (members[c].size() < 2) continue;
    std::sort(members[c].begin(), members[c].end());
    order.push_back(c);
  }
  std::sort(order.begin(), order.end(),
            [&](std::size_t a, std::size_t b) { return members[a].front() < members[b].front(); });
  for (std::size_t c : order) {
    const std::size_t object = out.objects.size();
    Eigen::Vector2d mean = Eigen::Vector2d::Zero();
    for (std::size_t i : members[c]) {
      mean += world[i];
      const StepSample& sample = samples[i];
      out.observations.push_back({sample.sensor, sample.group, object, i, sample.z, sample.jd,
                                  sample.sqrt_info, sample.shared_bias});
    }
    out.objects.push_back(mean / static_cast<double>(members[c].size()));
    out.object_step.push_back(step_index);
  }
}

// Drops the observations not kept and the objects left with fewer than two; renumbers the rest.
void CompactObjects(Association& a, const std::vector<bool>& keep_observation) {
  std::vector<std::size_t> count(a.objects.size(), 0);
  for (std::size_t i = 0; i < a.observations.size(); ++i) {
    if (keep_observation[i]) ++count[a.observations[i].object];
  }
  std::vector<std::size_t> new_index(a.objects.size(), kNone);
  std::vector<Eigen::Vector2d> objects;
  std::vector<std::size_t> object_step;
  for (std::size_t o = 0; o < a.objects.size(); ++o) {
    if (count[o] >= 2) {
      new_index[o] = objects.size();
      objects.push_back(a.objects[o]);
      object_step.push_back(a.object_step[o]);
    }
  }
  std::vector<Observation> observations;
  for (std::size_t i = 0; i < a.observations.size(); ++i) {
    Observation ob = a.observations[i];
    if (!keep_observation[i] || new_index[ob.object] == kNone) continue;
    ob.object = new_index[ob.object];
    observations.push_back(ob);
  }
  a.objects = std::move(objects);
  a.object_step = std::move(object_step);
  a.observations = std::move(observations);
}

std::vector<std::size_t> CountPerSensor(const Association& a, std::size_t sensors) {
  std::vector<std::size_t> count(sensors, 0);
  for (const Observation& ob : a.observations) ++count[ob.sensor];
  return count;
}

// Keeps the sensors with enough observations that are connected to the reference through shared
// objects (the others have no gauge); returns the sensors that remain.
std::vector<bool> PruneSensors(Association& a, const std::vector<Constraint>& constraints,
                               std::size_t sensors, std::size_t reference,
                               std::size_t min_sensor_observations) {
  // A constraint holds a sensor in place as well as enough observations do.
  std::vector<bool> constrained(sensors, false);
  for (const Constraint& c : constraints) constrained[c.r] = constrained[c.s] = true;
  std::vector<bool> active(sensors, true);
  for (;;) {
    const std::vector<std::size_t> count = CountPerSensor(a, sensors);
    bool changed = false;
    for (std::size_t s = 0; s < sensors; ++s) {
      if (active[s] && !constrained[s] && count[s] < min_sensor_observations) {
        active[s] = false;
        changed = true;
      }
    }
    if (!changed) break;
    std::vector<bool> keep(a.observations.size());
    for (std::size_t i = 0; i < keep.size(); ++i) keep[i] = active[a.observations[i].sensor];
    CompactObjects(a, keep);
  }

  // Connectivity over the sensor-object incidence graph and the constraints, from the reference.
  std::vector<std::vector<std::size_t>> object_sensors(a.objects.size());
  std::vector<std::vector<std::size_t>> sensor_objects(sensors);
  std::vector<std::vector<std::size_t>> sensor_neighbours(sensors);
  for (const Observation& ob : a.observations) {
    object_sensors[ob.object].push_back(ob.sensor);
    sensor_objects[ob.sensor].push_back(ob.object);
  }
  for (const Constraint& c : constraints) {
    sensor_neighbours[c.r].push_back(c.s);
    sensor_neighbours[c.s].push_back(c.r);
  }
  std::vector<bool> reached(sensors, false);
  std::vector<bool> object_seen(a.objects.size(), false);
  std::vector<std::size_t> queue;
  if (active[reference]) {
    reached[reference] = true;
    queue.push_back(reference);
  }
  while (!queue.empty()) {
    const std::size_t s = queue.back();
    queue.pop_back();
    for (std::size_t t : sensor_neighbours[s]) {
      if (active[t] && !reached[t]) {
        reached[t] = true;
        queue.push_back(t);
      }
    }
    for (std::size_t o : sensor_objects[s]) {
      if (object_seen[o]) continue;
      object_seen[o] = true;
      for (std::size_t t : object_sensors[o]) {
        if (!reached[t]) {
          reached[t] = true;
          queue.push_back(t);
        }
      }
    }
  }
  std::vector<bool> keep(a.observations.size());
  for (std::size_t i = 0; i < keep.size(); ++i) keep[i] = reached[a.observations[i].sensor];
  CompactObjects(a, keep);
  return reached;
}

struct SolveOutcome {
  bool usable = false;
  std::string report;
  int iterations = 0;
  double time_s = 0.0;
};

SolveOutcome Solve(const Association& a, const std::vector<Constraint>& constraints,
                   const std::vector<bool>& free_sensor, const std::array<bool, 2>& free_size,
                   double size_prior_sigma_m, std::vector<PoseParams>& poses, SizeParams& size,
                   std::vector<Eigen::Vector2d>& objects, const ceres::LossFunction* loss,
                   double observation_weight, const JointRefineOptions& options,
                   const std::vector<bool>& free_bias, const std::vector<double>& applied_bias,
                   std::vector<double>& bias_step) {
  // Declared before the problem, which refers to them until destroyed.
  ceres::ScaledLoss observation_loss(loss, observation_weight, ceres::DO_NOT_TAKE_OWNERSHIP);
  ceres::CauchyLoss constraint_loss(options.constraint_loss_scale);
  ceres::Problem::Options problem_options;
  problem_options.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem problem(problem_options);
  auto ordering = std::make_shared<ceres::ParameterBlockOrdering>();

  // Objects go into the eliminated group 0; poses and the size correction form the reduced
  // system.
  std::vector<bool> in_problem(poses.size(), false);
  std::size_t free_count = 0;
  auto add_pose = [&](std::size_t sensor) {
    if (in_problem[sensor]) return;
    in_problem[sensor] = true;
    problem.AddParameterBlock(poses[sensor].data(), 3);
    ordering->AddElementToGroup(poses[sensor].data(), 1);
    if (free_sensor[sensor]) {
      ++free_count;
    } else {
      problem.SetParameterBlockConstant(poses[sensor].data());
    }
  };
  for (const Constraint& c : constraints) {
    add_pose(c.r);
    add_pose(c.s);
  }
  for (const Observation& ob : a.observations) add_pose(ob.sensor);
  for (int k = 0; k < 2; ++k) {
    problem.AddParameterBlock(&size[k], 1);
    ordering->AddElementToGroup(&size[k], 1);
    if (!free_size[k] || !(size_prior_sigma_m > 0.0)) {
      problem.SetParameterBlockConstant(&size[k]);
    } else {
      problem.AddResidualBlock(new SizePriorCost(size_prior_sigma_m), nullptr, &size[k]);
    }
  }
  bias_step.assign(poses.size(), 0.0);
  for (std::size_t sensor = 0; sensor < poses.size(); ++sensor) {
    if (sensor >= free_bias.size() || !free_bias[sensor]) continue;
    problem.AddParameterBlock(&bias_step[sensor], 1);
    ordering->AddElementToGroup(&bias_step[sensor], 1);
    problem.AddResidualBlock(new BiasPriorCost(applied_bias[sensor]), nullptr, &bias_step[sensor]);
  }
  for (Eigen::Vector2d& o : objects) {
    problem.AddParameterBlock(o.data(), 2);
    ordering->AddElementToGroup(o.data(), 0);
  }
  for (const Observation& ob : a.observations) {
    if (ob.sensor < free_bias.size() && free_bias[ob.sensor]) {
      problem.AddResidualBlock(new ObservationBiasCost(ob.z, ob.jd, ob.sqrt_info, ob.shared_bias),
                               &observation_loss, objects[ob.object].data(),
                               poses[ob.sensor].data(), &size[0], &size[1], &bias_step[ob.sensor]);
      continue;
    }
    problem.AddResidualBlock(new ObservationCost(ob.z, ob.jd, ob.sqrt_info), &observation_loss,
                             objects[ob.object].data(), poses[ob.sensor].data(), &size[0],
                             &size[1]);
  }
  for (const Constraint& c : constraints) {
    problem.AddResidualBlock(new ConstraintCost(c.measured, c.sqrt_info), &constraint_loss,
                             poses[c.r].data(), poses[c.s].data());
  }

  ceres::Solver::Options solver;
  solver.logging_type = ceres::SILENT;
  solver.minimizer_progress_to_stdout = false;
  solver.max_num_iterations = options.max_iterations;
  solver.num_threads = options.threads;
  solver.function_tolerance = options.function_tolerance;
  solver.parameter_tolerance = options.parameter_tolerance;
  solver.gradient_tolerance = 1e-14;
  solver.linear_solver_ordering = ordering;
  bool sparse = options.linear_solver == RefineLinearSolver::kSparseSchur ||
                (options.linear_solver == RefineLinearSolver::kAuto &&
                 free_count > options.dense_schur_max_sensors);
  if (sparse) {
    // Debian's Ceres 2.1 has SuiteSparse, CXSparse and Eigen sparse; take what this build has.
    const std::array<ceres::SparseLinearAlgebraLibraryType, 3> libraries = {
        ceres::SUITE_SPARSE, ceres::EIGEN_SPARSE, ceres::CX_SPARSE};
    sparse = false;
    for (const auto library : libraries) {
      if (ceres::IsSparseLinearAlgebraLibraryTypeAvailable(library)) {
        solver.sparse_linear_algebra_library_type = library;
        sparse = true;
        break;
      }
    }
  }
  solver.linear_solver_type = sparse ? ceres::SPARSE_SCHUR : ceres::DENSE_SCHUR;

  ceres::Solver::Summary summary;
  ceres::Solve(solver, &problem, &summary);
  SolveOutcome out;
  out.usable = summary.IsSolutionUsable();
  out.report = summary.message;
  out.iterations = static_cast<int>(summary.iterations.size());
  out.time_s = summary.total_time_in_seconds;
  return out;
}

std::vector<std::vector<std::size_t>> ObservationsByObject(const Association& a) {
  std::vector<std::vector<std::size_t>> by_object(a.objects.size());
  for (std::size_t i = 0; i < a.observations.size(); ++i) {
    by_object[a.observations[i].object].push_back(i);
  }
  return by_object;
}

// Every object at its optimum with poses and the size correction fixed: iteratively reweighted
// Gauss-Newton per object (objects are independent once the rest is fixed), halving steps that do
// not lower the cost (the robust loss).
void OptimizeObjects(const Association& a, const std::vector<PoseParams>& params,
                     const SizeParams& size, const ceres::LossFunction* loss,
                     std::vector<Eigen::Vector2d>& objects) {
  const std::vector<std::vector<std::size_t>> by_object = ObservationsByObject(a);
  const std::vector<std::pair<double, double>> cos_sin = CosSin(params);
  auto linearize = [&](const Observation& ob, const Eigen::Vector2d& x) {
    const auto [c, s] = cos_sin[ob.sensor];
    return Linearize(ob.z, ob.jd, x.data(), params[ob.sensor].data(), c, s, size.data());
  };
  auto cost_of = [&](const std::vector<std::size_t>& members, const Eigen::Vector2d& x) {
    double cost = 0.0;
    for (std::size_t i : members) {
      const Observation& ob = a.observations[i];
      cost += 0.5 * Rho(loss, (ob.sqrt_info * linearize(ob, x).e).squaredNorm()).first;
    }
    return cost;
  };
  for (std::size_t o = 0; o < objects.size(); ++o) {
    Eigen::Vector2d& x = objects[o];
    double cost = cost_of(by_object[o], x);
    for (int iteration = 0; iteration < 20; ++iteration) {
      Eigen::Matrix2d h = Eigen::Matrix2d::Zero();
      Eigen::Vector2d g = Eigen::Vector2d::Zero();
      for (std::size_t i : by_object[o]) {
        const Observation& ob = a.observations[i];
        const Linearization l = linearize(ob, x);
        const Eigen::Vector2d r = ob.sqrt_info * l.e;
        const Eigen::Matrix2d j = ob.sqrt_info * l.d_object;
        const double w = Rho(loss, r.squaredNorm()).second;
        h += w * j.transpose() * j;
        g += w * j.transpose() * r;
      }
      const Eigen::LDLT<Eigen::Matrix2d> ldlt(h);
      if (ldlt.info() != Eigen::Success) break;
      const Eigen::Vector2d step = -ldlt.solve(g);
      if (!step.allFinite()) break;
      double scale = 1.0;
      bool improved = false;
      for (int k = 0; k < 20 && !improved; ++k, scale *= 0.5) {
        const double next = cost_of(by_object[o], x + scale * step);
        if (next <= cost) {
          x += scale * step;
          cost = next;
          improved = true;
        }
      }
      // A micrometre: far below any noise; the solver polishes the objects it uses.
      if (!improved || scale * step.norm() < 1e-6) break;
    }
  }
}

struct CostSummary {
  double cost = 0.0;            // 1/2 (w sum rho(obs) + sum rho_c(constraints) + size prior)
  double unweighted_sum = 0.0;  // sum rho(observations) + sum rho_c(constraints)
  double rms_m = 0.0;
  std::size_t downweighted = 0;
  double constraint_rms = 0.0;  // whitened
};

// Robust cost (observations, constraints, the size prior) and RMS of the observations, with poses
// and the size correction fixed and every object at its optimum.
CostSummary EvaluateAtOptimalObjects(
    const Association& a, const std::vector<Constraint>& constraints,
    const std::vector<Pose2>& poses, const SizeParams& size, double size_prior_sigma_m,
    std::vector<Eigen::Vector2d> objects, const ceres::LossFunction* loss,
    const ceres::LossFunction* constraint_loss, double observation_weight) {
  std::vector<PoseParams> params(poses.size());
  for (std::size_t s = 0; s < poses.size(); ++s) params[s] = ToParams(poses[s]);
  OptimizeObjects(a, params, size, loss, objects);
  CostSummary out;
  for (const Constraint& c : constraints) {
    const ConstraintLinearization l =
        LinearizeConstraint(c.measured, params[c.r].data(), params[c.s].data());
    const double squared = (c.sqrt_info * l.e).squaredNorm();
    const double rho = Rho(constraint_loss, squared).first;
    out.cost += 0.5 * rho;
    out.unweighted_sum += rho;
    out.constraint_rms += squared;
  }
  if (!constraints.empty()) {
    out.constraint_rms = std::sqrt(out.constraint_rms / static_cast<double>(constraints.size()));
  }
  if (size_prior_sigma_m > 0.0) {
    out.cost +=
        0.5 * (size[0] * size[0] + size[1] * size[1]) / (size_prior_sigma_m * size_prior_sigma_m);
  }
  double sum_e2 = 0.0;
  for (const Observation& ob : a.observations) {
    const Linearization l =
        Linearize(ob.z, ob.jd, objects[ob.object].data(), params[ob.sensor].data(), size.data());
    const auto [rho, weight] = Rho(loss, (ob.sqrt_info * l.e).squaredNorm());
    out.cost += 0.5 * observation_weight * rho;
    out.unweighted_sum += rho;
    if (weight < 0.5) ++out.downweighted;
    sum_e2 += l.e.squaredNorm();
  }
  if (!a.observations.empty()) {
    out.rms_m = std::sqrt(sum_e2 / static_cast<double>(a.observations.size()));
  }
  return out;
}

// The Gauss-Newton system of the free poses and both size-correction components with the objects
// eliminated (Schur complement of J^T W J, W = rho' IRLS weights times the observation weight),
// and per track the response of its gradient to a unit offset of its samples (for the
// systematic floor): d x = -H^-1 G_track eps.
struct ReducedSystem {
  std::vector<std::size_t> pose_offset;  // per sensor, kNone when not free
  std::size_t size_offset = 0;           // the two size columns
  std::size_t dim = 0;
  Eigen::MatrixXd h;                    // without the size prior
  std::vector<Eigen::MatrixXd> groups;  // dim x 2 per track with observations (responses)
  std::vector<double> group_sigma;      // the systematic sigma of each of them
  // dim x sensors: column s is the gradient's response to one standard deviation of sensor s's
  // shared radial bias (every sample of s shifted by its Observation::shared_bias), i.e. H_theta_b
  // of the consider parameter b_s (refine.h "Sensor bias").
  Eigen::MatrixXd sensor_bias;
  // sensors x sensors: H_bb of the same biases (objects eliminated), per standard deviation.
  Eigen::MatrixXd bias_bias;
};

ReducedSystem BuildReducedSystem(const Association& a, const std::vector<Constraint>& constraints,
                                 const std::vector<PoseParams>& poses, const SizeParams& size,
                                 const std::vector<Eigen::Vector2d>& objects,
                                 const std::vector<bool>& free_sensor,
                                 const ceres::LossFunction* loss,
                                 const ceres::LossFunction* constraint_loss,
                                 double observation_weight, bool with_groups,
                                 const std::vector<double>& group_sigma = {}) {
  ReducedSystem out;
  out.pose_offset.assign(poses.size(), kNone);
  for (std::size_t s = 0; s < poses.size(); ++s) {
    if (free_sensor[s]) {
      out.pose_offset[s] = out.dim;
      out.dim += 3;
    }
  }
  out.size_offset = out.dim;
  out.dim += 2;
  const auto dim = static_cast<Eigen::Index>(out.dim);
  out.h = Eigen::MatrixXd::Zero(dim, dim);

  // Columns of an observation's reduced Jacobian: x, y, yaw of its sensor, then the two sizes.
  using Columns = std::array<std::size_t, 5>;
  auto columns_of = [&](const Observation& ob) {
    const std::size_t p = out.pose_offset[ob.sensor];
    return Columns{p, p == kNone ? kNone : p + 1, p == kNone ? kNone : p + 2, out.size_offset,
                   out.size_offset + 1};
  };
  using Matrix5d = Eigen::Matrix<double, 5, 5>;
  auto scatter = [&](const Columns& rows, const Columns& cols, const Matrix5d& block, double sign) {
    for (std::size_t i = 0; i < 5; ++i) {
      if (rows[i] == kNone) continue;
      for (std::size_t j = 0; j < 5; ++j) {
        if (cols[j] == kNone) continue;
        out.h(static_cast<Eigen::Index>(rows[i]), static_cast<Eigen::Index>(cols[j])) +=
            sign * block(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j));
      }
    }
  };

  for (const Constraint& c : constraints) {
    const ConstraintLinearization l =
        LinearizeConstraint(c.measured, poses[c.r].data(), poses[c.s].data());
    const double w = Rho(constraint_loss, (c.sqrt_info * l.e).squaredNorm()).second;
    const std::array<std::size_t, 2> sensor = {c.r, c.s};
    const std::array<Eigen::Matrix3d, 2> j = {c.sqrt_info * l.d_r, c.sqrt_info * l.d_s};
    for (std::size_t u = 0; u < 2; ++u) {
      if (out.pose_offset[sensor[u]] == kNone) continue;
      for (std::size_t v = 0; v < 2; ++v) {
        if (out.pose_offset[sensor[v]] == kNone) continue;
        out.h.block<3, 3>(static_cast<Eigen::Index>(out.pose_offset[sensor[u]]),
                          static_cast<Eigen::Index>(out.pose_offset[sensor[v]])) +=
            w * j[u].transpose() * j[v];
      }
    }
  }

  std::size_t group_count = 0;
  for (const Observation& ob : a.observations) group_count = std::max(group_count, ob.group + 1);
  std::vector<std::size_t> group_index(with_groups ? group_count : 0, kNone);
  auto group_matrix = [&](std::size_t group) -> Eigen::MatrixXd& {
    if (group_index[group] == kNone) {
      group_index[group] = out.groups.size();
      // Rows: the reduced system's, then one per sensor's shared bias.
      out.groups.push_back(Eigen::MatrixXd::Zero(dim + static_cast<Eigen::Index>(poses.size()), 2));
      out.group_sigma.push_back(group < group_sigma.size() ? group_sigma[group] : 0.0);
    }
    return out.groups[group_index[group]];
  };
  auto scatter_rows = [&](Eigen::MatrixXd& m, const Columns& rows,
                          const Eigen::Matrix<double, 5, 2>& block) {
    for (std::size_t i = 0; i < 5; ++i) {
      if (rows[i] == kNone) continue;
      m.row(static_cast<Eigen::Index>(rows[i])) += block.row(static_cast<Eigen::Index>(i));
    }
  };

  const std::vector<std::vector<std::size_t>> by_object = ObservationsByObject(a);
  std::vector<Eigen::Matrix<double, 2, 5>> coupling;     // w J_o^T J_g per observation
  std::vector<Eigen::Matrix<double, 2, 2>> object_side;  // w J_o^T sqrt_info per observation
  std::vector<Columns> cols;
  const auto sensors = static_cast<Eigen::Index>(poses.size());
  out.sensor_bias = Eigen::MatrixXd::Zero(dim, sensors);
  out.bias_bias = Eigen::MatrixXd::Zero(sensors, sensors);
  auto scatter_bias = [&](std::size_t sensor, const Columns& rows,
                          const Eigen::Matrix<double, 5, 1>& block) {
    for (std::size_t i = 0; i < 5; ++i) {
      if (rows[i] == kNone) continue;
      out.sensor_bias(static_cast<Eigen::Index>(rows[i]), static_cast<Eigen::Index>(sensor)) +=
          block(static_cast<Eigen::Index>(i));
    }
  };
  for (std::size_t o = 0; o < objects.size(); ++o) {
    const std::vector<std::size_t>& members = by_object[o];
    Eigen::Matrix2d h_oo = Eigen::Matrix2d::Zero();
    coupling.assign(members.size(), Eigen::Matrix<double, 2, 5>::Zero());
    object_side.assign(members.size(), Eigen::Matrix2d::Zero());
    cols.assign(members.size(), Columns{});
    for (std::size_t k = 0; k < members.size(); ++k) {
      const Observation& ob = a.observations[members[k]];
      const Linearization l =
          Linearize(ob.z, ob.jd, objects[o].data(), poses[ob.sensor].data(), size.data());
      const Eigen::Vector2d r = ob.sqrt_info * l.e;
      const double w = observation_weight * Rho(loss, r.squaredNorm()).second;
      const Eigen::Matrix2d j_o = ob.sqrt_info * l.d_object;
      Eigen::Matrix<double, 2, 5> j_g;
      j_g.leftCols<3>() = ob.sqrt_info * l.d_pose;
      j_g.rightCols<2>() = ob.sqrt_info * l.d_size;
      h_oo += w * j_o.transpose() * j_o;
      coupling[k] = w * j_o.transpose() * j_g;
      object_side[k] = w * j_o.transpose() * ob.sqrt_info;
      cols[k] = columns_of(ob);
      scatter(cols[k], cols[k], w * j_g.transpose() * j_g, 1.0);
      const Eigen::Vector2d j_b = ob.sqrt_info * ob.shared_bias;
      scatter_bias(ob.sensor, cols[k], w * j_g.transpose() * j_b);
      const auto b = static_cast<Eigen::Index>(ob.sensor);
      out.bias_bias(b, b) += w * j_b.squaredNorm();
      if (with_groups) {
        Eigen::MatrixXd& g = group_matrix(ob.group);
        scatter_rows(g, cols[k], w * j_g.transpose() * ob.sqrt_info);
        g.row(dim + b) += w * j_b.transpose() * ob.sqrt_info;
      }
    }
    const Eigen::LDLT<Eigen::Matrix2d> ldlt(h_oo);
    if (ldlt.info() != Eigen::Success || ldlt.rcond() < 1e-12) continue;
    const Eigen::Matrix2d h_oo_inv = ldlt.solve(Eigen::Matrix2d::Identity());
    for (std::size_t k = 0; k < members.size(); ++k) {
      for (std::size_t m = 0; m < members.size(); ++m) {
        scatter(cols[k], cols[m], coupling[k].transpose() * h_oo_inv * coupling[m], -1.0);
      }
      // The object moves with an offset of observation k too: its share of the reduced response.
      const Eigen::Matrix<double, 2, 2> moved = h_oo_inv * object_side[k];
      const Observation& ob = a.observations[members[k]];
      const Eigen::Vector2d moved_bias = moved * ob.shared_bias;
      for (std::size_t m = 0; m < members.size(); ++m) {
        scatter_bias(ob.sensor, cols[m], -(coupling[m].transpose() * moved_bias));
        const Observation& other = a.observations[members[m]];
        out.bias_bias(static_cast<Eigen::Index>(other.sensor),
                      static_cast<Eigen::Index>(ob.sensor)) -=
            (object_side[m] * other.shared_bias).dot(moved_bias);
      }
      if (with_groups) {
        Eigen::MatrixXd& g = group_matrix(ob.group);
        for (std::size_t m = 0; m < members.size(); ++m) {
          scatter_rows(g, cols[m], -(coupling[m].transpose() * moved));
          const Observation& other = a.observations[members[m]];
          g.row(dim + static_cast<Eigen::Index>(other.sensor)) -=
              (object_side[m] * other.shared_bias).transpose() * moved;
        }
      }
    }
  }
  return out;
}

// Inverse of a symmetric positive definite matrix, or nullopt.
std::optional<Eigen::MatrixXd> InverseSpd(const Eigen::MatrixXd& m) {
  const Eigen::LLT<Eigen::MatrixXd> llt(m);
  if (llt.info() != Eigen::Success) return std::nullopt;
  Eigen::MatrixXd inverse = llt.solve(Eigen::MatrixXd::Identity(m.rows(), m.cols()));
  if (!inverse.allFinite()) return std::nullopt;
  return inverse;
}

// How well the data alone determine each size component (standard deviation, +inf when not at
// all) and its correlation with the layout's scale (the free sensors' positions relative to the
// reference stretched uniformly), from the reduced system without the size prior.
void SizeObservability(const ReducedSystem& system, const std::vector<PoseParams>& poses,
                       std::size_t reference, std::array<double, 2>& data_sigma,
                       std::array<double, 2>& scale_correlation) {
  data_sigma.fill(std::numeric_limits<double>::infinity());
  scale_correlation.fill(1.0);
  Eigen::MatrixXd h = system.h;
  // A tiny regularisation keeps an unobservable direction finite (huge) instead of failing.
  const double ridge = 1e-9 * std::max(1.0, h.diagonal().cwiseAbs().maxCoeff());
  h.diagonal().array() += ridge;
  const auto inverse = InverseSpd(h);
  if (!inverse) return;
  Eigen::VectorXd scale = Eigen::VectorXd::Zero(h.rows());
  for (std::size_t s = 0; s < poses.size(); ++s) {
    if (system.pose_offset[s] == kNone) continue;
    const auto p = static_cast<Eigen::Index>(system.pose_offset[s]);
    scale(p) = poses[s][0] - poses[reference][0];
    scale(p + 1) = poses[s][1] - poses[reference][1];
  }
  const double var_scale = scale.dot(*inverse * scale);
  for (std::size_t k = 0; k < 2; ++k) {
    const auto i = static_cast<Eigen::Index>(system.size_offset + k);
    const double var = (*inverse)(i, i);
    data_sigma[k] =
        var > 0.0 && var < 1.0 / ridge ? std::sqrt(var) : std::numeric_limits<double>::infinity();
    const double cov = scale.dot(inverse->col(i));
    scale_correlation[k] =
        var > 0.0 && var_scale > 0.0 ? std::abs(cov) / std::sqrt(var * var_scale) : 1.0;
  }
}

// How well the data alone determine each sensor's shared radial bias, in standard deviations of
// its prior (+inf: the sensor has none, or the data say nothing of it): the marginal of the
// reduced system extended by the biases, every pose free, the size correction under its prior.
std::vector<double> SensorBiasDataSigma(const ReducedSystem& system, double size_prior_sigma_m) {
  const auto d = static_cast<Eigen::Index>(system.dim);
  const Eigen::Index nb = system.bias_bias.rows();
  std::vector<double> out(static_cast<std::size_t>(nb), std::numeric_limits<double>::infinity());
  Eigen::MatrixXd m = Eigen::MatrixXd::Zero(d + nb, d + nb);
  m.topLeftCorner(d, d) = system.h;
  const double prior_info =
      size_prior_sigma_m > 0.0 ? 1.0 / (size_prior_sigma_m * size_prior_sigma_m) : 1e12;
  for (std::size_t k = 0; k < 2; ++k) {
    const auto i = static_cast<Eigen::Index>(system.size_offset + k);
    m(i, i) += prior_info;
  }
  m.topRightCorner(d, nb) = system.sensor_bias;  // the sign of H_theta_b does not matter here
  m.bottomLeftCorner(nb, d) = system.sensor_bias.transpose();
  m.bottomRightCorner(nb, nb) = 0.5 * (system.bias_bias + system.bias_bias.transpose());
  std::vector<bool> present(static_cast<std::size_t>(nb), false);
  for (Eigen::Index b = 0; b < nb; ++b) {
    present[static_cast<std::size_t>(b)] = m(d + b, d + b) > 0.0;
    if (!present[static_cast<std::size_t>(b)]) m(d + b, d + b) = 1.0;  // not in the problem
  }
  // A tiny regularisation keeps an unobservable direction finite (huge) instead of failing.
  const double ridge = 1e-9 * std::max(1.0, m.diagonal().cwiseAbs().maxCoeff());
  m.diagonal().array() += ridge;
  const auto inverse = InverseSpd(m);
  if (!inverse) return out;
  for (Eigen::Index b = 0; b < nb; ++b) {
    const double var = (*inverse)(d + b, d + b);
    if (present[static_cast<std::size_t>(b)] && var > 0.0 && var < 1.0 / ridge) {
      out[static_cast<std::size_t>(b)] = std::sqrt(var);
    }
  }
  return out;
}

// Marginal covariance of the free poses (size correction marginalised under its prior, the
// estimated sensor biases under theirs) plus the systematic floor and the consider term of the
// biases held at their prior (refine.h "Sensor bias"); the estimated biases' standard deviations
// (in units of their prior, per sensor) go to bias_sigma. Returns false when the system is not
// positive definite.
bool PoseCovariance(const ReducedSystem& system, double size_prior_sigma_m, double scale,
                    const std::vector<bool>& estimated_bias,
                    std::vector<Eigen::Matrix3d>& covariance, std::vector<double>& bias_sigma) {
  if (system.dim == 2) return true;  // no free pose
  const auto d = static_cast<Eigen::Index>(system.dim);
  // The system extended by the estimated biases (per standard deviation, prior N(0, 1)).
  std::vector<Eigen::Index> estimated, held;
  for (Eigen::Index b = 0; b < system.bias_bias.rows(); ++b) {
    if (static_cast<std::size_t>(b) < estimated_bias.size() &&
        estimated_bias[static_cast<std::size_t>(b)]) {
      estimated.push_back(b);
    } else if (system.sensor_bias.col(b).squaredNorm() > 0.0) {
      held.push_back(b);
    }
  }
  const auto ne = static_cast<Eigen::Index>(estimated.size());
  Eigen::MatrixXd h = Eigen::MatrixXd::Zero(d + ne, d + ne);
  h.topLeftCorner(d, d) = system.h;
  const double prior_info =
      size_prior_sigma_m > 0.0 ? 1.0 / (size_prior_sigma_m * size_prior_sigma_m) : 1e12;
  for (std::size_t k = 0; k < 2; ++k) {
    const auto i = static_cast<Eigen::Index>(system.size_offset + k);
    h(i, i) += prior_info;
  }
  for (Eigen::Index i = 0; i < ne; ++i) {
    h.block(0, d + i, d, 1) = system.sensor_bias.col(estimated[static_cast<std::size_t>(i)]);
    h.block(d + i, 0, 1, d) =
        system.sensor_bias.col(estimated[static_cast<std::size_t>(i)]).transpose();
    for (Eigen::Index j = 0; j < ne; ++j) {
      h(d + i, d + j) = 0.5 * (system.bias_bias(estimated[static_cast<std::size_t>(i)],
                                                estimated[static_cast<std::size_t>(j)]) +
                               system.bias_bias(estimated[static_cast<std::size_t>(j)],
                                                estimated[static_cast<std::size_t>(i)]));
    }
    h(d + i, d + i) += 1.0;
  }
  const auto inverse = InverseSpd(h);
  if (!inverse) return false;
  Eigen::MatrixXd total = scale * *inverse;
  // Rows of an extended column: the reduced system's, then the estimated biases'.
  auto extend = [&](const Eigen::MatrixXd& column, Eigen::Index bias_rows_at) {
    Eigen::MatrixXd out(d + ne, column.cols());
    out.topRows(d) = column.topRows(d);
    for (Eigen::Index i = 0; i < ne; ++i) {
      out.row(d + i) = column.row(bias_rows_at + estimated[static_cast<std::size_t>(i)]);
    }
    return out;
  };
  for (std::size_t k = 0; k < system.groups.size(); ++k) {
    const Eigen::MatrixXd response = *inverse * extend(system.groups[k], d);
    const double sigma = system.group_sigma[k];
    total.noalias() += (sigma * sigma) * (response * response.transpose());
  }
  // The consider parameters: Sigma += S Sigma_b S^T, S = -H^-1 H_x_b, Sigma_b = I (the columns
  // are per standard deviation), H_x_b of the poses and of the estimated biases.
  for (const Eigen::Index b : held) {
    Eigen::MatrixXd column(d + static_cast<Eigen::Index>(system.bias_bias.rows()), 1);
    column.topRows(d) = system.sensor_bias.col(b);
    column.bottomRows(system.bias_bias.rows()) = system.bias_bias.col(b);
    const Eigen::MatrixXd response = *inverse * extend(column, d);
    total.noalias() += response * response.transpose();
  }
  for (std::size_t s = 0; s < system.pose_offset.size(); ++s) {
    if (system.pose_offset[s] == kNone) continue;
    const auto p = static_cast<Eigen::Index>(system.pose_offset[s]);
    const Eigen::Matrix3d c = total.block<3, 3>(p, p);
    covariance[s] = 0.5 * (c + c.transpose());
  }
  for (Eigen::Index i = 0; i < ne; ++i) {
    const auto b = static_cast<std::size_t>(estimated[static_cast<std::size_t>(i)]);
    if (b < bias_sigma.size()) bias_sigma[b] = std::sqrt(std::max(0.0, total(d + i, d + i)));
  }
  return true;
}

std::string Fixed(double value, int digits) {
  std::ostringstream out;
  out << std::fixed << std::setprecision(digits) << value;
  return out.str();
}

}  // namespace

std::optional<std::string> Validate(const JointRefineOptions& o) {
  auto positive = [](double v) { return std::isfinite(v) && v > 0.0; };
  auto non_negative = [](double v) { return std::isfinite(v) && v >= 0.0; };
  if (!positive(o.association_gate_m)) return "association_gate_m must be > 0";
  if (!(positive(o.initial_association_gate_m) &&
        o.initial_association_gate_m >= o.association_gate_m)) {
    return "initial_association_gate_m must be >= association_gate_m";
  }
  if (!non_negative(o.model_sigma_per_m)) return "model_sigma_per_m must be finite and >= 0";
  if (!(o.max_size_scale_correlation > 0.0 && o.max_size_scale_correlation <= 1.0)) {
    return "max_size_scale_correlation must be in (0, 1]";
  }
  if (!(o.sensor_bias_max_data_sigma >= 0.0) || !std::isfinite(o.sensor_bias_max_data_sigma)) {
    return "sensor_bias_max_data_sigma must be a finite value >= 0";
  }
  if (o.loss != RobustLoss::kNone && o.loss != RobustLoss::kHuber &&
      o.loss != RobustLoss::kCauchy) {
    return "loss must be none, huber or cauchy";
  }
  if (!positive(o.loss_scale)) return "loss_scale must be > 0";
  if (!positive(o.constraint_loss_scale)) return "constraint_loss_scale must be > 0";
  if (!(std::isfinite(o.observation_correlation_steps) && o.observation_correlation_steps >= 1.0)) {
    return "observation_correlation_steps must be >= 1";
  }
  if (!non_negative(o.segment_sigma_m) || !non_negative(o.segment_sigma_per_m)) {
    return "segment_sigma_m and segment_sigma_per_m must be finite and >= 0";
  }
  if (o.step_stride < 1) return "step_stride must be >= 1";
  if (o.max_steps < 1) return "max_steps must be >= 1";
  if (o.max_iterations < 1) return "max_iterations must be >= 1";
  if (o.association_rounds < 1) return "association_rounds must be >= 1";
  if (o.min_observations < 1) return "min_observations must be >= 1";
  if (!positive(o.max_correction_m)) return "max_correction_m must be > 0";
  if (!positive(o.max_correction_rad)) return "max_correction_rad must be > 0";
  if (o.linear_solver != RefineLinearSolver::kAuto &&
      o.linear_solver != RefineLinearSolver::kDenseSchur &&
      o.linear_solver != RefineLinearSolver::kSparseSchur) {
    return "linear_solver must be auto, dense_schur or sparse_schur";
  }
  if (o.threads < 1) return "threads must be >= 1";
  if (!positive(o.function_tolerance) || !positive(o.parameter_tolerance)) {
    return "function_tolerance and parameter_tolerance must be > 0";
  }
  return std::nullopt;
}

JointRefineResult RefineJointly(const AlignedTracks& tracks,
                                const std::vector<Pose2>& world_from_sensor,
                                const std::vector<bool>& calibrated, std::size_t reference,
                                const JointRefineOptions& options,
                                const std::vector<RelativePoseConstraint>& constraints) {
  const std::size_t n = tracks.sensors.size();
  JointRefineResult result;
  auto fail = [&](std::string why) {
    result.ok = false;
    result.message = std::move(why);
    result.world_from_sensor = world_from_sensor;
    result.covariance.assign(world_from_sensor.size(), Eigen::Matrix3d::Zero());
    result.refined.assign(world_from_sensor.size(), false);
    result.sensor_observations.assign(world_from_sensor.size(), 0);
    result.size_correction_m.setZero();
    result.size_correction_estimated = {};
    return result;
  };

  if (auto invalid = Validate(options)) return fail("invalid options: " + *invalid);
  if (world_from_sensor.size() != n || calibrated.size() != n) {
    return fail("input size mismatch: " + std::to_string(n) + " sensors with tracks, " +
                std::to_string(world_from_sensor.size()) + " poses, " +
                std::to_string(calibrated.size()) + " calibrated flags");
  }
  if (reference >= n) return fail("reference index " + std::to_string(reference) + " out of range");
  if (!calibrated[reference]) {
    return fail("reference sensor " + tracks.sensors[reference].id + " is not calibrated");
  }
  for (std::size_t s = 0; s < n; ++s) {
    if (calibrated[s] && !IsFinite(world_from_sensor[s])) {
      return fail("initial pose of sensor " + tracks.sensors[s].id + " is not finite");
    }
  }
  const double prior_sigma =
      std::isfinite(tracks.size_prior_sigma_m) && tracks.size_prior_sigma_m > 0.0
          ? tracks.size_prior_sigma_m
          : 0.0;

  std::size_t stride = options.step_stride;
  if (tracks.steps > 0 && (tracks.steps - 1) / stride + 1 > options.max_steps) {
    stride = (tracks.steps + options.max_steps - 1) / options.max_steps;
  }
  result.stride = stride;
  std::vector<double> group_sigma;
  std::vector<std::vector<StepSample>> samples =
      CollectSamples(tracks, calibrated, stride, options, result.rejected_samples, group_sigma);
  // Each sensor's shared radial bias (refine.h "Sensor bias"): its prior standard deviation (the
  // mean over its samples), whether it is estimated, and what has been applied to the samples' z
  // (prior standard deviations).
  std::vector<double> bias_sigma_m(n, 0.0);
  {
    std::vector<double> count(n, 0.0);
    for (const auto& step : samples) {
      for (const StepSample& x : step) {
        bias_sigma_m[x.sensor] += x.shared_bias.norm();
        count[x.sensor] += 1.0;
      }
    }
    for (std::size_t s = 0; s < n; ++s) {
      if (count[s] > 0.0) bias_sigma_m[s] /= count[s];
    }
  }
  std::vector<bool> free_bias(n, false);
  std::vector<double> applied_bias(n, 0.0);
  bool bias_checked = !options.estimate_sensor_bias || !options.sensor_bias;
  const std::unique_ptr<ceres::LossFunction> loss = MakeLoss(options);
  const ceres::CauchyLoss constraint_loss(options.constraint_loss_scale);
  // Smoothed tracks are correlated over observation_correlation_steps grid steps: the used
  // samples carry the information of stride / correlation_steps independent ones each.
  const double observation_weight =
      std::min(1.0, static_cast<double>(stride) / options.observation_correlation_steps);
  const std::vector<Constraint> usable =
      UsableConstraints(constraints, calibrated, result.constraints_rejected);

  std::vector<Pose2> poses = world_from_sensor;
  SizeParams size{0.0, 0.0};
  std::array<bool, 2> free_size = {options.estimate_size_correction && prior_sigma > 0.0,
                                   options.estimate_size_correction && prior_sigma > 0.0};
  Association final_association;
  std::vector<bool> final_free(n, false);
  std::vector<PoseParams> final_params;
  std::vector<Constraint> final_constraints;
  bool solved = false;
  bool size_checked = false;
  std::string last_note;
  double gate = options.initial_association_gate_m;
  for (int round = 0; round < options.association_rounds + 3; ++round) {
    Association a;
    for (std::size_t k = 0; k < samples.size(); ++k) {
      AssociateStep(samples[k], k, poses, size, gate, a);
    }
    const std::size_t associated = a.observations.size();
    const std::vector<bool> reached =
        PruneSensors(a, usable, n, reference, options.min_sensor_observations);
    std::vector<bool> free_sensor(n, false);
    std::size_t free_count = 0;
    for (std::size_t s = 0; s < n; ++s) {
      free_sensor[s] = reached[s] && s != reference;
      if (free_sensor[s]) ++free_count;
    }
    std::vector<Constraint> round_constraints;
    for (const Constraint& c : usable) {
      if (reached[c.r] && reached[c.s]) round_constraints.push_back(c);
    }
    if (a.observations.size() < options.min_observations || free_count == 0) {
      std::string why;
      if (a.observations.size() < options.min_observations) {
        why = "too few associated observations: " + std::to_string(a.observations.size()) +
              " (of " + std::to_string(associated) + " before pruning) seen by two or more " +
              "sensors connected to the reference " + tracks.sensors[reference].id + ", need " +
              std::to_string(options.min_observations);
      } else {
        why = "no sensor besides the reference " + tracks.sensors[reference].id +
              " shares enough observed objects with it (min_sensor_observations " +
              std::to_string(options.min_sensor_observations) + ")";
      }
      if (!solved) return fail(why);
      last_note = "round " + std::to_string(round + 1) + " stopped: " + why;
      break;
    }

    const bool at_final_gate = gate <= options.association_gate_m;
    bool converged = solved && at_final_gate && a.SameGrouping(final_association);
    if (converged || round >= options.association_rounds) {
      // The association has settled (or the rounds are spent): decide once whether the size
      // correction is observable; a component that is not is held at 0 and the poses solved
      // again. Then, once, which sensors' shared bias the data observe: those are estimated and
      // the poses solved again.
      bool changed = false;
      if (!size_checked && (free_size[0] || free_size[1])) {
        size_checked = true;
        const ReducedSystem system = BuildReducedSystem(
            final_association, final_constraints, final_params, size, final_association.objects,
            final_free, loss.get(), &constraint_loss, observation_weight, false);
        SizeObservability(system, final_params, reference, result.size_data_sigma_m,
                          result.size_scale_correlation);
        for (std::size_t k = 0; k < 2; ++k) {
          const bool observable =
              result.size_data_sigma_m[k] <= prior_sigma &&
              result.size_scale_correlation[k] <= options.max_size_scale_correlation;
          if (!observable && free_size[k]) {
            free_size[k] = false;
            size[k] = 0.0;
            changed = true;
          }
        }
      }
      if (!changed && !bias_checked) {
        bias_checked = true;
        const ReducedSystem system = BuildReducedSystem(
            final_association, final_constraints, final_params, size, final_association.objects,
            final_free, loss.get(), &constraint_loss, observation_weight, false);
        const std::vector<double> data_sigma = SensorBiasDataSigma(system, prior_sigma);
        for (std::size_t s = 0; s < n; ++s) {
          free_bias[s] =
              bias_sigma_m[s] > 0.0 && data_sigma[s] <= options.sensor_bias_max_data_sigma;
          changed = changed || free_bias[s];
        }
        result.sensor_bias_data_sigma = data_sigma;
      }
      if (!changed) break;
    }

    std::vector<PoseParams> params(n);
    for (std::size_t s = 0; s < n; ++s) params[s] = ToParams(poses[s]);
    SizeParams next_size = size;
    // Objects start at their optimum for the current poses, so that the solver's steps go to the
    // poses from the first iteration on.
    OptimizeObjects(a, params, size, loss.get(), a.objects);
    std::vector<double> bias_step;
    const SolveOutcome outcome = Solve(a, round_constraints, free_sensor, free_size, prior_sigma,
                                       params, next_size, a.objects, loss.get(), observation_weight,
                                       options, free_bias, applied_bias, bias_step);
    result.iterations += outcome.iterations;
    result.solver_time_s += outcome.time_s;
    ++result.rounds;
    if (!outcome.usable) {
      if (!solved) return fail("solver failure: " + outcome.report);
      last_note = "round " + std::to_string(round + 1) + " failed: " + outcome.report;
      break;
    }
    for (std::size_t s = 0; s < n; ++s) {
      if (free_sensor[s]) poses[s] = ToPose(params[s]);
    }
    size = next_size;
    // The estimated biases' change goes into the samples' centres (and this round's
    // observations, whose objects the solver fitted with it).
    bool bias_moved = false;
    for (std::size_t s = 0; s < n; ++s) {
      applied_bias[s] += bias_step[s];
      bias_moved = bias_moved || bias_step[s] != 0.0;
    }
    if (bias_moved) {
      for (auto& step : samples) {
        for (StepSample& x : step) x.z += bias_step[x.sensor] * x.shared_bias;
      }
      for (Observation& ob : a.observations) ob.z += bias_step[ob.sensor] * ob.shared_bias;
    }
    final_association = std::move(a);
    final_free = free_sensor;
    final_params = std::move(params);
    final_constraints = std::move(round_constraints);
    solved = true;
    gate = std::max(options.association_gate_m, gate * kGateShrink);
  }

  for (std::size_t s = 0; s < n; ++s) {
    if (!final_free[s]) continue;
    const double moved_m = common::TranslationDistanceM(poses[s], world_from_sensor[s]);
    const double moved_rad = common::RotationDistanceRad(poses[s], world_from_sensor[s]);
    if (moved_m > options.max_correction_m || moved_rad > options.max_correction_rad) {
      return fail("sensor " + tracks.sensors[s].id + " moved " + Fixed(moved_m, 3) + " m / " +
                  Fixed(common::RadToDeg(moved_rad), 2) + " deg from its initial pose (limits " +
                  Fixed(options.max_correction_m, 3) + " m / " +
                  Fixed(common::RadToDeg(options.max_correction_rad), 2) +
                  " deg): the association is likely wrong; initial poses kept");
    }
  }

  const Association& a = final_association;
  const SizeParams zero_size{0.0, 0.0};
  const CostSummary before =
      EvaluateAtOptimalObjects(a, final_constraints, world_from_sensor, zero_size, prior_sigma,
                               a.objects, loss.get(), &constraint_loss, observation_weight);
  const CostSummary after =
      EvaluateAtOptimalObjects(a, final_constraints, poses, size, prior_sigma, a.objects,
                               loss.get(), &constraint_loss, observation_weight);
  if (after.cost > before.cost * (1.0 + 1e-9) + 1e-12) {
    return fail("refinement increased the robust cost (" + Fixed(before.cost, 4) + " -> " +
                Fixed(after.cost, 4) + "); initial poses kept");
  }

  result.ok = true;
  result.world_from_sensor = poses;
  result.covariance.assign(n, Eigen::Matrix3d::Zero());
  result.refined = final_free;
  result.refined[reference] = true;
  result.sensor_observations = CountPerSensor(a, n);
  result.size_correction_m = Eigen::Vector2d(size[0], size[1]);
  result.size_correction_estimated = free_size;
  result.sensor_bias_estimated = free_bias;
  result.sensor_bias_m.assign(n, 0.0);
  for (std::size_t s = 0; s < n; ++s) result.sensor_bias_m[s] = applied_bias[s] * bias_sigma_m[s];
  if (result.sensor_bias_data_sigma.size() != n) {
    result.sensor_bias_data_sigma.assign(n, std::numeric_limits<double>::infinity());
  }
  result.cost_before = before.cost;
  result.cost_after = after.cost;
  result.rms_before_m = before.rms_m;
  result.rms_after_m = after.rms_m;
  result.downweighted = after.downweighted;
  result.constraints_used = final_constraints.size();
  result.constraint_rms_sigma = after.constraint_rms;
  result.observations = a.observations.size();
  result.objects = a.objects.size();
  result.steps = a.Steps();

  std::size_t unknowns = 2 * a.objects.size();
  std::size_t refined_count = 0;
  for (std::size_t s = 0; s < n; ++s) {
    if (final_free[s]) ++refined_count;
  }
  unknowns += 3 * refined_count;
  for (bool b : free_size) unknowns += b ? 1 : 0;
  for (std::size_t s = 0; s < n; ++s) unknowns += free_bias[s] ? 1 : 0;
  const std::size_t residuals = 2 * a.observations.size() + 3 * final_constraints.size();
  result.variance_factor =
      residuals > unknowns ? after.unweighted_sum / static_cast<double>(residuals - unknowns) : 0.0;
  const double scale =
      options.scale_covariance_by_variance_factor ? std::max(1.0, result.variance_factor) : 1.0;

  std::ostringstream message;
  message << "refined " << refined_count << " sensors from " << result.observations
          << " observations of " << result.objects << " objects in " << result.rounds
          << " rounds; rms " << Fixed(result.rms_before_m, 4) << " m -> "
          << Fixed(result.rms_after_m, 4) << " m";
  if (prior_sigma > 0.0) {
    message << "; body size correction " << Fixed(size[0], 3) << " / " << Fixed(size[1], 3)
            << " m (";
    for (std::size_t k = 0; k < 2; ++k) {
      message << (k == 0 ? "major " : ", minor ")
              << (free_size[k] ? "estimated" : "prior: not observable apart from the scale");
    }
    message << ")";
  }
  bool any_bias = false;
  for (std::size_t s = 0; s < n; ++s) {
    if (!free_bias[s]) continue;
    message << (any_bias ? ", " : "; shared radial bias estimated: ") << tracks.sensors[s].id << ' '
            << Fixed(result.sensor_bias_m[s], 3) << " m";
    any_bias = true;
  }
  std::vector<std::string> held;
  for (std::size_t s = 0; s < n; ++s) {
    if (calibrated[s] && s != reference && !final_free[s]) held.push_back(tracks.sensors[s].id);
  }
  if (!final_constraints.empty()) {
    message << "; " << final_constraints.size() << " relative-pose constraints (rms "
            << Fixed(result.constraint_rms_sigma, 2) << " sigma)";
  }
  if (!held.empty()) {
    message << "; held at the initial pose (too few observations shared with the others):";
    for (const std::string& id : held) message << ' ' << id;
  }
  const ReducedSystem system =
      BuildReducedSystem(a, final_constraints, final_params, size, a.objects, final_free,
                         loss.get(), &constraint_loss, observation_weight, true, group_sigma);
  // Held (and, should the covariance fail, estimated) biases: their prior.
  std::vector<double> bias_sigma(n, 1.0);
  if (!PoseCovariance(system, prior_sigma, scale, free_bias, result.covariance, bias_sigma)) {
    result.covariance.assign(n, Eigen::Matrix3d::Zero());
    message << "; covariance unavailable (reduced system not positive definite)";
  }
  result.sensor_bias_sigma_m.assign(n, 0.0);
  for (std::size_t s = 0; s < n; ++s) {
    result.sensor_bias_sigma_m[s] = bias_sigma[s] * bias_sigma_m[s];
  }
  if (!last_note.empty()) message << "; " << last_note;
  result.message = message.str();
  return result;
}

}  // namespace lrfnet::calib
