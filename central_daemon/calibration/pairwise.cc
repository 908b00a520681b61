#include "central_daemon/calibration/pairwise.h"

#include <spdlog/fmt/fmt.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <limits>
#include <numeric>
#include <utility>

#include "common/eigen_instances.h"

namespace lrfnet::calib {

using common::AngleDiff;
using common::DegToRad;
using common::NormalizeAngle;
using common::RadToDeg;

std::optional<std::string> Validate(const PairwiseOptions& o) {
  if (auto e = Validate(o.intervals)) return e;
  const auto positive = [](double v) { return std::isfinite(v) && v > 0.0; };
  if (o.msac_iterations < 1) return "msac_iterations must be at least 1";
  if (o.msac_max_points < 2) return "msac_max_points must be at least 2";
  if (!positive(o.msac_threshold_m)) return "msac_threshold_m must be positive";
  if (!positive(o.min_sample_separation_m)) return "min_sample_separation_m must be positive";
  if (!(o.min_track_spread_m >= 0.0)) return "min_track_spread_m must be >= 0";
  if (!(o.min_hypothesis_inlier_fraction >= 0.0 && o.min_hypothesis_inlier_fraction <= 1.0)) {
    return "min_hypothesis_inlier_fraction must be in [0, 1]";
  }
  if (o.min_hypothesis_inliers < 2) return "min_hypothesis_inliers must be at least 2";
  if (!positive(o.cluster_yaw_deg) || !positive(o.cluster_distance_m)) {
    return "cluster_yaw_deg and cluster_distance_m must be positive";
  }
  if (o.max_verified_hypotheses < 1) return "max_verified_hypotheses must be at least 1";
  if (!positive(o.model_sigma_m)) return "model_sigma_m must be positive";
  if (!positive(o.verify_gate)) return "verify_gate must be positive";
  if (o.verify_stride < 1) return "verify_stride must be at least 1";
  if (!positive(o.distinct_yaw_deg) || !positive(o.distinct_distance_m)) {
    return "distinct_yaw_deg and distinct_distance_m must be positive";
  }
  if (!positive(o.refit_gate_m)) return "refit_gate_m must be positive";
  if (o.refit_rounds < 1) return "refit_rounds must be at least 1";
  if (!positive(o.huber_k)) return "huber_k must be positive";
  if (!(o.covariance_correlation_steps >= 1.0) || !std::isfinite(o.covariance_correlation_steps)) {
    return "covariance_correlation_steps must be >= 1";
  }
  if (!(std::isfinite(o.segment_sigma_m) && o.segment_sigma_m >= 0.0 &&
        std::isfinite(o.segment_sigma_per_m) && o.segment_sigma_per_m >= 0.0)) {
    return "segment_sigma_m and segment_sigma_per_m must be >= 0";
  }
  if (o.min_matches < 3) return "min_matches must be at least 3";
  if (!positive(o.max_rms_m)) return "max_rms_m must be positive";
  if (!positive(o.max_yaw_sigma_deg)) return "max_yaw_sigma_deg must be positive";
  if (!positive(o.max_translation_sigma_m)) return "max_translation_sigma_m must be positive";
  if (!(o.max_ambiguity_ratio > 0.0 && o.max_ambiguity_ratio <= 1.0)) {
    return "max_ambiguity_ratio must be in (0, 1]";
  }
  if (!(o.min_match_fraction_ratio >= 0.0 && o.min_match_fraction_ratio <= 1.0)) {
    return "min_match_fraction_ratio must be in [0, 1]";
  }
  if (!(o.default_detection_probability > 0.0 && o.default_detection_probability <= 1.0)) {
    return "default_detection_probability must be in (0, 1]";
  }
  if (!positive(o.coverage_cell_m)) return "coverage_cell_m must be positive";
  return std::nullopt;
}

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
// Clearly different hypotheses (lowest E first) examined for ambiguity.
constexpr std::size_t kCompetitorsExamined = 5;

// Bounds far beyond any real track; they keep every product below finite overflow.
constexpr double kMaxAbsPosition_m = 1e5;
constexpr double kMaxVariance_m2 = 1e8;
constexpr double kMaxModelValue = 100.0;
// A range band of the detection probability needs this many visible observations to count.
constexpr std::size_t kMinBandObservations = 20;

bool Usable(const TrackSample& x) {
  if (!x.position_m.allFinite() || !x.position_cov_m2.allFinite()) return false;
  if (x.position_m.cwiseAbs().maxCoeff() > kMaxAbsPosition_m) return false;
  const Eigen::Matrix2d& c = x.position_cov_m2;
  const double off = 0.5 * (c(0, 1) + c(1, 0));
  if (!(c(0, 0) > 0.0 && c(1, 1) > 0.0 && c(0, 0) <= kMaxVariance_m2 &&
        c(1, 1) <= kMaxVariance_m2 && c(0, 0) * c(1, 1) - off * off > 0.0)) {
    return false;
  }
  // The measurement model: finite and far below anything a body could be.
  for (const float v :
       {x.bias_m, x.bias_per_major, x.bias_per_minor, x.bias_sigma_m, x.model_sigma_m}) {
    if (!std::isfinite(v) || std::abs(v) > kMaxModelValue) return false;
  }
  return true;
}

double Cross(const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  return a.x() * b.y() - a.y() * b.x();
}

// Square root of the largest eigenvalue of the points' scatter (metres): the standard deviation
// along the main direction of motion.
double Spread(const std::vector<Eigen::Vector2d>& points) {
  if (points.size() < 2) return 0.0;
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (const auto& p : points) mean += p;
  mean /= static_cast<double>(points.size());
  double sxx = 0.0, sxy = 0.0, syy = 0.0;
  for (const auto& p : points) {
    const Eigen::Vector2d d = p - mean;
    sxx += d.x() * d.x();
    sxy += d.x() * d.y();
    syy += d.y() * d.y();
  }
  const double n = static_cast<double>(points.size());
  sxx /= n;
  sxy /= n;
  syy /= n;
  const double half_trace = 0.5 * (sxx + syy);
  const double disc = std::sqrt(std::max(0.0, 0.25 * (sxx - syy) * (sxx - syy) + sxy * sxy));
  return std::sqrt(std::max(0.0, half_trace + disc));
}

// splitmix64: a counter-based generator, so every (sensor pair, p, q) has its own stream and
// the result does not depend on the order of evaluation.
struct SplitMix64 {
  std::uint64_t state;
  std::uint64_t Next() {
    std::uint64_t z = (state += 0x9E3779B97F4A7C15ULL);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
  }
  std::size_t Below(std::size_t n) { return static_cast<std::size_t>(Next() % n); }
};

std::uint64_t MixSeed(std::uint64_t seed, std::uint64_t v) {
  SplitMix64 g{seed ^ (v * 0xD6E8FEB86659FD93ULL)};
  return g.Next();
}

// Closed-form weighted 2D rigid fit (Procrustes/Umeyama without scale): minimises
// sum w_i |R p_i + t - q_i|^2. nullopt when the points carry no rotation information.
std::optional<Pose2> ProcrustesFit(const std::vector<Eigen::Vector2d>& p,
                                   const std::vector<Eigen::Vector2d>& q,
                                   const std::vector<double>& w) {
  double w_sum = 0.0;
  Eigen::Vector2d pc = Eigen::Vector2d::Zero(), qc = Eigen::Vector2d::Zero();
  for (std::size_t i = 0; i < p.size(); ++i) {
    w_sum += w[i];
    pc += w[i] * p[i];
    qc += w[i] * q[i];
  }
  if (!(w_sum > 0.0)) return std::nullopt;
  pc /= w_sum;
  qc /= w_sum;
  double dot = 0.0, cross = 0.0, norm_p = 0.0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    const Eigen::Vector2d dp = p[i] - pc, dq = q[i] - qc;
    dot += w[i] * dp.dot(dq);
    cross += w[i] * Cross(dp, dq);
    norm_p += w[i] * dp.squaredNorm();
  }
  if (!(norm_p > 1e-12 * w_sum) || !(std::hypot(dot, cross) > 0.0)) return std::nullopt;
  Pose2 pose;
  pose.yaw_rad = std::atan2(cross, dot);
  const Eigen::Vector2d t = qc - pose.rotation() * pc;
  pose.x_m = t.x();
  pose.y_m = t.y();
  return pose;
}

