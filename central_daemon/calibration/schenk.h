#pragma once
// Baseline: Schenk et al., "Automatic Calibration of a Stationary Network of Laser Range Finders by
// Matching Movement Trajectories" (IROS 2012; papers/001). Section numbers and equations below are
// that paper's.
//
//   III-B  track association: every track of sensor r is paired with every track of sensor s, both
//          are trimmed to their common time steps, r's points are aligned onto s's by the SVD
//          (least-squares) registration of Besl-McKay (eq. 1), and the pair is associated when the
//          mean Euclidean distance after the alignment (eq. 2) is below 20 cm.
//   III-C  pairing sensors: all associated pairs of (r, s) are joined into two virtual tracks
//          (eq. 3) and aligned the same way; this gives the constraint s_from_r, its mean distance
//          d and the weight w = N / d, N the number of samples of the virtual track (eq. 4).
//   III-D  greedy placement from the reference by descending weight (eq. 5).
//   III-E  mass-spring relaxation (Duckett et al.) over every constraint (eqs. 6-10).
//   III-F  ICP on the background points that only pairs points close to each other.
//
// Readings where the paper is not explicit (papers/000 remarks that parts of the relaxation are
// unclear); each is the plainest one we found, and the tests pin it down:
//  - Placement (III-D): the paper puts one sensor of the heaviest pair at the origin; we put the
//    given reference there and then repeatedly place the unplaced sensor of the heaviest edge that
//    has exactly one placed end (Prim's order). This builds the maximum-weight spanning tree, which
//    does not depend on the root, so the tree (not the later steps, which hold the reference
//    fixed) is the paper's whichever sensor is the reference.
//  - Relaxation node weights (eqs. 7-8): the reference is held fixed with infinite weight (so
//    v = w_mn for its neighbours); every other sensor starts with the weight eq. 7 gives along its
//    placement edge. Updates are simultaneous (Jacobi): all estimates of eq. 6 use the poses of the
//    previous iteration ("after calculating all position estimates ... for all LRF").
//  - Eq. 10 as printed adds the constraint's relative *orientation* to φ and compares it with the
//    world bearing to the neighbour; that is not satisfied even by noise-free data. We read φ̌_{n,m}
//    there as the bearing of n in m's frame, atan2(y̌_{n,m}, x̌_{n,m}) of the constraint's
//    translation, so eq. 10 turns m until its constraints point at where its neighbours now are.
//    `atan` is taken as atan2 and the sum of absolute wrapped differences is minimised exactly (a
//    circular median; unweighted as printed; a tie between two neighbours takes the middle of the
//    optimal arc). Neighbours closer than `relaxation_min_bearing_distance_m` give no bearing.
//    Every iteration runs eqs. 6-9 for all sensors and then eq. 10 for all sensors.
//  - ICP (III-F): after relaxation, each placed sensor except the reference, in placement order,
//    is aligned (point-to-point, SVD as in eq. 1) onto the background points of the reference and
//    of the sensors aligned before it (a map growing from the reference: no sensor is pulled
//    towards one whose pose the ICP has yet to correct); a point takes part only when its nearest
//    map point is closer than `icp_max_correspondence_m`. The paper applies ICP unconditionally; we
//    only leave a sensor as it is when it has fewer than `icp_min_correspondences` close points
//    (nothing to align on). `icp_growing_map = false` aligns onto all other placed sensors
//    instead, `icp_sweeps > 1` repeats the pass (later passes onto all others); neither is the
//    default, both exist for comparison.
// Guards not in the paper (documented defaults, 0 disables where noted): a minimum number of
// common samples per track pair, a minimum spatial extent of a track pair (a track that stays on
// one spot carries no rotation and matches anything under 20 cm), and a floor on d in w = N / d.
//
// Frames: positions of AlignedTracks are in each sensor's frame; a constraint between r and s is
// s_from_r (maps r coordinates into s, as in types.h); world_from_r = world_from_s * s_from_r. The
// reference sensor is the world frame. Background beams: angle = first_angle_rad + i *
// angle_step_rad in the sensor frame (x forward, counter-clockwise), ranges_mm 0 = no return.
//
// Pure functions; no state, no logging; safe to call from several threads on different data.

#include <Eigen/Core>
#include <cstddef>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "central_daemon/calibration/types.h"
#include "common/geometry.h"

namespace lrfnet::calib {

struct SchenkOptions {
  // III-B: a track pair is associated when its mean distance after alignment (eq. 2) is below this.
  double association_threshold_m = 0.2;
  // Track pairs with fewer common time steps are not compared (not in the paper; 20 = 1 s on
  // the default 0.05 s grid).
  std::size_t min_common_samples = 20;
  // Track pairs whose trimmed points (of either sensor) have an RMS distance to their centroid
  // below this are not compared: no rotation information (not in the paper; 0 disables).
  double min_track_extent_m = 0.3;
  // Floor on d in w = N / d (eq. 4), so that noise-free data gives finite weights.
  double min_mean_distance_m = 1e-3;

  // III-E: relaxation iterations (0 = placement only), step applied to every update (1 = the
  // paper's full update, < 1 damps), and convergence: stop when no position moved more than
  // relaxation_tolerance_m and no heading more than relaxation_tolerance_rad in one iteration.
  int relaxation_iterations = 200;
  double relaxation_step = 1.0;
  double relaxation_tolerance_m = 1e-7;
  double relaxation_tolerance_rad = 1e-9;
  // Eq. 10: neighbours closer than this give no bearing.
  double relaxation_min_bearing_distance_m = 0.05;

