// L1 rotation averaging at 10-200 sensors: the node-angle form (production) against the full
// L1MC formulation of Quenzel et al.'s Algorithm 1 (all directed pairs, all triangles) solved by
// the same kind of IRLS, and the spectral relaxation [21]. Graphs: sensors on a ring, each linked
// to its k nearest on either side, and random geometric graphs (mean degree ~8); a fraction of
// the edges replaced by outliers (uniformly random yaw), inliers with Gaussian noise. Prints a
// markdown table and writes it to OUT.
//
//   rotation_averaging_benchmark [--out FILE] [--reps N] [--max-full N] [--seed S]
//   (FILE: results/rotation_averaging_benchmark.md; --max-full: largest n for which the full
//   formulation is solved, default 40)

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "central_daemon/calibration/l1mc_full.h"
#include "central_daemon/calibration/pose_graph.h"
#include "central_daemon/calibration/rotation_averaging.h"
#include "central_daemon/calibration/spectral.h"
#include "central_daemon/calibration/translations.h"

namespace {

using Clock = std::chrono::steady_clock;
using lrfnet::calib::RelativeMeasurement;
namespace common = lrfnet::common;

double Seconds(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double>(b - a).count();
}

struct Graph {
  std::size_t n = 0;
  std::vector<double> truth;
  std::vector<Eigen::Vector2d> position_m;  // for the whole global stage
  std::vector<RelativeMeasurement> m;
  std::vector<bool> outlier;
};

enum class Topology { kRing, kGeometric };

Graph MakeGraph(std::size_t n, Topology topology, double outlier_fraction, double noise_deg,
                unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::normal_distribution<double> noise(0.0, common::DegToRad(noise_deg));
  Graph g;
  g.n = n;
  for (std::size_t v = 0; v < n; ++v)
    g.truth.push_back(common::NormalizeAngle(2 * common::kPi * u(rng)));
  // Positions: on a ring 10 m apart, or spread over a square with ~10 m between neighbours.
  const double side_m = 10.0 * std::sqrt(static_cast<double>(n));
  for (std::size_t v = 0; v < n; ++v) {
    const double a = 2.0 * common::kPi * static_cast<double>(v) / static_cast<double>(n);
    const double ring_m = 10.0 * static_cast<double>(n) / (2.0 * common::kPi);
    g.position_m.push_back(topology == Topology::kRing
                               ? Eigen::Vector2d(ring_m * std::cos(a), ring_m * std::sin(a))
                               : Eigen::Vector2d(side_m * u(rng), side_m * u(rng)));
  }
  std::vector<std::pair<std::size_t, std::size_t>> pairs;
  if (topology == Topology::kRing) {
    const std::size_t k = 3;
    for (std::size_t i = 0; i < n; ++i) {
      for (std::size_t d = 1; d <= k && d < n; ++d) {
        const std::size_t j = (i + d) % n;
        if (n <= 2 * k && j < i) continue;  // small rings: each pair once
        pairs.emplace_back(i, j);
      }
    }
  } else {
    std::vector<double> x(n), y(n);
    for (std::size_t v = 0; v < n; ++v) {
      x[v] = u(rng);
      y[v] = u(rng);
    }
    const double radius =
        std::sqrt(8.0 / (common::kPi * static_cast<double>(n)));  // mean degree ~8
    for (std::size_t i = 0; i < n; ++i) {
      for (std::size_t j = i + 1; j < n; ++j) {
        if (std::hypot(x[i] - x[j], y[i] - y[j]) < radius || j == i + 1) pairs.emplace_back(i, j);
      }
    }
  }
  std::shuffle(pairs.begin(), pairs.end(), rng);
  const auto outliers =
      static_cast<std::size_t>(std::round(outlier_fraction * static_cast<double>(pairs.size())));
  for (std::size_t e = 0; e < pairs.size(); ++e) {
    RelativeMeasurement m;
    m.r = pairs[e].first;
    m.s = pairs[e].second;
    const bool bad = e < outliers;
    const lrfnet::calib::Pose2 world_from_r{g.position_m[m.r].x(), g.position_m[m.r].y(),
                                            g.truth[m.r]};
    const lrfnet::calib::Pose2 world_from_s{g.position_m[m.s].x(), g.position_m[m.s].y(),
                                            g.truth[m.s]};
    m.s_from_r = world_from_s.inverse() * world_from_r;
    std::normal_distribution<double> noise_m(0.0, 0.02);
    m.s_from_r.x_m += bad ? 5.0 * (u(rng) - 0.5) : noise_m(rng);
    m.s_from_r.y_m += bad ? 5.0 * (u(rng) - 0.5) : noise_m(rng);
    m.s_from_r.yaw_rad = bad ? common::NormalizeAngle(2 * common::kPi * u(rng))
                             : common::NormalizeAngle(g.truth[m.r] - g.truth[m.s] + noise(rng));
    m.covariance = Eigen::Vector3d(4e-4, 4e-4, std::pow(common::DegToRad(noise_deg), 2)).asDiagonal();
    g.m.push_back(m);
    g.outlier.push_back(bad);
  }
  return g;
}

// Nodes whose yaw (relative to node 0) is off by more than 3°.
int BadNodes(const Graph& g, const std::vector<double>& yaw) {
  int bad = 0;
  for (std::size_t v = 0; v < g.n; ++v) {
    if (std::abs(common::AngleDiff(yaw[v] - yaw[0], g.truth[v] - g.truth[0])) >
        common::DegToRad(3.0))
      ++bad;
  }
  return bad;
}

// Median yaw error over the nodes, degrees.
double MedianError(const Graph& g, const std::vector<double>& yaw) {
  std::vector<double> e;
  for (std::size_t v = 1; v < g.n; ++v) {
    e.push_back(std::abs(common::AngleDiff(yaw[v] - yaw[0], g.truth[v] - g.truth[0])));
  }
  std::sort(e.begin(), e.end());
  return common::RadToDeg(e[e.size() / 2]);
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  std::string out = "results/rotation_averaging_benchmark.md";
  int reps = 5;
  std::size_t max_full = 40;
  unsigned seed = 1;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--out" && i + 1 < argc) {
      out = argv[++i];
    } else if (a == "--reps" && i + 1 < argc) {
      reps = std::stoi(argv[++i]);
    } else if (a == "--max-full" && i + 1 < argc) {
      max_full = std::stoul(argv[++i]);
    } else if (a == "--seed" && i + 1 < argc) {
      seed = static_cast<unsigned>(std::stoul(argv[++i]));
    } else {
      std::fprintf(stderr,
                   "usage: rotation_averaging_benchmark [--out FILE] [--reps N] [--max-full N] "
                   "[--seed S]\n");
      return 2;
    }
  }
  if (reps < 1 || reps > 1000) {
    std::fprintf(stderr, "rotation_averaging_benchmark: --reps must be 1..1000\n");
    return 2;
  }

  const double noise_deg = 0.5;
  char header[2048];
  std::snprintf(
      header, sizeof(header),
      "# L1 rotation averaging\n\n"
      "Node-angle form (production: IRLS with sparse LDLT + exact network-simplex finish, three "
      "starts) against the paper's full L1MC formulation (unknowns for all directed pairs; "
      "measurement, inverse and transitivity rows for all triangles, every row weighted 1; IRLS "
      "with sparse LDLT to a relative duality gap of 1e-6, an exact vertex finish or 100 "
      "iterations) and the spectral "
      "relaxation [21]. \"Global stage\": what the calibration runs after the pairs (node form, "
      "least-squares translations on its inliers, then the joint weighted least squares of "
      "rotations and translations, pose_graph.h), on the same graphs with full relative poses "
      "(2 cm, outliers also up to 2.5 m off). "
      "Inlier noise %.1f°, outliers uniformly random yaws. Times: median of %d "
      "runs on one core (full form: building A included, one run from n = 40; solved up to n = "
      "%zu; \"exact\": its exact vertex finish succeeded, else the relative duality gap reached). "
      "Bad nodes: yaw off by more than 3°; \"from truth\" is the node form started at the true "
      "yaws (what L1 itself allows: where it has bad nodes the L1 optimum is not the truth, the "
      "outliers locally outweigh the inliers, or it ties). Outlier flags: true outliers "
      "(residual against the truth > 5°) not flagged / inliers flagged. L1 cost: the wrapped L1 "
      "cost reached by the node form and from the truth (lower from the truth: the starts missed "
      "the better local minimum).\n\n"
      "| graph | n | edges | outliers | node form ms | global stage ms | spectral ms | full form "
      "rows / unknowns / nonzeros | full IRLS ms | bad nodes: node / from truth / spectral / full "
      "| median err °: node / spectral | L1 cost: node / from truth | certified | outlier flags "
      "missed / false |\n"
      "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
      noise_deg, reps, max_full);
  std::string table = header;
  std::printf("%s", table.c_str());
  std::fflush(stdout);
  for (Topology topology : {Topology::kRing, Topology::kGeometric}) {
    for (std::size_t n : {10u, 20u, 40u, 100u, 200u}) {
      for (double fraction : {0.2, 0.4}) {
        const Graph g =
            MakeGraph(n, topology, fraction, noise_deg, seed * 1000 + static_cast<unsigned>(n));
        lrfnet::calib::RotationAveragingOptions options;
        std::vector<double> node_s, spectral_s;
        lrfnet::calib::RotationAveragingResult node, spectral;
        for (int r = 0; r < reps; ++r) {
          auto t0 = Clock::now();
          node = lrfnet::calib::AverageRotationsL1(n, 0, g.m, options);
          node_s.push_back(Seconds(t0, Clock::now()));
          t0 = Clock::now();
          spectral = lrfnet::calib::AverageRotationsSpectral(n, 0, g.m, false);
          spectral_s.push_back(Seconds(t0, Clock::now()));
        }
        // The whole global stage as the pipeline runs it on the strong pairs: L1 rotations, their
        // inliers' least-squares translations, then the joint weighted least squares.
        std::vector<double> global_s;
        bool global_ok = true;
        for (int r = 0; r < reps; ++r) {
          const auto t0 = Clock::now();
          const auto rotations = lrfnet::calib::AverageRotationsL1(n, 0, g.m, options);
          std::vector<bool> use(g.m.size(), true);
          for (std::size_t e = 0; e < g.m.size() && e < rotations.inlier.size(); ++e) {
            use[e] = rotations.inlier[e];
          }
          lrfnet::calib::TranslationOptions translation_options;
          translation_options.use_covariances = true;
          const auto translations = lrfnet::calib::SolveTranslations(
              n, 0, rotations.yaw_rad, g.m, use, translation_options);
          std::vector<lrfnet::calib::Pose2> initial(n);
          for (std::size_t v = 0; v < n && translations.ok; ++v) {
            initial[v] = {translations.position_m[v].x(), translations.position_m[v].y(),
                          rotations.yaw_rad[v]};
          }
          const auto wls = lrfnet::calib::SolvePoseGraph(n, 0, g.m, use, initial);
          global_s.push_back(Seconds(t0, Clock::now()));
          global_ok = global_ok && rotations.ok && translations.ok && wls.ok;
        }
        lrfnet::calib::RotationAveragingOptions from_truth = options;
        from_truth.initial_yaw_rad = g.truth;
        const auto truth_run = lrfnet::calib::AverageRotationsL1(n, 0, g.m, from_truth);
        if (!node.ok || !spectral.ok || !truth_run.ok) {
          std::fprintf(stderr, "failed: %s %s\n", node.error.c_str(), spectral.error.c_str());
          return 1;
        }
        std::size_t missed = 0, false_alarm = 0, outliers = 0;
        for (std::size_t e = 0; e < g.m.size(); ++e) {
          outliers += g.outlier[e] ? 1 : 0;
          // An outlier whose random yaw happens to agree with the truth is not an error.
          const double true_residual = std::abs(
              common::AngleDiff(g.truth[g.m[e].r] - g.truth[g.m[e].s], g.m[e].s_from_r.yaw_rad));
          const bool really_bad = true_residual > common::DegToRad(options.outlier_threshold_deg);
          if (really_bad && node.inlier[e]) ++missed;
          if (!really_bad && !node.inlier[e]) ++false_alarm;
        }
        const auto size = lrfnet::calib::L1mcFullSizeOf(n, g.m.size());
        std::string full_ms = "not run", full_bad = "-";
        if (n <= max_full) {
          std::vector<double> full_s;
          lrfnet::calib::L1IrlsResult full;
          lrfnet::calib::L1mcFull problem;
          for (int r = 0; r < (n >= 40 ? 1 : std::min(reps, 3)); ++r) {
            const auto t0 = Clock::now();
            problem = lrfnet::calib::BuildL1mcFull(
                n, g.m, lrfnet::calib::SpanningTreeYaws(n, 0, g.m), false);
            lrfnet::calib::L1IrlsOptions irls;
            irls.tolerance = 1e-6;
            full = lrfnet::calib::SolveL1Irls(problem.a, problem.b, problem.weight, problem.start,
                                              irls);
            full_s.push_back(Seconds(t0, Clock::now()));
          }
          char buf[96];
          if (full.exact) {
            std::snprintf(buf, sizeof(buf), "%.1f (%d it., exact)", Median(full_s) * 1e3,
                          full.iterations);
          } else {
            std::snprintf(buf, sizeof(buf), "%.1f (%d it., gap %.0e)", Median(full_s) * 1e3,
                          full.iterations, (full.cost - full.lower_bound) / full.cost);
          }
          full_ms = full.ok ? buf : "failed";
          full_bad =
              full.ok ? std::to_string(BadNodes(g, lrfnet::calib::YawsFromL1mc(problem, full.x, 0)))
                      : "-";
        }
        char global_ms[32];
        std::snprintf(global_ms, sizeof(global_ms), global_ok ? "%.2f" : "failed",
                      Median(global_s) * 1e3);
        char row[512];
        std::snprintf(
            row, sizeof(row),
            "| %s | %zu | %zu | %.0f %% | %.2f | %s | %.2f | %zu / %zu / %zu | %s | %d / %d / %d / "
            "%s | %.2f / %.2f | %.2f / %.2f | %s | %zu / %zu |\n",
            topology == Topology::kRing ? "ring, k = 3" : "geometric", n, g.m.size(),
            100.0 * static_cast<double>(outliers) / static_cast<double>(g.m.size()),
            Median(node_s) * 1e3, global_ms, Median(spectral_s) * 1e3, size.rows, size.unknowns, size.nonzeros,
            full_ms.c_str(), BadNodes(g, node.yaw_rad), BadNodes(g, truth_run.yaw_rad),
            BadNodes(g, spectral.yaw_rad), full_bad.c_str(), MedianError(g, node.yaw_rad),
            MedianError(g, spectral.yaw_rad), node.l1_cost, truth_run.l1_cost,
            node.certified ? "yes" : "no", missed, false_alarm);
        std::printf("%s", row);
        std::fflush(stdout);
        table += row;
      }
    }
  }
  table +=
      "\nThe full formulation grows as n^3 (161,700 triangles at n = 100); its IRLS factorises a "
      "normal matrix over n (n - 1) unknowns in which every pair is coupled to ~4n others, so it "
      "is run only up to --max-full. Its soft constraint rows and the paper's per-triangle 2π "
      "normalisation make it differ from the node form where outliers are present (see "
      "l1mc_full_test.cc).\n";
  const auto parent = std::filesystem::path(out).parent_path();
  if (!parent.empty()) std::filesystem::create_directories(parent);
  std::ofstream(out) << table;
  std::printf("\nwritten to %s\n", out.c_str());
  return 0;
}