// Every simultaneous observation of the pair, grouped by grid step.
struct Obs {
  Eigen::Vector2d c;     // body centre at zero size correction (CentreOf)
  Eigen::Matrix2d cov;   // CentreCovariance
  Eigen::Matrix2d vcov;  // cov plus the prior size correction's uncertainty (verification)
  Eigen::Matrix2d jd;    // d centre / d size correction (CentrePerSizeCorrection)
  Eigen::Vector2d raw;   // the tracker's position (coverage: where the sensor tracks people)
  // The centre's shift for one standard deviation of its sensor's shared radial bias
  // (TrackSample::shared_bias_sigma_m along the line of sight).
  Eigen::Vector2d shared_bias;
  std::size_t track;
};

Obs MakeObs(const TrackSample& x, std::size_t track, double prior_var) {
  Obs o;
  o.c = CentreOf(x);
  o.cov = CentreCovariance(x);
  o.jd = CentrePerSizeCorrection(x);
  o.vcov = o.cov + prior_var * (o.jd * o.jd.transpose());
  o.raw = x.position_m;
  o.shared_bias = static_cast<double>(x.shared_bias_sigma_m) * LineOfSight(x.position_m);
  o.track = track;
  return o;
}

struct StepObs {
  std::size_t step;
  std::size_t r_begin, r_end, s_begin, s_end;  // ranges in PairData::r / ::s
};
struct PairData {
  std::vector<StepObs> steps;
  std::vector<Obs> r, s;
  std::size_t unusable = 0;
  Eigen::Vector2d r_centroid = Eigen::Vector2d::Zero();
};

double PriorVariance(const AlignedTracks& aligned) {
  const double sigma = aligned.size_prior_sigma_m;
  return std::isfinite(sigma) && sigma > 0.0 ? sigma * sigma : 0.0;
}

PairData BuildPairData(const AlignedTracks& aligned, std::size_t r, std::size_t s,
                       const std::vector<Interval>& intervals) {
  PairData d;
  const double prior_var = PriorVariance(aligned);
  const auto& tr = aligned.sensors[r].tracks;
  const auto& ts = aligned.sensors[s].tracks;
  for (const Interval& in : intervals) {
    for (std::size_t k = in.first_step; k < in.end_step; ++k) {
      StepObs so{k, d.r.size(), d.r.size(), d.s.size(), d.s.size()};
      for (std::size_t i : in.tracks_r) {
        const TrackSample& x = tr[i].At(k);
        if (Usable(x)) {
          d.r.push_back(MakeObs(x, i, prior_var));
        } else {
          ++d.unusable;
        }
      }
      for (std::size_t j : in.tracks_s) {
        const TrackSample& x = ts[j].At(k);
        if (Usable(x)) {
          d.s.push_back(MakeObs(x, j, prior_var));
        } else {
          ++d.unusable;
        }
      }
      so.r_end = d.r.size();
      so.s_end = d.s.size();
      if (so.r_end > so.r_begin && so.s_end > so.s_begin) {
        d.steps.push_back(so);
      } else {  // drop the observations of a step that lost one side to unusable samples
        d.r.resize(so.r_begin);
        d.s.resize(so.s_begin);
      }
    }
  }
  for (const Obs& o : d.r) d.r_centroid += o.c;
  if (!d.r.empty()) d.r_centroid /= static_cast<double>(d.r.size());
  return d;
}

struct Hypothesis {
  Pose2 pose;
  std::size_t inliers = 0;
};

struct Cluster {
  Pose2 pose;  // of the member with the most inliers
  std::size_t support = 0;
  double error = kInf;  // E of eq. 8
};

bool Near(const Pose2& a, const Pose2& b, const Eigen::Vector2d& at, double yaw_rad,
          double distance_m) {
  return std::abs(AngleDiff(a.yaw_rad, b.yaw_rad)) < yaw_rad &&
         ((a * at) - (b * at)).norm() < distance_m;
}

// MSAC on one track pair over steps [first_step, end_step) where both exist: minimal samples of
// eq. 5, truncated quadratic score, then least squares on the inliers.
enum class MsacOutcome { kHypothesis, kDegenerate, kNone };

MsacOutcome Msac(const GridTrack& tp, const GridTrack& tq, std::size_t first_step,
                 std::size_t end_step, const PairwiseOptions& o, std::uint64_t stream,
                 Hypothesis& out) {
  std::vector<Eigen::Vector2d> P, Q;
  std::vector<double> w;
  P.reserve(end_step - first_step);
  Q.reserve(end_step - first_step);
  w.reserve(end_step - first_step);
  const double model_var = o.model_sigma_m * o.model_sigma_m;
  for (std::size_t k = first_step; k < end_step; ++k) {
    const TrackSample& a = tp.At(k);
    const TrackSample& b = tq.At(k);
    if (!Usable(a) || !Usable(b)) continue;
    P.push_back(CentreOf(a));
    Q.push_back(CentreOf(b));
    w.push_back(1.0 /
                (0.5 * (CentreCovariance(a).trace() + CentreCovariance(b).trace()) + model_var));
  }
  const std::size_t n = P.size();
  if (n < std::max<std::size_t>(o.min_hypothesis_inliers, 2)) return MsacOutcome::kNone;
  if (Spread(P) < o.min_track_spread_m) return MsacOutcome::kDegenerate;

  const std::size_t m = std::min(n, o.msac_max_points);
  std::vector<std::size_t> idx(m);
  for (std::size_t j = 0; j < m; ++j) idx[j] = j * n / m;

  const double t2 = o.msac_threshold_m * o.msac_threshold_m;
  const double sep2 = o.min_sample_separation_m * o.min_sample_separation_m;
  SplitMix64 rng{stream};
  double best_score = kInf;
  Pose2 best;
  for (std::size_t it = 0; it < o.msac_iterations; ++it) {
    const std::size_t ia = rng.Below(m);
    std::size_t ib = rng.Below(m - 1);
    if (ib >= ia) ++ib;
    const std::size_t a = idx[ia], b = idx[ib];
    const Eigen::Vector2d dp = P[b] - P[a], dq = Q[b] - Q[a];
    if (dp.squaredNorm() < sep2) continue;
    // A rigid transform preserves distances: a wrong pairing usually fails here, for free.
    if (std::abs(dp.norm() - dq.norm()) > 2.0 * o.msac_threshold_m) continue;
    Pose2 h;
    h.yaw_rad = std::atan2(Cross(dp, dq), dp.dot(dq));
    const Eigen::Matrix2d R = h.rotation();
    const Eigen::Vector2d t = 0.5 * (Q[a] + Q[b]) - R * (0.5 * (P[a] + P[b]));
    h.x_m = t.x();
    h.y_m = t.y();
    double score = 0.0;  // eq. 5 with the MSAC truncation
    for (std::size_t j : idx) {
      score += std::min((R * P[j] + t - Q[j]).squaredNorm(), t2);
      if (score >= best_score) break;
    }
    if (score < best_score) {
      best_score = score;
      best = h;
    }
  }
  if (!std::isfinite(best_score)) return MsacOutcome::kNone;

  // Least-squares refinement of eq. 5 on all inlier steps of the span (twice: the refined
  // transform may admit a few more inliers).
  Pose2 pose = best;
  std::size_t inliers = 0;
  std::vector<Eigen::Vector2d> pi, qi;
  std::vector<double> wi;
  for (int round = 0; round < 2; ++round) {
    pi.clear();
    qi.clear();
    wi.clear();
    const Eigen::Matrix2d R = pose.rotation();
    const Eigen::Vector2d t = pose.translation();
    for (std::size_t j = 0; j < n; ++j) {
      if ((R * P[j] + t - Q[j]).squaredNorm() < t2) {
        pi.push_back(P[j]);
        qi.push_back(Q[j]);
        wi.push_back(w[j]);
      }
    }
    if (pi.size() < 2) return MsacOutcome::kNone;
    const auto fit = ProcrustesFit(pi, qi, wi);
    if (!fit) return MsacOutcome::kNone;
    pose = *fit;
  }
  {
    const Eigen::Matrix2d R = pose.rotation();
    const Eigen::Vector2d t = pose.translation();
    for (std::size_t j = 0; j < n; ++j) inliers += (R * P[j] + t - Q[j]).squaredNorm() < t2;
  }
  if (inliers < o.min_hypothesis_inliers ||
      static_cast<double>(inliers) < o.min_hypothesis_inlier_fraction * static_cast<double>(n)) {
    return MsacOutcome::kNone;
  }
  out = {pose, inliers};
  return MsacOutcome::kHypothesis;
}