  // III-F: close-points-only ICP on the background snapshots.
  bool use_icp = true;
  double icp_max_correspondence_m = 0.3;  // "only points which are close to each other"
  int icp_iterations = 30;
  std::size_t icp_min_correspondences = 20;
  double icp_tolerance_m = 1e-5;    // stop when one step moves less than this ...
  double icp_tolerance_rad = 1e-6;  // ... and turns less than this
  int icp_sweeps = 1;               // passes over all sensors (see the header comment)
  bool icp_growing_map = true;      // first pass onto the map grown from the reference
};

std::optional<std::string> Validate(const SchenkOptions& options);

// One associated track pair of an edge (III-B).
struct SchenkAssociation {
  std::size_t track_r = 0;  // index into AlignedTracks::sensors[r].tracks
  std::size_t track_s = 0;  // index into AlignedTracks::sensors[s].tracks
  std::size_t samples = 0;  // common time steps used
  double d_m = 0.0;         // mean distance after its own alignment (eq. 2)
};

// A sensor pair that had at least one comparable track pair. n == 0: none was associated, so there
// is no constraint (weight 0, never used).
struct SchenkEdge {
  std::size_t r = 0, s = 0;  // sensor indices, r < s
  Pose2 s_from_r;            // the constraint (III-C), valid when n > 0
  std::size_t n = 0;         // samples of the virtual track (N of eq. 4)
  double d_m = 0.0;          // mean distance of the virtual tracks after alignment (eq. 2)
  double weight = 0.0;       // w = N / max(d, min_mean_distance_m) (eq. 4)
  bool used = false;         // a constraint between two placed sensors (enters the relaxation)
  bool placement = false;    // the edge that placed one of its sensors (III-D)
  std::size_t compared = 0;  // track pairs compared
  std::vector<SchenkAssociation> associations;  // the pairs below the threshold
};

struct SchenkIcpReport {
  bool applied = false;                 // the pose was changed by the ICP
  std::size_t correspondences = 0;      // close pairs in the last iteration
  double mean_distance_before_m = 0.0;  // over the close pairs of the first iteration
  double mean_distance_after_m = 0.0;   // over the close pairs of the last iteration
  int iterations = 0;                   // ICP steps taken (over all sweeps)
};

struct SchenkResult {
  bool ok = false;      // every sensor placed (and the input and options valid)
  std::string message;  // why not: invalid input, or which sensors could not be placed and why
  std::vector<Pose2> world_from_sensor;  // reference at identity; identity for unplaced sensors
  std::vector<bool> placed;
  std::vector<SchenkEdge> edges;             // pairwise estimates with their N, d, weight
  std::vector<std::size_t> placement_order;  // sensor indices, reference first
  std::vector<double> node_weight;           // relaxation weights w_m (eq. 8); reference: +inf
  int relaxation_iterations = 0;             // iterations run
  std::vector<SchenkIcpReport> icp;          // per sensor (empty when ICP is off)
};

// Pose convention: world_from_r = world_from_s * s_from_r (common/geometry.h: a_from_b maps b
// coordinates to a). Data-caused failures (bad reference, no constraints) are reported in the
// result, never thrown.
SchenkResult CalibrateSchenk(const AlignedTracks& tracks, std::size_t reference,
                             const SchenkOptions& options);

// ---------------------------------------------------------------------------------------------
// The steps, exposed for tests and reports.

// Eqs. 1-2: the rigid transform that maps the points of r onto the corresponding points of s with
// the least sum of squared distances (the SVD solution of Besl-McKay), and the mean Euclidean
// distance after it. ok = false for fewer than 2 points or unequal sizes.
struct PointSetAlignment {
  bool ok = false;
  Pose2 s_from_r;
  double mean_distance_m = 0.0;
};
PointSetAlignment AlignPointSets(std::span<const Eigen::Vector2d> r_points,
                                 std::span<const Eigen::Vector2d> s_points);

// III-B and III-C for every sensor pair (r < s); returns the pairs with at least one comparable
// track pair, ordered by (r, s). Samples with non-finite positions are skipped.
std::vector<SchenkEdge> BuildSchenkEdges(const AlignedTracks& tracks, const SchenkOptions& options);

// III-D: greedy placement from `reference` over the edges with n > 0. Sets `placement` on the
// edges it uses. Poses of unplaced sensors stay identity.
struct SchenkPlacement {
  std::vector<Pose2> world_from_sensor;
  std::vector<bool> placed;
  std::vector<std::size_t> order;   // reference first
  std::vector<double> node_weight;  // initial relaxation weights (eq. 7 along the placement edge)
};
SchenkPlacement PlaceGreedy(std::size_t sensor_count, std::vector<SchenkEdge>& edges,
                            std::size_t reference);

// III-E: relaxation over every edge with n > 0 between placed sensors (eqs. 6-10); the reference
// stays fixed. Updates `world_from_sensor` and `node_weight` in place; returns the iterations run.
int RelaxSchenk(const std::vector<SchenkEdge>& edges, std::size_t reference,
                const std::vector<bool>& placed, const SchenkOptions& options,
                std::vector<Pose2>& world_from_sensor, std::vector<double>& node_weight);

// Background beams as points in the sensor frame (metres); beams without return are left out.
std::vector<Eigen::Vector2d> BackgroundPoints(const BackgroundScan& background);

// III-F: close-points-only ICP of every placed sensor but the reference, in `order`, onto the
// background points of the map grown from the reference (see the header comment). Sensors
// without a background are left as they are. Returns one report per sensor (index = sensor).
std::vector<SchenkIcpReport> RefineSchenkIcp(const AlignedTracks& tracks, std::size_t reference,
                                             const std::vector<bool>& placed,
                                             const std::vector<std::size_t>& order,
                                             const SchenkOptions& options,
                                             std::vector<Pose2>& world_from_sensor);

}  // namespace lrfnet::calib
