#include "central_daemon/calibration/refine.h"

#include <ceres/ceres.h>

#include <Eigen/Cholesky>
#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cmath>
#include <iomanip>
#include <memory>
#include <numeric>
#include <sstream>
#include <utility>

namespace lrfnet::calib {
namespace {

constexpr std::size_t kNone = static_cast<std::size_t>(-1);
constexpr std::size_t kKinds = 3;  // MeasurementKind values
// Below this range the direction of the radial bias is undefined; no object sits on a sensor.
constexpr double kMinBiasRangeM = 1e-6;

std::size_t KindIndex(MeasurementKind kind) {
  const auto k = static_cast<std::size_t>(kind);
  return k < kKinds ? k : static_cast<std::size_t>(MeasurementKind::kUnspecified);
}

// One valid track sample of a calibrated sensor at a used grid step, already whitened:
// sqrt_info = L^-1 with L L^T = S_z + (sigma_kind^2 + (sigma_per_m |z|)^2) I.
struct StepSample {
  std::size_t sensor = 0;
  std::size_t kind = 0;  // KindIndex
  Eigen::Vector2d z = Eigen::Vector2d::Zero();
  Eigen::Matrix2d sqrt_info = Eigen::Matrix2d::Identity();
};

struct Observation {
  std::size_t sensor = 0;
  std::size_t kind = 0;
  std::size_t object = 0;
  std::size_t sample = 0;  // index into the step's samples (identifies the association)
  Eigen::Vector2d z = Eigen::Vector2d::Zero();
  Eigen::Matrix2d sqrt_info = Eigen::Matrix2d::Identity();
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
using BiasParams = std::array<double, kKinds>;

PoseParams ToParams(const Pose2& p) { return {p.x_m, p.y_m, p.yaw_rad}; }
Pose2 ToPose(const PoseParams& p) { return {p[0], p[1], common::NormalizeAngle(p[2])}; }

// e = v - b v/|v| - z with v = R^T (o - t), and its Jacobians with respect to the object, the
// pose (x, y, yaw) and the bias b; unwhitened.
struct Linearization {
  Eigen::Vector2d e;
  Eigen::Matrix2d d_object;
  Eigen::Matrix<double, 2, 3> d_pose;
  Eigen::Vector2d d_bias;
};

// `c`, `s`: cos and sin of pose[2] (callers evaluating many observations of one sensor reuse them).
Linearization Linearize(const Eigen::Vector2d& z, const double* object, const double* pose,
                        double c, double s, double bias_m) {
  const double dx = object[0] - pose[0], dy = object[1] - pose[1];
  const Eigen::Vector2d v(c * dx + s * dy, -s * dx + c * dy);
  Eigen::Matrix2d rt;
  rt << c, s, -s, c;
  Eigen::Matrix<double, 2, 3> dv_pose;
  dv_pose.leftCols<2>() = -rt;
  dv_pose.col(2) = Eigen::Vector2d(-s * dx + c * dy, -c * dx - s * dy);

  Linearization l;
  const double range = v.norm();
  if (range < kMinBiasRangeM) {
    l.e = v - z;
    l.d_object = rt;
    l.d_pose = dv_pose;
    l.d_bias.setZero();
    return l;
  }
  const Eigen::Vector2d u = v / range;
  // d(v - b v/|v|)/dv = I - b (I - u u^T) / |v|
  const Eigen::Matrix2d de_dv =
      Eigen::Matrix2d::Identity() -
      (bias_m / range) * (Eigen::Matrix2d::Identity() - u * u.transpose());
  l.e = v - bias_m * u - z;
  l.d_object = de_dv * rt;
  l.d_pose = de_dv * dv_pose;
  l.d_bias = -u;
  return l;
}

Linearization Linearize(const Eigen::Vector2d& z, const double* object, const double* pose,
                        double bias_m) {
  return Linearize(z, object, pose, std::cos(pose[2]), std::sin(pose[2]), bias_m);
}

// cos and sin of every sensor's yaw.
std::vector<std::pair<double, double>> CosSin(const std::vector<PoseParams>& params) {
  std::vector<std::pair<double, double>> out(params.size());
  for (std::size_t s = 0; s < params.size(); ++s) {
    out[s] = {std::cos(params[s][2]), std::sin(params[s][2])};
  }
  return out;
}

// Whitened residual of one observation; parameter blocks: object (2), sensor pose (3), radial
// bias of the observation's kind (1). Where Quenzel et al. compare two sensors' observations by
// their Mahalanobis distance under the summed covariances (eq. 6), every observation here is
// compared with a common object position, so that any number of sensors share one object.
class ObservationCost final : public ceres::SizedCostFunction<2, 2, 3, 1> {
 public:
  ObservationCost(const Eigen::Vector2d& z, const Eigen::Matrix2d& sqrt_info)
      : z_(z), sqrt_info_(sqrt_info) {}

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const Linearization l = Linearize(z_, parameters[0], parameters[1], parameters[2][0]);
    Eigen::Map<Eigen::Vector2d> r(residuals);
    r = sqrt_info_ * l.e;
    if (jacobians != nullptr) {
      if (jacobians[0] != nullptr) {
        Eigen::Map<Eigen::Matrix<double, 2, 2, Eigen::RowMajor>> j_object(jacobians[0]);
        j_object = sqrt_info_ * l.d_object;
      }
      if (jacobians[1] != nullptr) {
        Eigen::Map<Eigen::Matrix<double, 2, 3, Eigen::RowMajor>> j_pose(jacobians[1]);
        j_pose = sqrt_info_ * l.d_pose;
      }
      if (jacobians[2] != nullptr) {
        Eigen::Map<Eigen::Vector2d> j_bias(jacobians[2]);
        j_bias = sqrt_info_ * l.d_bias;
      }
    }
    return true;
  }