// Squared Mahalanobis distance of eq. 6 between a (mapped r observation, covariance ca) and b,
// or +inf when it is certainly above gate2 (cheap bound: d^2 >= |a-b|^2 / trace).
double Mahalanobis2(const Eigen::Vector2d& diff, const Eigen::Matrix2d& ca,
                    const Eigen::Matrix2d& cb, double model_var, double gate2) {
  const double s00 = ca(0, 0) + cb(0, 0) + model_var;
  const double s11 = ca(1, 1) + cb(1, 1) + model_var;
  const double s01 = ca(0, 1) + cb(0, 1);
  const double n2 = diff.squaredNorm();
  if (n2 >= gate2 * (s00 + s11)) return kInf;
  const double det = s00 * s11 - s01 * s01;
  const double dx = diff.x(), dy = diff.y();
  return (s11 * dx * dx - 2.0 * s01 * dx * dy + s00 * dy * dy) / det;
}

// Eqs. 6-8 per r observation of the verified steps, in order: visit(j, d) with the nearest s
// observation j of the same step under pose (w of eq. 8; -1 when none is within the gate) and its
// Mahalanobis distance d_S of eq. 6, truncated at the gate (see PairwiseOptions::verify_gate).
template <typename Visit>
void VisitNearest(const PairData& d, const Pose2& pose, const PairwiseOptions& o, Visit&& visit) {
  const Eigen::Matrix2d R = pose.rotation();
  const Eigen::Vector2d t = pose.translation();
  const double model_var = o.model_sigma_m * o.model_sigma_m;
  const double gate2 = o.verify_gate * o.verify_gate;
  for (std::size_t k = 0; k < d.steps.size(); k += o.verify_stride) {
    const StepObs& so = d.steps[k];
    for (std::size_t i = so.r_begin; i < so.r_end; ++i) {
      const Eigen::Vector2d a = R * d.r[i].c + t;
      const Eigen::Matrix2d ca = R * d.r[i].vcov * R.transpose();
      double best2 = gate2;
      std::ptrdiff_t best_j = -1;
      for (std::size_t j = so.s_begin; j < so.s_end; ++j) {
        const double m2 = Mahalanobis2(a - d.s[j].c, ca, d.s[j].vcov, model_var, gate2);
        if (m2 < best2) {
          best2 = m2;
          best_j = static_cast<std::ptrdiff_t>(j);
        }
      }
      visit(best_j, std::sqrt(best2));
    }
  }
}

// E of eq. 8: the sum of eq. 7's truncated summands.
double VerificationError(const PairData& d, const Pose2& pose, const PairwiseOptions& o) {
  double e = 0.0;
  VisitNearest(d, pose, o, [&](std::ptrdiff_t, double d_s) { e += d_s; });
  return e;
}

// The associations and distances behind E.
struct Explanation {
  std::vector<std::ptrdiff_t> s_obs;
  std::vector<double> d;
};

Explanation Explain(const PairData& d, const Pose2& pose, const PairwiseOptions& o) {
  Explanation out;
  VisitNearest(d, pose, o, [&](std::ptrdiff_t j, double d_s) {
    out.s_obs.push_back(j);
    out.d.push_back(d_s);
  });
  return out;
}

std::size_t VerifiedObservations(const PairData& d, const PairwiseOptions& o) {
  std::size_t n = 0;
  for (std::size_t k = 0; k < d.steps.size(); k += o.verify_stride) {
    n += d.steps[k].r_end - d.steps[k].r_begin;
  }
  return n;
}

// One-to-one nearest neighbours per step under pose, by increasing distance, up to gate_m.
// Pairs of indices into PairData::r and ::s.
std::vector<std::pair<std::size_t, std::size_t>> Associate(const PairData& d, const Pose2& pose,
                                                           double gate_m) {
  std::vector<std::pair<std::size_t, std::size_t>> out;
  const Eigen::Matrix2d R = pose.rotation();
  const Eigen::Vector2d t = pose.translation();
  const double gate2 = gate_m * gate_m;
  struct Candidate {
    double d2;
    std::size_t i, j;
  };
  std::vector<Candidate> cand;
  std::vector<std::size_t> taken_i, taken_j;
  for (const StepObs& so : d.steps) {
    cand.clear();
    for (std::size_t i = so.r_begin; i < so.r_end; ++i) {
      const Eigen::Vector2d a = R * d.r[i].c + t;
      for (std::size_t j = so.s_begin; j < so.s_end; ++j) {
        const double d2 = (a - d.s[j].c).squaredNorm();
        if (d2 < gate2) cand.push_back({d2, i, j});
      }
    }
    if (cand.empty()) continue;
    std::sort(cand.begin(), cand.end(), [](const Candidate& x, const Candidate& y) {
      if (x.d2 != y.d2) return x.d2 < y.d2;
      return std::tie(x.i, x.j) < std::tie(y.i, y.j);
    });
    taken_i.clear();
    taken_j.clear();
    const std::size_t first = out.size();
    for (const Candidate& c : cand) {
      if (std::find(taken_i.begin(), taken_i.end(), c.i) != taken_i.end()) continue;
      if (std::find(taken_j.begin(), taken_j.end(), c.j) != taken_j.end()) continue;
      taken_i.push_back(c.i);
      taken_j.push_back(c.j);
      out.emplace_back(c.i, c.j);
    }
    std::sort(out.begin() + static_cast<std::ptrdiff_t>(first), out.end());
  }
  return out;
}

// The matched observations of a refit: body centres at zero size correction, their covariances,
// their sensitivities to the size correction, and the matched track pair (segment) of each.
struct FitInput {
  std::vector<Eigen::Vector2d> p, q;
  std::vector<Eigen::Matrix2d> cp, cq, jp, jq;
  std::vector<Eigen::Vector2d> bp, bq;  // Obs::shared_bias of both sides
  std::vector<std::size_t> segment;
  std::size_t segments = 0;
  // Per segment: summed ranges of both sides and the count (the systematic floor's sigma).
  std::vector<double> range_r, range_s, count;

  void Reserve(std::size_t n) {
    p.reserve(n);
    q.reserve(n);
    cp.reserve(n);
    cq.reserve(n);
    jp.reserve(n);
    jq.reserve(n);
    bp.reserve(n);
    bq.reserve(n);
    segment.reserve(n);
  }

  void Add(const Obs& a, const Obs& b, std::size_t seg) {
    p.push_back(a.c);
    cp.push_back(a.cov);
    jp.push_back(a.jd);
    q.push_back(b.c);
    cq.push_back(b.cov);
    jq.push_back(b.jd);
    bp.push_back(a.shared_bias);
    bq.push_back(b.shared_bias);
    segment.push_back(seg);
    segments = std::max(segments, seg + 1);
    if (range_r.size() < segments) {
      range_r.resize(segments, 0.0);
      range_s.resize(segments, 0.0);
      count.resize(segments, 0.0);
    }
    range_r[seg] += a.c.norm();
    range_s[seg] += b.c.norm();
    count[seg] += 1.0;
  }
};

// Segment ids of matches: one per (track of r, track of s), numbered in order of appearance.
class SegmentIds {
 public:
  std::size_t Of(std::size_t track_r, std::size_t track_s) {
    const auto key = std::make_pair(track_r, track_s);
    const auto it = std::find(keys_.begin(), keys_.end(), key);
    if (it != keys_.end()) return static_cast<std::size_t>(it - keys_.begin());
    keys_.push_back(key);
    return keys_.size() - 1;
  }

 private:
  std::vector<std::pair<std::size_t, std::size_t>> keys_;
};

// start: a fit to start from (the previous refit round); without it the closed-form weighted
// Procrustes solution. prior_var: variance of each component of the size correction's prior.
RigidFit Fit(const FitInput& in, const PairwiseOptions& o, double prior_var,
             const RigidFit* start = nullptr, int max_iterations = 15) {
  const auto& p = in.p;
  const auto& q = in.q;
  RigidFit fit;
  const std::size_t n = p.size();
  if (n < 3) return fit;
  const bool warm = start != nullptr && start->ok;
  Pose2 pose0;
  if (warm) {
    pose0 = start->s_from_r;
  } else {
    std::vector<double> w(n);
    for (std::size_t i = 0; i < n; ++i) w[i] = 1.0 / (0.5 * (in.cp[i].trace() + in.cq[i].trace()));
    const auto closed_form = ProcrustesFit(p, q, w);
    if (!closed_form) return fit;
    pose0 = *closed_form;
  }

  // Gauss-Newton on eq. 5 (untruncated: the association gate already bounds the residuals) with
  // full covariances and the Huber loss. x = (x, y, yaw, d_major, d_minor): the body centres of
  // both sides move with the shared size correction d (TrackSample), which has a zero-mean prior.
  // The observations are correlated over covariance_correlation_steps, so the sums below hold that
  // many times more information than they carry; the prior is weighed on the same scale. Without
  // estimate_size_correction d is held at 0 (its prior uncertainty still enters the covariance).
  using Vector5d = Eigen::Matrix<double, 5, 1>;
  using Matrix5d = Eigen::Matrix<double, 5, 5>;
  const double prior_info = prior_var > 0.0 ? o.covariance_correlation_steps / prior_var : 1e12;
  const double solve_prior_info = o.estimate_size_correction ? prior_info : 1e12;
  Vector5d x;
  x << pose0.x_m, pose0.y_m, pose0.yaw_rad,
      warm ? start->size_correction_m : Eigen::Vector2d::Zero();
  if (!o.estimate_size_correction) x.tail<2>().setZero();

  // The weights (R C_p R^T + C_q)^-1 at the start rotation: the rotation moves by a fraction of a
  // degree from there, which changes them by far less than their own uncertainty.
  std::vector<Eigen::Matrix2d> W(n);
  {
    const Eigen::Matrix2d R = pose0.rotation();
    for (std::size_t i = 0; i < n; ++i) {
      W[i] = (R * in.cp[i] * R.transpose() + in.cq[i]).inverse();
    }
  }
  std::vector<double> rho(n, 1.0);
  std::vector<Eigen::Matrix<double, 2, 5>> J(n);
  Matrix5d h = Matrix5d::Zero();
  double chi2 = 0.0;
  const auto linearize = [&]() {
    const double c = std::cos(x(2)), s = std::sin(x(2));
    Eigen::Matrix2d R, dR;
    R << c, -s, s, c;
    dR << -s, -c, c, -s;
    h.setZero();
    Vector5d g = Vector5d::Zero();
    chi2 = 0.0;
    const Eigen::Vector2d d = x.tail<2>();
    for (std::size_t i = 0; i < n; ++i) {
      const Eigen::Vector2d pi = p[i] + in.jp[i] * d;
      const Eigen::Vector2d e = R * pi + x.head<2>() - (q[i] + in.jq[i] * d);
      const Eigen::Vector2d We = W[i] * e;
      const double m2 = e.dot(We);
      rho[i] = m2 <= o.huber_k * o.huber_k ? 1.0 : o.huber_k / std::sqrt(m2);
      J[i].leftCols<2>().setIdentity();
      J[i].col(2) = dR * pi;
      J[i].rightCols<2>() = R * in.jp[i] - in.jq[i];
      const Eigen::Matrix<double, 2, 5> WJ = W[i] * J[i];
      h.noalias() += rho[i] * (J[i].transpose() * WJ);
      g.noalias() += rho[i] * (WJ.transpose() * e);
      chi2 += rho[i] * m2;
    }
    return g;
  };
  for (int iter = 0; iter < max_iterations; ++iter) {
    Vector5d g = linearize();
    for (int k = 3; k < 5; ++k) {
      h(k, k) += solve_prior_info;
      g(k) += solve_prior_info * x(k);
    }
    const Eigen::LDLT<Matrix5d> ldlt(h);
    if (ldlt.info() != Eigen::Success || !(ldlt.vectorD().minCoeff() > 0.0)) return fit;
    const Vector5d delta = -ldlt.solve(g);
    if (!delta.allFinite()) return fit;
    x += delta;
    x(2) = NormalizeAngle(x(2));
    if (delta.head<2>().norm() < 1e-6 && std::abs(delta(2)) < 1e-7 &&
        delta.tail<2>().norm() < 1e-6) {
      break;
    }
  }
  linearize();  // h, rho and J at the solution
  fit.s_from_r = {x(0), x(1), NormalizeAngle(x(2))};
  fit.size_correction_m = x.tail<2>();
  const Eigen::Matrix2d R = fit.s_from_r.rotation();
  const Eigen::Vector2d t = fit.s_from_r.translation();
  double sum2 = 0.0, sum = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    const double e = (R * (p[i] + in.jp[i] * fit.size_correction_m) + t -
                      (q[i] + in.jq[i] * fit.size_correction_m))
                         .norm();
    sum2 += e * e;
    sum += e;
  }
  fit.rms_m = std::sqrt(sum2 / static_cast<double>(n));
  fit.mean_residual_m = sum / static_cast<double>(n);
  const double dof = std::max(1.0, 2.0 * static_cast<double>(n) - 3.0);
  fit.variance_factor = chi2 / dof;

  // The honest covariance (pairwise.h): the size correction marginalised with its prior, the
  // variance factor floored at 1, the correlation in time, and each matched track pair's own
  // systematic offset propagated through the estimator (x responds to a common offset eps of a
  // segment's residuals by -H^-1 sum_i rho_i J_i^T W_i eps).
  Matrix5d hc = h;
  hc(3, 3) += prior_info;
  hc(4, 4) += prior_info;
  const Eigen::LDLT<Matrix5d> ldlt(hc);
  if (ldlt.info() != Eigen::Success || !(ldlt.vectorD().minCoeff() > 0.0)) return fit;
  const Matrix5d hc_inv = ldlt.solve(Matrix5d::Identity());
  Matrix5d cov = hc_inv * (std::max(1.0, fit.variance_factor) * o.covariance_correlation_steps);
  std::vector<Eigen::Matrix<double, 5, 2>> response(in.segments,
                                                    Eigen::Matrix<double, 5, 2>::Zero());
  for (std::size_t i = 0; i < n; ++i) {
    response[in.segment[i]].noalias() += rho[i] * (J[i].transpose() * W[i]);
  }
  Matrix5d systematic = Matrix5d::Zero();
  for (std::size_t k = 0; k < response.size(); ++k) {
    const double count = std::max(1.0, in.count[k]);
    const double side_r = o.segment_sigma_m + o.segment_sigma_per_m * in.range_r[k] / count;
    const double side_s = o.segment_sigma_m + o.segment_sigma_per_m * in.range_s[k] / count;
    const Eigen::Matrix<double, 5, 2> a = hc_inv * response[k];
    systematic.noalias() += (side_r * side_r + side_s * side_s) * (a * a.transpose());
  }
  if (o.sensor_bias) {
    // Each sensor's shared radial bias as a consider parameter (pairwise.h "Sensor bias";
    // refine.h): x responds to one standard deviation of r's by -H^-1 sum_i rho_i J_i^T W_i R b_p,i
    // (e = R p + t - q) and of s's by +H^-1 sum_i rho_i J_i^T W_i b_q,i.
    const Eigen::Matrix2d R0 = fit.s_from_r.rotation();
    Eigen::Matrix<double, 5, 1> g_r = Eigen::Matrix<double, 5, 1>::Zero();
    Eigen::Matrix<double, 5, 1> g_s = Eigen::Matrix<double, 5, 1>::Zero();
    for (std::size_t i = 0; i < n; ++i) {
      g_r.noalias() += rho[i] * (J[i].transpose() * (W[i] * (R0 * in.bp[i])));
      g_s.noalias() += rho[i] * (J[i].transpose() * (W[i] * in.bq[i]));
    }
    const Eigen::Matrix<double, 5, 1> a_r = hc_inv * g_r, a_s = hc_inv * g_s;
    const Matrix5d bias = a_r * a_r.transpose() + a_s * a_s.transpose();
    systematic.noalias() += bias;
    fit.covariance_sensor_bias = bias.topLeftCorner<3, 3>();
  }
  fit.segments = in.segments;
  fit.covariance_systematic = systematic.topLeftCorner<3, 3>();
  fit.covariance = cov.topLeftCorner<3, 3>() + fit.covariance_systematic;
  fit.covariance = 0.5 * (fit.covariance + fit.covariance.transpose());
  fit.ok = fit.covariance.allFinite() && fit.s_from_r.translation().allFinite() &&
           std::isfinite(fit.s_from_r.yaw_rad);
  return fit;
}