 private:
  Eigen::Vector2d z_;
  Eigen::Matrix2d sqrt_info_;
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

double ModelSigma(std::size_t kind, const JointRefineOptions& options) {
  switch (static_cast<MeasurementKind>(kind)) {
    case MeasurementKind::kCenterOfMass:
      return options.model_sigma_com_m;
    case MeasurementKind::kEllipse:
      return options.model_sigma_ellipse_m;
    case MeasurementKind::kUnspecified:
    case MeasurementKind::kShapeFit:  // body centre: no view offset; the unbiased sigma
      break;
  }
  return options.model_sigma_unspecified_m;
}

BiasParams InitialBias(const JointRefineOptions& options) {
  BiasParams b{};
  b[KindIndex(MeasurementKind::kUnspecified)] = options.radial_bias_unspecified_m;
  b[KindIndex(MeasurementKind::kCenterOfMass)] = options.radial_bias_com_m;
  b[KindIndex(MeasurementKind::kEllipse)] = options.radial_bias_ellipse_m;
  return b;
}

bool IsFinite(const Pose2& p) {
  return std::isfinite(p.x_m) && std::isfinite(p.y_m) && std::isfinite(p.yaw_rad);
}

// The valid samples of the calibrated sensors at every used step, whitened once.
std::vector<std::vector<StepSample>> CollectSamples(const AlignedTracks& tracks,
                                                    const std::vector<bool>& calibrated,
                                                    std::size_t stride,
                                                    const JointRefineOptions& options,
                                                    std::size_t& rejected) {
  const std::size_t used = tracks.steps == 0 ? 0 : (tracks.steps - 1) / stride + 1;
  std::vector<std::vector<StepSample>> per_step(used);
  for (std::size_t s = 0; s < tracks.sensors.size(); ++s) {
    if (!calibrated[s]) continue;
    for (const GridTrack& track : tracks.sensors[s].tracks) {
      if (track.first_step >= tracks.steps) continue;
      const std::size_t kind = KindIndex(track.kind);
      const double sigma = ModelSigma(kind, options);
      // First used step at or after the track's start; the grid end clips malformed tracks.
      std::size_t step = (track.first_step + stride - 1) / stride * stride;
      const std::size_t end = std::min(track.end_step(), tracks.steps);
      for (; step < end; step += stride) {
        const TrackSample& sample = track.At(step);
        const Eigen::Matrix2d& cov = sample.position_cov_m2;
        const double tolerance = 1e-9 * (1.0 + cov.cwiseAbs().maxCoeff());
        if (!sample.position_m.allFinite() || !cov.allFinite() ||
            std::abs(cov(0, 1) - cov(1, 0)) > tolerance || cov(0, 0) < 0.0 || cov(1, 1) < 0.0 ||
            cov.determinant() < -tolerance * tolerance) {
          ++rejected;
          continue;
        }
        const double range_sigma = options.model_sigma_per_m * sample.position_m.norm();
        const Eigen::Matrix2d total =
            cov + (sigma * sigma + range_sigma * range_sigma) * Eigen::Matrix2d::Identity();
        const Eigen::LLT<Eigen::Matrix2d> llt(total);
        if (llt.info() != Eigen::Success || total.determinant() <= 0.0) {
          ++rejected;
          continue;
        }
        StepSample out;
        out.sensor = s;
        out.kind = kind;
        out.z = sample.position_m;
        out.sqrt_info = llt.matrixL().solve(Eigen::Matrix2d::Identity());
        if (!out.sqrt_info.allFinite()) {
          ++rejected;
          continue;
        }
        per_step[step / stride].push_back(out);
      }
    }
  }
  return per_step;
}

// The object position an observation implies: z moved back out by the radial bias.
Eigen::Vector2d Unbiased(const StepSample& sample, const BiasParams& bias) {
  const double range = sample.z.norm();
  if (range < kMinBiasRangeM) return sample.z;
  return sample.z * ((range + bias[sample.kind]) / range);
}

// Greedy agglomerative clustering at one step: candidate pairs of different sensors within the
// gate, nearest first; two clusters merge when they share no sensor and every cross pair is
// within the gate (complete linkage keeps two people walking side by side apart).
void AssociateStep(const std::vector<StepSample>& samples, std::size_t step_index,
                   const std::vector<Pose2>& poses, const BiasParams& bias, double gate_m,
                   Association& out) {
  const std::size_t n = samples.size();
  if (n < 2) return;
  std::vector<Eigen::Vector2d> world(n);
  for (std::size_t i = 0; i < n; ++i)
    world[i] = poses[samples[i].sensor] * Unbiased(samples[i], bias);

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
      out.observations.push_back(
          {sample.sensor, sample.kind, object, i, sample.z, sample.sqrt_info});
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

// The kinds whose bias is estimated: enough observations of that kind.
std::array<bool, kKinds> FreeBiases(const Association& a, const JointRefineOptions& options) {
  std::array<std::size_t, kKinds> count{};
  for (const Observation& ob : a.observations) ++count[ob.kind];
  std::array<bool, kKinds> free{};
  for (std::size_t k = 0; k < kKinds; ++k) {
    free[k] = options.estimate_radial_bias && count[k] >= options.min_bias_observations;
  }
  return free;
}

struct SolveOutcome {
  bool usable = false;
  std::string report;
  int iterations = 0;
  double time_s = 0.0;
};

SolveOutcome Solve(const Association& a, const std::vector<Constraint>& constraints,
                   const std::vector<bool>& free_sensor, const std::array<bool, kKinds>& free_bias,
                   std::vector<PoseParams>& poses, BiasParams& bias,
                   std::vector<Eigen::Vector2d>& objects, const ceres::LossFunction* loss,
                   double observation_weight, const JointRefineOptions& options) {
  // Declared before the problem, which refers to it until destroyed.
  ceres::ScaledLoss observation_loss(loss, observation_weight, ceres::DO_NOT_TAKE_OWNERSHIP);
  ceres::Problem::Options problem_options;
  problem_options.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem problem(problem_options);
  auto ordering = std::make_shared<ceres::ParameterBlockOrdering>();

  // Objects go into the eliminated group 0; poses and biases form the reduced system.
  std::vector<bool> in_problem(poses.size(), false);
  std::array<bool, kKinds> bias_in_problem{};
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
  for (const Observation& ob : a.observations) {
    add_pose(ob.sensor);
    if (!bias_in_problem[ob.kind]) {
      bias_in_problem[ob.kind] = true;
      problem.AddParameterBlock(&bias[ob.kind], 1);
      ordering->AddElementToGroup(&bias[ob.kind], 1);
      if (!free_bias[ob.kind]) problem.SetParameterBlockConstant(&bias[ob.kind]);
    }
  }
  for (Eigen::Vector2d& o : objects) {
    problem.AddParameterBlock(o.data(), 2);
    ordering->AddElementToGroup(o.data(), 0);
  }
  for (const Observation& ob : a.observations) {
    problem.AddResidualBlock(new ObservationCost(ob.z, ob.sqrt_info), &observation_loss,
                             objects[ob.object].data(), poses[ob.sensor].data(), &bias[ob.kind]);
  }
  for (const Constraint& c : constraints) {
    // No robust loss: the caller vouches for its constraints, and a down-weighted constraint
    // would lose against thousands of observations whatever its accuracy.
    problem.AddResidualBlock(new ConstraintCost(c.measured, c.sqrt_info), nullptr,
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

// Every object at its optimum with poses and biases fixed: iteratively reweighted Gauss-Newton
// per object (objects are independent once the rest is fixed), halving steps that do not lower
// the cost (the radial bias makes the residual non-linear in the object).
void OptimizeObjects(const Association& a, const std::vector<PoseParams>& params,
                     const BiasParams& bias, const ceres::LossFunction* loss,
                     std::vector<Eigen::Vector2d>& objects) {
  const std::vector<std::vector<std::size_t>> by_object = ObservationsByObject(a);
  const std::vector<std::pair<double, double>> cos_sin = CosSin(params);
  auto linearize = [&](const Observation& ob, const Eigen::Vector2d& x) {
    const auto [c, s] = cos_sin[ob.sensor];
    return Linearize(ob.z, x.data(), params[ob.sensor].data(), c, s, bias[ob.kind]);
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
  double cost = 0.0;            // 1/2 (weight sum rho(observations) + sum |constraints|^2)
  double unweighted_sum = 0.0;  // sum rho(observations) + sum |constraints|^2
  double rms_m = 0.0;
  std::size_t downweighted = 0;
  double constraint_rms = 0.0;  // whitened
};

// Robust cost (observations and constraints) and RMS of the observations, with poses and biases
// fixed and every object at its optimum.
CostSummary EvaluateAtOptimalObjects(const Association& a,
                                     const std::vector<Constraint>& constraints,
                                     const std::vector<Pose2>& poses, const BiasParams& bias,
                                     std::vector<Eigen::Vector2d> objects,
                                     const ceres::LossFunction* loss, double observation_weight) {
  std::vector<PoseParams> params(poses.size());
  for (std::size_t s = 0; s < poses.size(); ++s) params[s] = ToParams(poses[s]);
  OptimizeObjects(a, params, bias, loss, objects);
  CostSummary out;
  for (const Constraint& c : constraints) {
    const ConstraintLinearization l =
        LinearizeConstraint(c.measured, params[c.r].data(), params[c.s].data());
    const double squared = (c.sqrt_info * l.e).squaredNorm();
    out.cost += 0.5 * squared;
    out.unweighted_sum += squared;
    out.constraint_rms += squared;
  }
  if (!constraints.empty()) {
    out.constraint_rms = std::sqrt(out.constraint_rms / static_cast<double>(constraints.size()));
  }
  double sum_e2 = 0.0;
  for (const Observation& ob : a.observations) {
    const Linearization l =
        Linearize(ob.z, objects[ob.object].data(), params[ob.sensor].data(), bias[ob.kind]);
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

// Marginal covariance of the free poses: the objects eliminated from J^T W J (W = rho', IRLS
// weights) by the Schur complement, then the reduced system over the free poses and biases
// inverted. Returns false when it is not positive definite.
bool PoseCovariance(const Association& a, const std::vector<Constraint>& constraints,
                    const std::vector<PoseParams>& poses, const BiasParams& bias,
                    const std::vector<Eigen::Vector2d>& objects,
                    const std::vector<bool>& free_sensor, const std::array<bool, kKinds>& free_bias,
                    const ceres::LossFunction* loss, double observation_weight, double scale,
                    std::vector<Eigen::Matrix3d>& covariance) {
  std::vector<std::size_t> pose_offset(poses.size(), kNone);
  std::size_t dim = 0;
  for (std::size_t s = 0; s < poses.size(); ++s) {
    if (free_sensor[s]) {
      pose_offset[s] = dim;
      dim += 3;
    }
  }
  if (dim == 0) return true;
  std::array<std::size_t, kKinds> bias_offset{};
  for (std::size_t k = 0; k < kKinds; ++k) bias_offset[k] = free_bias[k] ? dim++ : kNone;
  Eigen::MatrixXd reduced =
      Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(dim), static_cast<Eigen::Index>(dim));

  // Columns of an observation's reduced Jacobian: x, y, yaw of its sensor, then its kind's bias.
  using Columns = std::array<std::size_t, 4>;
  auto columns_of = [&](const Observation& ob) {
    const std::size_t p = pose_offset[ob.sensor];
    return Columns{p, p == kNone ? kNone : p + 1, p == kNone ? kNone : p + 2, bias_offset[ob.kind]};
  };
  auto scatter = [&](const Columns& rows, const Columns& cols, const Eigen::Matrix4d& block,
                     double sign) {
    for (std::size_t i = 0; i < 4; ++i) {
      if (rows[i] == kNone) continue;
      for (std::size_t j = 0; j < 4; ++j) {
        if (cols[j] == kNone) continue;
        reduced(static_cast<Eigen::Index>(rows[i]), static_cast<Eigen::Index>(cols[j])) +=
            sign * block(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j));
      }
    }
  };

  for (const Constraint& c : constraints) {
    const ConstraintLinearization l =
        LinearizeConstraint(c.measured, poses[c.r].data(), poses[c.s].data());
    const std::array<std::size_t, 2> sensor = {c.r, c.s};
    const std::array<Eigen::Matrix3d, 2> j = {c.sqrt_info * l.d_r, c.sqrt_info * l.d_s};
    for (std::size_t u = 0; u < 2; ++u) {
      if (pose_offset[sensor[u]] == kNone) continue;
      for (std::size_t v = 0; v < 2; ++v) {
        if (pose_offset[sensor[v]] == kNone) continue;
        reduced.block<3, 3>(static_cast<Eigen::Index>(pose_offset[sensor[u]]),
                            static_cast<Eigen::Index>(pose_offset[sensor[v]])) +=
            j[u].transpose() * j[v];
      }
    }
  }

  const std::vector<std::vector<std::size_t>> by_object = ObservationsByObject(a);
  std::vector<Eigen::Matrix<double, 2, 4>> coupling;  // H_o,reduced per observation
  std::vector<Columns> cols;
  for (std::size_t o = 0; o < objects.size(); ++o) {
    Eigen::Matrix2d h_oo = Eigen::Matrix2d::Zero();
    coupling.assign(by_object[o].size(), Eigen::Matrix<double, 2, 4>::Zero());
    cols.assign(by_object[o].size(), Columns{});
    for (std::size_t k = 0; k < by_object[o].size(); ++k) {
      const Observation& ob = a.observations[by_object[o][k]];
      const Linearization l =
          Linearize(ob.z, objects[o].data(), poses[ob.sensor].data(), bias[ob.kind]);
      const Eigen::Vector2d r = ob.sqrt_info * l.e;
      const double w = observation_weight * Rho(loss, r.squaredNorm()).second;
      const Eigen::Matrix2d j_o = ob.sqrt_info * l.d_object;
      Eigen::Matrix<double, 2, 4> j_g;
      j_g.leftCols<3>() = ob.sqrt_info * l.d_pose;
      j_g.col(3) = ob.sqrt_info * l.d_bias;
      h_oo += w * j_o.transpose() * j_o;
      coupling[k] = w * j_o.transpose() * j_g;
      cols[k] = columns_of(ob);
      scatter(cols[k], cols[k], w * j_g.transpose() * j_g, 1.0);
    }
    const Eigen::LDLT<Eigen::Matrix2d> ldlt(h_oo);
    if (ldlt.info() != Eigen::Success || ldlt.rcond() < 1e-12) continue;
    const Eigen::Matrix2d h_oo_inv = ldlt.solve(Eigen::Matrix2d::Identity());
    for (std::size_t k = 0; k < by_object[o].size(); ++k) {
      for (std::size_t m = 0; m < by_object[o].size(); ++m) {
        scatter(cols[k], cols[m], coupling[k].transpose() * h_oo_inv * coupling[m], -1.0);
      }
    }
  }
  const Eigen::LLT<Eigen::MatrixXd> llt(reduced);
  if (llt.info() != Eigen::Success) return false;
  const Eigen::MatrixXd inverse = llt.solve(
      Eigen::MatrixXd::Identity(static_cast<Eigen::Index>(dim), static_cast<Eigen::Index>(dim)));
  if (!inverse.allFinite()) return false;
  for (std::size_t s = 0; s < poses.size(); ++s) {
    if (pose_offset[s] == kNone) continue;
    const auto p = static_cast<Eigen::Index>(pose_offset[s]);
    const Eigen::Matrix3d c = scale * inverse.block<3, 3>(p, p);
    covariance[s] = 0.5 * (c + c.transpose());
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
  if (!non_negative(o.model_sigma_com_m) || !non_negative(o.model_sigma_ellipse_m) ||
      !non_negative(o.model_sigma_unspecified_m)) {
    return "model_sigma_*_m must be finite and >= 0";
  }
  if (!std::isfinite(o.radial_bias_com_m) || !std::isfinite(o.radial_bias_ellipse_m) ||
      !std::isfinite(o.radial_bias_unspecified_m)) {
    return "radial_bias_*_m must be finite";
  }
  if (o.loss != RobustLoss::kNone && o.loss != RobustLoss::kHuber &&
      o.loss != RobustLoss::kCauchy) {
    return "loss must be none, huber or cauchy";
  }
  if (!positive(o.loss_scale)) return "loss_scale must be > 0";
  if (!(std::isfinite(o.observation_correlation_steps) && o.observation_correlation_steps >= 1.0)) {
    return "observation_correlation_steps must be >= 1";
  }
  if (!non_negative(o.model_sigma_per_m)) return "model_sigma_per_m must be finite and >= 0";
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
  const BiasParams initial_bias = InitialBias(options);
  auto fail = [&](std::string why) {
    result.ok = false;
    result.message = std::move(why);
    result.world_from_sensor = world_from_sensor;
    result.covariance.assign(world_from_sensor.size(), Eigen::Matrix3d::Zero());
    result.refined.assign(world_from_sensor.size(), false);
    result.sensor_observations.assign(world_from_sensor.size(), 0);
    result.radial_bias_m = initial_bias;
    result.radial_bias_estimated = {};
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

  std::size_t stride = options.step_stride;
  if (tracks.steps > 0 && (tracks.steps - 1) / stride + 1 > options.max_steps) {
    stride = (tracks.steps + options.max_steps - 1) / options.max_steps;
  }
  result.stride = stride;
  const std::vector<std::vector<StepSample>> samples =
      CollectSamples(tracks, calibrated, stride, options, result.rejected_samples);
  const std::unique_ptr<ceres::LossFunction> loss = MakeLoss(options);
  // Smoothed tracks are correlated over observation_correlation_steps grid steps: the used
  // samples carry the information of stride / correlation_steps independent ones each.
  const double observation_weight =
      std::min(1.0, static_cast<double>(stride) / options.observation_correlation_steps);
  const std::vector<Constraint> usable =
      UsableConstraints(constraints, calibrated, result.constraints_rejected);

  std::vector<Pose2> poses = world_from_sensor;
  BiasParams bias = initial_bias;
  Association final_association;
  std::vector<bool> final_free(n, false);
  std::array<bool, kKinds> final_free_bias{};
  std::vector<PoseParams> final_params;
  std::vector<Constraint> final_constraints;
  bool solved = false;
  std::string last_note;
  for (int round = 0; round < options.association_rounds; ++round) {
    Association a;
    for (std::size_t k = 0; k < samples.size(); ++k) {
      AssociateStep(samples[k], k, poses, bias, options.association_gate_m, a);
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

    // Same association as the last solve: that solve already is the answer.
    if (solved && a.SameGrouping(final_association)) break;

    const std::array<bool, kKinds> free_bias = FreeBiases(a, options);
    std::vector<PoseParams> params(n);
    for (std::size_t s = 0; s < n; ++s) params[s] = ToParams(poses[s]);
    BiasParams next_bias = bias;
    // Objects start at their optimum for the current poses, so that the solver's steps go to the
    // poses from the first iteration on.
    OptimizeObjects(a, params, bias, loss.get(), a.objects);
    const SolveOutcome outcome =
        Solve(a, round_constraints, free_sensor, free_bias, params, next_bias, a.objects,
              loss.get(), observation_weight, options);
    result.iterations += outcome.iterations;
    result.solver_time_s += outcome.time_s;
    ++result.rounds;
    if (!outcome.usable) {
      if (!solved) return fail("solver failure: " + outcome.report);
      last_note = "round " + std::to_string(round + 1) + " failed: " + outcome.report;
      break;
    }
    double change_m = 0.0, change_rad = 0.0;
    for (std::size_t s = 0; s < n; ++s) {
      if (!free_sensor[s]) continue;
      const Pose2 next = ToPose(params[s]);
      change_m = std::max(change_m, common::TranslationDistanceM(next, poses[s]));
      change_rad = std::max(change_rad, common::RotationDistanceRad(next, poses[s]));
      poses[s] = next;
    }
    for (std::size_t k = 0; k < kKinds; ++k) {
      change_m = std::max(change_m, std::abs(next_bias[k] - bias[k]));
    }
    bias = next_bias;
    final_association = std::move(a);
    final_free = free_sensor;
    final_free_bias = free_bias;
    final_params = std::move(params);
    final_constraints = std::move(round_constraints);
    solved = true;
    // The association depends only on the poses and biases: nothing left to gain once they stand
    // still.
    if (change_m < 1e-6 && change_rad < 1e-7) break;
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
  const CostSummary before =
      EvaluateAtOptimalObjects(a, final_constraints, world_from_sensor, initial_bias, a.objects,
                               loss.get(), observation_weight);
  const CostSummary after = EvaluateAtOptimalObjects(a, final_constraints, poses, bias, a.objects,
                                                     loss.get(), observation_weight);
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
  result.radial_bias_m = bias;
  result.radial_bias_estimated = final_free_bias;
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
  for (bool b : final_free_bias) unknowns += b ? 1 : 0;
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
  if (!PoseCovariance(a, final_constraints, final_params, bias, a.objects, final_free,
                      final_free_bias, loss.get(), observation_weight, scale, result.covariance)) {
    result.covariance.assign(n, Eigen::Matrix3d::Zero());
    message << "; covariance unavailable (reduced system not positive definite)";
  }
  if (!last_note.empty()) message << "; " << last_note;
  result.message = message.str();
  return result;
}

}  // namespace lrfnet::calib