RigidFit FitPairs(const PairData& d, const std::vector<std::pair<std::size_t, std::size_t>>& pairs,
                  const PairwiseOptions& o, double prior_var, const RigidFit* start,
                  int max_iterations) {
  FitInput in;
  in.Reserve(pairs.size());
  SegmentIds segments;
  for (const auto& [i, j] : pairs) {
    in.Add(d.r[i], d.s[j], segments.Of(d.r[i].track, d.s[j].track));
  }
  return Fit(in, o, prior_var, start, max_iterations);
}

// Whether some track of r and some track of s are visible together for min_steps.
bool HasLongTrackPair(const AlignedTracks& aligned, std::size_t r, std::size_t s,
                      const std::vector<Interval>& intervals, std::size_t min_steps) {
  for (const Interval& in : intervals) {
    for (std::size_t p : in.tracks_r) {
      for (std::size_t q : in.tracks_s) {
        const GridTrack& tp = aligned.sensors[r].tracks[p];
        const GridTrack& tq = aligned.sensors[s].tracks[q];
        if (std::min(tp.end_step(), tq.end_step()) >=
            std::max(tp.first_step, tq.first_step) + min_steps) {
          return true;
        }
      }
    }
  }
  return false;
}

// The per-sensor detection probability by range band (see PairwiseOptions), as the expected match
// fraction of one direction of a pair. probability[b] < 0: not measured.
using Detection = std::array<double, kRangeBands>;

double ExpectedFraction(const VisibilityCounts& counts, const Detection& detection,
                        double fallback) {
  double visible = 0.0, expected = 0.0;
  for (std::size_t b = 0; b < kRangeBands; ++b) {
    if (counts.visible[b] == 0) continue;
    // An unmeasured band takes the nearest measured one (detection falls with range; the nearer
    // band on the far side is the conservative choice), else the fallback.
    double p = -1.0;
    for (std::size_t k = 0; k < kRangeBands && p < 0.0; ++k) {
      if (b + k < kRangeBands && detection[b + k] >= 0.0) p = detection[b + k];
      if (p < 0.0 && b >= k && detection[b - k] >= 0.0) p = detection[b - k];
    }
    if (p < 0.0) p = fallback;
    visible += static_cast<double>(counts.visible[b]);
    expected += static_cast<double>(counts.visible[b]) * p;
  }
  return visible > 0.0 ? expected / visible : fallback;
}

double ObservedFraction(const VisibilityCounts& counts, std::size_t* visible_out = nullptr) {
  std::size_t visible = 0, matched = 0;
  for (std::size_t b = 0; b < kRangeBands; ++b) {
    visible += counts.visible[b];
    matched += counts.matched[b];
  }
  if (visible_out != nullptr) *visible_out = visible;
  return visible > 0 ? static_cast<double>(matched) / static_cast<double>(visible) : 1.0;
}

// The negative-evidence decision of a pair that passed everything else (pairwise.h): each
// direction's observed match fraction against min_match_fraction_ratio times the detecting
// sensor's expected one. Rejects with the reason, or fills the fractions.
void JudgeVisibility(const AlignedTracks& aligned, const PairDiagnostics& diag,
                     const Detection& detect_s, const Detection& detect_r, const PairwiseOptions& o,
                     PairEstimate* est) {
  struct Direction {
    const VisibilityCounts* counts;
    const Detection* detection;
    std::size_t seen, seeing;  // sensor indices: whose observations, whose coverage
  };
  const Direction directions[2] = {{&diag.r_in_s, &detect_s, est->r, est->s},
                                   {&diag.s_in_r, &detect_r, est->s, est->r}};
  double worst_ratio = kInf;
  for (const Direction& d : directions) {
    std::size_t visible = 0;
    const double observed = ObservedFraction(*d.counts, &visible);
    const double expected =
        ExpectedFraction(*d.counts, *d.detection, o.default_detection_probability);
    const double ratio = expected > 0.0 ? observed / expected : kInf;
    if (visible > 0 && ratio < worst_ratio) {
      worst_ratio = ratio;
      est->match_fraction = observed;
      est->expected_match_fraction = expected;
    }
    if (visible > 0 && observed < o.min_match_fraction_ratio * expected) {
      est->accepted = false;
      est->weak = false;
      est->weak_reason.clear();
      est->reason = fmt::format(
          "inconsistent: only {:.0f}% of the {} observations of {} mapped into the area {} sees "
          "are "
          "matched, where {} detects people {:.0f}% of the time (need {:.0f}% of that)",
          100.0 * observed, visible, aligned.sensors[d.seen].id, aligned.sensors[d.seeing].id,
          aligned.sensors[d.seeing].id, 100.0 * expected, 100.0 * o.min_match_fraction_ratio);
      return;
    }
  }
}

// The observations of `from` at steps where `to` has no track at all, mapped into `to`'s coverage:
// visible and unmatched.
void CountUnpaired(const AlignedTracks& aligned, std::size_t from, std::size_t to,
                   const Pose2& to_from_from, const Coverage& coverage, VisibilityCounts* out) {
  std::size_t steps = 0;
  for (const GridTrack& t : aligned.sensors[to].tracks) {
    if (t.end_step() >= t.first_step) steps = std::max(steps, t.end_step());
  }
  for (const GridTrack& t : aligned.sensors[from].tracks) {
    if (t.end_step() >= t.first_step) steps = std::max(steps, t.end_step());
  }
  steps = std::min(steps, aligned.steps);
  std::vector<std::uint8_t> tracked(steps, 0);
  for (const GridTrack& t : aligned.sensors[to].tracks) {
    for (std::size_t k = t.first_step; k < std::min(t.end_step(), steps); ++k) tracked[k] = 1;
  }
  for (const GridTrack& t : aligned.sensors[from].tracks) {
    for (std::size_t k = t.first_step; k < std::min(t.end_step(), steps); ++k) {
      if (tracked[k] != 0) continue;
      const TrackSample& x = t.At(k);
      if (!Usable(x)) continue;
      const Eigen::Vector2d mapped = to_from_from * x.position_m;
      if (!coverage.Covered(mapped)) continue;
      ++out->visible[RangeBandOf(mapped.norm())];
    }
  }
}

// Cells of every sensor's coverage, built once per EstimateAllPairs.
std::vector<Coverage> Coverages(const AlignedTracks& aligned, double cell_m) {
  std::vector<Coverage> out;
  out.reserve(aligned.sensors.size());
  for (const SensorTracks& sensor : aligned.sensors) out.emplace_back(sensor, cell_m);
  return out;
}

// Everything of a pair but the negative evidence (JudgeVisibility), whose counts go into `diag`.
PairEstimate EstimateWithIntervals(const AlignedTracks& aligned, std::size_t r, std::size_t s,
                                   const std::vector<Interval>& all_intervals,
                                   const Coverage& coverage_r, const Coverage& coverage_s,
                                   const PairwiseOptions& o, PairDiagnostics& diag) {
  PairEstimate est;
  est.r = r;
  est.s = s;
  est.second_error = kInf;
  diag = {};
  const auto finish = [&](std::string reason) {
    est.reason = std::move(reason);
    est.accepted = est.reason.empty();
    if (!est.accepted) {
      est.weak = false;
      est.weak_reason.clear();
    }
    return est;
  };

  const auto& tracks_r = aligned.sensors[r].tracks;
  const auto& tracks_s = aligned.sensors[s].tracks;
  const double prior_var = PriorVariance(aligned);

  // Step 4: MSAC hypotheses (eq. 5) per simultaneous track pair (p, q). The paper runs MSAC per
  // interval and track pair; an interval ends whenever any track of either sensor appears or
  // vanishes, which with a few people cuts the common life of (p, q) into pieces of often less
  // than a second. The union of the consecutive intervals in which both p and q are visible -
  // their whole common span, both tracks being contiguous - is exactly as free of appearing and
  // vanishing objects for this pair and gives MSAC the longest baseline, once per pair.
  est.intervals = all_intervals.size();
  std::vector<std::pair<std::size_t, std::size_t>> track_pairs;
  for (const Interval& in : all_intervals) {
    for (std::size_t p : in.tracks_r) {
      for (std::size_t q : in.tracks_s) track_pairs.emplace_back(p, q);
    }
  }
  std::sort(track_pairs.begin(), track_pairs.end());
  track_pairs.erase(std::unique(track_pairs.begin(), track_pairs.end()), track_pairs.end());

  std::vector<Hypothesis> hypotheses;
  std::size_t tried = 0;
  for (const auto& [p, q] : track_pairs) {
    const GridTrack& tp = tracks_r[p];
    const GridTrack& tq = tracks_s[q];
    const std::size_t first = std::max(tp.first_step, tq.first_step);
    const std::size_t end = std::min(tp.end_step(), tq.end_step());
    if (end < first + o.intervals.min_steps) continue;
    ++tried;
    const std::uint64_t stream = MixSeed(MixSeed(MixSeed(o.seed, r * 1000003u + s), p), q);
    Hypothesis h;
    switch (Msac(tp, tq, first, end, o, stream, h)) {
      case MsacOutcome::kHypothesis:
        hypotheses.push_back(h);
        break;
      case MsacOutcome::kDegenerate:
        ++diag.degenerate_pairs;
        break;
      case MsacOutcome::kNone:
        break;
    }
  }
  est.hypotheses = hypotheses.size();
  if (tried == 0) return finish("no simultaneous tracks long enough for a hypothesis");
  if (hypotheses.empty()) {
    if (diag.degenerate_pairs == tried) {
      return finish("degenerate motion: the tracks barely move while both sensors see them");
    }
    return finish(fmt::format(
        "no hypothesis: none of {} simultaneous track pairs moves alike under a rigid transform",
        tried));
  }

  const PairData data = BuildPairData(aligned, r, s, all_intervals);
  diag.unusable_samples = data.unusable;
  const Eigen::Vector2d at = data.r_centroid;

  // Merge near-identical hypotheses; verify the best-supported ones.
  std::stable_sort(hypotheses.begin(), hypotheses.end(),
                   [](const Hypothesis& a, const Hypothesis& b) { return a.inliers > b.inliers; });
  std::vector<Cluster> clusters;
  const double cluster_yaw = DegToRad(o.cluster_yaw_deg);
  for (const Hypothesis& h : hypotheses) {
    auto it = std::find_if(clusters.begin(), clusters.end(), [&](const Cluster& c) {
      return Near(c.pose, h.pose, at, cluster_yaw, o.cluster_distance_m);
    });
    if (it == clusters.end()) {
      clusters.push_back({h.pose, h.inliers, kInf});
    } else {
      it->support += h.inliers;
    }
  }
  diag.clusters = clusters.size();
  std::stable_sort(clusters.begin(), clusters.end(),
                   [](const Cluster& a, const Cluster& b) { return a.support > b.support; });
  if (clusters.size() > o.max_verified_hypotheses) clusters.resize(o.max_verified_hypotheses);
  diag.verified = clusters.size();

  // Step 5: verification over all intervals (eqs. 6-8).
  for (Cluster& c : clusters) c.error = VerificationError(data, c.pose, o);
  const auto best_it =
      std::min_element(clusters.begin(), clusters.end(),
                       [](const Cluster& a, const Cluster& b) { return a.error < b.error; });
  const Cluster best = *best_it;
  est.best_error = best.error;
  const double distinct_yaw = DegToRad(o.distinct_yaw_deg);
  std::vector<const Cluster*> competitors;  // clearly different from the best, by E
  for (const Cluster& c : clusters) {
    if (!Near(c.pose, best.pose, at, distinct_yaw, o.distinct_distance_m)) {
      competitors.push_back(&c);
    }
  }
  std::sort(competitors.begin(), competitors.end(),
            [](const Cluster* a, const Cluster* b) { return a->error < b->error; });
  if (!competitors.empty()) {
    est.second_error = competitors.front()->error;
    diag.second_s_from_r = competitors.front()->pose;
  }
  diag.r_observations = VerifiedObservations(data, o);
  est.s_from_r = best.pose;
  diag.best_hypothesis = best.pose;

  // Least-squares refit over every associated simultaneous observation, re-associating until
  // the association settles (a few Gauss-Newton steps per round are enough to re-associate; the
  // last association gets a converged fit).
  Pose2 pose = best.pose;
  std::vector<std::pair<std::size_t, std::size_t>> pairs;
  RigidFit fit;
  for (std::size_t round = 0; round < o.refit_rounds; ++round) {
    auto next = Associate(data, pose, o.refit_gate_m);
    if (next.size() < 3) break;
    if (fit.ok && next == pairs) break;
    RigidFit f = FitPairs(data, next, o, prior_var, &fit, 3);
    if (!f.ok) break;
    fit = f;
    pairs = std::move(next);
    pose = fit.s_from_r;
  }
  if (fit.ok) {
    RigidFit f = FitPairs(data, pairs, o, prior_var, &fit, 15);
    if (f.ok) fit = f;
  }
  if (!fit.ok) {
    return finish(fmt::format(
        "too few matches: {} associated observations under the best hypothesis", pairs.size()));
  }
  est.s_from_r = fit.s_from_r;
  est.covariance = fit.covariance;
  est.matches = pairs.size();
  est.rms_m = fit.rms_m;
  est.mean_residual_m = fit.mean_residual_m;

  std::vector<Eigen::Vector2d> matched_r;
  matched_r.reserve(pairs.size());
  std::vector<std::uint8_t> r_matched(data.r.size(), 0), s_matched(data.s.size(), 0);
  for (const auto& [i, j] : pairs) {
    matched_r.push_back(data.r[i].c);
    r_matched[i] = 1;
    s_matched[j] = 1;
  }
  diag.match_spread_m = Spread(matched_r);
  diag.size_correction_m = fit.size_correction_m;
  diag.segments = fit.segments;

  // Negative evidence, counted both ways (judged by JudgeVisibility): observations of one sensor
  // mapped where the other demonstrably sees people, and whether they were matched, by the range
  // band of the seeing sensor.
  const Pose2 r_from_s = fit.s_from_r.inverse();
  const auto count = [](const std::vector<Obs>& obs, const std::vector<std::uint8_t>& matched,
                        const Pose2& to_other, const Coverage& coverage, VisibilityCounts* out) {
    for (std::size_t i = 0; i < obs.size(); ++i) {
      const Eigen::Vector2d mapped = to_other * obs[i].raw;
      if (matched[i] == 0 && !coverage.Covered(mapped)) continue;
      const std::size_t band = RangeBandOf(mapped.norm());
      ++out->visible[band];
      if (matched[i] != 0) ++out->matched[band];
    }
  };
  count(data.r, r_matched, fit.s_from_r, coverage_s, &diag.r_in_s);
  count(data.s, s_matched, r_from_s, coverage_r, &diag.s_in_r);
  // And the steps at which the other sensor tracks nobody at all (a miss counts as a miss).
  CountUnpaired(aligned, r, s, fit.s_from_r, coverage_s, &diag.r_in_s);
  CountUnpaired(aligned, s, r, r_from_s, coverage_r, &diag.s_in_r);

  if (est.matches < o.min_matches) {
    return finish(fmt::format("too few matches: {} associated observations (need {})", est.matches,
                              o.min_matches));
  }
  if (est.rms_m > o.max_rms_m) {
    return finish(fmt::format("residual too large: rms {:.3f} m over {} matches (max {:.3f} m)",
                              est.rms_m, est.matches, o.max_rms_m));
  }
  // Ambiguity: does a clearly different hypothesis explain a comparable share of the data by
  // other associations? A hypothesis a few degrees off the right one re-uses the right one's
  // associations with larger d_S (in a small crowded room it still scores well under eq. 8); it
  // is not an alternative. Only the evidence it draws from associations of its own counts.
  const Explanation best_explained = Explain(data, fit.s_from_r, o);
  diag.best_gain = 0.0;
  for (std::size_t i = 0; i < best_explained.s_obs.size(); ++i) {
    if (best_explained.s_obs[i] >= 0) diag.best_gain += o.verify_gate - best_explained.d[i];
  }
  diag.second_gain = 0.0;
  std::size_t examined = 0;
  for (const Cluster* c : competitors) {
    if (examined++ == kCompetitorsExamined) break;
    if (Near(c->pose, fit.s_from_r, at, distinct_yaw, o.distinct_distance_m)) continue;
    const Explanation other = Explain(data, c->pose, o);
    double own = 0.0;
    for (std::size_t i = 0; i < other.s_obs.size(); ++i) {
      if (other.s_obs[i] >= 0 && other.s_obs[i] != best_explained.s_obs[i]) {
        own += o.verify_gate - other.d[i];
      }
    }
    if (own > diag.second_gain) {
      diag.second_gain = own;
      diag.second_s_from_r = c->pose;
    }
  }
  if (diag.second_gain > o.max_ambiguity_ratio * diag.best_gain) {
    return finish(fmt::format(
        "ambiguous: a different hypothesis (yaw {:.1f} deg apart) explains {:.0f}% as much by "
        "other associations",
        RadToDeg(std::abs(AngleDiff(diag.second_s_from_r->yaw_rad, fit.s_from_r.yaw_rad))),
        diag.best_gain > 0.0 ? 100.0 * diag.second_gain / diag.best_gain : 100.0));
  }
  // Information: a pose the honest covariance leaves uncertain is a candidate only.
  const double yaw_sigma_deg = RadToDeg(std::sqrt(std::max(0.0, est.covariance(2, 2))));
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(
      Eigen::Matrix2d(est.covariance.topLeftCorner<2, 2>()));
  const double translation_sigma_m = std::sqrt(std::max(0.0, eig.eigenvalues().maxCoeff()));
  if (!(yaw_sigma_deg <= o.max_yaw_sigma_deg) ||
      !(translation_sigma_m <= o.max_translation_sigma_m)) {
    est.weak = true;
    est.weak_reason = fmt::format(
        "weak: sigma {:.2f} deg / {:.3f} m from {} matches of {} track pairs spread {:.2f} m "
        "(strong: at most {:.2f} deg / {:.3f} m)",
        yaw_sigma_deg, translation_sigma_m, est.matches, fit.segments, diag.match_spread_m,
        o.max_yaw_sigma_deg, o.max_translation_sigma_m);
  }
  return finish("");
}

// Per sensor and range band, the best two detection probabilities measured by its pairs (as the
// seeing sensor), with the pair each came from, so that a pair can be judged against its
// partners' measurements only.
struct BandBest {
  double p1 = -1.0, p2 = -1.0;
  std::size_t pair1 = static_cast<std::size_t>(-1);
};

void AddMeasurement(const VisibilityCounts& counts, std::size_t pair,
                    std::array<BandBest, kRangeBands>* bands) {
  for (std::size_t b = 0; b < kRangeBands; ++b) {
    if (counts.visible[b] < kMinBandObservations) continue;
    const double p =
        static_cast<double>(counts.matched[b]) / static_cast<double>(counts.visible[b]);
    BandBest& x = (*bands)[b];
    if (p > x.p1) {
      x.p2 = x.p1;
      x.p1 = p;
      x.pair1 = pair;
    } else if (p > x.p2) {
      x.p2 = p;
    }
  }
}

Detection WithoutPair(const std::array<BandBest, kRangeBands>& bands, std::size_t pair) {
  Detection d;
  for (std::size_t b = 0; b < kRangeBands; ++b)
    d[b] = bands[b].pair1 == pair ? bands[b].p2 : bands[b].p1;
  return d;
}

}  // namespace

Coverage::Coverage(const SensorTracks& sensor, double cell_m) : cell_m_(cell_m) {
  Eigen::Vector2d lo(kInf, kInf), hi(-kInf, -kInf);
  for (const GridTrack& t : sensor.tracks) {
    for (const TrackSample& x : t.samples) {
      if (!Usable(x)) continue;
      lo = lo.cwiseMin(x.position_m);
      hi = hi.cwiseMax(x.position_m);
    }
  }
  if (!(lo.x() <= hi.x())) return;
  // Bounded memory whatever the data: coarser cells for a huge extent.
  constexpr double kMaxCells = 4e6;
  const Eigen::Vector2d extent = hi - lo;
  while ((extent.x() / cell_m_ + 3.0) * (extent.y() / cell_m_ + 3.0) > kMaxCells) cell_m_ *= 2.0;
  origin_ = lo - Eigen::Vector2d::Constant(cell_m_);
  nx_ = static_cast<long>(extent.x() / cell_m_) + 3;
  ny_ = static_cast<long>(extent.y() / cell_m_) + 3;
  cells_.assign(static_cast<std::size_t>(nx_ * ny_), 0);
  for (const GridTrack& t : sensor.tracks) {
    for (const TrackSample& x : t.samples) {
      if (!Usable(x)) continue;
      const long cx = static_cast<long>((x.position_m.x() - origin_.x()) / cell_m_);
      const long cy = static_cast<long>((x.position_m.y() - origin_.y()) / cell_m_);
      for (long dy = -1; dy <= 1; ++dy) {
        for (long dx = -1; dx <= 1; ++dx) {
          const long u = cx + dx, v = cy + dy;
          if (u >= 0 && u < nx_ && v >= 0 && v < ny_) {
            cells_[static_cast<std::size_t>(v * nx_ + u)] = 1;
          }
        }
      }
    }
  }
}

bool Coverage::Covered(const Eigen::Vector2d& p) const {
  if (cells_.empty() || !p.allFinite()) return false;
  const double fx = (p.x() - origin_.x()) / cell_m_, fy = (p.y() - origin_.y()) / cell_m_;
  if (!(fx >= 0.0 && fy >= 0.0 && fx < static_cast<double>(nx_) && fy < static_cast<double>(ny_))) {
    return false;
  }
  return cells_[static_cast<std::size_t>(static_cast<long>(fy) * nx_ + static_cast<long>(fx))] != 0;
}

std::size_t RangeBandOf(double range_m) {
  static constexpr double kEdges[kRangeBands - 1] = {5.0, 10.0, 15.0, 20.0, 30.0, 50.0};
  std::size_t b = 0;
  while (b < kRangeBands - 1 && !(range_m < kEdges[b])) ++b;
  return b;
}

PairEstimate EstimatePair(const AlignedTracks& aligned, std::size_t r, std::size_t s,
                          const PairwiseOptions& options, PairDiagnostics* diagnostics) {
  if (Validate(options)) std::abort();
  PairDiagnostics diag;
  const auto fail = [&](const char* reason, std::size_t intervals) {
    PairEstimate est;
    est.r = r;
    est.s = s;
    est.second_error = kInf;
    est.intervals = intervals;
    est.reason = reason;
    if (diagnostics != nullptr) *diagnostics = {};
    return est;
  };
  if (r == s || r >= aligned.sensors.size() || s >= aligned.sensors.size()) {
    return fail("invalid sensor pair", 0);
  }
  const auto all = PairIntervals(aligned, r, s, IntervalOptions{1});
  if (all.empty()) return fail("no simultaneous tracks", 0);
  const Coverage coverage_r(aligned.sensors[r], options.coverage_cell_m);
  const Coverage coverage_s(aligned.sensors[s], options.coverage_cell_m);
  PairEstimate est =
      EstimateWithIntervals(aligned, r, s, all, coverage_r, coverage_s, options, diag);
  if (est.accepted) {
    Detection unknown;
    unknown.fill(-1.0);
    JudgeVisibility(aligned, diag, unknown, unknown, options, &est);
  }
  if (diagnostics != nullptr) *diagnostics = diag;
  return est;
}

std::vector<PairEstimate> EstimateAllPairs(const AlignedTracks& aligned,
                                           const PairwiseOptions& options) {
  if (Validate(options)) std::abort();
  const std::size_t n = aligned.sensors.size();
  const std::vector<Coverage> coverage = Coverages(aligned, options.coverage_cell_m);
  std::vector<PairEstimate> out;
  std::vector<PairDiagnostics> diags;
  for (std::size_t r = 0; r < n; ++r) {
    for (std::size_t s = r + 1; s < n; ++s) {
      const auto all = PairIntervals(aligned, r, s, IntervalOptions{1});
      if (!HasLongTrackPair(aligned, r, s, all, options.intervals.min_steps)) continue;
      diags.emplace_back();
      out.push_back(EstimateWithIntervals(aligned, r, s, all, coverage[r], coverage[s], options,
                                          diags.back()));
    }
  }
  // Each sensor's detection probability by range, measured by the pairs that passed the rest.
  std::vector<std::array<BandBest, kRangeBands>> detection(n);
  for (std::size_t k = 0; k < out.size(); ++k) {
    if (!out[k].accepted) continue;
    AddMeasurement(diags[k].r_in_s, k, &detection[out[k].s]);
    AddMeasurement(diags[k].s_in_r, k, &detection[out[k].r]);
  }
  for (std::size_t k = 0; k < out.size(); ++k) {
    if (!out[k].accepted) continue;
    JudgeVisibility(aligned, diags[k], WithoutPair(detection[out[k].s], k),
                    WithoutPair(detection[out[k].r], k), options, &out[k]);
  }
  return out;
}

std::vector<Match> AssociatePair(const AlignedTracks& aligned, std::size_t r, std::size_t s,
                                 const Pose2& s_from_r, double gate_m) {
  std::vector<Match> out;
  if (r == s || r >= aligned.sensors.size() || s >= aligned.sensors.size()) return out;
  const PairData data =
      BuildPairData(aligned, r, s, PairIntervals(aligned, r, s, IntervalOptions{1}));
  const auto pairs = Associate(data, s_from_r, gate_m);
  out.reserve(pairs.size());
  std::size_t k = 0;
  for (const auto& [i, j] : pairs) {
    // pairs are grouped by step in step order; find the step of observation i.
    while (data.steps[k].r_end <= i) ++k;
    out.push_back({data.steps[k].step, data.r[i].track, data.s[j].track});
  }
  return out;
}

RigidFit FitMatches(const AlignedTracks& aligned, std::size_t r, std::size_t s,
                    const std::vector<Match>& matches, const PairwiseOptions& options) {
  if (Validate(options)) std::abort();
  if (r == s || r >= aligned.sensors.size() || s >= aligned.sensors.size()) return {};
  const auto& tr = aligned.sensors[r].tracks;
  const auto& ts = aligned.sensors[s].tracks;
  const double prior_var = PriorVariance(aligned);
  FitInput in;
  SegmentIds segments;
  for (const Match& m : matches) {
    if (m.track_r >= tr.size() || m.track_s >= ts.size()) continue;
    if (!tr[m.track_r].Covers(m.step) || !ts[m.track_s].Covers(m.step)) continue;
    const TrackSample& a = tr[m.track_r].At(m.step);
    const TrackSample& b = ts[m.track_s].At(m.step);
    if (!Usable(a) || !Usable(b)) continue;
    in.Add(MakeObs(a, m.track_r, prior_var), MakeObs(b, m.track_s, prior_var),
           segments.Of(m.track_r, m.track_s));
  }
  return Fit(in, options, prior_var);
}

}  // namespace lrfnet::calib
