// Tracking accuracy over every shipped scenario: the simulator's scans of each sensor through the
// tracking pipeline, scored against the simulator's truth with CLEAR-MOT (Bernardin & Stiefelhagen,
// "Evaluating multiple object tracking performance: the CLEAR MOT metrics", 2008), per sensor and
// after fusion in the world frame, for the tracker's body-centre measurement ("new": shape fit,
// static-object handling, motion limits) and the previous one ("old": fixed-axes ellipse with its
// centre-of-mass fallback, none of the rest) on the very same scans.
//
// Every scenario runs as it is (each sensor at its mount, upper-body height unless it says legs),
// and again with every sensor at knee height ("legs") when it has people.
//
// Scoring, per sensor: in every scan, the objects a sensor must track are the people (a trolley's
// pusher too), cylinders and trolleys whose outline returned at least kMinHits beams of that scan;
// the hypotheses are the tracks the tracker reports (confirmed or coasting). Tracks and truth are
// matched within kMatchRadiusM (Hungarian on the distance, correspondences of the previous scan
// kept while within it). Tracks within kMatchRadiusM of a door or chair, or of a person hidden in
// this scan (a track coasting through an occlusion), are not counted either way (the
// door/chair/hidden column says for how long there were such tracks).
//   MOTA = 1 - (misses + false positives + id switches) / objects, MOTP = mean match distance,
//   p95 = its 95th percentile, precision = matches / (matches + false positives);
//   false tracks: track ids unmatched in more than half of their scans; missed targets: objects
//   visible for 1 s or more that were never matched; id switches (an object's track id changes)
//   and fragments (its track is lost and found again) per target-minute (of visibility);
//   NEES: (track - truth)^T P^-1 (track - truth) of the position (2 dof: 2 for a covariance that
//   matches the error) over the measured (not coasting) matches, and the share within the 99 %
//   chi-square bound 9.21.
// Fusion: all sensors' reported tracks (as the daemon receives them) into the daemon's Fuser with
// the true sensor poses, evaluated every 0.1 s against the objects that at least one sensor saw in
// its latest scan.
//
// Scans are stamped with their true start time (no clock mapping: that is the clock benchmark's
// business). The simulator draws people's sizes per person; nothing of the scene is known to the
// tracker beyond its defaults and the device's range.
//
//   tracking_benchmark --scenarios DIR [--extra DIR] [--only NAME] [--out FILE] [--jobs N]
//                      [--explain] [--breakdown]
//                      [--before-report-rules |
//                       [--before-mixed-pixels] [--before-far] [--before-evidence-coasting]
//                       [--before-one-leg] [--before-confirm-time] [--before-whole-person]
//                       [--before-box-size] [--before-single-beam] [--before-deep-pieces]
//                       [--before-deep-evidence] [--before-isotropic-bias] [--before-across-walk]
//                       [--before-few-point-legs] [--before-deep-legs]
//                       [--before-legs-seen-through]
//                       [--before-legs-report-coasting] [--before-leg-edges]
//                       [--before-outline-departure] [--before-partial-view]
//                       [--before-underdetermined-fit]
//                       [--before-recent-veil]
//                       [--before-single-precision-fit] [--before-edge-sides]
//                       [--before-outside-start] [--before-across-sway] [--before-receded-edges]
//                       [--before-stance-weight] [--before-adopt] [--before-inherit-moved]
//                       [--before-touching-legs] [--before-still-legs-cov]
//                       [--before-walking-legs-cov] [--before-occluded-gap]
//                       [--before-still-legs] [--before-mixed-legs] [--before-mixed-leg-band]
//                       [--before-box-occluders] [--before-box-rejoin] [--before-box-unseen-cov]
//                       [--before-box-seen-extent] [--before-knee-box-faces] [--before-see-through]
//                       [--before-step-seam] [--before-deep-tail] [--before-torso-edge-echo]
//                       [--before-person-size]
//                       [--before-person-reach] [--before-partial-extent]
//                       [--before-fusion-merge] [--before-report-sourceless]]
//   (--extra: more scenario folders, e.g. held-out scenes, reported in their own section;
//   --explain: per run on stderr, what became of an object's previous track at every id switch
//   and missed scan, what the false positives are (by scan and by false track: a track left
//   behind by its object, a second track beside a tracked one, clutter, furniture; see
//   MotSequence::FalseClass; per sensor also where each false scan lies from the nearest object as
//   the sensor sees it: straight behind it (held by another track or untracked, and how far), in
//   front of it or beside it, MotSequence::LineOfSight; and how a track parted from the object
//   it held (its first false scan since): its object out of view, coasting while its object was
//   visible and what became of the object's returns, or measured on something else, how far off and
//   on what) and the tracker's counters; --breakdown: a table more per section, the per-sensor
//   matched error along and across the line of sight by range and point count, by the sensor's
//   model and scan rate, the person's size and outline, the object's speed, a partial view (a
//   nearer return beside it) or another object near it, a moving trolley's view and whether its
//   track is a box (at either height), and the filtered track's error beside
//   that of the scan's measurement it was updated with, see Breakdown; and a second one, a
//   person's matches by source (coasting, a track just born, a partial view, another object near,
//   else a clear view by sensor model and range) with each source's share of the matches, of the
//   summed error and of the matches above the people's p95 (PersonSourceTable);
//   --before-report-rules: a third tracker, "before", the new one without
//   ShapeOptions::unseen_coasting_m and MultiTrackerOptions::moving_speed_mps, the tree before
//   them; --before-mixed-pixels: "before" is the new one taking knee-height mixed pixels for legs,
//   ShapeOptions::drop_mixed_pixel_legs = false; --before-far: "before" is the new one without the
//   mixed-pixel model of far edges at upper-body height, ShapeOptions::mixed_pixel_min_footprint_m
//   = 0; --before-evidence-coasting: "before" is the new one reporting every coasting track for
//   report_coasting_s whatever its evidence, MultiTrackerOptions::report_coasting_per_measured_s =
//   0; --before-one-leg: "before" measures every single knee-height leg as the leg itself, also
//   where its partner is hidden behind it, ShapeOptions::hidden_leg_behind = false;
//   --before-confirm-time: "before" is the new one confirming by M of N alone,
//   MultiTrackerOptions::confirm_min_s = 0; --before-whole-person: "before" drops knee-height
//   mixed pixels beside a nearer return only, ShapeOptions::drop_mixed_pixel_legs_whole_person =
//   false; --before-box-size: "before" reports a box's (cart's) centre with its learned size's
//   sigma as it is, ShapeOptions::box_size_floor_sigma_m = 0; --before-single-beam: "before" drops
//   knee-height legs returned by a single beam, ShapeOptions::single_beam_legs = false;
//   --before-deep-pieces: "before" measures knee-height pieces deep along the line of sight but
//   no wider across it than a pair of legs as wide objects, also where a leg fills no beam,
//   ShapeOptions::drop_deep_mixed_pixel_pieces = false; --before-deep-evidence: "before" drops
//   those pieces by their shape alone, also with no surface behind them to mix with,
//   ShapeOptions::deep_mixed_pixel_behind_ratio = 0;
//   --before-isotropic-bias: "before" reports the centre's shared error as the same sigma in every
//   direction, ShapeOptions::centre_bias_along_ray = false;
//   --before-across-walk: "before" measures a walking track's single leg as the leg itself,
//   ShapeOptions::single_leg_across_walk = false;
//   --before-side-uncertainty: "before" takes a walking track's single leg's side of the centre as
//   sure, ShapeOptions::single_leg_side_uncertainty = false;
//   --before-side-from-view: "before" takes the side of the centre a walking track's single leg
//   stands on from the prediction alone, not from where the scan sees through the other leg's
//   place, ShapeOptions::single_leg_side_from_view = false;
//   --before-lone-leg-standing: "before" takes a walking track's single leg's centre along the
//   walk as anywhere within the legs' reach also where the hidden leg stood at the last two-leg
//   measurement, ShapeOptions::single_leg_from_standing = false;
//   --before-few-point-legs: "before" measures a knee-height segment of two or three points wider
//   than a leg as one leg, ShapeOptions::split_few_point_legs = false;
//   --before-deep-legs: "before" measures a confirmed track's knee-height segment of two or three
//   points deeper along the line of sight than a leg as one leg, ShapeOptions::deep_legs_as_pair
//   = false; --before-outside-start: "before" starts a fit at the track's prediction also where it
//   lies outside the silhouette, ShapeFitOptions::outside_guess_start = kGuess;
//   --before-across-sway: "before" reports an upper-body centre with the sideways sway allowance
//   across the ray as before, ShapeOptions::centre_bias_across_sigma_m = 0.006;
//   --before-receded-edges: "before" takes a segment's end as a silhouette also where the beam
//   beyond returned from the body's range over a background that receded there,
//   ShapeOptions::receded_background_edge_m = 0;
//   --before-legs-seen-through: "before" reports a knee-height coasting track also where the scan
//   sees through every place its legs may stand, ShapeOptions::legs_seen_through = false;
//   --before-legs-report-coasting: "before" reports a knee-height coasting track for all of
//   MultiTrackerOptions::report_coasting_s, ShapeOptions::legs_report_coasting_s = 0;
//   --before-legs-coasting-sigma: "before" reports a knee-height coasting track whatever its
//   position sigma, ShapeOptions::legs_coasting_max_sigma_m = 0;
//   --before-coasting-sigma: "before" reports an upper-body coasting track whatever its position
//   sigma, ShapeOptions::coasting_max_sigma_m = 0;
//   --before-recent-veil: "before" takes a knee-height leg-sized segment behind a nearer return its
//   beams had in the last scans for a leg, ShapeOptions::recent_veil_s = 0;
//   --before-single-precision-fit: "before" fits a person's outline with every point in double
//   precision, two at a time, ShapeFitOptions::single_precision_points = false;
//   --before-edge-sides: "before" turns each silhouette edge of a fit away from the fit's start
//   (the track's prediction) instead of away from the points, ShapeFitOptions::edges_face_points
//   = false;
//   --before-leg-edges: "before" takes a knee-height leg's silhouette edge half a step beyond its
//   last returning beam also where the beam beyond is a mixed echo,
//   ShapeOptions::leg_edge_in_mixed_beam = false;
//   --before-stance-weight: "before" measures a walking knee-height track's two legs by their
//   midpoint also where one stands and the other swings, ShapeOptions::stance_leg_weight = 0.5;
//   --before-adopt: "before" leaves a track born beside a coasting one to itself, the coasting one
//   reported until its time is up, MultiTrackerOptions::adopt_successor_m = 0;
//   --before-inherit-moved: "before" waits for a track born where a moved track was just lost to
//   move by itself before reporting it, MultiTrackerOptions::inherit_moved_s = 0;
//   --before-touching-legs: "before" measures two legs that touch in the scan with a pair's
//   covariance, ShapeOptions::touching_legs_along_ray = false;
//   --before-occluded-gap: "before" reports two knee-height legs with something nearer between
//   them with a pair's covariance, ShapeOptions::occluded_gap_depth_m = 0;
//   --before-still-legs-cov: "before" reports a knee-height track's two legs seen still with a
//   walking pair's covariance, ShapeOptions::still_legs_cov = false;
//   --before-walking-legs-cov: "before" reports a knee-height track's two legs seen walking with
//   the gait allowance as noise the filter averages, ShapeOptions::walking_legs_cov = false;
//   --before-still-legs: "before" takes a still knee-height track for a person's whatever the
//   depth of its legs along the line of sight, ShapeOptions::still_legs_max_depth_m = 0;
//   --before-mixed-legs: "before" fits a far knee-height leg to its points also where each may be
//   a mixed pixel with a near background, ShapeOptions::mixed_leg_max_gap_m = 0;
//   --before-mixed-leg-band: "before" gives a leg measured from mixed pixels' range deficits the
//   radius' share of the whole gap to the background along the ray, also where its nearest return
//   may be the leg's own echo, ShapeOptions::mixed_leg_band_variance = false;
//   --before-box-occluders: "before" fits a box (a cart) to every point of its segment, also to
//   those in front of it (its pusher's), ShapeOptions::box_drop_occluders = false;
//   --before-box-unseen-cov: "before" reports a box's size error as the same in every direction,
//   also along an axis the scan does not show, ShapeOptions::box_unseen_depth_cov = false;
//   --before-box-seen-extent: "before" widens a box's reported centre covariance along an axis
//   only where the scan does not show its semi-axis, not where the track never saw it whole,
//   ShapeOptions::box_seen_extent_cov = false;
//   --before-knee-box-faces: "before" learns a knee-height box's semi-axes from every fit, also
//   one whose scan does not show them, ShapeOptions::box_size_from_faces_seen_at_knee = false;
//   --before-box-rejoin: "before" measures every segment on its own, also the pieces the width
//   limit cuts a box's outline into, ShapeOptions::box_rejoin_pieces = false;
//   --before-see-through: "before" measures every segment as one observation, also where beams
//   saw through it between objects side by side, ShapeOptions::split_see_through = false;
//   --before-torso-edge-echo: "before" measures an upper-body segment of a footprint's beams beside
//   a nearer return as any, ShapeOptions::torso_edge_echo = false;
//   --before-step-seam: "before" measures a segment as one observation also where its range steps
//   between two bodies that touch in the view, ShapeOptions::split_step_seam = false;
//   --before-deep-tail: "before" measures a segment's end points deeper than its nearest point by
//   more than a body with it, ShapeOptions::split_deep_tail = false;
//   --before-person-size: "before" runs with ShapeOptions::person_size_across_ray the other way
//   round from the default (off by default since it moves round objects' centres towards the
//   sensor: "before" learns each semi-axis only from views that show it across the ray);
//   --before-person-reach: "before" fits an upper-body person to every point of its segment, also
//   to a run at its end beyond the reach of the predicted body (another object's),
//   ShapeOptions::person_drop_beyond_reach = false;
//   --before-partial-extent: "before" reports an upper-body partial view's shared covariance
//   with the size's own sigma, ShapeOptions::partial_view_size_sigma_m = 0;
//   --before-outline-departure: "before" reports an upper-body centre with the fixed allowances
//   for the outline alone, not the departure its fit's residuals measure,
//   ShapeOptions::outline_departure_gain = 0; --before-partial-view: "before" reports an
//   upper-body partial view as a whole one, ShapeOptions::partial_view_shared = false;
//   --before-underdetermined-fit: "before" reports an upper-body fit of no more points and
//   silhouette ends than its parameters as any other,
//   ShapeOptions::underdetermined_fit_shared = false;
//   --before-fusion-merge: "before"'s fusion leaves a fused track without sources to coast beside
//   the track that took its object and reports fused tracks no tracker holds any more,
//   FusionOptions::merge_sourceless = false and report_sourceless = true (its tracker is the new
//   one unless other --before-* flags are given);
//   --before-report-sourceless: "before"'s fusion reports fused tracks no tracker holds any more
//   as coasting, FusionOptions::report_sourceless = true (merging as the new one unless
//   --before-fusion-merge is given too); several:
//   without any of them). --explain also
//   writes the false positives' classes to the results (ExplainTable) and, on stderr, what the
//   tracks measured again after more than 1 s (a lost track resumed) came back on, and what the
//   measured false scans of tracks that held an object before were measured on (LeftBehind: the
//   nearest object to the measurement, how far it and the track's own object are, the time since
//   the track last matched, its age and the measurement's point count); at upper-body height also
//   the matches of a person more than 0.25 m off by what the track was updated with ("far off":
//   coasting, or the observation's points on the person's body, another object's, the
//   background, with their share of those matches; FarOffErrors).

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "central_daemon/fusion/assignment.h"
#include "central_daemon/fusion/fusion.h"
#include "common/geometry.h"
#include "firmware_tracker/cola/scan_telegram.h"
#include "firmware_tracker/tracking/pipeline.h"
#include "tools/sim/scenario.h"
#include "tools/sim/simulator.h"

namespace {

namespace fs = std::filesystem;
using namespace lrfnet;
using Eigen::Matrix2d;
using Eigen::Vector2d;

constexpr double kMatchRadiusM = 0.5;
constexpr std::uint32_t kMinHits = 2;
constexpr double kFusionStepS = 0.1;
constexpr double kMissedAfterS = 1.0;
constexpr double kNees99 = 9.21;

// ---- CLEAR-MOT

struct Truth {
  std::size_t id = 0;
  Vector2d p = Vector2d::Zero();
  Vector2d v = Vector2d::Zero();  // velocity of its path (--breakdown), same frame
  bool trolley = false;           // --breakdown: the object is a trolley
  // --breakdown: a walking person's leg nearer the sensor in stance (0) or in swing (1), else -1;
  // a trolley's view: its heading within 30 deg of the line of sight, coming nearer (0) or going
  // away (3), within 30 deg of across it (2), between (1), else (standing) -1.
  int gait = -1;
  int view = -1;
  // --breakdown, knee height, a walking person: how far apart the legs stand along the walk (m, -1
  // standing) and whether one leg swings while the other stands (0) or both stand (1).
  double legs_spread_m = -1.0;
  int legs_support = -1;
  // --explain, knee height, a person: its legs' centres (same frame) and radius (0: not a person).
  std::array<Vector2d, 2> legs{Vector2d::Zero(), Vector2d::Zero()};
  double leg_radius_m = 0.0;
  // --breakdown: the sensor's model (kModelBins), a person's upper-body semi-axis across the
  // shoulders and its cross-section's superellipse exponent (0: not a person), and whether the scan
  // has a return nearer than the object's front beside or in front of it (a partial view).
  std::size_t model = 0;
  double a_m = 0.0;
  double exponent = 0.0;
  bool occluded = false;
  double nearest_other_m = std::numeric_limits<double>::infinity();  // to another object's centre
  double rate_hz = 0.0;                                              // the sensor's scan rate
};
// --breakdown: a person walks (Truth::gait) above this speed, a trolley moves (Truth::view); a
// trolley is seen end-on or broadside within this angle of it.
constexpr double kWalkingMps = 0.3;
constexpr double kViewSectorRad = common::kPi / 6.0;  // 30 degrees
struct Hypothesis {
  std::uint64_t id = 0;
  Vector2d p = Vector2d::Zero();
  Matrix2d cov = Matrix2d::Identity();
  bool measured = false;
  // --breakdown, per sensor: the scan's points of the track, and the measurement it was updated
  // with and that measurement's time after the scan start (when measured).
  std::uint32_t points = 0;
  Vector2d z = Vector2d::Zero();
  double z_offset_s = 0.0;
  std::size_t parts = 0;  // --breakdown: the measurement's observation, a Breakdown::PartsBin
  int edges = -1;         // --breakdown: its observation's silhouette ends (0-2), -1 unknown
  // --explain, per sensor, coasting: what the scan shows across its body (CoastingView).
  std::string view;
  // --breakdown: the track's shape state is a box (ObjectShape::kBox).
  bool box = false;
  std::uint32_t age_scans = 0;  // --breakdown: scans since the track was created
};

// --breakdown: where the matched error of the per-sensor tracks comes from. Every match's error
// e = track - truth (the sensor at the origin of the frame) is split along the line of sight
// (radial, signed: + away from the sensor, - towards it) and across it, binned by the truth's range
// and by the scan's point count of the track (0: coasting). Where the track was measured in the
// scan, the same is done for that measurement (the refined body centre the filter was updated
// with) against the truth at the measurement's time: the filter's error beside its input's shows
// what the filtering adds or removes (lag behind a start or turn, noise averaged away). "along
// motion": the error's component along the truth's direction of travel (signed: - behind), over
// matches of objects moving faster than kMovingMps.
constexpr double kMovingMps = 0.3;
struct ErrorStats {
  double n = 0, sum = 0, radial = 0, radial2 = 0, across2 = 0;
  double moving = 0, along = 0, along2 = 0, beside2 = 0;  // beside: across the motion
  double nees = 0;                                        // sum of the position's NEES (AddNees)
  double var = 0;  // sum of the reported covariance's trace / 2 (AddNees)
  std::vector<double> norms;
  void Add(const Vector2d& e, const Vector2d& los, const Vector2d& v) {
    const Vector2d across(-los.y(), los.x());
    const double r = e.dot(los), c = e.dot(across);
    n += 1;
    sum += e.norm();
    radial += r;
    radial2 += r * r;
    across2 += c * c;
    norms.push_back(e.norm());
    if (v.norm() > kMovingMps) {
      const Vector2d u = v.normalized();
      moving += 1;
      along += e.dot(u);
      along2 += e.dot(u) * e.dot(u);
      beside2 += (u.x() * e.y() - u.y() * e.x()) * (u.x() * e.y() - u.y() * e.x());
    }
  }
  void AddNees(const Vector2d& e, const Matrix2d& cov) {
    const Eigen::LDLT<Matrix2d> ldlt(cov);
    if (ldlt.info() == Eigen::Success) nees += e.dot(ldlt.solve(e));
    var += 0.5 * cov.trace();
  }
  void Merge(const ErrorStats& o) {
    n += o.n;
    sum += o.sum;
    radial += o.radial;
    radial2 += o.radial2;
    across2 += o.across2;
    moving += o.moving;
    along += o.along;
    along2 += o.along2;
    beside2 += o.beside2;
    nees += o.nees;
    var += o.var;
    norms.insert(norms.end(), o.norms.begin(), o.norms.end());
  }
  double Mean() const { return n > 0 ? sum / n : 0.0; }
  double Rms() const { return n > 0 ? std::sqrt((radial2 + across2) / n) : 0.0; }
  double RadialMean() const { return n > 0 ? radial / n : 0.0; }
  double RadialRms() const { return n > 0 ? std::sqrt(radial2 / n) : 0.0; }
  double AcrossRms() const { return n > 0 ? std::sqrt(across2 / n) : 0.0; }
  double AlongMean() const { return moving > 0 ? along / moving : 0.0; }
  double AlongRms() const { return moving > 0 ? std::sqrt(along2 / moving) : 0.0; }
  double BesideRms() const { return moving > 0 ? std::sqrt(beside2 / moving) : 0.0; }
  double Nees() const { return n > 0 ? nees / n : 0.0; }
  double ReportedSigma() const { return n > 0 ? std::sqrt(var / n) : 0.0; }
  double P95() const {
    if (norms.empty()) return 0.0;
    std::vector<double> e = norms;
    const auto k = static_cast<std::size_t>(0.95 * static_cast<double>(e.size() - 1));
    std::nth_element(e.begin(), e.begin() + static_cast<std::ptrdiff_t>(k), e.end());
    return e[k];
  }
};
struct BreakdownCell {
  ErrorStats all;       // every match
  ErrorStats filtered;  // measured matches: the track
  ErrorStats raw;       // the same matches: the scan's measurement
  void Merge(const BreakdownCell& o) {
    all.Merge(o.all);
    filtered.Merge(o.filtered);
    raw.Merge(o.raw);
  }
};
constexpr const char* kRangeBins[] = {"range 0-5 m", "range 5-10 m", "range 10-20 m",
                                      "range 20+ m"};
constexpr const char* kPointBins[] = {"points 0 (coasting)", "points 1",     "points 2-4",
                                      "points 5-9",          "points 10-19", "points 20+"};
// What the scan's measurement of a track was made of (the pipeline's observation): knee height
// one leg (its partner not seen, or both legs in one segment of too few points to split), one
// part wider than a leg (two legs that touch; over the shipped scenes nearly all 2-3 points that
// spread 0.2-0.4 m along the line of sight at 5-15 m: a leg with the other leg or mixed echoes
// behind it), two legs, a segment wider than a pair of legs (of a person, or of a trolley, a
// box at every height: its own row), one leg taken as hiding the other
// (ShapeOptions::hidden_leg_behind); coasting, with or without an observation within 0.5 m of the
// track (one it could have taken).
constexpr const char* kPartsBins[] = {"parts: coasting",
                                      "parts: one segment (torso)",
                                      "parts: one leg",
                                      "parts: one leg-sized part wider than a leg",
                                      "parts: two legs",
                                      "parts: wider than two legs",
                                      "parts: coasting beside an observation (0.5 m)",
                                      "parts: one leg hiding the other",
                                      "parts: wider than two legs, a trolley"};
constexpr const char* kHeadingBins[] = {
    "walking along the line of sight, coming nearer", "walking oblique to the line of sight",
    "walking across the line of sight", "walking along the line of sight, going away"};
// The sensor's model (the simulator's key); a person's shoulder semi-axis a_m (the shipped scenes
// draw 0.23 +- 0.02 per person) and the upper body's superellipse exponent (2: an ellipse); a
// partial view: a return nearer than the object's front within its angular extent plus two beams
// to either side.
constexpr const char* kModelBins[] = {"sensor lms111", "sensor lms151", "sensor lms511",
                                      "sensor tim561", "sensor tim781", "sensor other"};
constexpr const char* kSizeBins[] = {"person a < 0.22 m", "person a 0.22-0.27 m",
                                     "person a > 0.27 m"};
constexpr const char* kExponentBins[] = {"person torso ellipse (exponent < 2.25)",
                                         "person torso boxier (exponent >= 2.25)"};
constexpr const char* kOcclusionBins[] = {"unoccluded", "a nearer return beside it"};
constexpr const char* kRateBins[] = {"scan rate <= 15 Hz", "scan rate 15-30 Hz",
                                     "scan rate > 30 Hz"};
constexpr const char* kObjectBins[] = {"object: a person", "object: a trolley", "object: other"};
constexpr const char* kEdgeBins[] = {"silhouette ends 0", "silhouette ends 1", "silhouette ends 2"};
constexpr const char* kSpeedBins[] = {"speed < 0.3 m/s", "speed 0.3-1.0 m/s", "speed 1.0-1.3 m/s",
                                      "speed > 1.3 m/s"};
constexpr const char* kCrowdBins[] = {"another object within 1 m", "another object 1-2 m",
                                      "no other object within 2 m"};
// --breakdown, a person's matches (trolleys and other objects left out) each in the first of
// these sources that applies: coasting, a track younger than kJustBornS, a partial view (a nearer
// return beside it), another object within 1 m, 1-2 m, else a clear view by sensor model and range.
constexpr const char* kPersonSourceBins[] = {"coasting", "just born (track younger than 1 s)",
                                             "partial view (a nearer return beside it)",
                                             "another object within 1 m", "another object 1-2 m"};
constexpr double kJustBornS = 1.0;
constexpr std::size_t kPersonSources =
    std::size(kPersonSourceBins) + std::size(kModelBins) * std::size(kRangeBins);
std::size_t ModelBin(std::string_view key) {
  for (std::size_t i = 0; i + 1 < std::size(kModelBins); ++i) {
    if (std::string_view(kModelBins[i]).substr(7) == key) return i;
  }
  return std::size(kModelBins) - 1;
}
struct Breakdown {
  std::array<BreakdownCell, std::size(kModelBins)> by_model;
  std::array<BreakdownCell, std::size(kSizeBins)> by_size;
  std::array<BreakdownCell, std::size(kExponentBins)> by_exponent;
  std::array<BreakdownCell, std::size(kOcclusionBins)> by_occlusion;
  std::array<BreakdownCell, std::size(kSpeedBins)> by_speed;
  std::array<BreakdownCell, std::size(kCrowdBins)> by_crowd;
  std::array<BreakdownCell, std::size(kSpeedBins)> unoccluded_by_speed;
  std::array<BreakdownCell, std::size(kCrowdBins)> unoccluded_by_crowd;
  // Unoccluded with no other object within 2 m (a clear view): by sensor model, size, exponent.
  std::array<BreakdownCell, std::size(kModelBins)> clear_by_model;
  // ... and per range bin (kRangeBins): a sensor model's bias along the ray by range.
  std::array<std::array<BreakdownCell, std::size(kRangeBins)>, std::size(kModelBins)>
      clear_by_model_range;
  std::array<BreakdownCell, std::size(kSizeBins)> clear_by_size;
  std::array<BreakdownCell, std::size(kExponentBins)> clear_by_exponent;
  std::array<BreakdownCell, std::size(kRateBins)> by_rate, clear_by_rate;
  std::array<BreakdownCell, std::size(kObjectBins)> by_object;
  // By the measured observation's silhouette ends, with and without a nearer return beside it.
  std::array<BreakdownCell, std::size(kEdgeBins)> occluded_by_edges, unoccluded_by_edges;
  // Points 2-4 and 5-9 split by the person's size (few points: where the size prior counts most).
  std::array<BreakdownCell, std::size(kSizeBins)> few_points_by_size, some_points_by_size;
  std::array<BreakdownCell, 4> by_range;
  std::array<BreakdownCell, 6> by_points;
  std::array<BreakdownCell, 9> by_parts;
  // Knee height, by the number of legs measured and the range.
  std::array<BreakdownCell, 4> one_leg_by_range, two_legs_by_range;
  // Knee height, one leg: the nearer leg in stance / swing (Truth::gait); a trolley by its view.
  std::array<BreakdownCell, 2> one_leg_by_gait;
  // Knee height, one leg: by the time since the object's last two-leg measurement (kSinceBins;
  // the last bin also where there was none).
  std::array<BreakdownCell, 3> one_leg_by_since;
  // Knee height, two legs of a walking person: by the legs' spread along the walk
  // (kSpreadBins) and by one leg swinging or both standing (Truth::legs_support).
  std::array<BreakdownCell, 4> two_legs_by_spread;
  std::array<BreakdownCell, 2> two_legs_by_support;
  std::array<BreakdownCell, 4> trolley_by_view;
  // A moving trolley at either height, by its view (Truth::view) and whether its track is a box.
  std::array<std::array<BreakdownCell, 2>, 4> trolley_by_view_shape;
  // A walking person (faster than kWalkingMps, not a trolley): its heading against the line of
  // sight (HeadingBin, kHeadingBins), over every range and per range bin (kRangeBins).
  std::array<BreakdownCell, 4> walking_by_heading;
  std::array<std::array<BreakdownCell, 4>, 4> walking_by_heading_range;
  // A person's matches by their source (kPersonSourceBins, then the clear view's model x range).
  std::array<BreakdownCell, kPersonSources> person_by_source;
  BreakdownCell total;
  static std::size_t RangeBin(double r_m) {
    return r_m < 5.0 ? 0 : r_m < 10.0 ? 1 : r_m < 20.0 ? 2 : 3;
  }
  // The truth's velocity v against the line of sight los (unit): within kViewSectorRad of it,
  // coming nearer (0) or going away (3), within kViewSectorRad of across it (2), between (1).
  static std::size_t HeadingBin(const Vector2d& v, const Vector2d& los) {
    const double c = v.normalized().dot(los);
    const double along = std::cos(kViewSectorRad), across = std::sin(kViewSectorRad);
    return c <= -along ? 0 : c >= along ? 3 : std::abs(c) <= across ? 2 : 1;
  }
  static std::size_t SinceBin(double s) { return s < 0.3 ? 0 : s < 1.0 ? 1 : 2; }
  static std::size_t SpreadBin(double d_m) {
    return d_m < 0.1 ? 0 : d_m < 0.2 ? 1 : d_m < 0.3 ? 2 : 3;
  }
  static std::size_t PointBin(std::uint32_t n) {
    return n == 0 ? 0 : n == 1 ? 1 : n <= 4 ? 2 : n <= 9 ? 3 : n <= 19 ? 4 : 5;
  }
  // since_two_legs_s: the time since the object's last two-leg measurement (infinite: none).
  void Add(const Truth& t, const Hypothesis& h, double since_two_legs_s) {
    const double range_m = t.p.norm();
    if (!(range_m > 1e-6)) return;
    const Vector2d los = t.p / range_m;
    const std::size_t parts = h.measured || h.parts == 6 ? h.parts : 0;
    BreakdownCell* legs = parts == 2 || parts == 3 || parts == 7
                              ? &one_leg_by_range[RangeBin(range_m)]
                          : parts == 4 ? &two_legs_by_range[RangeBin(range_m)]
                                       : nullptr;
    BreakdownCell* gait = parts == 2 && t.gait >= 0 ? &one_leg_by_gait[t.gait] : nullptr;
    BreakdownCell* since = parts == 2 ? &one_leg_by_since[SinceBin(since_two_legs_s)] : nullptr;
    BreakdownCell* view =
        parts == 5 && t.trolley && t.view >= 0 ? &trolley_by_view[t.view] : nullptr;
    BreakdownCell* view_shape =
        t.trolley && t.view >= 0 ? &trolley_by_view_shape[t.view][h.box ? 1 : 0] : nullptr;
    BreakdownCell* spread = parts == 4 && t.legs_spread_m >= 0.0
                                ? &two_legs_by_spread[SpreadBin(t.legs_spread_m)]
                                : nullptr;
    BreakdownCell* support =
        parts == 4 && t.legs_support >= 0 ? &two_legs_by_support[t.legs_support] : nullptr;
    const bool walking = !t.trolley && t.v.norm() > kWalkingMps;
    BreakdownCell* heading = walking ? &walking_by_heading[HeadingBin(t.v, los)] : nullptr;
    BreakdownCell* heading_range =
        walking ? &walking_by_heading_range[HeadingBin(t.v, los)][RangeBin(range_m)] : nullptr;
    const std::size_t size_bin = t.a_m < 0.22 ? 0 : t.a_m <= 0.27 ? 1 : 2;
    const bool person = t.a_m > 0.0;
    const double speed = t.v.norm();
    const std::size_t speed_bin = speed < 0.3 ? 0 : speed < 1.0 ? 1 : speed <= 1.3 ? 2 : 3;
    const std::size_t crowd_bin = t.nearest_other_m < 1.0 ? 0 : t.nearest_other_m < 2.0 ? 1 : 2;
    const bool clear = !t.occluded && crowd_bin == 2;
    const std::size_t rate_bin = t.rate_hz <= 15.0 ? 0 : t.rate_hz <= 30.0 ? 1 : 2;
    const std::size_t model_bin = std::min(t.model, by_model.size() - 1);
    const bool just_born =
        t.rate_hz > 0.0 && static_cast<double>(h.age_scans) < kJustBornS * t.rate_hz;
    const std::size_t source = !h.measured  ? 0
                               : just_born  ? 1
                               : t.occluded ? 2
                               : !clear     ? 2 + crowd_bin + 1
                                            : std::size(kPersonSourceBins) +
                                              model_bin * std::size(kRangeBins) + RangeBin(range_m);
    BreakdownCell* cells[] = {
        person ? &person_by_source[source] : nullptr,
        &by_model[model_bin],
        person ? &by_size[size_bin] : nullptr,
        person ? &by_exponent[t.exponent < 2.25 ? 0 : 1] : nullptr,
        &by_occlusion[t.occluded ? 1 : 0],
        &by_speed[speed_bin],
        &by_crowd[crowd_bin],
        t.occluded ? nullptr : &unoccluded_by_speed[speed_bin],
        t.occluded ? nullptr : &unoccluded_by_crowd[crowd_bin],
        clear ? &clear_by_model[model_bin] : nullptr,
        clear ? &clear_by_model_range[model_bin][RangeBin(range_m)] : nullptr,
        clear && person ? &clear_by_size[size_bin] : nullptr,
        &by_rate[rate_bin],
        &by_object[person      ? 0
                   : t.trolley ? 1
                               : 2],
        h.measured && h.edges >= 0
            ? (t.occluded ? &occluded_by_edges[static_cast<std::size_t>(h.edges)]
                          : &unoccluded_by_edges[static_cast<std::size_t>(h.edges)])
            : nullptr,
        clear ? &clear_by_rate[rate_bin] : nullptr,
        clear && person ? &clear_by_exponent[t.exponent < 2.25 ? 0 : 1] : nullptr,
        person && h.points >= 2 && h.points <= 4 ? &few_points_by_size[size_bin] : nullptr,
        person && h.points >= 5 && h.points <= 9 ? &some_points_by_size[size_bin] : nullptr,
        &by_range[RangeBin(range_m)],
        &by_points[PointBin(h.points)],
        &by_parts[parts == 5 && t.trolley ? 8 : parts],
        &total,
        legs,
        gait,
        since,
        view,
        view_shape,
        spread,
        support,
        heading,
        heading_range};
    const Vector2d e = h.p - t.p;
    for (BreakdownCell* c : cells) {
      if (c != nullptr) c->all.Add(e, los, t.v);
    }
    if (!h.measured) return;
    // The truth at the measurement's time (its path's velocity over a fraction of a scan).
    const Vector2d ez = h.z - (t.p + h.z_offset_s * t.v);
    for (BreakdownCell* c : cells) {
      if (c == nullptr) continue;
      c->filtered.Add(e, los, t.v);
      c->filtered.AddNees(e, h.cov);
      c->raw.Add(ez, los, t.v);
    }
  }
  void Merge(const Breakdown& o) {
    for (std::size_t i = 0; i < by_model.size(); ++i) by_model[i].Merge(o.by_model[i]);
    for (std::size_t i = 0; i < by_size.size(); ++i) {
      by_size[i].Merge(o.by_size[i]);
      few_points_by_size[i].Merge(o.few_points_by_size[i]);
      some_points_by_size[i].Merge(o.some_points_by_size[i]);
    }
    for (std::size_t i = 0; i < by_exponent.size(); ++i) by_exponent[i].Merge(o.by_exponent[i]);
    for (std::size_t i = 0; i < by_occlusion.size(); ++i) by_occlusion[i].Merge(o.by_occlusion[i]);
    for (std::size_t i = 0; i < by_model.size(); ++i) clear_by_model[i].Merge(o.clear_by_model[i]);
    for (std::size_t i = 0; i < by_model.size(); ++i) {
      for (std::size_t j = 0; j < clear_by_model_range[i].size(); ++j) {
        clear_by_model_range[i][j].Merge(o.clear_by_model_range[i][j]);
      }
    }
    for (std::size_t i = 0; i < by_size.size(); ++i) clear_by_size[i].Merge(o.clear_by_size[i]);
    for (std::size_t i = 0; i < by_exponent.size(); ++i) {
      clear_by_exponent[i].Merge(o.clear_by_exponent[i]);
    }
    for (std::size_t i = 0; i < by_object.size(); ++i) by_object[i].Merge(o.by_object[i]);
    for (std::size_t i = 0; i < occluded_by_edges.size(); ++i) {
      occluded_by_edges[i].Merge(o.occluded_by_edges[i]);
      unoccluded_by_edges[i].Merge(o.unoccluded_by_edges[i]);
    }
    for (std::size_t i = 0; i < by_rate.size(); ++i) {
      by_rate[i].Merge(o.by_rate[i]);
      clear_by_rate[i].Merge(o.clear_by_rate[i]);
    }
    for (std::size_t i = 0; i < by_speed.size(); ++i) {
      by_speed[i].Merge(o.by_speed[i]);
      unoccluded_by_speed[i].Merge(o.unoccluded_by_speed[i]);
    }
    for (std::size_t i = 0; i < by_crowd.size(); ++i) {
      by_crowd[i].Merge(o.by_crowd[i]);
      unoccluded_by_crowd[i].Merge(o.unoccluded_by_crowd[i]);
    }
    for (std::size_t i = 0; i < by_range.size(); ++i) by_range[i].Merge(o.by_range[i]);
    for (std::size_t i = 0; i < by_points.size(); ++i) by_points[i].Merge(o.by_points[i]);
    for (std::size_t i = 0; i < by_parts.size(); ++i) by_parts[i].Merge(o.by_parts[i]);
    for (std::size_t i = 0; i < by_range.size(); ++i) {
      one_leg_by_range[i].Merge(o.one_leg_by_range[i]);
      two_legs_by_range[i].Merge(o.two_legs_by_range[i]);
    }
    for (std::size_t i = 0; i < one_leg_by_gait.size(); ++i) {
      one_leg_by_gait[i].Merge(o.one_leg_by_gait[i]);
    }
    for (std::size_t i = 0; i < one_leg_by_since.size(); ++i) {
      one_leg_by_since[i].Merge(o.one_leg_by_since[i]);
    }
    for (std::size_t i = 0; i < two_legs_by_spread.size(); ++i) {
      two_legs_by_spread[i].Merge(o.two_legs_by_spread[i]);
    }
    for (std::size_t i = 0; i < two_legs_by_support.size(); ++i) {
      two_legs_by_support[i].Merge(o.two_legs_by_support[i]);
    }
    for (std::size_t i = 0; i < trolley_by_view.size(); ++i) {
      trolley_by_view[i].Merge(o.trolley_by_view[i]);
      for (std::size_t j = 0; j < trolley_by_view_shape[i].size(); ++j) {
        trolley_by_view_shape[i][j].Merge(o.trolley_by_view_shape[i][j]);
      }
    }
    for (std::size_t i = 0; i < walking_by_heading.size(); ++i) {
      walking_by_heading[i].Merge(o.walking_by_heading[i]);
      for (std::size_t j = 0; j < walking_by_heading_range[i].size(); ++j) {
        walking_by_heading_range[i][j].Merge(o.walking_by_heading_range[i][j]);
      }
    }
    for (std::size_t i = 0; i < person_by_source.size(); ++i) {
      person_by_source[i].Merge(o.person_by_source[i]);
    }
    total.Merge(o.total);
  }
};

struct Mot {
  double objects = 0, matches = 0, misses = 0, false_positives = 0, id_switches = 0, fragments = 0;
  double target_seconds = 0;
  double false_tracks = 0, missed_targets = 0;
  std::vector<double> errors;
  double nees_sum = 0;
  double nees_count = 0, nees_within = 0;
  double dont_care_seconds = 0;  // a track on a door or chair that stands still

  void Add(const Mot& o) {
    objects += o.objects;
    matches += o.matches;
    misses += o.misses;
    false_positives += o.false_positives;
    id_switches += o.id_switches;
    fragments += o.fragments;
    target_seconds += o.target_seconds;
    false_tracks += o.false_tracks;
    missed_targets += o.missed_targets;
    errors.insert(errors.end(), o.errors.begin(), o.errors.end());
    nees_sum += o.nees_sum;
    nees_count += o.nees_count;
    nees_within += o.nees_within;
    dont_care_seconds += o.dont_care_seconds;
  }
  double Mota() const {
    return objects > 0 ? 1.0 - (misses + false_positives + id_switches) / objects : 0.0;
  }
  double Motp() const {
    double s = 0;
    for (double e : errors) s += e;
    return errors.empty() ? 0.0 : s / static_cast<double>(errors.size());
  }
  double P95() const {
    if (errors.empty()) return 0.0;
    std::vector<double> e = errors;
    const auto k = static_cast<std::size_t>(0.95 * static_cast<double>(e.size() - 1));
    std::nth_element(e.begin(), e.begin() + static_cast<std::ptrdiff_t>(k), e.end());
    return e[k];
  }
  double Precision() const {
    return matches + false_positives > 0 ? matches / (matches + false_positives) : 1.0;
  }
  double PerTargetMinute(double n) const {
    return target_seconds > 0 ? n / (target_seconds / 60.0) : 0.0;
  }
};

// Why ids switched and tracks broke (--explain): for every id switch, what became of the
// object's previous track in that scan, and whether the object was hidden since its last match;
// for every missed scan of an object that had been matched, where its previous track was; for
// every false positive, where it was.
// What the false positives are (--explain, by scan and by false track, see FalseClass): the class
// of every unmatched reported scan of a track, and of every false track its most frequent class.
// false_classes: by class and, when coasting, the time since the track's last measurement;
// false_scan_classes: by class alone (the results file's table).
struct Causes {
  std::map<std::string, double> switches, misses, false_positives;
  std::map<std::string, double> false_classes, false_scan_classes, false_track_classes;
  // False scans per sensor by class and what was there (CoastingView).
  std::map<std::string, double> false_views;
  // False scans per sensor by where they lie from the nearest object as the sensor sees it
  // (LineOfSight): straight behind it, in front of it or beside it, by its range.
  std::map<std::string, double> false_sight;
  // Tracks measured again more than kResumedAfterS after their previous measurement (a lost
  // track resumed): what they came back on, and their false scans within 1 s after.
  std::map<std::string, double> resumes;
  // A reported track coasting beside a person the scan returned (the nearest track within
  // kMatchRadiusM of them, not measured): what became of the person's returns (CoastingCause).
  std::map<std::string, double> coasting;
  // Measured false scans of tracks that held an object before: what measured them (LeftBehind).
  std::map<std::string, double> left_measured;
  // Per sensor: how a track parted from the object it held (its first false scan since it last
  // held it, by how many scans since; a track unreported or on a hidden object meanwhile parted
  // later than that scan): its object out of view; coasting while its object was visible (what
  // became of the object's returns, CoastingCause); measured on something else (how far its
  // measurement lay from its object and what it was made of).
  std::map<std::string, double> partings;
  // Per sensor: a false scan beside an untracked object (left behind by it while it is visible, or
  // never matched and 0.5-1.5 m off it): what the tracker holds at that object (a tentative track,
  // a confirmed one not reported, none), what became of its returns (CoastingCause), and for the
  // never matched, where the false track was first reported (beside a person or not).
  std::map<std::string, double> untracked;
  // Per sensor: a track's first coasting scan on the object it was measured on in the scan
  // before, by what its last measurements were (CoastStart): count, summed error, summed error of
  // the state before its last update predicted on (where the scan before that was measured too),
  // and how many had that.
  std::map<std::string, std::array<double, 4>> coast_start;
  // Knee height, per sensor: measured matches of a person by their measurement's error along the
  // line of sight (LineOfSightErrors): count, summed |radial error|, summed radial NEES (the
  // radial error squared over the measurement's variance along the ray), summed 2-dof NEES.
  std::map<std::string, std::array<double, 4>> los;
  // Upper-body height, per sensor: measured matches of a person by what lies beyond their
  // observation's ends (TorsoEndErrors): count, summed and squared radial error, summed NEES.
  std::map<std::string, std::array<double, 4>> torso_ends;
  // Upper-body height, per sensor: matches of a person more than kFarOffM off (FarOffErrors) by
  // what the track was updated with: count, summed error, summed NEES, matches of a person.
  std::map<std::string, std::array<double, 4>> far_off;
  void Add(const Causes& o) {
    for (const auto& [k, v] : o.far_off) {
      for (std::size_t i = 0; i < v.size(); ++i) far_off[k][i] += v[i];
    }
    for (const auto& [k, v] : o.los) {
      for (std::size_t i = 0; i < v.size(); ++i) los[k][i] += v[i];
    }
    for (const auto& [k, v] : o.torso_ends) {
      for (std::size_t i = 0; i < v.size(); ++i) torso_ends[k][i] += v[i];
    }
    for (const auto& [k, v] : o.coast_start) {
      for (std::size_t i = 0; i < v.size(); ++i) coast_start[k][i] += v[i];
    }
    for (const auto& [k, v] : o.partings) partings[k] += v;
    for (const auto& [k, v] : o.untracked) untracked[k] += v;
    for (const auto& [k, v] : o.left_measured) left_measured[k] += v;
    for (const auto& [k, v] : o.coasting) coasting[k] += v;
    for (const auto& [k, v] : o.resumes) resumes[k] += v;
    for (const auto& [k, v] : o.false_classes) false_classes[k] += v;
    for (const auto& [k, v] : o.false_views) false_views[k] += v;
    for (const auto& [k, v] : o.false_sight) false_sight[k] += v;
    for (const auto& [k, v] : o.false_scan_classes) false_scan_classes[k] += v;
    for (const auto& [k, v] : o.false_track_classes) false_track_classes[k] += v;
    for (const auto& [k, v] : o.false_positives) false_positives[k] += v;
    for (const auto& [k, v] : o.switches) switches[k] += v;
    for (const auto& [k, v] : o.misses) misses[k] += v;
  }
};

// One stream of frames (a sensor, or the fused world) scored frame by frame.
class MotSequence {
 public:
  // alive: ids the tracker still holds (reported or not), nullptr when unknown. furniture: the
  // doors and chairs among dont_care (--explain's classes).
  void Frame(double dt_s, const std::vector<Truth>& truths, const std::vector<Hypothesis>& hyps,
             const std::vector<Vector2d>& dont_care, const std::set<std::uint64_t>* alive = nullptr,
             const std::vector<Vector2d>* furniture = nullptr) {
    partings_.clear();
    matched_truth_.assign(hyps.size(), -1);
    false_class_.assign(hyps.size(), std::string());
    false_object_.assign(hyps.size(), -1);
    std::set<std::size_t> present;
    for (const Truth& t : truths) present.insert(t.id);
    for (auto& [id, st] : state_) {
      if (!present.count(id) && st.ever_matched) {
        st.hidden_since_match = true;
        st.hidden_s += dt_s;
      }
    }
    mot_.objects += static_cast<double>(truths.size());
    mot_.target_seconds += dt_s * static_cast<double>(truths.size());
    std::vector<int> truth_to_hyp(truths.size(), -1);
    std::vector<bool> hyp_taken(hyps.size(), false);
    // Keep last frame's correspondences that still hold.
    for (std::size_t t = 0; t < truths.size(); ++t) {
      const auto it = state_.find(truths[t].id);
      if (it == state_.end() || !it->second.matched_last) continue;
      for (std::size_t h = 0; h < hyps.size(); ++h) {
        if (!hyp_taken[h] && hyps[h].id == it->second.last_hyp &&
            (hyps[h].p - truths[t].p).norm() <= kMatchRadiusM) {
          truth_to_hyp[t] = static_cast<int>(h);
          hyp_taken[h] = true;
        }
      }
    }
    // The rest by minimum total distance.
    std::vector<std::size_t> rows, cols;
    for (std::size_t t = 0; t < truths.size(); ++t) {
      if (truth_to_hyp[t] < 0) rows.push_back(t);
    }
    for (std::size_t h = 0; h < hyps.size(); ++h) {
      if (!hyp_taken[h]) cols.push_back(h);
    }
    if (!rows.empty() && !cols.empty()) {
      Eigen::MatrixXd cost(static_cast<Eigen::Index>(rows.size()),
                           static_cast<Eigen::Index>(cols.size()));
      for (std::size_t i = 0; i < rows.size(); ++i) {
        for (std::size_t j = 0; j < cols.size(); ++j) {
          const double d = (hyps[cols[j]].p - truths[rows[i]].p).norm();
          cost(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j)) =
              d <= kMatchRadiusM ? d : fusion::kForbiddenCost;
        }
      }
      const std::vector<int> a = fusion::SolveAssignment(cost);
      for (std::size_t i = 0; i < rows.size(); ++i) {
        if (a[i] < 0) continue;
        const std::size_t h = cols[static_cast<std::size_t>(a[i])];
        truth_to_hyp[rows[i]] = static_cast<int>(h);
        hyp_taken[h] = true;
      }
    }
    for (std::size_t t = 0; t < truths.size(); ++t) {
      TruthState& s = state_[truths[t].id];
      s.visible_s += dt_s;
      if (truth_to_hyp[t] < 0) {
        ++mot_.misses;
        if (s.ever_matched) {
          std::string why = "previous track gone";
          for (std::size_t h = 0; h < hyps.size(); ++h) {
            if (hyps[h].id != s.last_hyp) continue;
            const double d = (hyps[h].p - truths[t].p).norm();
            why = hyp_taken[h] ? "previous track on another object"
                  : d <= 1.0   ? "previous track 0.5-1 m off"
                               : "previous track > 1 m off";
          }
          if (why == "previous track gone" && alive != nullptr && alive->count(s.last_hyp)) {
            why = "previous track alive, not reported";
          }
          causes_.misses[why] += 1;
        }
        if (s.matched_last) s.interrupted = true;
        s.matched_last = false;
        continue;
      }
      const Hypothesis& h = hyps[static_cast<std::size_t>(truth_to_hyp[t])];
      matched_truth_[static_cast<std::size_t>(truth_to_hyp[t])] = static_cast<long>(truths[t].id);
      if (breakdown_ != nullptr) {
        if (h.measured && h.parts == 4) s.two_legs_at_s = s.visible_s;
        breakdown_->Add(truths[t], h,
                        s.two_legs_at_s >= 0 ? s.visible_s - s.two_legs_at_s
                                             : std::numeric_limits<double>::infinity());
      }
      ++mot_.matches;
      const Vector2d e = h.p - truths[t].p;
      mot_.errors.push_back(e.norm());
      if (h.measured) {
        const Eigen::LDLT<Matrix2d> ldlt(h.cov);
        if (ldlt.info() == Eigen::Success) {
          const double nees = e.dot(ldlt.solve(e));
          if (std::isfinite(nees)) {
            mot_.nees_sum += nees;
            ++mot_.nees_count;
            mot_.nees_within += nees <= kNees99 ? 1 : 0;
          }
        }
      }
      if (s.ever_matched && s.last_hyp != h.id) {
        ++mot_.id_switches;
        std::string why = "previous track gone";
        for (std::size_t k = 0; k < hyps.size(); ++k) {
          if (hyps[k].id != s.last_hyp) continue;
          why = hyp_taken[k] ? "previous track on another object" : "previous track off the object";
        }
        if (why == "previous track gone" && alive != nullptr && alive->count(s.last_hyp)) {
          why = "previous track alive, not reported";
        }
        why += !s.hidden_since_match ? ""
               : s.hidden_s < 1.0    ? ", hidden < 1 s"
               : s.hidden_s < 3.0    ? ", hidden 1-3 s"
                                     : ", hidden > 3 s";
        why += hyp_age_[h.id] < 0.5 ? ", new track" : ", old track";
        causes_.switches[why] += 1;
      }
      s.hidden_since_match = false;
      s.hidden_s = 0;
      if (s.interrupted) ++mot_.fragments;
      s.interrupted = false;
      s.ever_matched = true;
      s.matched_last = true;
      s.last_hyp = h.id;
      HypState& hs = hyps_[h.id];
      NoteResume(h, hs, dt_s,
                 truths[t].id == hs.last_truth ? "on its own object" : "on another object");
      hs.frames += 1;
      hs.ever_matched = true;
      hs.last_truth = truths[t].id;
      hs.last_matched_s = now_s_ + dt_s;
      hs.last_matched_frame = frame_ + 1;
      hs.parted = false;
    }
    for (std::size_t h = 0; h < hyps.size(); ++h) {
      if (hyp_taken[h]) continue;
      HypState& hs = hyps_[hyps[h].id];
      if (!hs.ever_matched) continue;
      std::string cls = "unmatched, its object out of view";
      for (std::size_t t = 0; t < truths.size(); ++t) {
        if (truths[t].id != hs.last_truth) continue;
        const double d = (hyps[h].p - truths[t].p).norm();
        cls = std::string(truth_to_hyp[t] >= 0 ? "unmatched, its object on another track"
                                               : "unmatched, its object untracked") +
              (d < 1.0   ? " < 1 m"
               : d < 2.0 ? " 1-2 m"
                         : " >= 2 m");
      }
      NoteResume(hyps[h], hs, dt_s, cls);
      if (!hs.resumed_cls.empty() && now_s_ + dt_s - hs.resumed_at_s < 1.0) {
        causes_.resumes["false scans within 1 s after: " + hs.resumed_cls] += 1;
      }
    }
    now_s_ += dt_s;
    ++frame_;
    for (const Hypothesis& h : hyps) {
      hyp_age_[h.id] += dt_s;
      if (h.measured) {
        hyps_[h.id].last_measured_s = now_s_;
        hyps_[h.id].last_measured_p = h.p;
      }
    }
    for (std::size_t h = 0; h < hyps.size(); ++h) {
      if (hyp_taken[h]) continue;
      bool ignored = false;
      for (const Vector2d& d : dont_care)
        ignored = ignored || (hyps[h].p - d).norm() <= kMatchRadiusM;
      if (ignored) {
        mot_.dont_care_seconds += dt_s;
        continue;
      }
      ++mot_.false_positives;
      {
        double nearest = std::numeric_limits<double>::infinity();
        bool taken = false;
        for (std::size_t t = 0; t < truths.size(); ++t) {
          const double d = (hyps[h].p - truths[t].p).norm();
          if (d < nearest) {
            nearest = d;
            taken = truth_to_hyp[t] >= 0;
          }
        }
        const std::string why = nearest > 1.5 ? "far from every object"
                                : taken       ? "beside an object another track holds"
                                              : "0.5-1.5 m off an untracked object";
        causes_
            .false_positives[std::string(hyps[h].measured ? "measured, " : "coasting, ") + why] +=
            1;
      }
      HypState& hs = hyps_[hyps[h].id];
      if (hs.ever_matched && !hs.parted) {
        hs.parted = true;
        partings_.push_back({h, hs.last_truth, frame_ - hs.last_matched_frame});
      }
      hs.frames += 1;
      hs.unmatched += 1;
      const std::string cls =
          FalseClass(hyps[h], hs.ever_matched, hs.last_truth, truths, truth_to_hyp, furniture);
      causes_.false_scan_classes[cls] += 1;
      false_class_[h] = cls;
      if (hs.ever_matched) {
        false_object_[h] = static_cast<long>(hs.last_truth);
      } else {
        double nearest_d = std::numeric_limits<double>::infinity();
        for (const Truth& t : truths) {
          if ((hyps[h].p - t.p).norm() < nearest_d) {
            nearest_d = (hyps[h].p - t.p).norm();
            false_object_[h] = static_cast<long>(t.id);
          }
        }
      }
      hs.classes[cls] += 1;
      std::string timed = cls;
      if (!hyps[h].measured) {
        const double coast_s = now_s_ - hs.last_measured_s;
        timed += coast_s < 0.15 ? " < 0.15 s" : coast_s < 0.3 ? " 0.15-0.3 s" : " >= 0.3 s";
      }
      causes_.false_classes[timed] += 1;
      if (hs.ever_matched && hyps[h].measured) {
        causes_.left_measured[LeftBehind(hyps[h], hs.last_truth, now_s_ - hs.last_matched_s,
                                         hyp_age_[hyps[h].id], truths, truth_to_hyp)] += 1;
      }
      if (!hyps[h].view.empty()) {
        causes_.false_views[cls + " | " + hyps[h].view] += 1;
        causes_.false_sight[LineOfSight(hyps[h], truths, truth_to_hyp)] += 1;
      }
    }
  }

  // --explain: a measured false scan of a track that held an object before, by what measured it:
  // the nearest object to the track's measurement (its own object that it held last, another one
  // held by a track or untracked) and how far, how far its own object is, how long since the track
  // last matched it and how long the track has been reported.
  static std::string LeftBehind(const Hypothesis& hyp, std::size_t last_truth, double since_s,
                                double age_s, const std::vector<Truth>& truths,
                                const std::vector<int>& truth_to_hyp) {
    const Vector2d z = hyp.points > 0 ? hyp.z : hyp.p;
    const Truth* nearest = nullptr;
    bool held = false;
    double own_d = std::numeric_limits<double>::infinity();
    for (std::size_t t = 0; t < truths.size(); ++t) {
      if (truths[t].id == last_truth) own_d = (hyp.p - truths[t].p).norm();
      if (nearest == nullptr || (z - truths[t].p).norm() < (z - nearest->p).norm()) {
        nearest = &truths[t];
        held = truth_to_hyp[t] >= 0;
      }
    }
    auto bin = [](double d) {
      return d < 0.3 ? "<0.3" : d < 0.5 ? "0.3-0.5" : d < 1.0 ? "0.5-1" : d < 2.0 ? "1-2" : ">=2";
    };
    std::string s = "own ";
    s += std::isfinite(own_d) ? bin(own_d) : "gone";
    if (nearest != nullptr) {
      const double d = (z - nearest->p).norm();
      s += std::string(", z nearest ") +
           (nearest->id == last_truth ? "own"
            : held                    ? "other held"
                                      : "other untracked") +
           " " + bin(d);
    }
    s += std::string(", since match ") + (since_s < 0.2   ? "<0.2s"
                                          : since_s < 0.5 ? "0.2-0.5s"
                                          : since_s < 2   ? "0.5-2s"
                                                          : ">=2s");
    s += std::string(", age ") + (age_s < 2 ? "<2s" : age_s < 10 ? "2-10s" : ">=10s");
    s += ", pts " + std::to_string(std::min<std::uint32_t>(hyp.points, 9));
    return s;
  }

  // --explain, per sensor (the sensor at the origin): where a false scan lies from the nearest
  // object along the sensor's line of sight to it: "straight behind" (farther by more than
  // kMatchRadiusM, within kAcrossM of the ray), "in front", else "beside"; with the object's range.
  // A knee-height track on the mixed pixels between a person's legs and what is behind them lies
  // straight behind the person. Straight behind also says whether another track held that object
  // in this scan (a second track in its shadow) or none did (the false track is all the tracker
  // has of it), and how far behind it lies (0.5-1, 1-2, >= 2 m).
  static std::string LineOfSight(const Hypothesis& hyp, const std::vector<Truth>& truths,
                                 const std::vector<int>& truth_to_hyp) {
    constexpr double kAcrossM = 0.3;
    const Truth* nearest = nullptr;
    bool held = false;
    for (std::size_t t = 0; t < truths.size(); ++t) {
      if (nearest == nullptr || (hyp.p - truths[t].p).norm() < (hyp.p - nearest->p).norm()) {
        nearest = &truths[t];
        held = t < truth_to_hyp.size() && truth_to_hyp[t] >= 0;
      }
    }
    const std::string state = hyp.measured ? "measured" : "coasting";
    if (nearest == nullptr || !(nearest->p.norm() > 0.0)) return "no object in view, " + state;
    const Vector2d ray = nearest->p.normalized();
    const Vector2d d = hyp.p - nearest->p;
    const double along = d.dot(ray);
    const double across = std::abs(ray.x() * d.y() - ray.y() * d.x());
    const double range = nearest->p.norm();
    const std::string where = across > kAcrossM        ? "beside the nearest object"
                              : along > kMatchRadiusM  ? "straight behind the nearest object"
                              : along < -kMatchRadiusM ? "straight in front of the nearest object"
                                                       : "beside the nearest object";
    const std::string bin = range < 8.0    ? "< 8 m"
                            : range < 12.0 ? "8-12 m"
                            : range < 15.0 ? "12-15 m"
                                           : ">= 15 m";
    if (!(across > kAcrossM) && along > kMatchRadiusM) {
      char near_bin[32];
      std::snprintf(near_bin, sizeof near_bin, "%g-1 m", kMatchRadiusM);
      const std::string depth = along < 1.0 ? near_bin : along < 2.0 ? "1-2 m" : ">= 2 m";
      return where + " (" + (held ? "it tracked" : "it untracked") + ", " + depth +
             " behind), it at " + bin + ", " + state;
    }
    return where + ", it at " + bin + ", " + state;
  }

  // The class of a false positive: a track that held an object before ("left behind": its object
  // out of view now, held by another track, or visible and untracked but > kMatchRadiusM away), or
  // one that never held any: a second track within 1.5 m of an object another track holds (a
  // split), within 1.5 m of an untracked object (offset from it), of a door or chair (furniture
  // taken for a person), or of nothing (clutter: a background edge, noise, a shadow's border).
  static std::string FalseClass(const Hypothesis& hyp, bool ever_matched, std::size_t last_truth,
                                const std::vector<Truth>& truths,
                                const std::vector<int>& truth_to_hyp,
                                const std::vector<Vector2d>* furniture) {
    const std::string state = hyp.measured ? " (measured)" : " (coasting)";
    if (ever_matched) {
      for (std::size_t t = 0; t < truths.size(); ++t) {
        if (truths[t].id != last_truth) continue;
        return (truth_to_hyp[t] >= 0 ? "left behind: its object on another track"
                                     : "left behind: its object visible, untracked") +
               state;
      }
      return "left behind: its object out of view" + state;
    }
    double nearest = std::numeric_limits<double>::infinity();
    bool taken = false;
    for (std::size_t t = 0; t < truths.size(); ++t) {
      const double d = (hyp.p - truths[t].p).norm();
      if (d < nearest) {
        nearest = d;
        taken = truth_to_hyp[t] >= 0;
      }
    }
    if (nearest <= 1.5) {
      return (taken ? "never matched: beside an object another track holds (split)"
                    : "never matched: 0.5-1.5 m off an untracked object") +
             state;
    }
    if (furniture != nullptr) {
      for (const Vector2d& f : *furniture) {
        if ((hyp.p - f).norm() <= 1.5) return "never matched: door or chair" + state;
      }
    }
    return "never matched: far from every object (clutter)" + state;
  }

  Mot Finish() {
    Mot m = mot_;
    for (const auto& [id, h] : hyps_) {
      if (h.unmatched <= 0.5 * h.frames) continue;
      m.false_tracks += 1;
      const auto top =
          std::max_element(h.classes.begin(), h.classes.end(),
                           [](const auto& a, const auto& b) { return a.second < b.second; });
      if (top != h.classes.end()) causes_.false_track_classes[top->first] += 1;
    }
    for (const auto& [id, s] : state_) {
      m.missed_targets += (s.visible_s >= kMissedAfterS && !s.ever_matched) ? 1 : 0;
    }
    return m;
  }
  const Causes& causes() const { return causes_; }
  void set_breakdown(Breakdown* b) { breakdown_ = b; }

 private:
  Breakdown* breakdown_ = nullptr;
  struct TruthState {
    bool hidden_since_match = false;
    double hidden_s = 0;  // since the last match
    bool matched_last = false;
    bool ever_matched = false;
    bool interrupted = false;
    std::uint64_t last_hyp = 0;
    double visible_s = 0;
    double two_legs_at_s = -1;  // visible_s at its last two-leg measurement (--breakdown), -1 none
  };
  struct HypState {
    double frames = 0;
    double unmatched = 0;
    bool ever_matched = false;
    std::size_t last_truth = 0;
    double last_measured_s = 0;            // time of its last measured report (MotSequence's clock)
    double last_matched_s = 0;             // time of its last match
    std::uint64_t last_matched_frame = 0;  // frame number of its last match (from 1)
    bool parted = false;                   // a false scan since its last match
    Vector2d last_measured_p = Vector2d::Zero();
    std::string resumed_cls;  // what it came back on when last resumed
    double resumed_at_s = 0;
    std::map<std::string, double> classes;  // its false positives by FalseClass
  };
  static constexpr double kResumedAfterS = 1.0;
  void NoteResume(const Hypothesis& h, HypState& hs, double dt_s, const std::string& cls) {
    if (!h.measured || hs.frames == 0 || now_s_ + dt_s - hs.last_measured_s <= kResumedAfterS) {
      return;
    }
    const double jump = (h.p - hs.last_measured_p).norm();
    const double gap = now_s_ + dt_s - hs.last_measured_s;
    hs.resumed_cls = cls;
    hs.resumed_at_s = now_s_ + dt_s;
    causes_.resumes[cls] += 1;
    causes_.resumes[cls + (jump < 0.5   ? ", jump < 0.5 m"
                           : jump < 1.0 ? ", jump 0.5-1 m"
                           : jump < 2.0 ? ", jump 1-2 m"
                                        : ", jump >= 2 m")] += 1;
    causes_.resumes[cls + (gap < 1.5 ? ", gap < 1.5 s" : ", gap >= 1.5 s")] += 1;
  }

  Mot mot_;
  double now_s_ = 0;         // sum of the frames' dt_s
  std::uint64_t frame_ = 0;  // frames seen

 public:
  // The last Frame's partings, a track's first false scan since it last held an object: index
  // into its hyps, that object, and how many frames ago it held it.
  struct Parting {
    std::size_t hyp = 0;
    std::size_t truth_id = 0;
    std::uint64_t frames_since = 0;
  };
  const std::vector<Parting>& partings() const { return partings_; }
  // The last Frame's match of each hyp: the object's id, -1 unmatched.
  const std::vector<long>& matched_truth() const { return matched_truth_; }
  // The last Frame's false class of each hyp (FalseClass, empty when matched) and the object it
  // refers to (its last object when it held one, else the nearest; -1 none).
  const std::vector<std::string>& false_class() const { return false_class_; }
  const std::vector<long>& false_object() const { return false_object_; }

 private:
  std::vector<std::string> false_class_;
  std::vector<long> false_object_;
  std::vector<Parting> partings_;
  std::vector<long> matched_truth_;
  std::map<std::size_t, TruthState> state_;
  std::map<std::uint64_t, HypState> hyps_;
  std::map<std::uint64_t, double> hyp_age_;  // seconds reported
  Causes causes_;
};

// ---- the runs

bool Scored(sim::TargetShape s) {
  return s == sim::TargetShape::kPerson || s == sim::TargetShape::kCylinder ||
         s == sim::TargetShape::kTrolley;
}

struct Variant {
  std::string name;
  tracking::TrackerOptions options;
};

// --before-report-rules: a third tracker, "before", the new one as it was before coasting
// tracks were dropped where the scan shows nothing of them (shape.unseen_coasting_m = 0) and
// before a track was reported once its speed is clear (tracking.moving_speed_mps = 0).
bool g_before_report_rules = false;
// --before-mixed-pixels: "before" is the new tracker that takes knee-height mixed pixels for legs
// (ShapeOptions::drop_mixed_pixel_legs = false).
bool g_before_mixed_pixels = false;
// --before-far: "before" is the new tracker without the mixed-pixel model of far edges at
// upper-body height (ShapeOptions::mixed_pixel_min_footprint_m = 0). With --before-mixed-pixels:
// "before" has neither.
bool g_before_far = false;
// --before-evidence-coasting: "before" is the new tracker reporting every coasting track for
// report_coasting_s whatever its evidence (MultiTrackerOptions::report_coasting_per_measured_s =
// 0).
bool g_before_evidence_coasting = false;
// --before-one-leg: "before" is the new tracker measuring every single leg as the leg itself with
// the hip and stride extent (ShapeOptions::hidden_leg_behind = false). With the other --before-*
// options: without any of them.
bool g_before_one_leg = false;
// --before-confirm-time: "before" is the new tracker confirming by M of N alone, at every mount
// (MultiTrackerOptions::confirm_min_s = 0).
bool g_before_confirm_time = false;
// --before-whole-person: "before" drops knee-height mixed pixels beside a much nearer return only,
// not within the pairing distance of it (ShapeOptions::drop_mixed_pixel_legs_whole_person = false).
bool g_before_whole_person = false;
// --before-box-size: "before" reports a box's centre with its learned size's sigma however small
// (ShapeOptions::box_size_floor_sigma_m = 0).
bool g_before_box_size = false;
// --before-single-beam: "before" drops knee-height legs returned by a single beam, also beside a
// confirmed track (ShapeOptions::single_beam_legs = false).
bool g_before_single_beam = false;
// --before-single-beam-partner: "before" pairs no knee-height leg of a segment with a lone beam
// (ShapeOptions::single_beam_partner = false).
bool g_before_single_beam_partner = false;
// --before-edge-echo-birth: "before" lets a knee-height single leg beside a nearer edge start a
// track (ShapeOptions::edge_echo_no_birth = false).
bool g_before_edge_echo_birth = false;
// --before-lone-beam-echo: "before" takes a knee-height lone beam beside a nearer return (that
// edge's mixed echo) for a leg (ShapeOptions::lone_beam_edge_echo = false).
bool g_before_lone_beam_echo = false;
// --before-far-leg-birth: "before" lets knee-height legs start tracks also where a leg covers at
// most half of a beam's footprint (ShapeOptions::far_legs_no_birth = false).
bool g_before_far_leg_birth = false;
// --before-person-size: "before" runs with ShapeOptions::person_size_across_ray the other way
// round from the default (default off: "before" learns each semi-axis across the ray only).
bool g_before_person_size = false;
// --before-person-reach: "before" fits an upper-body person to every point of its segment
// (ShapeOptions::person_drop_beyond_reach = false).
bool g_before_person_reach = false;
// --before-partial-extent: "before" reports an upper-body partial view's shared covariance with
// the size's own sigma (ShapeOptions::partial_view_size_sigma_m = 0).
bool g_before_partial_extent = false;
// --before-neighbour: "before" reports an upper-body person with another object beside it as
// one alone (ShapeOptions::neighbour_sigma_m = 0).
bool g_before_neighbour = false;
// --before-segment-excess: "before" reports an upper-body person whose segment is wider than the
// body without the covariance of where along it the body lies
// (ShapeOptions::segment_excess_shared = false).
bool g_before_segment_excess = false;
// --before-box-view: "before" reports a track fitted as a body and measured from a box's outline
// (one face or two) without the covariance of where the box's centre lies
// (ShapeOptions::box_view_shared = false).
bool g_before_box_view = false;
// --before-box-view-torso: "before" applies box_view_shared at knee height only
// (ShapeOptions::box_view_at_torso = false).
bool g_before_box_view_torso = false;
// --before-gain-covariance: "before" reports a measured upper-body track with the filter's own
// covariance (MultiTrackerOptions::report_gain_covariance = false).
bool g_before_gain_covariance = false;
// --before-range-noise: "before" fits with the range noise growing by 1 mm per metre
// (ShapeFitOptions::point_sigma_per_m = 0.001).
bool g_before_range_noise = false;
// --before-deep-pieces: "before" measures knee-height pieces deep along the line of sight but no
// wider across it than a pair of legs as wide objects, also where a leg fills no beam
// (ShapeOptions::drop_deep_mixed_pixel_pieces = false).
bool g_before_deep_pieces = false;
// --before-deep-evidence: "before" drops such deep pieces by their shape alone, also where no
// surface stands behind them to mix with (ShapeOptions::deep_mixed_pixel_behind_ratio = 0).
bool g_before_deep_evidence = false;
// --before-isotropic-bias: "before" reports the centre's shared error in every direction alike
// (ShapeOptions::centre_bias_along_ray = false).
bool g_before_isotropic_bias = false;
// --before-across-walk: "before" measures a walking track's single leg (partner not hidden behind
// it) as the leg itself with the hip and stride extent, not hip_half_width_m across the walk from
// it (ShapeOptions::single_leg_across_walk = false).
bool g_before_across_walk = false;
// --before-side-uncertainty: "before" takes the side of the centre a walking track's single leg
// stands on as sure (ShapeOptions::single_leg_side_uncertainty = false).
bool g_before_side_uncertainty = false;
// --before-side-from-view: "before" takes the side of the centre a walking track's single leg
// stands on from the prediction alone (ShapeOptions::single_leg_side_from_view = false).
bool g_before_side_from_view = false;
// --before-lone-leg-standing: "before" takes a walking track's single leg's centre along the walk
// as anywhere within the legs' reach, also where the hidden leg stood at the last two-leg
// measurement (ShapeOptions::single_leg_from_standing = false).
bool g_before_lone_leg_standing = false;
// --before-few-point-legs: "before" fits a leg-sized segment of two or three points wider than a
// leg as one leg (ShapeOptions::split_few_point_legs = false).
bool g_before_few_point_legs = false;
// --before-deep-legs: "before" measures a knee-height segment of two or three points deeper along
// the line of sight than a leg as one leg also for a confirmed track
// (ShapeOptions::deep_legs_as_pair = false).
bool g_before_deep_legs = false;
// --before-legs-seen-through: "before" reports a knee-height coasting track also where the scan
// sees through every place its legs may stand (ShapeOptions::legs_seen_through = false).
bool g_before_legs_seen_through = false;
// --before-legs-report-coasting: "before" reports a knee-height coasting track for all of
// report_coasting_s (ShapeOptions::legs_report_coasting_s = 0).
bool g_before_legs_report_coasting = false;
// --before-legs-coasting-sigma: "before" reports a knee-height coasting track whatever its position
// sigma (ShapeOptions::legs_coasting_max_sigma_m = 0).
bool g_before_legs_coasting_sigma = false;
// --before-coasting-sigma: "before" reports an upper-body coasting track whatever its position
// sigma (ShapeOptions::coasting_max_sigma_m = 0).
bool g_before_coasting_sigma = false;
// --before-recent-veil: "before" takes a knee-height leg-sized segment behind a nearer return its
// beams had in the last scans for a leg (ShapeOptions::recent_veil_s = 0).
bool g_before_recent_veil = false;
// --before-single-precision-fit: "before" fits a person's outline with every point in double
// precision (ShapeFitOptions::single_precision_points = false).
bool g_before_single_precision_fit = false;
// --before-edge-sides: "before" turns each silhouette edge of a fit away from the fit's start (the
// track's prediction where one is taken) instead of away from the points
// (ShapeFitOptions::edges_face_points = false).
bool g_before_edge_sides = false;
// --before-outside-start: "before" starts a fit at the track's prediction also where it lies
// outside the silhouette (ShapeFitOptions::outside_guess_start = kGuess).
bool g_before_outside_start = false;
// --before-across-sway: "before" reports the centre with the sideways sway allowance across the
// ray as before (ShapeOptions::centre_bias_across_sigma_m = 0.006).
bool g_before_across_sway = false;
// --before-receded-edges: "before" takes a segment's end as a silhouette also where the beam
// beyond returned from the body's range over a background that receded there
// (ShapeOptions::receded_background_edge_m = 0).
bool g_before_receded_edges = false;
// --before-leg-edges: "before" takes a knee-height leg's silhouette edge half a step beyond its
// last returning beam also where the beam beyond is a mixed echo
// (ShapeOptions::leg_edge_in_mixed_beam = false).
bool g_before_leg_edges = false;
// --before-outline-departure: "before" reports an upper-body centre with the fixed allowances for
// the outline alone (ShapeOptions::outline_departure_gain = 0).
bool g_before_outline_departure = false;
// --before-partial-view: "before" reports an upper-body partial view (fewer than two silhouette
// ends) as a whole one, without its fit's covariance (ShapeOptions::partial_view_shared = false).
bool g_before_partial_view = false;
// --before-underdetermined-fit: "before" reports an upper-body fit of no more points and
// silhouette ends than its parameters as any other, without its fit's covariance
// (ShapeOptions::underdetermined_fit_shared = false).
bool g_before_underdetermined_fit = false;
// --before-stance-weight: "before" measures two legs by their midpoint also where one stands and
// the other swings (ShapeOptions::stance_leg_weight = 0.5).
bool g_before_stance_weight = false;
// --before-adopt: "before" leaves a track born beside a coasting one to itself, the coasting one
// reported until its time is up (MultiTrackerOptions::adopt_successor_m = 0).
bool g_before_adopt = false;
// --before-inherit-moved: "before" waits for a track born where a moved track was just lost to
// move by itself before reporting it (MultiTrackerOptions::inherit_moved_s = 0).
bool g_before_inherit_moved = false;
// --before-touching-legs: "before" measures two legs that touch in the scan with a pair's
// covariance (ShapeOptions::touching_legs_along_ray = false).
bool g_before_touching_legs = false;
// --before-occluded-gap: "before" reports two knee-height legs with something nearer between them
// with a pair's covariance (ShapeOptions::occluded_gap_depth_m = 0).
bool g_before_occluded_gap = false;
// --before-still-legs-cov: "before" reports a knee-height track's two legs seen still with a
// walking pair's covariance (ShapeOptions::still_legs_cov = false).
bool g_before_still_legs_cov = false;
// --before-walking-legs-cov: "before" reports a knee-height track's two legs seen walking with the
// gait allowance as noise the filter averages (ShapeOptions::walking_legs_cov = false).
bool g_before_walking_legs_cov = false;
// --before-still-legs: "before" takes a still knee-height track for a person's whatever the depth
// of its legs along the line of sight (ShapeOptions::still_legs_max_depth_m = 0).
bool g_before_still_legs = false;
// --before-mixed-legs: "before" fits a far knee-height leg to its points also where each may be a
// mixed pixel with a near background (ShapeOptions::mixed_leg_max_gap_m = 0).
bool g_before_mixed_legs = false;
// --before-mixed-leg-band: "before" gives a leg measured from mixed pixels' range deficits the
// radius' share of the whole gap along the ray (ShapeOptions::mixed_leg_band_variance = false).
bool g_before_mixed_leg_band = false;
// --before-box-occluders: "before" fits a box to every point of its segment, also those in front
// of it (ShapeOptions::box_drop_occluders = false).
bool g_before_box_occluders = false;
// --before-box-rejoin: "before" measures every segment on its own, also the pieces the width limit
// cuts a box's outline into (ShapeOptions::box_rejoin_pieces = false).
bool g_before_box_rejoin = false;
// --before-see-through: "before" measures every segment as one observation, also where beams saw
// through it between objects side by side (ShapeOptions::split_see_through = false).
bool g_before_see_through = false;
// --before-torso-edge-echo: "before" measures an upper-body segment of a footprint's beams beside a
// nearer return as any (ShapeOptions::torso_edge_echo = false).
bool g_before_torso_edge_echo = false;
// --before-step-seam: "before" measures a segment as one observation also where its range steps
// between two bodies that touch in the view (ShapeOptions::split_step_seam = false).
bool g_before_step_seam = false;
// --before-deep-tail: "before" measures a segment's end points deeper than its nearest point by
// more than a body with it (ShapeOptions::split_deep_tail = false).
bool g_before_deep_tail = false;
// --before-box-unseen-cov: "before" reports a box's size error as the same in every direction,
// also along an axis the scan does not show (ShapeOptions::box_unseen_depth_cov = false).
bool g_before_box_unseen_cov = false;
// --before-box-seen-extent: "before" widens a box's reported centre covariance along an axis only
// where this scan does not show its semi-axis, not where the track never saw it whole
// (ShapeOptions::box_seen_extent_cov = false).
bool g_before_box_seen_extent = false;
// --before-knee-box-faces: "before" learns a knee-height box's semi-axes from every fit
// (ShapeOptions::box_size_from_faces_seen_at_knee = false).
bool g_before_knee_box_faces = false;
// --before-fusion-merge: "before"'s fusion without merging fused tracks left without sources and
// reporting fused tracks no tracker holds any more (FusionOptions::merge_sourceless = false,
// report_sourceless = true).
bool g_before_fusion_merge = false;
// --before-report-sourceless: "before"'s fusion reports fused tracks no tracker holds any more as
// coasting (FusionOptions::report_sourceless = true).
bool g_before_report_sourceless = false;
const char* const kVariantNames[] = {"old", "new", "before"};
// --explain: why tracks coast beside a person the scan returned (CoastingCause).
bool g_explain_coasting = false;

std::vector<Variant> Variants(sim::Mount mount, double range_m) {
  tracking::TrackerOptions fresh;
  fresh.background.max_range_m = std::max(fresh.background.max_range_m, range_m + 1.0);
  fresh.shape.mount = mount == sim::Mount::kLegs ? tracking::Mount::kLegs : tracking::Mount::kTorso;
  tracking::TrackerOptions old = fresh;
  old.method = tracking::MeasurementMethod::kEllipse;
  old.tracking.static_objects = false;
  old.tracking.max_speed_mps = 1000.0;
  old.tracking.report_coasting_s = old.tracking.coast_timeout_s;
  old.tracking.report_coasting_per_measured_s = 0.0;
  old.tracking.recover_gate_mahalanobis_sq = 0.0;
  old.tracking.inflate_nis_above = 0.0;
  old.tracking.resume_window_s = 0.0;
  old.tracking.confirm_min_s = 0.0;
  old.shape.mixed_pixel_min_footprint_m = 0.0;
  old.shape.drop_mixed_pixel_legs = false;
  old.shape.drop_mixed_pixel_legs_whole_person = false;
  old.shape.mixed_leg_max_gap_m = 0.0;
  old.shape.still_legs_max_depth_m = 0.0;
  old.shape.split_step_seam = false;
  old.shape.split_deep_tail = false;
  old.tracking.report_gain_covariance = false;
  old.shape.hidden_leg_behind = false;
  old.shape.single_beam_legs = false;
  old.shape.single_beam_partner = false;
  old.shape.edge_echo_no_birth = false;
  old.shape.lone_beam_edge_echo = false;
  old.shape.far_legs_no_birth = false;
  old.shape.drop_deep_mixed_pixel_pieces = false;
  old.shape.single_leg_across_walk = false;
  old.shape.split_few_point_legs = false;
  old.shape.deep_legs_as_pair = false;
  old.shape.legs_report_coasting_s = 0.0;
  old.shape.legs_seen_through = false;
  old.shape.legs_coasting_max_sigma_m = 0.0;
  old.shape.coasting_max_sigma_m = 0.0;
  old.shape.recent_veil_s = 0.0;
  old.tracking.adopt_successor_m = 0.0;
  old.tracking.inherit_moved_s = 0.0;
  old.shape.single_leg_from_standing = false;
  std::vector<Variant> variants = {{"old", old}, {"new", fresh}};
  if (g_before_report_rules) {
    tracking::TrackerOptions before = fresh;
    before.shape.unseen_coasting_m = 0.0;
    before.tracking.moving_speed_mps = 0.0;
    variants.push_back({"before", before});
  } else if (g_before_mixed_pixels || g_before_far || g_before_evidence_coasting ||
             g_before_one_leg || g_before_confirm_time || g_before_whole_person ||
             g_before_box_size || g_before_single_beam || g_before_deep_pieces ||
             g_before_deep_evidence || g_before_isotropic_bias || g_before_across_walk ||
             g_before_side_uncertainty || g_before_side_from_view || g_before_few_point_legs ||
             g_before_deep_legs || g_before_legs_seen_through || g_before_legs_report_coasting ||
             g_before_legs_coasting_sigma || g_before_coasting_sigma || g_before_leg_edges ||
             g_before_outline_departure || g_before_partial_view || g_before_underdetermined_fit ||
             g_before_fusion_merge || g_before_report_sourceless || g_before_recent_veil ||
             g_before_single_precision_fit || g_before_edge_sides || g_before_outside_start ||
             g_before_across_sway || g_before_receded_edges || g_before_stance_weight ||
             g_before_adopt || g_before_inherit_moved || g_before_touching_legs ||
             g_before_still_legs_cov || g_before_walking_legs_cov || g_before_still_legs ||
             g_before_mixed_legs || g_before_mixed_leg_band || g_before_box_occluders ||
             g_before_box_rejoin || g_before_see_through || g_before_step_seam ||
             g_before_deep_tail || g_before_torso_edge_echo || g_before_box_unseen_cov ||
             g_before_box_seen_extent || g_before_knee_box_faces || g_before_lone_leg_standing ||
             g_before_single_beam_partner || g_before_edge_echo_birth || g_before_lone_beam_echo ||
             g_before_far_leg_birth || g_before_person_size || g_before_person_reach ||
             g_before_partial_extent || g_before_neighbour || g_before_segment_excess ||
             g_before_box_view || g_before_box_view_torso || g_before_range_noise ||
             g_before_gain_covariance || g_before_occluded_gap) {
    tracking::TrackerOptions before = fresh;
    if (g_before_one_leg) before.shape.hidden_leg_behind = false;
    if (g_before_mixed_pixels) before.shape.drop_mixed_pixel_legs = false;
    if (g_before_far) before.shape.mixed_pixel_min_footprint_m = 0.0;
    if (g_before_evidence_coasting) before.tracking.report_coasting_per_measured_s = 0.0;
    if (g_before_confirm_time) before.tracking.confirm_min_s = 0.0;
    if (g_before_whole_person) before.shape.drop_mixed_pixel_legs_whole_person = false;
    if (g_before_box_size) before.shape.box_size_floor_sigma_m = 0.0;
    if (g_before_single_beam) before.shape.single_beam_legs = false;
    if (g_before_isotropic_bias) before.shape.centre_bias_along_ray = false;
    if (g_before_deep_pieces) before.shape.drop_deep_mixed_pixel_pieces = false;
    if (g_before_deep_evidence) before.shape.deep_mixed_pixel_behind_ratio = 0.0;
    if (g_before_across_walk) before.shape.single_leg_across_walk = false;
    if (g_before_side_uncertainty) before.shape.single_leg_side_uncertainty = false;
    if (g_before_side_from_view) before.shape.single_leg_side_from_view = false;
    if (g_before_lone_leg_standing) before.shape.single_leg_from_standing = false;
    if (g_before_few_point_legs) before.shape.split_few_point_legs = false;
    if (g_before_deep_legs) before.shape.deep_legs_as_pair = false;
    if (g_before_legs_seen_through) before.shape.legs_seen_through = false;
    if (g_before_legs_report_coasting) before.shape.legs_report_coasting_s = 0.0;
    if (g_before_legs_coasting_sigma) before.shape.legs_coasting_max_sigma_m = 0.0;
    if (g_before_coasting_sigma) before.shape.coasting_max_sigma_m = 0.0;
    if (g_before_leg_edges) before.shape.leg_edge_in_mixed_beam = false;
    if (g_before_outline_departure) before.shape.outline_departure_gain = 0.0;
    if (g_before_partial_view) before.shape.partial_view_shared = false;
    if (g_before_underdetermined_fit) before.shape.underdetermined_fit_shared = false;
    if (g_before_recent_veil) before.shape.recent_veil_s = 0.0;
    if (g_before_single_precision_fit) before.shape.fit.single_precision_points = false;
    if (g_before_edge_sides) before.shape.fit.edges_face_points = false;
    if (g_before_across_sway) before.shape.centre_bias_across_sigma_m = 0.006;
    if (g_before_receded_edges) before.shape.receded_background_edge_m = 0.0;
    if (g_before_outside_start) {
      before.shape.fit.outside_guess_start = tracking::OutsideGuessStart::kGuess;
    }
    if (g_before_stance_weight) before.shape.stance_leg_weight = 0.5;
    if (g_before_adopt) before.tracking.adopt_successor_m = 0.0;
    if (g_before_inherit_moved) before.tracking.inherit_moved_s = 0.0;
    if (g_before_touching_legs) before.shape.touching_legs_along_ray = false;
    if (g_before_occluded_gap) before.shape.occluded_gap_depth_m = 0.0;
    if (g_before_still_legs_cov) before.shape.still_legs_cov = false;
    if (g_before_walking_legs_cov) before.shape.walking_legs_cov = false;
    if (g_before_still_legs) before.shape.still_legs_max_depth_m = 0.0;
    if (g_before_mixed_legs) before.shape.mixed_leg_max_gap_m = 0.0;
    if (g_before_mixed_leg_band) before.shape.mixed_leg_band_variance = false;
    if (g_before_box_occluders) before.shape.box_drop_occluders = false;
    if (g_before_box_rejoin) before.shape.box_rejoin_pieces = false;
    if (g_before_see_through) before.shape.split_see_through = false;
    if (g_before_torso_edge_echo) before.shape.torso_edge_echo = false;
    if (g_before_step_seam) before.shape.split_step_seam = false;
    if (g_before_deep_tail) before.shape.split_deep_tail = false;
    if (g_before_box_unseen_cov) before.shape.box_unseen_depth_cov = false;
    if (g_before_box_seen_extent) before.shape.box_seen_extent_cov = false;
    if (g_before_knee_box_faces) before.shape.box_size_from_faces_seen_at_knee = false;
    if (g_before_single_beam_partner) before.shape.single_beam_partner = false;
    if (g_before_edge_echo_birth) before.shape.edge_echo_no_birth = false;
    if (g_before_lone_beam_echo) before.shape.lone_beam_edge_echo = false;
    if (g_before_far_leg_birth) before.shape.far_legs_no_birth = false;
    if (g_before_person_size) {
      before.shape.person_size_across_ray = !fresh.shape.person_size_across_ray;
    }
    if (g_before_person_reach) before.shape.person_drop_beyond_reach = false;
    if (g_before_partial_extent) before.shape.partial_view_size_sigma_m = 0.0;
    if (g_before_neighbour) before.shape.neighbour_sigma_m = 0.0;
    if (g_before_segment_excess) before.shape.segment_excess_shared = false;
    if (g_before_box_view) before.shape.box_view_shared = false;
    if (g_before_box_view_torso) before.shape.box_view_at_torso = false;
    if (g_before_gain_covariance) before.tracking.report_gain_covariance = false;
    if (g_before_range_noise) before.shape.fit.point_sigma_per_m = 0.001;
    variants.push_back({"before", before});
  }
  return variants;
}

daemon::TrackObservation ToObservation(const tracking::TrackReport& r) {
  daemon::TrackObservation o;
  o.track_id = r.track_id;
  o.state = r.state == tracking::TrackState::kConfirmed  ? daemon::TrackState::kConfirmed
            : r.state == tracking::TrackState::kCoasting ? daemon::TrackState::kCoasting
                                                         : daemon::TrackState::kTentative;
  o.kind = r.kind == tracking::MeasurementKind::kShapeFit  ? daemon::MeasurementKind::kShapeFit
           : r.kind == tracking::MeasurementKind::kEllipse ? daemon::MeasurementKind::kEllipse
                                                           : daemon::MeasurementKind::kCenterOfMass;
  o.x_m = static_cast<float>(r.x_m);
  o.y_m = static_cast<float>(r.y_m);
  o.vx_mps = static_cast<float>(r.vx_mps);
  o.vy_mps = static_cast<float>(r.vy_mps);
  std::size_t k = 0;
  for (int row = 0; row < 4; ++row) {
    for (int col = row; col < 4; ++col)
      o.covariance[k++] = static_cast<float>(r.covariance(row, col));
  }
  o.age_scans = r.age_scans;
  o.points = r.points;
  o.ellipse_yaw_rad = static_cast<float>(r.ellipse_yaw_rad);
  o.size_major_m = static_cast<float>(r.size_major_m);
  o.size_minor_m = static_cast<float>(r.size_minor_m);
  o.size_sigma_m = static_cast<float>(r.size_sigma_m);
  return o;
}

// The scan's observation a measured track was updated with: of those with `points` points, the one
// whose measurement lies nearest z; obs.size() when none has that many.
std::size_t ObservationOf(std::span<const tracking::Observation> obs,
                          std::span<const tracking::Measurement> ms, const Eigen::Vector2d& z,
                          std::size_t points) {
  double best = std::numeric_limits<double>::infinity();
  std::size_t found = obs.size();
  for (std::size_t i = 0; i < obs.size() && i < ms.size(); ++i) {
    std::size_t n = 0;
    for (std::size_t k = 0; k < obs[i].part_count; ++k) n += obs[i].parts[k].point_count;
    const double d = (ms[i].position_m - z).norm();
    if (n == points && d < best) {
      best = d;
      found = i;
    }
  }
  return found;
}

// --breakdown: what the measurement of a track measured in this scan was made of (a kPartsBins
// index): the pipeline's observation with the track's point count whose first position lies
// nearest to the refined measurement.
std::size_t PartsOf(const tracking::TrackingPipeline& pipeline, const tracking::TrackReport& r) {
  const auto obs = pipeline.observations();
  const auto ms = pipeline.measurements();
  const Vector2d z(r.measured_x_m, r.measured_y_m);
  if (r.state != tracking::TrackState::kConfirmed) {
    // Coasting: an observation it could have taken?
    for (const tracking::Measurement& m : ms) {
      if ((m.position_m - Vector2d(r.x_m, r.y_m)).norm() < 0.5) return 6;
    }
    return 0;
  }
  const std::size_t found = ObservationOf(obs, ms, z, r.points);
  if (found == obs.size()) return 0;
  const tracking::Observation& ob = obs[found];
  if (pipeline.options().shape.mount == tracking::Mount::kTorso) return 1;
  if (!ob.legs) return 5;
  if (ob.part_count == 2) return 4;
  if (ob.partner_behind) return 7;
  const auto pts =
      pipeline.segments().points_m.span().subspan(ob.parts[0].first_point, ob.parts[0].point_count);
  const tracking::ShapeOptions& o = pipeline.options().shape;
  return (pts.back() - pts.front()).norm() > 2.0 * o.leg_radius_m + 0.08 ? 3 : 2;
}

// --breakdown: the silhouette ends (MakePart: not an occluder's edge nor the field of view's end)
// of the observation a measured track was updated with, -1 where not found.
int EdgesOf(const tracking::TrackingPipeline& pipeline, const tracking::TrackReport& r) {
  if (r.state != tracking::TrackState::kConfirmed) return -1;
  const auto obs = pipeline.observations();
  const auto ms = pipeline.measurements();
  const Vector2d z(r.measured_x_m, r.measured_y_m);
  const std::size_t found = ObservationOf(obs, ms, z, r.points);
  if (found == obs.size() || obs[found].part_count == 0) return -1;
  const tracking::Observation& ob = obs[found];
  return (ob.parts[0].silhouette.first_valid ? 1 : 0) +
         (ob.parts[ob.part_count - 1].silhouette.last_valid ? 1 : 0);
}

// The truth matched to a hypothesis (its id; the last of equal ids, nullptr when none).
const Truth* TruthById(const std::vector<Truth>& truths, long id) {
  const Truth* t = nullptr;
  for (const Truth& c : truths) t = static_cast<long>(c.id) == id ? &c : t;
  return t;
}

// The range at which beam `beam` of `sensor` meets target `target`'s body at that beam's time
// (sim::kNoHit where it misses or the target is absent); yaw_rad, origin: the sensor's pose.
double BodyRangeOnBeam(const sim::Simulator& simulator, std::size_t sensor,
                       const tracking::ScanView& scan, double start_s, std::size_t target,
                       std::size_t beam) {
  const sim::SensorSetup& setup = simulator.sensor(sensor);
  const double a = common::DegToRad(setup.yaw_deg) + scan.BeamAngleRad(beam);
  const double t_beam = start_s + static_cast<double>(beam) * setup.device.beam_time_s;
  const sim::Target& tg = simulator.targets()[target];
  const sim::TargetState st = tg.StateAt(t_beam);
  if (!st.present) return sim::kNoHit;
  return tg.Intersect({{setup.x_m, setup.y_m}, {std::cos(a), std::sin(a)}}, st, setup.mount);
}

// --explain, knee height: every measured match of a person, its measurement's error along the
// line of sight binned by what made it (Causes::los): all of them ("all ...") and those off by at
// least 0.1 m ("off ..."), by the observation's class, point count, range, sign (nearer / farther
// than the truth), which of the true legs its points lie on, how much of the farther leg the
// nearer hides, its silhouette ends (outline or occluded) and mixed-beam edges, the points' depth
// along the ray, the fitted leg radius against the true one.
void LineOfSightErrors(const tracking::TrackingPipeline& pipeline, const tracking::ScanView& scan,
                       const tracking::ScanTracks& out, const std::vector<Hypothesis>& hyps,
                       const std::vector<Truth>& truths, const std::vector<long>& matched,
                       std::map<std::string, std::array<double, 4>>* los) {
  const auto obs = pipeline.observations();
  const auto ms = pipeline.measurements();
  for (std::size_t hi = 0; hi < hyps.size() && hi < matched.size(); ++hi) {
    const Hypothesis& h = hyps[hi];
    if (!h.measured || matched[hi] < 0) continue;
    const Truth* t = TruthById(truths, matched[hi]);
    if (t == nullptr || t->leg_radius_m <= 0.0) continue;
    const tracking::TrackReport* rep = nullptr;
    for (const tracking::TrackReport& r : out.tracks) rep = r.track_id == h.id ? &r : rep;
    if (rep == nullptr) continue;
    // Its observation (as PartsOf finds it).
    const std::size_t found = ObservationOf(obs, ms, h.z, rep->points);
    if (found == obs.size()) continue;
    const tracking::Observation& ob = obs[found];
    const double range = t->p.norm();
    if (!(range > 0.0)) continue;
    const Vector2d u = t->p / range;
    const Vector2d ez = h.z - (t->p + h.z_offset_s * t->v);
    const double er = ez.dot(u);
    const std::optional<Matrix2d> refined = pipeline.RefinedCovariance(found);
    if (!refined) continue;  // not refined in this scan
    const Matrix2d& R = *refined;
    const double var_r = u.dot(R * u);
    const double nees_r = var_r > 0.0 ? er * er / var_r : 0.0;
    double nees = 0.0;
    {
      const Eigen::LDLT<Matrix2d> ldlt(R);
      if (ldlt.info() == Eigen::Success && R(0, 0) * R(1, 1) - R(0, 1) * R(1, 0) > 0.0)
        nees = ez.dot(ldlt.solve(ez));
    }
    const std::size_t parts = h.parts;
    const std::string cls = std::string(kPartsBins[parts]).substr(7);
    const std::string pts = rep->points <= 1   ? "1"
                            : rep->points <= 3 ? "2-3"
                            : rep->points <= 6 ? "4-6"
                                               : "7+";
    const std::string rng = range < 5.0 ? "<5" : range < 10.0 ? "5-10" : ">=10";
    const std::string sign = er < 0.0 ? "nearer" : "farther";
    // The legs: the nearer (n) and the farther (f); how much of f's bearing interval n covers.
    const std::size_t n = t->legs[0].norm() <= t->legs[1].norm() ? 0 : 1, f = 1 - n;
    const double lr = t->leg_radius_m;
    const auto bearing = [](const Vector2d& p) { return std::atan2(p.y(), p.x()); };
    const double hn = std::asin(std::min(1.0, lr / t->legs[n].norm()));
    const double hf = std::asin(std::min(1.0, lr / t->legs[f].norm()));
    const double dn = std::remainder(bearing(t->legs[f]) - bearing(t->legs[n]), 2.0 * common::kPi);
    const double cover =
        std::clamp((std::min(dn + hf, hn) - std::max(dn - hf, -hn)) / (2.0 * hf), 0.0, 1.0);
    const std::string hidden = cover >= 0.9  ? "far leg hidden"
                               : cover > 0.1 ? "far leg partly hidden"
                                             : "legs apart";
    // Which legs its points lie on (within 3 cm of the circle), and points on neither.
    std::size_t on_n = 0, on_f = 0, other = 0;
    double depth_lo = std::numeric_limits<double>::infinity(), depth_hi = -depth_lo;
    int edges = 0, mixed_edges = 0;
    for (std::size_t k = 0; k < ob.part_count; ++k) {
      const tracking::ObservationPart& part = ob.parts[k];
      const auto p =
          pipeline.segments().points_m.span().subspan(part.first_point, part.point_count);
      for (const Vector2d& q : p) {
        const double a = std::abs((q - t->legs[n]).norm() - lr);
        const double b = std::abs((q - t->legs[f]).norm() - lr);
        if (std::min(a, b) > 0.03) {
          ++other;
        } else if (a <= b) {
          ++on_n;
        } else {
          ++on_f;
        }
        depth_lo = std::min(depth_lo, q.dot(u));
        depth_hi = std::max(depth_hi, q.dot(u));
      }
      edges += (part.silhouette.first_valid ? 1 : 0) + (part.silhouette.last_valid ? 1 : 0);
      mixed_edges +=
          (part.first_edge_in_mixed_beam ? 1 : 0) + (part.last_edge_in_mixed_beam ? 1 : 0);
    }
    const std::string on = std::string(on_n > 0 && on_f > 0 ? "both legs"
                                       : on_n > 0           ? "nearer leg"
                                       : on_f > 0           ? "farther leg"
                                                            : "no leg") +
                           (other > 0 ? " + other points" : "");
    const double depth = depth_hi - depth_lo;
    const std::string dep = depth < 0.06 ? "<0.06" : depth < 0.12 ? "0.06-0.12" : ">=0.12";
    const std::string edge = std::to_string(edges) + " outline ends of " +
                             std::to_string(2 * ob.part_count) + ", mixed " +
                             std::to_string(mixed_edges);
    const double fit_r = pipeline.LegRadius(found, 0);
    const std::string rad = fit_r - lr < -0.02  ? "fit r < true - 2cm"
                            : fit_r - lr > 0.02 ? "fit r > true + 2cm"
                                                : "fit r within 2cm";
    // Two parts: beams between them (0: touching, the farther may be echoes mixed between the
    // nearer and what lies behind), the farther part's points, their depth apart along the ray.
    std::string pair;
    if (ob.part_count == 2) {
      const std::size_t gap = ob.parts[1].begin_beam >= ob.parts[0].end_beam
                                  ? ob.parts[1].begin_beam - ob.parts[0].end_beam
                                  : 0;
      const auto centre_of = [&](const tracking::ObservationPart& part) {
        const auto p =
            pipeline.segments().points_m.span().subspan(part.first_point, part.point_count);
        double r = std::numeric_limits<double>::infinity();
        for (const Vector2d& q : p) r = std::min(r, q.norm());
        return r;
      };
      const double r0 = centre_of(ob.parts[0]), r1 = centre_of(ob.parts[1]);
      const std::size_t far_points = r0 > r1 ? ob.parts[0].point_count : ob.parts[1].point_count;
      const double apart = std::abs(r0 - r1);
      pair = std::string(gap == 0   ? "touching"
                         : gap <= 2 ? "gap 1-2 beams"
                                    : "gap 3+ beams") +
             ", far part " +
             (far_points == 1   ? "1 pt"
              : far_points <= 3 ? "2-3 pts"
                                : "4+ pts") +
             ", depth apart " +
             (apart < 0.1   ? "<0.1"
              : apart < 0.2 ? "0.1-0.2"
                            : ">=0.2") +
             (ob.deep_pair ? ", deep pair" : "");
      // Each part's fitted leg against the nearest true leg, along the ray: which is off.
      std::string part_err;
      for (std::size_t k = 0; k < 2; ++k) {
        const Vector2d c = pipeline.LegCentre(found, k);
        const Vector2d& tl =
            (c - t->legs[0]).norm() < (c - t->legs[1]).norm() ? t->legs[0] : t->legs[1];
        const double e = (c - tl).dot(tl.normalized());
        const bool is_far = (k == 0) == (r0 > r1);
        part_err += std::string(is_far ? " far " : " near ") + (e < -0.1    ? "<-0.1"
                                                                : e < -0.04 ? "-0.1..-0.04"
                                                                : e < 0.04  ? "ok"
                                                                : e < 0.1   ? "0.04..0.1"
                                                                            : ">0.1");
      }
      pair += ";" + part_err;
    }
    // One leg: the beams that returned from the true leg its points do not lie on (within 3 cm of
    // its circle), and whether those are in a segment.
    std::string other_leg;
    if (ob.part_count == 1) {
      const std::size_t seen = on_n >= on_f ? n : f;
      const Vector2d& o_leg = t->legs[1 - seen];
      int hits = 0, in_segment = 0;
      bool in_obs = false;
      for (std::size_t b = 0; b < scan.range_m.size(); ++b) {
        const float rb = scan.range_m[b];
        if (!(std::isfinite(rb) && rb > 0.0f)) continue;
        const double a = scan.BeamAngleRad(b);
        const Vector2d q = static_cast<double>(rb) * Vector2d(std::cos(a), std::sin(a));
        if (std::abs((q - o_leg).norm() - lr) > 0.03) continue;
        ++hits;
        for (const tracking::Observation& any : obs) {
          for (std::size_t k = 0; k < any.part_count; ++k) {
            if (b >= any.parts[k].begin_beam && b < any.parts[k].end_beam) in_obs = true;
          }
        }
        for (const tracking::Segment& sg : pipeline.segments().segments) {
          if (b >= sg.begin_beam && b < sg.end_beam) {
            ++in_segment;
            break;
          }
        }
      }
      const std::string where = std::string(in_segment == 0     ? ", in no segment"
                                            : in_segment < hits ? ", partly in a segment"
                                                                : ", in a segment") +
                                (in_obs ? ", in an observation" : ", in none");
      other_leg = "other leg " +
                  std::string(hits == 0   ? "unseen"
                              : hits == 1 ? "1 beam"
                                          : "2+ beams") +
                  (hits > 0 ? where : "");
    }
    const std::string keys[] = {
        "",
        cls,
        cls + " | " + other_leg,
        cls + " | " + other_leg + ", " + hidden,
        cls + " | pair " + pair,
        cls + " | pair " + pair.substr(0, pair.find(',')) + ", " + sign,
        cls + " | pts " + pts,
        cls + " | range " + rng,
        cls + " | " + sign,
        cls + " | " + hidden,
        cls + " | on " + on,
        cls + " | " + edge,
        cls + " | depth " + dep,
        cls + " | " + rad,
        cls + " | " + sign + ", " + hidden + ", on " + on,
    };
    const bool off = std::abs(er) >= 0.1;
    for (const std::string& key : keys) {
      for (const char* which : {"all", "off"}) {
        if (which[0] == 'o' && !off) continue;
        auto& a = (*los)[std::string(which) + " " + key];
        a[0] += 1;
        a[1] += std::abs(er);
        a[2] += nees_r;
        a[3] += nees;
      }
    }
  }
}

// --explain, upper-body height: every measured match of a person, binned by what lies beyond each
// end of its observation's outline and whether the tracker took that end for a silhouette
// (Causes::torso_ends): "real" where the ray of the beam beyond the end misses the person's body
// (at that beam's time), else hidden, by that beam's return against the end point's range r_e and
// the body's range on that beam (no return; nearer than r_e by less or more than 0.1 m; between
// r_e and the body; at the body) and whether another object's body returned it; "end point off the
// body" where the end point lies more than 0.05 m off the body along its beam. Count, summed radial
// error of the measurement (signed: + away from the sensor), summed squares, summed NEES of the
// reported track.
void TorsoEndErrors(const tracking::TrackingPipeline& pipeline, const tracking::ScanView& scan,
                    const sim::Simulator& simulator, std::size_t sensor, double start_s,
                    const std::vector<Hypothesis>& hyps, const std::vector<Truth>& truths,
                    const std::vector<long>& matched,
                    std::map<std::string, std::array<double, 4>>* ends) {
  const auto obs = pipeline.observations();
  const auto ms = pipeline.measurements();
  const std::size_t beams = scan.range_m.size();
  for (std::size_t hi = 0; hi < hyps.size() && hi < matched.size(); ++hi) {
    const Hypothesis& h = hyps[hi];
    if (!h.measured || matched[hi] < 0) continue;
    const Truth* t = TruthById(truths, matched[hi]);
    if (t == nullptr || (t->a_m <= 0.0 && !t->trolley) || h.edges < 0) continue;
    // Its observation (as EdgesOf finds it).
    const std::size_t found = ObservationOf(obs, ms, h.z, h.points);
    if (found == obs.size() || obs[found].part_count == 0) continue;
    const tracking::Observation& ob = obs[found];
    const double range = t->p.norm();
    if (!(range > 0.0)) continue;
    const auto body_range = [&](std::size_t target, std::size_t beam) {
      return BodyRangeOnBeam(simulator, sensor, scan, start_s, target, beam);
    };
    // Where the end point is another object's: from that end inwards, the first point on the
    // person's body; the range step there and how far the foreign end point lies from the track.
    const auto foreign = [&](bool last_end) {
      const tracking::ObservationPart& part = ob.parts[last_end ? ob.part_count - 1 : 0];
      const auto pts =
          pipeline.segments().points_m.span().subspan(part.first_point, part.point_count);
      const std::size_t n = pts.size();
      const Vector2d end_point = last_end ? pts[n - 1] : pts[0];
      for (std::size_t k = 0; k < n; ++k) {
        const std::size_t i = last_end ? n - 1 - k : k;
        const double a = std::atan2(pts[i].y(), pts[i].x());
        const long beam = std::lround((a - scan.first_angle_rad) / scan.angle_step_rad);
        if (beam < 0 || static_cast<std::size_t>(beam) >= beams) continue;
        const double d = body_range(t->id, static_cast<std::size_t>(beam));
        if (!(std::abs(d - pts[i].norm()) < 0.05)) continue;
        if (k == 0) return std::string(" [no foreign run]");
        const std::size_t j = last_end ? i + 1 : i - 1;
        const double step = pts[j].norm() - pts[i].norm();
        const double from_track = (end_point - h.p).norm();
        return std::string(" [run ") + (k > 3 ? std::string("4+") : std::to_string(k)) +
               " pts, step " +
               (step > 0.08    ? "behind"
                : step < -0.08 ? "in front"
                               : "none") +
               ", end point " +
               (from_track > 0.4   ? "> 0.4"
                : from_track > 0.3 ? "0.3-0.4"
                                   : "< 0.3") +
               " m from track]";
      }
      return std::string(" [no point on the body]");
    };
    const auto classify = [&](bool judged, std::size_t edge_beam, long beyond_signed,
                              const Vector2d& edge_point) {
      std::string c = judged ? "taken " : "left out ";
      if (beyond_signed < 0 || static_cast<std::size_t>(beyond_signed) >= beams) {
        return c + "field of view";
      }
      const std::size_t beyond = static_cast<std::size_t>(beyond_signed);
      const double r_e = edge_point.norm();
      const double d_edge = body_range(t->id, edge_beam);
      bool edge_other = false;
      for (std::size_t j = 0; j < simulator.targets().size(); ++j) {
        if (j != t->id && std::abs(body_range(j, edge_beam) - r_e) < 0.1) edge_other = true;
      }
      const std::string mixed =
          !std::isfinite(d_edge)
              ? (edge_other ? ", end point another object's" +
                                  foreign(static_cast<long>(edge_beam) < beyond_signed)
                            : ", end point off the body (beside it)")
          : r_e < d_edge - 0.05 ? ", end point off the body (nearer)"
          : r_e > d_edge + 0.05 ? ", end point off the body (farther)"
                                : "";
      const double d_body = body_range(t->id, beyond);
      if (!std::isfinite(d_body)) return c + "real" + mixed;
      const double r = static_cast<double>(scan.range_m[beyond]);
      c += "hidden: ";
      if (!(std::isfinite(r) && r > 0.0)) return c + "no return" + mixed;
      bool other = false;
      for (std::size_t j = 0; j < simulator.targets().size(); ++j) {
        if (j != t->id && std::abs(body_range(j, beyond) - r) < 0.1) other = true;
      }
      const std::string who = other ? " (another object)" : " (background)";
      if (std::abs(r - d_body) < 0.05) return c + "at the body" + mixed;
      if (r > d_body) return c + "behind the body" + mixed;
      if (r < r_e - 0.1) return c + "nearer than the end by >= 0.1 m" + who + mixed;
      if (r <= r_e) return c + "nearer than the end by < 0.1 m" + who + mixed;
      return c + "between the end and the body" + who + mixed;
    };
    const tracking::ObservationPart& first = ob.parts[0];
    const tracking::ObservationPart& last = ob.parts[ob.part_count - 1];
    const auto pts = pipeline.segments().points_m.span();
    const std::string a = classify(first.silhouette.first_valid, first.begin_beam,
                                   static_cast<long>(first.begin_beam) - 1, pts[first.first_point]);
    const std::string b =
        classify(last.silhouette.last_valid, last.end_beam - 1, static_cast<long>(last.end_beam),
                 pts[last.first_point + last.point_count - 1]);
    const Vector2d u = t->p / range;
    const double er = (h.z - (t->p + h.z_offset_s * t->v)).dot(u);
    double nees = 0.0;
    const Eigen::LDLT<Matrix2d> ldlt(h.cov);
    if (ldlt.info() == Eigen::Success) nees = (h.p - t->p).dot(ldlt.solve(h.p - t->p));
    const std::string occl = std::string(t->trolley ? "trolley, " : "person, ") +
                             (t->occluded ? "nearer return beside | " : "unoccluded | ");
    for (const std::string& key :
         {std::string("all ") + occl + std::to_string(h.edges) + " ends",
          std::string("end ") + occl + a, std::string("end ") + occl + b}) {
      auto& s = (*ends)[key];
      s[0] += 1;
      s[1] += er;
      s[2] += er * er;
      s[3] += nees;
    }
  }
}

// --explain, upper-body height: every match of a person more than kFarOffM off (Causes::far_off),
// by what the track was updated with: coasting (a nearer return beside the person or not);
// measured on a measurement within kFarOffM of the truth (the filter off, not its input); else by
// the observation's points (each by its beam: on the person's body within 0.05 m, on another
// object's within 0.1 m, else background): some of another object's, none on the body, some of
// the background, or the body's alone (a nearer return beside it or not, its silhouette ends, the
// points' extent across the ray against the body's width 2a), and whether another reported track
// lies within 1 m. Count, summed error, summed NEES; "~person matches": every match of a person.
constexpr double kFarOffM = 0.25;
void FarOffErrors(const tracking::TrackingPipeline& pipeline, const tracking::ScanView& scan,
                  const sim::Simulator& simulator, std::size_t sensor, double start_s,
                  const std::vector<Hypothesis>& hyps, const std::vector<Truth>& truths,
                  const std::vector<long>& matched,
                  std::map<std::string, std::array<double, 4>>* far) {
  const auto obs = pipeline.observations();
  const auto ms = pipeline.measurements();
  const std::size_t beams = scan.range_m.size();
  std::size_t person_matches = 0;
  std::vector<std::pair<std::string, std::array<double, 2>>> rows;
  for (std::size_t hi = 0; hi < hyps.size() && hi < matched.size(); ++hi) {
    const Hypothesis& h = hyps[hi];
    if (matched[hi] < 0) continue;
    const Truth* t = TruthById(truths, matched[hi]);
    if (t == nullptr || t->a_m <= 0.0 || t->trolley) continue;
    ++person_matches;
    const double err = (h.p - t->p).norm();
    if (!(err > kFarOffM)) continue;
    double nees = 0.0;
    const Eigen::LDLT<Matrix2d> ldlt(h.cov);
    if (ldlt.info() == Eigen::Success) nees = (h.p - t->p).dot(ldlt.solve(h.p - t->p));
    bool near_track = false;
    for (std::size_t o = 0; o < hyps.size(); ++o) {
      if (o != hi && (hyps[o].p - h.p).norm() < 1.0) near_track = true;
    }
    const std::string occl = t->occluded ? "nearer return beside" : "unoccluded";
    const std::string crowd = near_track ? ", another track within 1 m" : "";
    std::string key;
    const std::size_t found = h.measured ? ObservationOf(obs, ms, h.z, h.points) : obs.size();
    const Vector2d ez = h.z - (t->p + h.z_offset_s * t->v);
    if (!h.measured) {
      key = "coasting, " + occl + crowd;
    } else if (ez.norm() <= kFarOffM) {
      key = "measured, its measurement within 0.25 m (the filter off)" + crowd;
    } else if (found == obs.size() || obs[found].part_count == 0) {
      key = "measured, observation not found";
    } else {
      const tracking::Observation& ob = obs[found];
      const auto body_range = [&](std::size_t target, std::size_t beam) {
        return BodyRangeOnBeam(simulator, sensor, scan, start_s, target, beam);
      };
      std::size_t own = 0, other = 0, background = 0;
      double lo = std::numeric_limits<double>::infinity(), hi_a = -lo;
      const double bearing = std::atan2(t->p.y(), t->p.x());
      const auto pts = pipeline.segments().points_m.span();
      for (std::size_t pi = 0; pi < ob.part_count; ++pi) {
        const tracking::ObservationPart& part = ob.parts[pi];
        for (std::size_t k = 0; k < part.point_count; ++k) {
          const Vector2d& q = pts[part.first_point + k];
          const double a = std::atan2(q.y(), q.x());
          const long beam = std::lround((a - scan.first_angle_rad) / scan.angle_step_rad);
          if (beam < 0 || static_cast<std::size_t>(beam) >= beams) continue;
          const double r = q.norm();
          if (std::abs(body_range(t->id, static_cast<std::size_t>(beam)) - r) < 0.05) {
            ++own;
            const double across = std::remainder(a - bearing, 2.0 * common::kPi) * r;
            lo = std::min(lo, across);
            hi_a = std::max(hi_a, across);
            continue;
          }
          bool o = false;
          for (std::size_t j = 0; j < simulator.targets().size() && !o; ++j) {
            if (j != t->id && std::abs(body_range(j, static_cast<std::size_t>(beam)) - r) < 0.1)
              o = true;
          }
          ++(o ? other : background);
        }
      }
      if (own == 0) {
        key = std::string("measured, no point on its body") +
              (other > 0 ? " (another object's)" : " (background)") + crowd;
      } else if (other > 0) {
        key = std::string("measured, another object's points too (") +
              (other == 1   ? "1"
               : other <= 3 ? "2-3"
                            : "4+") +
              "), " + occl + crowd;
      } else if (background > 0) {
        key = "measured, background points too, " + occl + crowd;
      } else {
        const double seen = own > 1 ? (hi_a - lo) / (2.0 * t->a_m) : 0.0;
        key = "measured, its own points alone, " + occl + ", " + std::to_string(h.edges) +
              " ends, extent " +
              (seen < 0.33   ? "< 1/3"
               : seen < 0.67 ? "1/3-2/3"
                             : ">= 2/3") +
              " of 2a" + crowd;
      }
    }
    rows.push_back({key, {err, nees}});
  }
  for (const auto& [key, v] : rows) {
    auto& s = (*far)[key];
    s[0] += 1;
    s[1] += v[0];
    s[2] += v[1];
  }
  (*far)["all (> 0.25 m off)"][0] += static_cast<double>(rows.size());
  for (const auto& [key, v] : rows) (*far)["all (> 0.25 m off)"][1] += v[0];
  for (const auto& [key, v] : rows) (*far)["all (> 0.25 m off)"][2] += v[1];
  (*far)["~person matches"][0] += static_cast<double>(person_matches);
}

struct SensorFrames {
  std::string id;
  std::vector<daemon::TrackFrameData> frames;  // per scan
  std::vector<std::vector<std::size_t>> seen;  // per scan: targets visible to this sensor
};

struct RunResult {
  std::vector<Mot> per_sensor;  // per variant, summed over sensors
  // The same summed over the sensors of each mount ("torso", "legs"), per variant: the totals
  // count a sensor by its own mount (a scenario "as given" mixes them).
  std::map<std::string, std::vector<Mot>> per_sensor_by_mount;
  std::vector<Causes> causes;                                  // per variant, summed over sensors
  std::map<std::string, std::vector<Causes>> causes_by_mount;  // as per_sensor_by_mount
  std::vector<Causes> fused_causes;                            // per variant
  std::vector<tracking::MultiTrackerCounters> counters;        // per variant, summed over sensors
  std::vector<Mot> fused;                                      // per variant
  std::vector<Breakdown> breakdown;                            // per variant, per sensor summed
  std::map<std::string, std::vector<Breakdown>> breakdown_by_mount;  // as per_sensor_by_mount
  double scans = 0;
  double track_seconds = 0;
  double cpu_s = 0;
};

// --explain, per sensor: what the scan shows across a coasting track's body (the beams within
// shape.person_major_m + 2 sigma of its reported position to either side, as the see-through rule
// takes them): "at it" (an echo within that reach of its range; foreground, or background only),
// "behind a nearer return" (an echo nearer, none at it), "seen through" (every echo more than
// shape.seen_through_margin_m beyond it, at least 2), else "no echo"; with the track's range and
// whether the beams lie closer than a leg's width (shape.leg_radius_m) there (a leg cannot fall
// between two beams). Measured false scans are tagged with what the measurement was made of
// (kPartsBins), the range and the point count instead. On stderr as "false scans, what was
// there", per class (Causes::false_views).
std::string CoastingView(const tracking::TrackingPipeline& pipeline, const tracking::ScanView& scan,
                         const Vector2d& p, const Matrix2d& cov) {
  const tracking::ShapeOptions& o = pipeline.options().shape;
  const double range = p.norm();
  const double sigma = std::sqrt(std::max(0.0, 0.5 * cov.trace()));
  const double reach = o.person_major_m + 2.0 * sigma;
  const std::string bin = range < 5.0    ? "< 5 m"
                          : range < 10.0 ? "5-10 m"
                          : range < 15.0 ? "10-15 m"
                                         : ">= 15 m";
  const bool dense = range * scan.angle_step_rad <= 2.0 * o.leg_radius_m;
  const std::string where = bin + (dense ? ", beams < a leg apart" : ", beams >= a leg apart");
  if (!(range > reach)) return "at the sensor, " + where;
  const double bearing = std::atan2(p.y(), p.x());
  const double half = std::atan(reach / range);
  std::size_t at = 0, at_foreground = 0, nearer = 0, beyond = 0;
  const auto fg = pipeline.background().foreground();
  for (std::size_t b = 0; b < scan.range_m.size(); ++b) {
    const double a = scan.first_angle_rad + static_cast<double>(b) * scan.angle_step_rad;
    if (std::abs(std::remainder(a - bearing, 2.0 * M_PI)) > half) continue;
    const double r = static_cast<double>(scan.range_m[b]);
    if (!(r > 0.0)) continue;
    if (r < range - reach) {
      ++nearer;
    } else if (r <= range + o.seen_through_margin_m) {
      ++at;
      if (b < fg.size() && fg[b] != 0) ++at_foreground;
    } else {
      ++beyond;
    }
  }
  const std::string what = at_foreground > 0 ? "at it, foreground"
                           : at > 0          ? "at it, background only"
                           : nearer > 0      ? "behind a nearer return"
                           : beyond >= 2     ? "seen through"
                                             : "no echo";
  return what + ", " + where;
}

// --explain: why a track coasts beside a person the scan returned, from the pipeline's stages
// around the person's true centre (returns within kCoastingNearM of it): the returns' fate in
// background model, segmentation (min_points), the legs' observations (Veiled, the shadow rule)
// and association (an observation near the person that the track did not take: how far its first
// position lay from the track, whether it was one leg or two).
constexpr double kCoastingNearM = 0.4;
std::string CoastingCause(const tracking::TrackingPipeline& pipeline,
                          const tracking::ScanView& scan, const Vector2d& truth_m,
                          const Vector2d& track_m) {
  const auto near = [&](const Vector2d& p) { return (p - truth_m).norm() <= kCoastingNearM; };
  std::size_t raw = 0, foreground = 0;
  const auto fg = pipeline.background().foreground();
  for (std::size_t b = 0; b < scan.range_m.size(); ++b) {
    const float r = scan.range_m[b];
    if (!(std::isfinite(r) && r > 0.0f)) continue;
    const double a = scan.first_angle_rad + static_cast<double>(b) * scan.angle_step_rad;
    if (!near(static_cast<double>(r) * Vector2d(std::cos(a), std::sin(a)))) continue;
    ++raw;
    if (b < fg.size() && fg[b] != 0) ++foreground;
  }
  if (raw == 0) return "a: no return near the person (drop-outs, far returns)";
  if (raw == 1) {
    return foreground == 1 ? "a: one return near the person, foreground"
                           : "a: one return near the person, background";
  }
  if (foreground == 0) return "b: no return near the person foreground";
  const tracking::SegmentList& segs = pipeline.segments();
  std::size_t seg_points = 0;
  for (const Vector2d& p : segs.points_m.span()) seg_points += near(p) ? 1 : 0;
  if (seg_points == 0) {
    return foreground == 1 ? "c: one foreground return (below segmentation.min_points)"
                           : "c: foreground returns in no segment (min_points)";
  }
  const auto obs = pipeline.observations();
  const auto ms = pipeline.measurements();
  double best = std::numeric_limits<double>::infinity();
  std::size_t best_i = obs.size();
  for (std::size_t i = 0; i < obs.size(); ++i) {
    bool hit = false;
    for (std::size_t k = 0; k < obs[i].part_count && !hit; ++k) {
      const auto pts =
          segs.points_m.span().subspan(obs[i].parts[k].first_point, obs[i].parts[k].point_count);
      for (const Vector2d& p : pts) hit = hit || near(p);
    }
    if (!hit || i >= ms.size()) continue;
    const double d = (ms[i].position_m - track_m).norm();
    if (d < best) {
      best = d;
      best_i = i;
    }
  }
  if (best_i == obs.size()) {
    return seg_points == 1 ? "d: segment point near, no observation (veiled, shadowed), 1 point"
                           : "d: segment points near, no observation (veiled, shadowed)";
  }
  const tracking::Observation& ob = obs[best_i];
  std::size_t points = 0;
  for (std::size_t k = 0; k < ob.part_count; ++k) points += ob.parts[k].point_count;
  const char* what = !ob.legs ? "wide" : ob.part_count == 2 ? "two legs" : "one leg";
  const char* dist = best < 0.2   ? "< 0.2 m"
                     : best < 0.4 ? "0.2-0.4 m"
                     : best < 0.7 ? "0.4-0.7 m"
                                  : ">= 0.7 m";
  return std::string("e: observation not taken, ") + what + (points <= 2 ? " (<= 2 points)" : "") +
         ", first position " + dist + " from the track";
}

// The tracker over every scan of one sensor, for every variant.
void RunSensor(const sim::Simulator& simulator, std::size_t sensor,
               const std::vector<Variant>& variants, std::vector<Mot>* mots,
               std::vector<SensorFrames>* frames, std::vector<Causes>* causes,
               std::vector<tracking::MultiTrackerCounters>* counters,
               std::vector<Breakdown>* breakdowns) {
  const sim::SensorSetup& setup = simulator.sensor(sensor);
  const common::Pose2 world_from_sensor{setup.x_m, setup.y_m, common::DegToRad(setup.yaw_deg)};
  const common::Pose2 sensor_from_world = world_from_sensor.inverse();
  std::vector<std::unique_ptr<tracking::TrackingPipeline>> pipelines;
  std::vector<MotSequence> sequences(variants.size());
  for (std::size_t v = 0; v < variants.size(); ++v) sequences[v].set_breakdown(&(*breakdowns)[v]);
  // The scanner's echo separation from its DeviceIdent name, as lrfnet-tracker takes it from the
  // device's start-up dialogue (TrackerNode::SetDeviceIdentity).
  const double resolved_echo_m = tracking::ResolvedEchoSeparationM(
      setup.device.model != nullptr ? setup.device.model->ident_name : "");
  for (std::size_t v = 0; v < variants.size(); ++v) {
    pipelines.push_back(std::make_unique<tracking::TrackingPipeline>(variants[v].options));
    pipelines.back()->SetResolvedEchoSeparation(resolved_echo_m);
  }
  for (std::size_t v = 0; v < variants.size(); ++v) (*frames)[v].id = setup.id;
  auto telegram = std::make_unique<cola::ScanTelegram>();
  auto polar = std::make_unique<cola::PolarScan>();
  std::vector<std::uint32_t> hits;
  const std::int64_t start_ns = simulator.scenario().start_utc_ns;
  const double period_s = setup.device.period_s;
  // --explain, what a track starts to coast from (Causes::coast_start, "coast start" on stderr):
  // per variant, per track, its last three measured reports in a row: the reported position and
  // velocity, what the measurement was made of (kPartsBins) and its point count, the object it
  // matched, the report's and the measurement's error against it, and how far the update moved
  // the report from the previous one predicted on (a measurement that pulls the state). At a
  // track's first coasting scan on the object it matched in the scan before, its error is binned
  // by those, beside the error the state before its last update, predicted on, would have had.
  struct CoastEntry {
    Vector2d p = Vector2d::Zero(), v = Vector2d::Zero();
    std::size_t parts = 0, truth = 0;
    std::uint32_t points = 0;
    bool has_truth = false;
    double raw_err = 0, filt_err = 0, move = 0;
  };
  struct CoastHist {
    std::uint64_t frame = 0;  // k + 1 of its last report
    bool measured = false;    // that report measured
    int run = 0;              // measured reports in a row up to it
    std::array<CoastEntry, 3> e;
  };
  std::vector<std::map<std::uint64_t, CoastHist>> coast_hist(variants.size());
  // --explain: where each track was first reported: how far from the nearest object and whether
  // another track held that object then.
  std::vector<std::map<std::uint64_t, std::string>> birth(variants.size());
  for (std::uint64_t k = 0; k < setup.scan_count; ++k) {
    const sim::ScanTiming timing = simulator.Timing(sensor, k);
    simulator.SimulateScan(sensor, k, telegram.get(), &hits);
    if (!cola::ToPolarScan(*telegram, polar.get())) continue;
    tracking::ScanView view;
    view.first_angle_rad = polar->first_angle_rad;
    view.angle_step_rad = polar->angle_step_rad;
    view.range_m = std::span<const float>(polar->range_m.data(), polar->count);
    view.scan_period_s = polar->scan_frequency_hz > 0 ? 1.0 / polar->scan_frequency_hz : period_s;
    view.stamp_ns = start_ns + static_cast<std::int64_t>(std::llround(timing.start_s * 1e9));
    // The truth at the scan start, in this sensor's frame.
    std::vector<Truth> truths;
    std::vector<Vector2d> dont_care, furniture;
    std::vector<std::size_t> seen;
    for (const sim::TruthSample& ts : simulator.TruthAt(timing.start_s)) {
      const sim::Target& target = simulator.targets()[ts.target];
      const Vector2d p = sensor_from_world * Vector2d(ts.state.center.x, ts.state.center.y);
      const Vector2d vel =
          sensor_from_world.rotation() * Vector2d(ts.state.velocity_mps.x, ts.state.velocity_mps.y);
      // Doors and chairs, and people hidden in this scan (a track may coast on them), are neither
      // to be tracked nor false.
      if (!Scored(target.shape()) || hits[ts.target] < kMinHits) {
        dont_care.push_back(p);
        if (!Scored(target.shape())) furniture.push_back(p);
        continue;
      }
      Truth truth{ts.target, p, vel, target.shape() == sim::TargetShape::kTrolley};
      if (target.shape() == sim::TargetShape::kPerson) {
        truth.legs[0] = sensor_from_world * Vector2d(ts.state.legs[0].x, ts.state.legs[0].y);
        truth.legs[1] = sensor_from_world * Vector2d(ts.state.legs[1].x, ts.state.legs[1].y);
        truth.leg_radius_m = target.body().leg_radius_m;
      }
      const double range = p.norm();
      if (target.shape() == sim::TargetShape::kPerson && ts.state.speed_mps > kWalkingMps &&
          range > 0.0) {
        const Vector2d l0 = sensor_from_world * Vector2d(ts.state.legs[0].x, ts.state.legs[0].y);
        const Vector2d l1 = sensor_from_world * Vector2d(ts.state.legs[1].x, ts.state.legs[1].y);
        const double phase = ts.state.gait_phase + (l0.norm() <= l1.norm() ? 0.0 : 0.5);
        truth.gait = phase - std::floor(phase) < sim::kStanceFraction ? 0 : 1;
        if (vel.norm() > 0.0) truth.legs_spread_m = std::abs((l0 - l1).dot(vel.normalized()));
        const double p0 = ts.state.gait_phase - std::floor(ts.state.gait_phase);
        const double p1 = ts.state.gait_phase + 0.5 - std::floor(ts.state.gait_phase + 0.5);
        truth.legs_support = p0 < sim::kStanceFraction && p1 < sim::kStanceFraction ? 1 : 0;
      }
      if (truth.trolley && range > 0.0 && vel.norm() > kWalkingMps) {
        const double c = std::abs(vel.dot(p)) / (vel.norm() * range);
        truth.view = c > std::cos(kViewSectorRad)   ? (vel.dot(p) < 0.0 ? 0 : 3)
                     : c < std::sin(kViewSectorRad) ? 2
                                                    : 1;
      }
      truth.rate_hz = period_s > 0.0 ? 1.0 / period_s : 0.0;
      truth.model = ModelBin(setup.device.model != nullptr ? setup.device.model->key : "");
      double extent_m = 0.3;
      if (target.shape() == sim::TargetShape::kPerson) {
        truth.a_m = target.body().a_m;
        truth.exponent = target.body().exponent;
        extent_m = target.body().a_m;
      }
      if (range > extent_m) {
        const double bearing = std::atan2(p.y(), p.x());
        const double half = std::atan(extent_m / range) + 2.0 * view.angle_step_rad;
        for (std::size_t b = 0; b < view.range_m.size() && !truth.occluded; ++b) {
          const double a = view.first_angle_rad + static_cast<double>(b) * view.angle_step_rad;
          if (std::abs(std::remainder(a - bearing, 2.0 * common::kPi)) > half) continue;
          const double r = static_cast<double>(view.range_m[b]);
          truth.occluded = r > 0.0 && r < range - extent_m - 0.1;
        }
      }
      truths.push_back(truth);
      seen.push_back(ts.target);
    }
    for (Truth& t : truths) {
      for (const Truth& o : truths) {
        if (&o != &t) t.nearest_other_m = std::min(t.nearest_other_m, (o.p - t.p).norm());
      }
      for (const Vector2d& o : dont_care) {
        t.nearest_other_m = std::min(t.nearest_other_m, (o - t.p).norm());
      }
    }
    for (std::size_t v = 0; v < variants.size(); ++v) {
      const tracking::ScanTracks& out = pipelines[v]->Process(view, static_cast<std::uint32_t>(k));
      std::vector<Hypothesis> hyps;
      daemon::TrackFrameData frame;
      frame.session_id = 1;
      frame.scan_start_ns = out.scan_start_ns;
      frame.scan_period_s = out.scan_period_s;
      frame.scan_counter = static_cast<std::uint32_t>(k);
      for (const tracking::TrackReport& r : out.tracks) {
        if (r.state == tracking::TrackState::kTentative) continue;
        std::string coasting_view;
        if (g_explain_coasting && r.state == tracking::TrackState::kCoasting) {
          coasting_view =
              CoastingView(*pipelines[v], view, {r.x_m, r.y_m}, r.covariance.topLeftCorner<2, 2>());
        } else if (g_explain_coasting) {
          const double range = std::hypot(r.x_m, r.y_m);
          coasting_view = std::string("measured: ") + kPartsBins[PartsOf(*pipelines[v], r)] +
                          (range < 10.0   ? ", < 10 m"
                           : range < 15.0 ? ", 10-15 m"
                                          : ", >= 15 m") +
                          ", " + std::to_string(r.points) + " points";
        }
        hyps.push_back({r.track_id,
                        {r.x_m, r.y_m},
                        r.covariance.topLeftCorner<2, 2>(),
                        r.state == tracking::TrackState::kConfirmed,
                        r.points,
                        {r.measured_x_m, r.measured_y_m},
                        r.measured_offset_s,
                        PartsOf(*pipelines[v], r),
                        EdgesOf(*pipelines[v], r),
                        std::move(coasting_view),
                        r.shape == tracking::ObjectShape::kBox,
                        r.age_scans});
        frame.tracks.push_back(ToObservation(r));
      }
      std::array<tracking::TrackPrediction, tracking::kMaxTracks> predictions;
      const std::size_t n_alive = pipelines[v]->tracker().Predict(out.scan_start_ns, predictions);
      std::set<std::uint64_t> alive;
      for (std::size_t a = 0; a < n_alive; ++a) alive.insert(predictions[a].id);
      sequences[v].Frame(period_s, truths, hyps, dont_care, &alive, &furniture);
      if (g_explain_coasting && pipelines[v]->options().shape.mount == tracking::Mount::kLegs) {
        LineOfSightErrors(*pipelines[v], view, out, hyps, truths, sequences[v].matched_truth(),
                          &(*causes)[v].los);
      }
      if (g_explain_coasting && pipelines[v]->options().shape.mount == tracking::Mount::kTorso) {
        TorsoEndErrors(*pipelines[v], view, simulator, sensor, timing.start_s, hyps, truths,
                       sequences[v].matched_truth(), &(*causes)[v].torso_ends);
        FarOffErrors(*pipelines[v], view, simulator, sensor, timing.start_s, hyps, truths,
                     sequences[v].matched_truth(), &(*causes)[v].far_off);
      }
      if (g_explain_coasting) {
        for (std::size_t hi = 0; hi < hyps.size(); ++hi) {
          if (birth[v].count(hyps[hi].id)) continue;
          double nd = std::numeric_limits<double>::infinity();
          long nid = -1;
          for (const Truth& t : truths) {
            if ((hyps[hi].p - t.p).norm() < nd) {
              nd = (hyps[hi].p - t.p).norm();
              nid = static_cast<long>(t.id);
            }
          }
          bool held = false;
          for (std::size_t o = 0; o < hyps.size(); ++o) {
            held = held || (o != hi && sequences[v].matched_truth()[o] == nid);
          }
          birth[v][hyps[hi].id] = std::string(nd < 0.5   ? "on an object"
                                              : nd < 1.0 ? "0.5-1 m off"
                                              : nd < 1.5 ? "1-1.5 m off"
                                                         : "far") +
                                  (nd < 1.5 ? (held ? ", held by another" : ", untracked") : "");
        }
      }
      if (g_explain_coasting) {
        const auto bin = [](double d, double a, double b) {
          return d < a   ? "<" + std::to_string(static_cast<int>(a * 100)) + "cm"
                 : d < b ? std::to_string(static_cast<int>(a * 100)) + "-" +
                               std::to_string(static_cast<int>(b * 100)) + "cm"
                         : ">=" + std::to_string(static_cast<int>(b * 100)) + "cm";
        };
        const auto part = [](std::size_t parts) {
          return std::string(kPartsBins[parts]).substr(7);
        };
        for (std::size_t hi = 0; hi < hyps.size(); ++hi) {
          const Hypothesis& h = hyps[hi];
          const tracking::TrackReport* rep = nullptr;
          for (const tracking::TrackReport& r : out.tracks) rep = r.track_id == h.id ? &r : rep;
          const Vector2d vel =
              rep != nullptr ? Vector2d(rep->vx_mps, rep->vy_mps) : Vector2d::Zero();
          CoastHist& ch = coast_hist[v][h.id];
          const bool consecutive = ch.frame == k && ch.measured && ch.run > 0;
          // The object this scan matched the track to.
          const Truth* matched = nullptr;
          for (const Truth& t : truths) {
            if (static_cast<long>(t.id) == sequences[v].matched_truth()[hi]) matched = &t;
          }
          if (!h.measured && consecutive && ch.e[0].has_truth) {
            const Truth* own = matched;  // still the object its last measurement matched
            if (own != nullptr && own->id == ch.e[0].truth) {
              const double ec = (h.p - own->p).norm();
              double ea = 0, na = 0;
              if (ch.run >= 2) {
                ea = (ch.e[1].p + 2.0 * period_s * ch.e[1].v - own->p).norm();
                na = 1;
              }
              const CoastEntry& l = ch.e[0];
              const std::string pts = std::to_string(std::min<std::uint32_t>(l.points, 5));
              const std::string prev = ch.run >= 2 ? part(ch.e[1].parts) : "none";
              const std::string last = part(l.parts);
              const std::string filt = bin(l.filt_err, 0.05, 0.1);
              const std::string raw = bin(l.raw_err, 0.05, 0.1);
              const std::string keys[] = {
                  "all",
                  "last " + last + ", pts " + pts,
                  "last raw err " + raw,
                  "last filt err " + filt,
                  "last move " + bin(l.move, 0.03, 0.08),
                  "last two: " + last + " <- " + prev,
                  "run " + std::to_string(std::min(ch.run, 5)),
                  "range " + std::string(own->p.norm() < 5    ? "<5"
                                         : own->p.norm() < 10 ? "5-10"
                                                              : ">=10"),
                  "filt " + filt + ": last " + last + ", raw " + raw,
                  "filt " + filt + ": filt before " +
                      (ch.run >= 2 ? bin(ch.e[1].filt_err, 0.05, 0.1) : "none") + ", " +
                      (ch.run >= 3 ? bin(ch.e[2].filt_err, 0.05, 0.1) : "none"),
                  "filt " + filt + ": speed " + (own->v.norm() < 0.3 ? "<0.3" : "walking") +
                      ", radial " +
                      bin(std::abs((l.p - own->p).dot(own->p.normalized())), 0.05, 0.1),
              };
              for (const std::string& key : keys) {
                auto& a = (*causes)[v].coast_start[key];
                a[0] += 1;
                a[1] += ec;
                a[2] += ea;
                a[3] += na;
              }
            }
          }
          CoastEntry e;
          e.p = h.p;
          e.v = vel;
          e.parts = h.parts;
          e.points = h.points;
          if (consecutive) e.move = (h.p - (ch.e[0].p + period_s * ch.e[0].v)).norm();
          if (matched != nullptr) {
            e.has_truth = true;
            e.truth = matched->id;
            e.filt_err = (h.p - matched->p).norm();
            e.raw_err = (h.z - (matched->p + h.z_offset_s * matched->v)).norm();
          }
          if (h.measured) {
            ch.run = consecutive ? ch.run + 1 : 1;
            ch.e[2] = ch.e[1];
            ch.e[1] = ch.e[0];
            ch.e[0] = e;
          } else {
            ch.run = 0;
          }
          ch.measured = h.measured;
          ch.frame = k + 1;
        }
        for (const MotSequence::Parting& parting : sequences[v].partings()) {
          const Hypothesis& h = hyps[parting.hyp];
          const Truth* own = nullptr;
          for (const Truth& t : truths) own = t.id == parting.truth_id ? &t : own;
          std::string why;
          if (own == nullptr) {
            why =
                std::string("c: its object out of view, ") + (h.measured ? "measured" : "coasting");
          } else if (!h.measured) {
            why = "a: coasting, its object visible: " +
                  CoastingCause(*pipelines[v], view, own->p, h.p);
          } else {
            const double d = (h.z - own->p).norm();
            const auto it = coast_hist[v].find(h.id);
            why = std::string("b: measured ") +
                  (it != coast_hist[v].end() && it->second.frame == k + 1 && it->second.run >= 2
                       ? "after measured, "
                       : "after coasting, ") +
                  (d < 0.5   ? "< 0.5 m"
                   : d < 1.0 ? "0.5-1 m"
                             : ">= 1 m") +
                  " from its object, on " + kPartsBins[h.parts] + ", " +
                  std::to_string(std::min<std::uint32_t>(h.points, 9)) + " points";
          }
          (*causes)[v].partings[why] += 1.0;
          (*causes)[v]
              .partings[std::string(why.substr(0, 2)) +
                        (parting.frames_since <= 1   ? " (all): held it the scan before"
                         : parting.frames_since <= 5 ? " (all): held it 2-5 scans before"
                                                     : " (all): held it > 5 scans before")] += 1.0;
        }
        for (std::size_t hi = 0; hi < hyps.size(); ++hi) {
          const std::string& cls = sequences[v].false_class()[hi];
          const bool left = cls.rfind("left behind: its object visible, untracked", 0) == 0;
          const bool off = cls.rfind("never matched: 0.5-1.5 m off", 0) == 0;
          if (!left && !off) continue;
          const Truth* obj = nullptr;
          for (const Truth& t : truths) {
            if (static_cast<long>(t.id) == sequences[v].false_object()[hi]) obj = &t;
          }
          if (obj == nullptr) continue;
          const Hypothesis& h = hyps[hi];
          // The nearest other live track at the object.
          double best = kMatchRadiusM;
          const tracking::TrackPrediction* at = nullptr;
          for (std::size_t a = 0; a < n_alive; ++a) {
            if (predictions[a].id == h.id) continue;
            const double d = (predictions[a].position_m - obj->p).norm();
            if (d < best) {
              best = d;
              at = &predictions[a];
            }
          }
          bool reported = false;
          for (const Hypothesis& o : hyps) reported = reported || (at != nullptr && o.id == at->id);
          const std::string holder = at == nullptr    ? "none at it"
                                     : !at->confirmed ? "a tentative track at it"
                                     : reported       ? "a reported track at it (unmatched?)"
                                                      : "a confirmed unreported track at it";
          const double dist = (h.p - obj->p).norm();
          const std::string prefix =
              std::string(left ? "left" : "off") + (h.measured ? " measured" : " coasting");
          auto& u = (*causes)[v].untracked;
          u[prefix + " | holder: " + holder] += 1;
          u[prefix + " | returns: " + CoastingCause(*pipelines[v], view, obj->p, h.p)] += 1;
          u[prefix + " | track-object " +
            (dist < 0.7   ? "0.5-0.7 m"
             : dist < 1.0 ? "0.7-1 m"
             : dist < 1.5 ? "1-1.5 m"
                          : ">= 1.5 m")] += 1;
          u[prefix + " | object speed " + (obj->v.norm() < 0.3 ? "< 0.3" : "walking") + ", range " +
            (obj->p.norm() < 5    ? "< 5"
             : obj->p.norm() < 10 ? "5-10"
                                  : ">= 10")] += 1;
          if (off) {
            const auto b = birth[v].find(h.id);
            if (b != birth[v].end()) u[prefix + " | first reported: " + b->second] += 1;
          }
        }
        for (const Truth& t : truths) {
          const Hypothesis* nearest = nullptr;
          double best = kMatchRadiusM;
          for (const Hypothesis& h : hyps) {
            const double d = (h.p - t.p).norm();
            if (d < best) {
              best = d;
              nearest = &h;
            }
          }
          if (nearest != nullptr && !nearest->measured) {
            (*causes)[v].coasting[CoastingCause(*pipelines[v], view, t.p, nearest->p)] += 1.0;
          }
        }
      }
      (*frames)[v].frames.push_back(std::move(frame));
      (*frames)[v].seen.push_back(seen);
    }
  }
  for (std::size_t v = 0; v < variants.size(); ++v) {
    (*mots)[v].Add(sequences[v].Finish());
    const auto coasting = std::move((*causes)[v].coasting);
    const auto partings = std::move((*causes)[v].partings);
    const auto untracked = std::move((*causes)[v].untracked);
    const auto coast_start = std::move((*causes)[v].coast_start);
    const auto los = std::move((*causes)[v].los);
    const auto torso_ends = std::move((*causes)[v].torso_ends);
    const auto far_off = std::move((*causes)[v].far_off);
    (*causes)[v] = sequences[v].causes();
    (*causes)[v].torso_ends = torso_ends;
    (*causes)[v].far_off = far_off;
    (*causes)[v].coast_start = coast_start;
    (*causes)[v].los = los;
    (*causes)[v].coasting = coasting;
    (*causes)[v].partings = partings;
    (*causes)[v].untracked = untracked;
    (*counters)[v] = pipelines[v]->tracker().counters();
  }
}

Mot RunFusion(const sim::Simulator& simulator, const std::vector<SensorFrames>& sensors,
              const fusion::FusionOptions& options, Causes* causes) {
  fusion::Fuser fuser(options);
  std::vector<fusion::SensorPlacement> placements;
  for (std::size_t i = 0; i < simulator.sensor_count(); ++i) {
    const sim::SensorSetup& s = simulator.sensor(i);
    fusion::SensorPlacement p;
    p.id = s.id;
    p.world_from_sensor = {s.x_m, s.y_m, common::DegToRad(s.yaw_deg)};
    p.covariance = Eigen::Vector3d(1e-6, 1e-6, 1e-8).asDiagonal();
    placements.push_back(p);
  }
  fuser.SetPlacements(placements);
  struct Item {
    common::UtcNs t;
    std::size_t sensor, frame;
  };
  std::vector<Item> items;
  for (std::size_t s = 0; s < sensors.size(); ++s) {
    for (std::size_t f = 0; f < sensors[s].frames.size(); ++f) {
      items.push_back({sensors[s].frames[f].scan_start_ns, s, f});
    }
  }
  std::stable_sort(items.begin(), items.end(),
                   [](const Item& a, const Item& b) { return a.t < b.t; });
  const std::int64_t start_ns = simulator.scenario().start_utc_ns;
  const auto step_ns = static_cast<common::DurationNs>(kFusionStepS * 1e9);
  common::UtcNs next_ns = start_ns + step_ns;
  std::vector<std::size_t> latest(sensors.size(), SIZE_MAX);  // latest frame of each sensor
  MotSequence sequence;
  auto evaluate = [&](common::UtcNs now_ns) {
    fuser.Tick(now_ns);
    std::set<std::size_t> seen;
    for (std::size_t s = 0; s < sensors.size(); ++s) {
      if (latest[s] == SIZE_MAX) continue;
      for (std::size_t target : sensors[s].seen[latest[s]]) seen.insert(target);
    }
    const double t_s = static_cast<double>(now_ns - start_ns) * 1e-9;
    std::vector<Truth> truths;
    std::vector<Vector2d> dont_care;
    for (const sim::TruthSample& ts : simulator.TruthAt(t_s)) {
      const Vector2d p(ts.state.center.x, ts.state.center.y);
      if (Scored(simulator.targets()[ts.target].shape()) && seen.count(ts.target)) {
        truths.push_back({ts.target, p});
      } else {
        dont_care.push_back(p);
      }
    }
    std::vector<Hypothesis> hyps;
    for (const fusion::FusedTrack& f : fuser.Snapshot(now_ns)) {
      Hypothesis h;
      h.id = f.id;
      h.p = {f.x_m, f.y_m};
      h.cov = f.covariance.topLeftCorner<2, 2>();
      h.measured = f.state == fusion::FusedState::kConfirmed;
      hyps.push_back(std::move(h));
    }
    sequence.Frame(kFusionStepS, truths, hyps, dont_care);
  };
  for (const Item& item : items) {
    while (item.t > next_ns) {
      evaluate(next_ns);
      next_ns += step_ns;
    }
    fuser.AddFrame(sensors[item.sensor].id, sensors[item.sensor].frames[item.frame]);
    latest[item.sensor] = item.frame;
  }
  Mot m = sequence.Finish();
  *causes = sequence.causes();
  return m;
}

void AddCounters(const tracking::MultiTrackerCounters& c, tracking::MultiTrackerCounters* sum) {
  sum->created += c.created;
  sum->confirmed += c.confirmed;
  sum->deleted_tentative += c.deleted_tentative;
  sum->deleted_coast_timeout += c.deleted_coast_timeout;
  sum->deleted_covariance += c.deleted_covariance;
  sum->deleted_static += c.deleted_static;
  sum->births_suppressed += c.births_suppressed;
  sum->refine_failures += c.refine_failures;
  sum->speed_clamps += c.speed_clamps;
  sum->associations += c.associations;
  sum->recovered += c.recovered;
  sum->resumed += c.resumed;
  sum->adopted += c.adopted;
  sum->inherited_moved += c.inherited_moved;
}

// --explain: the causes and the tracker's counters of one run, per variant, on stderr.
void Explain(const std::string& scenario, const std::string& mount, const RunResult& r) {
  const char* const* names = kVariantNames;
  for (std::size_t v = 0; v < r.causes.size(); ++v) {
    const tracking::MultiTrackerCounters& c = r.counters[v];
    std::fprintf(
        stderr,
        "%s %s %s: created %llu confirmed %llu deleted: tentative %llu coast %llu "
        "covariance %llu static %llu; births suppressed %llu refine failures %llu speed "
        "clamps %llu recovered %llu resumed %llu adopted %llu "
        "inherited moved %llu\n",
        scenario.c_str(), mount.c_str(), names[v], static_cast<unsigned long long>(c.created),
        static_cast<unsigned long long>(c.confirmed),
        static_cast<unsigned long long>(c.deleted_tentative),
        static_cast<unsigned long long>(c.deleted_coast_timeout),
        static_cast<unsigned long long>(c.deleted_covariance),
        static_cast<unsigned long long>(c.deleted_static),
        static_cast<unsigned long long>(c.births_suppressed),
        static_cast<unsigned long long>(c.refine_failures),
        static_cast<unsigned long long>(c.speed_clamps),
        static_cast<unsigned long long>(c.recovered), static_cast<unsigned long long>(c.resumed),
        static_cast<unsigned long long>(c.adopted),
        static_cast<unsigned long long>(c.inherited_moved));
    for (const auto& [why, count] : r.causes[v].switches)
      std::fprintf(stderr, "  switch: %-60s %5.0f\n", why.c_str(), count);
    for (const auto& [why, count] : r.causes[v].false_positives)
      std::fprintf(stderr, "  false positive: %-52s %5.0f\n", why.c_str(), count);
    for (const auto& [why, count] : r.causes[v].misses)
      std::fprintf(stderr, "  missed scan: %-55s %5.0f\n", why.c_str(), count);
    for (const auto& [cls, count] : r.causes[v].false_classes)
      std::fprintf(stderr, "  false scans: %-72s %6.0f\n", cls.c_str(), count);
    for (const auto& [cls, count] : r.causes[v].false_track_classes)
      std::fprintf(stderr, "  false tracks: %-71s %6.0f\n", cls.c_str(), count);
    for (const auto& [cls, count] : r.causes[v].false_views)
      std::fprintf(stderr, "  false scans, what was there: %-100s %6.0f\n", cls.c_str(), count);
    for (const auto& [where, count] : r.causes[v].false_sight)
      std::fprintf(stderr, "  false scans, seen from the sensor: %-70s %6.0f\n", where.c_str(),
                   count);
    for (const auto& [cls, count] : r.fused_causes[v].false_scan_classes)
      std::fprintf(stderr, "  fused false scans: %-66s %6.0f\n", cls.c_str(), count);
    for (const auto& [cls, count] : r.fused_causes[v].false_track_classes)
      std::fprintf(stderr, "  fused false tracks: %-65s %6.0f\n", cls.c_str(), count);
    for (const auto& [why, count] : r.fused_causes[v].switches)
      std::fprintf(stderr, "  fused switch: %-60s %5.0f\n", why.c_str(), count);
    for (const auto& [why, count] : r.causes[v].resumes)
      std::fprintf(stderr, "  resumed: %-90s %5.0f\n", why.c_str(), count);
    for (const auto& [why, count] : r.causes[v].coasting)
      std::fprintf(stderr, "  coasting beside the person: %-80s %6.0f\n", why.c_str(), count);
    for (const auto& [why, count] : r.causes[v].left_measured)
      std::fprintf(stderr, "  left behind, measured on: %-90s %6.0f\n", why.c_str(), count);
    for (const auto& [why, count] : r.causes[v].untracked)
      std::fprintf(stderr, "  beside untracked: %-100s %6.0f\n", why.c_str(), count);
    for (const auto& [why, count] : r.causes[v].partings)
      std::fprintf(stderr, "  parted from its object: %-100s %6.0f\n", why.c_str(), count);
    for (const auto& [why, a] : r.causes[v].los)
      std::fprintf(stderr, "  los: %-90s | %6.0f %9.3f %9.3f %9.3f\n", why.c_str(), a[0], a[1],
                   a[2], a[3]);
    for (const auto& [why, a] : r.causes[v].torso_ends) {
      std::fprintf(stderr, "  torso ends: %-110s | %6.0f %8.3f %8.3f %7.2f\n", why.c_str(), a[0],
                   a[1] / a[0], std::sqrt(a[2] / a[0]), a[3] / a[0]);
    }
    const auto far_all = r.causes[v].far_off.find("all (> 0.25 m off)");
    for (const auto& [why, a] : r.causes[v].far_off) {
      // Count, its share of the matches more than 0.25 m off, mean error, mean NEES.
      const double n_far = far_all != r.causes[v].far_off.end() ? far_all->second[0] : 0.0;
      std::fprintf(stderr, "  far off: %-110s | %6.0f %5.1f%% %7.3f %8.2f\n", why.c_str(), a[0],
                   n_far > 0 ? 100.0 * a[0] / n_far : 0.0, a[0] > 0 ? a[1] / a[0] : 0.0,
                   a[0] > 0 ? a[2] / a[0] : 0.0);
    }
    for (const auto& [why, a] : r.causes[v].coast_start)
      std::fprintf(stderr, "  coast start: %-70s | %6.0f %9.3f %9.3f %6.0f\n", why.c_str(), a[0],
                   a[1], a[2], a[3]);
  }
}

bool HasPeople(const sim::Scenario& s) {
  return std::any_of(s.targets.begin(), s.targets.end(), [](const sim::TargetSpec& t) {
    return t.shape == sim::TargetShape::kPerson || t.shape == sim::TargetShape::kTrolley;
  });
}

RunResult RunScenario(sim::Scenario scenario, bool all_legs, int jobs) {
  if (all_legs) {
    for (sim::SensorSpec& s : scenario.sensors) s.mount = sim::Mount::kLegs;
  }
  std::string error;
  auto simulator = sim::Simulator::Create(scenario, &error);
  if (!simulator) {
    std::fprintf(stderr, "%s\n", error.c_str());
    std::exit(1);
  }
  const std::size_t n = simulator->sensor_count();
  std::vector<std::vector<Variant>> variants(n);
  for (std::size_t i = 0; i < n; ++i) {
    variants[i] = Variants(simulator->sensor(i).mount, simulator->sensor(i).device.range_m);
  }
  const std::size_t nv = variants[0].size();
  std::vector<std::vector<Mot>> mots(n, std::vector<Mot>(nv));
  std::vector<std::vector<SensorFrames>> frames(n, std::vector<SensorFrames>(nv));
  std::vector<std::vector<Causes>> causes(n, std::vector<Causes>(nv));
  std::vector<std::vector<tracking::MultiTrackerCounters>> counters(
      n, std::vector<tracking::MultiTrackerCounters>(nv));
  std::vector<std::vector<Breakdown>> breakdowns(n, std::vector<Breakdown>(nv));
  const auto started = std::chrono::steady_clock::now();
  std::mutex mutex;
  std::size_t next = 0;
  auto worker = [&]() {
    for (;;) {
      std::size_t i;
      {
        std::lock_guard<std::mutex> lock(mutex);
        if (next >= n) return;
        i = next++;
      }
      RunSensor(*simulator, i, variants[i], &mots[i], &frames[i], &causes[i], &counters[i],
                &breakdowns[i]);
    }
  };
  std::vector<std::thread> threads;
  for (int j = 1; j < jobs; ++j) threads.emplace_back(worker);
  worker();
  for (std::thread& t : threads) t.join();
  RunResult result;
  result.cpu_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  result.per_sensor.assign(nv, Mot{});
  result.causes.assign(nv, Causes{});
  result.counters.assign(nv, tracking::MultiTrackerCounters{});
  result.breakdown.assign(nv, Breakdown{});
  for (std::size_t v = 0; v < nv; ++v) {
    std::vector<SensorFrames> by_sensor;
    for (std::size_t i = 0; i < n; ++i) {
      result.per_sensor[v].Add(mots[i][v]);
      const std::string mount = simulator->sensor(i).mount == sim::Mount::kLegs ? "legs" : "torso";
      auto& by_mount = result.per_sensor_by_mount[mount];
      by_mount.resize(nv);
      by_mount[v].Add(mots[i][v]);
      auto& causes_by_mount = result.causes_by_mount[mount];
      causes_by_mount.resize(nv);
      causes_by_mount[v].Add(causes[i][v]);
      result.causes[v].Add(causes[i][v]);
      AddCounters(counters[i][v], &result.counters[v]);
      result.breakdown[v].Merge(breakdowns[i][v]);
      auto& breakdown_by_mount = result.breakdown_by_mount[mount];
      breakdown_by_mount.resize(nv);
      breakdown_by_mount[v].Merge(breakdowns[i][v]);
      by_sensor.push_back(std::move(frames[i][v]));
    }
    result.fused_causes.emplace_back();
    fusion::FusionOptions fusion_options;
    // "old" is the previous system: its fusion too.
    if (std::string(kVariantNames[v]) == "old" ||
        (g_before_fusion_merge && std::string(kVariantNames[v]) == "before")) {
      fusion_options.merge_sourceless = false;
      fusion_options.report_sourceless = true;
    }
    if (g_before_report_sourceless && std::string(kVariantNames[v]) == "before") {
      fusion_options.report_sourceless = true;
    }
    result.fused.push_back(
        RunFusion(*simulator, by_sensor, fusion_options, &result.fused_causes.back()));
  }
  return result;
}

std::string Row(const std::string& scenario, const std::string& mount, const std::string& what,
                const Mot& m) {
  char line[512];
  std::snprintf(line, sizeof line,
                "| %s | %s | %s | %.1f | %.3f | %.3f | %.3f | %.4f | %.2f | %.0f | %.2f | %.2f | "
                "%.2f | %.2f | %.1f |\n",
                scenario.c_str(), mount.c_str(), what.c_str(), m.target_seconds / 60.0, m.Mota(),
                m.Motp(), m.P95(), m.Precision(), m.PerTargetMinute(m.false_tracks),
                m.missed_targets, m.PerTargetMinute(m.id_switches), m.PerTargetMinute(m.fragments),
                m.nees_count > 0 ? m.nees_sum / m.nees_count : 0.0,
                m.nees_count > 0 ? m.nees_within / m.nees_count : 0.0, m.dont_care_seconds);
  return line;
}

const char* kHeader =
    "| scenario | mount | tracker | target-min | MOTA | MOTP m | p95 m | precision | false "
    "tracks /tgt-min | missed targets | id switches /tgt-min | fragments /tgt-min | NEES | NEES "
    "<= 9.21 | door/chair/hidden track-s |\n"
    "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";

const char* kBreakdownHeader =
    "| scenario | mount | tracker | bin | matches | MOTP m | p95 m | radial mean m | radial RMS m "
    "| across RMS m | measured | filtered RMS m | raw RMS m | filtered radial mean m | raw radial "
    "mean m | filtered along-motion mean m | raw along-motion mean m | raw along-motion RMS m | "
    "raw across-motion RMS m | filtered NEES | reported sigma m |\n"
    "|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|--"
    "-:|---:|\n";

std::string BreakdownRow(const std::string& lead, const std::string& bin, const BreakdownCell& c) {
  char line[512];
  std::snprintf(line, sizeof line,
                "| %s | %s | %.0f | %.3f | %.3f | %+.3f | %.3f | %.3f | %.0f | %.3f | %.3f | "
                "%+.3f | %+.3f | %+.3f | %+.3f | %.3f | %.3f | %.2f | %.3f |\n",
                lead.c_str(), bin.c_str(), c.all.n, c.all.Mean(), c.all.P95(), c.all.RadialMean(),
                c.all.RadialRms(), c.all.AcrossRms(), c.filtered.n, c.filtered.Rms(), c.raw.Rms(),
                c.filtered.RadialMean(), c.raw.RadialMean(), c.filtered.AlongMean(),
                c.raw.AlongMean(), c.raw.AlongRms(), c.raw.BesideRms(), c.filtered.Nees(),
                c.filtered.ReportedSigma());
  return line;
}

// The rows of one bin array that hold matches, each bin's name after prefix.
template <std::size_t N>
std::string BreakdownRows(const std::string& lead, const std::string& prefix,
                          const char* const (&bins)[N], const std::array<BreakdownCell, N>& cells) {
  std::string t;
  for (std::size_t i = 0; i < N; ++i) {
    if (cells[i].all.n > 0) t += BreakdownRow(lead, prefix + bins[i], cells[i]);
  }
  return t;
}

struct Section {
  std::string title;
  std::string table;
  std::map<std::string, Mot> totals;            // "<mount> <tracker>"
  std::map<std::string, Breakdown> breakdowns;  // "<mount> <tracker>" (per sensor)
  std::string breakdown_rows;                   // per scenario, every match
  // --explain, per variant: the false positives' causes per "<scenario> | <mount> | <counted>"
  // (counted: per sensor, by the sensors' own mount where a run mixes them, or fused), and summed
  // per "<mount> | <counted>" over the scenarios.
  std::map<std::string, std::vector<Causes>> explain_rows, explain_totals;
};

// The totals' group of an --explain row "<scenario> | <run mount> | <counted>": per sensor by the
// sensor's mount ("per sensor at torso"), fused by the run's mount ("as given" counts as torso, as
// in the totals above).
std::string ExplainGroup(const std::string& row_key) {
  const std::size_t a = row_key.find(" | ");
  const std::size_t b = row_key.find(" | ", a + 3);
  const std::string run_mount = row_key.substr(a + 3, b - a - 3);
  const std::string counted = row_key.substr(b + 3);
  const std::string prefix = "per sensor at ";
  if (counted.rfind(prefix, 0) == 0) return counted.substr(prefix.size()) + " | per sensor";
  return (run_mount == "legs" ? "legs" : "torso") + std::string(" | ") + counted;
}

void AddCauses(const std::vector<Causes>& causes, std::vector<Causes>* sum) {
  sum->resize(std::max(sum->size(), causes.size()));
  for (std::size_t v = 0; v < causes.size(); ++v) (*sum)[v].Add(causes[v]);
}

// --explain's table: every false-positive class with its scans and false tracks per variant, the
// rows ordered by the new tracker's scans; `where` adds the scenarios' share of each class (the
// new tracker's scans, from `rows`) for the totals.
std::string ExplainTable(const std::map<std::string, std::vector<Causes>>& groups, bool where,
                         const std::map<std::string, std::vector<Causes>>* rows) {
  std::size_t nv = 0;
  for (const auto& [key, causes] : groups) nv = std::max(nv, causes.size());
  if (nv == 0) return "";
  const std::size_t v_new = 1;  // kVariantNames: old, new, before
  std::string t = where ? "| mount | counted | class |" : "| scenario | mount | counted | class |";
  std::string rule = where ? "|---|---|---|" : "|---|---|---|---|";
  for (std::size_t v = 0; v < nv; ++v) {
    t += std::string(" FP scans ") + kVariantNames[v] + " |";
    rule += "---:|";
  }
  for (std::size_t v = 0; v < nv; ++v) {
    t += std::string(" false tracks ") + kVariantNames[v] + " |";
    rule += "---:|";
  }
  if (where) {
    t += " where (FP scans new: scenario count) |";
    rule += "---|";
  }
  t += "\n" + rule + "\n";
  char cell[64];
  // Upper-body height first.
  std::vector<std::pair<std::string, const std::vector<Causes>*>> ordered_groups;
  for (const bool legs : {false, true}) {
    for (const auto& [key, causes] : groups) {
      const std::string group = where ? key : ExplainGroup(key);
      if ((group.rfind("legs", 0) == 0) == legs) ordered_groups.emplace_back(key, &causes);
    }
  }
  for (const auto& [key, causes_ptr] : ordered_groups) {
    const std::vector<Causes>& causes = *causes_ptr;
    std::set<std::string> classes;
    for (const Causes& c : causes) {
      for (const auto& [cls, n] : c.false_scan_classes) classes.insert(cls);
      for (const auto& [cls, n] : c.false_track_classes) classes.insert(cls);
    }
    auto count = [&](const std::map<std::string, double>& m, const std::string& cls) {
      const auto it = m.find(cls);
      return it == m.end() ? 0.0 : it->second;
    };
    std::vector<std::string> ordered(classes.begin(), classes.end());
    std::stable_sort(ordered.begin(), ordered.end(), [&](const auto& a, const auto& b) {
      return count(causes[v_new].false_scan_classes, a) >
             count(causes[v_new].false_scan_classes, b);
    });
    std::vector<double> all_scans(nv, 0.0), all_tracks(nv, 0.0);
    auto line = [&](const std::string& cls, const std::vector<double>& scans,
                    const std::vector<double>& tracks, const std::string& places) {
      std::string l = "| " + key + " | " + cls + " |";
      for (std::size_t v = 0; v < nv; ++v) {
        std::snprintf(cell, sizeof cell, " %.0f |", scans[v]);
        l += cell;
      }
      for (std::size_t v = 0; v < nv; ++v) {
        std::snprintf(cell, sizeof cell, " %.0f |", tracks[v]);
        l += cell;
      }
      if (where) l += " " + places + " |";
      return l + "\n";
    };
    for (const std::string& cls : ordered) {
      std::vector<double> scans(nv, 0.0), tracks(nv, 0.0);
      for (std::size_t v = 0; v < causes.size(); ++v) {
        scans[v] = count(causes[v].false_scan_classes, cls);
        tracks[v] = count(causes[v].false_track_classes, cls);
        all_scans[v] += scans[v];
        all_tracks[v] += tracks[v];
      }
      std::string places;
      if (where && rows != nullptr) {
        // The rows of this group: "<scenario> | <mount> | <counted>" whose counted and sensor
        // mount match the key "<mount> | <counted>".
        std::vector<std::pair<double, std::string>> share;
        for (const auto& [row_key, row_causes] : *rows) {
          if (row_causes.size() <= v_new || ExplainGroup(row_key) != key) continue;
          const double n = count(row_causes[v_new].false_scan_classes, cls);
          if (n <= 0) continue;
          // "<scenario> (<run>)": a scenario's knee-height sensors are counted in both its runs,
          // as given and with every sensor at knee height, so its name alone appeared twice.
          const std::size_t a = row_key.find(" | ");
          const std::size_t b = row_key.find(" | ", a + 3);
          const std::string run = row_key.substr(a + 3, b - a - 3);
          share.emplace_back(n, row_key.substr(0, a) + " (" +
                                    (run == "legs"    ? std::string("all at knee height")
                                     : run == "torso" ? std::string("all at upper-body height")
                                                      : run) +
                                    ")");
        }
        std::sort(share.begin(), share.end(), std::greater<>());
        for (const auto& [n, scenario] : share) {
          std::snprintf(cell, sizeof cell, "%.0f", n);
          places += (places.empty() ? "" : ", ") + scenario + " " + cell;
        }
      }
      t += line(cls, scans, tracks, places);
    }
    t += line("all", all_scans, all_tracks, "");
  }
  return t;
}

Section RunFolder(const std::string& title, const std::string& dir, const std::string& only,
                  int jobs, bool explain) {
  Section section;
  section.title = title;
  section.table = kHeader;
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(dir)) {
    if (e.path().extension() == ".yaml") files.push_back(e.path());
  }
  std::sort(files.begin(), files.end());
  for (const fs::path& f : files) {
    if (!only.empty() && f.stem().string() != only) continue;
    sim::Scenario scenario;
    std::string error;
    if (!sim::LoadScenarioFile(f.string(), &scenario, &error)) {
      std::fprintf(stderr, "%s\n", error.c_str());
      std::exit(1);
    }
    std::vector<bool> modes = {false};
    if (HasPeople(scenario)) modes.push_back(true);
    for (const bool legs : modes) {
      bool mixed = false;
      for (const auto& s : scenario.sensors) mixed = mixed || s.mount == sim::Mount::kLegs;
      const std::string mount = legs ? "legs" : (mixed ? "as given" : "torso");
      const RunResult r = RunScenario(scenario, legs, jobs);
      if (explain) {
        Explain(scenario.name, mount, r);
        for (const auto& [sensor_mount, causes] : r.causes_by_mount) {
          const std::string key =
              scenario.name + " | " + mount + " | per sensor at " + sensor_mount;
          AddCauses(causes, &section.explain_rows[key]);
          AddCauses(causes, &section.explain_totals[ExplainGroup(key)]);
        }
        const std::string key = scenario.name + " | " + mount + " | fused";
        AddCauses(r.fused_causes, &section.explain_rows[key]);
        AddCauses(r.fused_causes, &section.explain_totals[ExplainGroup(key)]);
      }
      const char* const* names = kVariantNames;
      // Each sensor counted by its own mount, as the totals: a scenario's knee-height sensors in
      // its run as given go to "legs", not to "torso".
      for (const auto& [sensor_mount, breakdowns] : r.breakdown_by_mount) {
        for (std::size_t v = 0; v < breakdowns.size(); ++v) {
          section.breakdowns[sensor_mount + " " + names[v]].Merge(breakdowns[v]);
        }
      }
      for (std::size_t v = 0; v < r.breakdown.size(); ++v) {
        section.breakdown_rows += BreakdownRow(scenario.name + " | " + mount + " | " + names[v],
                                               "all", r.breakdown[v].total);
      }
      for (std::size_t v = 0; v < r.per_sensor.size(); ++v) {
        section.table +=
            Row(scenario.name, mount, std::string(names[v]) + " per sensor", r.per_sensor[v]);
      }
      for (const auto& [sensor_mount, mots] : r.per_sensor_by_mount) {
        for (std::size_t v = 0; v < mots.size(); ++v)
          section.totals[sensor_mount + " " + names[v] + " per sensor"].Add(mots[v]);
      }
      for (std::size_t v = 0; v < r.fused.size(); ++v) {
        section.table += Row(scenario.name, mount, std::string(names[v]) + " fused", r.fused[v]);
        section
            .totals[(legs ? std::string("legs") : std::string("torso")) + " " + names[v] + " fused"]
            .Add(r.fused[v]);
      }
      std::fprintf(stderr, "%s (%s): %.1f s\n", scenario.name.c_str(), mount.c_str(), r.cpu_s);
      std::fflush(stderr);
    }
  }
  return section;
}

std::string BreakdownTable(const Section& s) {
  std::string t = kBreakdownHeader;
  for (const auto& [key, b] : s.breakdowns) {
    const std::size_t space = key.find(' ');
    const std::string lead = "all | " + key.substr(0, space) + " | " + key.substr(space + 1);
    t += BreakdownRow(lead, "all", b.total);
    t += BreakdownRows(lead, "", kModelBins, b.by_model);
    t += BreakdownRows(lead, "", kSizeBins, b.by_size);
    for (std::size_t i = 0; i < b.by_size.size(); ++i) {
      if (b.few_points_by_size[i].all.n > 0) {
        t +=
            BreakdownRow(lead, std::string("points 2-4, ") + kSizeBins[i], b.few_points_by_size[i]);
      }
      if (b.some_points_by_size[i].all.n > 0) {
        t += BreakdownRow(lead, std::string("points 5-9, ") + kSizeBins[i],
                          b.some_points_by_size[i]);
      }
    }
    t += BreakdownRows(lead, "", kExponentBins, b.by_exponent);
    t += BreakdownRows(lead, "", kOcclusionBins, b.by_occlusion);
    t += BreakdownRows(lead, "", kSpeedBins, b.by_speed);
    t += BreakdownRows(lead, "", kCrowdBins, b.by_crowd);
    t += BreakdownRows(lead, "unoccluded, ", kSpeedBins, b.unoccluded_by_speed);
    t += BreakdownRows(lead, "unoccluded, ", kCrowdBins, b.unoccluded_by_crowd);
    const std::string clear = "clear view (unoccluded, nothing within 2 m), ";
    t += BreakdownRows(lead, clear, kModelBins, b.clear_by_model);
    for (std::size_t i = 0; i < b.clear_by_model_range.size(); ++i) {
      for (std::size_t j = 0; j < b.clear_by_model_range[i].size(); ++j) {
        if (b.clear_by_model_range[i][j].all.n == 0) continue;
        t += BreakdownRow(lead, clear + kModelBins[i] + ", " + kRangeBins[j],
                          b.clear_by_model_range[i][j]);
      }
    }
    t += BreakdownRows(lead, "", kObjectBins, b.by_object);
    for (std::size_t i = 0; i < b.occluded_by_edges.size(); ++i) {
      if (b.occluded_by_edges[i].all.n > 0) {
        t += BreakdownRow(lead, std::string("a nearer return beside it, ") + kEdgeBins[i],
                          b.occluded_by_edges[i]);
      }
      if (b.unoccluded_by_edges[i].all.n > 0) {
        t += BreakdownRow(lead, std::string("unoccluded, ") + kEdgeBins[i],
                          b.unoccluded_by_edges[i]);
      }
    }
    t += BreakdownRows(lead, "", kRateBins, b.by_rate);
    t += BreakdownRows(lead, clear, kRateBins, b.clear_by_rate);
    t += BreakdownRows(lead, clear, kSizeBins, b.clear_by_size);
    t += BreakdownRows(lead, clear, kExponentBins, b.clear_by_exponent);
    for (std::size_t i = 0; i < b.by_range.size(); ++i)
      t += BreakdownRow(lead, kRangeBins[i], b.by_range[i]);
    for (std::size_t i = 0; i < b.by_points.size(); ++i)
      t += BreakdownRow(lead, kPointBins[i], b.by_points[i]);
    for (std::size_t i = 0; i < b.by_parts.size(); ++i) {
      if (b.by_parts[i].all.n > 0) t += BreakdownRow(lead, kPartsBins[i], b.by_parts[i]);
    }
    for (std::size_t i = 0; i < b.by_range.size(); ++i) {
      if (b.one_leg_by_range[i].all.n > 0)
        t += BreakdownRow(lead, std::string("one leg, ") + kRangeBins[i], b.one_leg_by_range[i]);
      if (b.two_legs_by_range[i].all.n > 0)
        t += BreakdownRow(lead, std::string("two legs, ") + kRangeBins[i], b.two_legs_by_range[i]);
    }
    const char* const gaits[] = {"one leg, the nearer leg in stance",
                                 "one leg, the nearer leg in swing"};
    for (std::size_t i = 0; i < b.one_leg_by_gait.size(); ++i) {
      if (b.one_leg_by_gait[i].all.n > 0) t += BreakdownRow(lead, gaits[i], b.one_leg_by_gait[i]);
    }
    const char* const sinces[] = {"one leg, 0-0.3 s since the last two legs",
                                  "one leg, 0.3-1 s since the last two legs",
                                  "one leg, 1 s or more since the last two legs (or none)"};
    for (std::size_t i = 0; i < b.one_leg_by_since.size(); ++i) {
      if (b.one_leg_by_since[i].all.n > 0)
        t += BreakdownRow(lead, sinces[i], b.one_leg_by_since[i]);
    }
    const char* const spreads[] = {
        "two legs, walking, spread along the walk 0-0.1 m", "two legs, walking, spread 0.1-0.2 m",
        "two legs, walking, spread 0.2-0.3 m", "two legs, walking, spread 0.3+ m"};
    for (std::size_t i = 0; i < b.two_legs_by_spread.size(); ++i) {
      if (b.two_legs_by_spread[i].all.n > 0)
        t += BreakdownRow(lead, spreads[i], b.two_legs_by_spread[i]);
    }
    const char* const supports[] = {"two legs, walking, one leg swinging",
                                    "two legs, walking, both legs standing"};
    for (std::size_t i = 0; i < b.two_legs_by_support.size(); ++i) {
      if (b.two_legs_by_support[i].all.n > 0)
        t += BreakdownRow(lead, supports[i], b.two_legs_by_support[i]);
    }
    const char* const views[] = {"trolley, end-on, coming nearer", "trolley, oblique",
                                 "trolley, broadside", "trolley, end-on, going away"};
    for (std::size_t i = 0; i < b.trolley_by_view.size(); ++i) {
      if (b.trolley_by_view[i].all.n > 0) t += BreakdownRow(lead, views[i], b.trolley_by_view[i]);
    }
    for (std::size_t i = 0; i < b.trolley_by_view_shape.size(); ++i) {
      for (std::size_t j = 0; j < b.trolley_by_view_shape[i].size(); ++j) {
        if (b.trolley_by_view_shape[i][j].all.n == 0) continue;
        t += BreakdownRow(
            lead,
            std::string(views[i]) + (j == 1 ? ", tracked as a box" : ", tracked as another shape"),
            b.trolley_by_view_shape[i][j]);
      }
    }
    for (std::size_t i = 0; i < b.walking_by_heading.size(); ++i) {
      if (b.walking_by_heading[i].all.n == 0) continue;
      t += BreakdownRow(lead, kHeadingBins[i], b.walking_by_heading[i]);
      for (std::size_t j = 0; j < b.walking_by_heading_range[i].size(); ++j) {
        if (b.walking_by_heading_range[i][j].all.n > 0)
          t += BreakdownRow(lead, std::string(kHeadingBins[i]) + ", " + kRangeBins[j],
                            b.walking_by_heading_range[i][j]);
      }
    }
  }
  return t + s.breakdown_rows;
}

// --breakdown: a person's per-sensor matches by source (Breakdown::person_by_source): each
// source's share of the matches, of the summed error (what MOTP averages) and of the tail (the
// matches above the people's own p95), and its matches more than 0.25 m off.
std::string PersonSourceTable(const Section& s) {
  std::string t =
      "| mount | tracker | source | matches | share of matches | MOTP m | p95 m | share of summed "
      "error | share of the tail (above the people's p95) | matches > 0.25 m | radial mean m | "
      "filtered NEES |\n|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";
  for (const auto& [key, b] : s.breakdowns) {
    const std::size_t space = key.find(' ');
    const std::string lead = key.substr(0, space) + " | " + key.substr(space + 1);
    BreakdownCell people;
    for (const BreakdownCell& c : b.person_by_source) people.Merge(c);
    if (people.all.n == 0) continue;
    const double p95 = people.all.P95();
    double tail = 0;
    for (const double e : people.all.norms) tail += e > p95 ? 1 : 0;
    const auto row = [&](const std::string& name, const BreakdownCell& c) {
      double above = 0, far = 0;
      for (const double x : c.all.norms) {
        above += x > p95 ? 1 : 0;
        far += x > 0.25 ? 1 : 0;
      }
      char line[512];
      std::snprintf(line, sizeof line,
                    "| %s | %s | %.0f | %.3f | %.3f | %.3f | %.3f | %.3f | %.0f | %+.3f | %.2f |\n",
                    lead.c_str(), name.c_str(), c.all.n, c.all.n / people.all.n, c.all.Mean(),
                    c.all.P95(), c.all.sum / people.all.sum, tail > 0 ? above / tail : 0.0, far,
                    c.all.RadialMean(), c.filtered.Nees());
      return std::string(line);
    };
    t += row("all people", people);
    const std::size_t n = std::size(kPersonSourceBins), r = std::size(kRangeBins);
    for (std::size_t i = 0; i < b.person_by_source.size(); ++i) {
      if (b.person_by_source[i].all.n == 0) continue;
      t += row(i < n ? std::string(kPersonSourceBins[i])
                     : std::string("clear view, ") + kModelBins[(i - n) / r] + ", " +
                           kRangeBins[(i - n) % r],
               b.person_by_source[i]);
    }
  }
  return t;
}

const char* const kExplainText =
    "Every reported track's scan that matched no object (a false positive: what lowers "
    "precision) in one class; a false track (unmatched in more than half of its scans) in the "
    "class of most of its false scans. \"Left behind\": the track had held an object before, and "
    "that object is now out of view (hidden or gone: the track goes on where it is not), visible "
    "but held by no track (the track ran off it), or held by another track. \"Never matched\": a "
    "track that never held an object, within 1.5 m of an object another track holds (a second "
    "track of it, a split), within 1.5 m of an untracked object (offset from it), within 1.5 m of "
    "a door or chair, or far from every object (clutter: a background edge, a shadow's border). "
    "Coasting: reported without a measurement in that scan. Tracks on doors and chairs and on "
    "hidden people within the match radius count neither way (the door/chair/hidden column). Per "
    "sensor under the sensor's own mount (shop_floor as given: two sensors at upper-body height, "
    "two at knee height), fused by the run (as given counts as upper-body height). Where: each "
    "scenario with its run, as given or with every sensor at knee height (a sensor at knee height "
    "as given is in both).\n\n";

std::string Totals(const Section& s) {
  std::string t = kHeader;
  for (const auto& [key, mot] : s.totals) {
    const std::size_t space = key.find(' ');
    t += Row("all", key.substr(0, space), key.substr(space + 1), mot);
  }
  return t;
}

// The issue's targets for the new tracker per sensor: at upper-body height mean MOTP <= 0.03 m,
// p95 <= 0.10 m, precision >= 0.99; at knee height within 1.5 times of that (precision >= 0.985);
// NEES mean in [1.5, 3] at both.
std::string Targets(const Section& s) {
  std::string t =
      "| mount | tracker | MOTP m (target) | p95 m (target) | precision (target) | NEES (target) "
      "| all met |\n|---|---|---|---|---|---|---|\n";
  char line[512];
  for (const char* mount : {"torso", "legs"}) {
    const bool legs = std::string(mount) == "legs";
    const double scale = legs ? 1.5 : 1.0;
    const double motp_max = 0.03 * scale, p95_max = 0.10 * scale;
    const double precision_min = 1.0 - 0.01 * scale;
    for (const char* tracker : {"new per sensor", "before per sensor", "old per sensor"}) {
      const auto it = s.totals.find(std::string(mount) + " " + tracker);
      if (it == s.totals.end()) continue;
      const Mot& m = it->second;
      const double nees = m.nees_count > 0 ? m.nees_sum / m.nees_count : 0.0;
      const bool motp = m.Motp() <= motp_max, p95 = m.P95() <= p95_max,
                 precision = m.Precision() >= precision_min, honest = nees >= 1.5 && nees <= 3.0;
      std::snprintf(line, sizeof line,
                    "| %s | %s | %.4f (<= %.3f) %s | %.4f (<= %.3f) %s | %.4f (>= %.3f) %s | %.2f "
                    "([1.5, 3]) %s | %s |\n",
                    mount, tracker, m.Motp(), motp_max, motp ? "met" : "missed", m.P95(), p95_max,
                    p95 ? "met" : "missed", m.Precision(), precision_min,
                    precision ? "met" : "missed", nees, honest ? "met" : "missed",
                    motp && p95 && precision && honest ? "yes" : "no");
      t += line;
    }
  }
  return t;
}

}  // namespace

// The "before" line for the knee-height rules alone (--before-one-leg, --before-confirm-time,
// --before-whole-person, --before-box-size, any of them), empty otherwise.
std::string KneeHeightBefore() {
  if (!(g_before_one_leg || g_before_confirm_time || g_before_whole_person || g_before_box_size ||
        g_before_single_beam || g_before_deep_pieces || g_before_deep_evidence ||
        g_before_isotropic_bias || g_before_across_walk || g_before_side_uncertainty ||
        g_before_side_from_view || g_before_lone_leg_standing || g_before_few_point_legs ||
        g_before_deep_legs || g_before_legs_seen_through || g_before_legs_report_coasting ||
        g_before_legs_coasting_sigma || g_before_coasting_sigma || g_before_leg_edges ||
        g_before_outline_departure || g_before_partial_view || g_before_underdetermined_fit ||
        g_before_fusion_merge || g_before_report_sourceless || g_before_recent_veil ||
        g_before_single_precision_fit || g_before_edge_sides || g_before_outside_start ||
        g_before_across_sway || g_before_receded_edges || g_before_stance_weight ||
        g_before_adopt || g_before_inherit_moved || g_before_touching_legs || g_before_still_legs ||
        g_before_still_legs_cov || g_before_walking_legs_cov || g_before_mixed_legs ||
        g_before_mixed_leg_band || g_before_box_occluders || g_before_box_rejoin ||
        g_before_see_through || g_before_step_seam || g_before_deep_tail ||
        g_before_torso_edge_echo || g_before_box_unseen_cov || g_before_box_seen_extent ||
        g_before_knee_box_faces || g_before_single_beam_partner || g_before_edge_echo_birth ||
        g_before_lone_beam_echo || g_before_far_leg_birth || g_before_person_size ||
        g_before_person_reach || g_before_partial_extent || g_before_neighbour ||
        g_before_segment_excess || g_before_box_view || g_before_box_view_torso ||
        g_before_range_noise || g_before_gain_covariance || g_before_occluded_gap) ||
      g_before_mixed_pixels || g_before_far || g_before_evidence_coasting ||
      g_before_report_rules) {
    return "";
  }
  std::vector<std::string> without;
  if (g_before_one_leg) {
    without.push_back(
        "measuring a single leg at knee height as the leg itself even where its partner is "
        "hidden behind it (`shape.hidden_leg_behind` false)");
  }
  if (g_before_confirm_time) {
    without.push_back("confirming a track by M of N alone (`tracking.confirm_min_s` 0)");
  }
  if (g_before_whole_person) {
    without.push_back(
        "dropping knee-height mixed pixels beside a nearer return only "
        "(`shape.drop_mixed_pixel_legs_whole_person` false)");
  }
  if (g_before_box_size) {
    without.push_back(
        "reporting a box's centre with its learned size's sigma however small "
        "(`shape.box_size_floor_sigma_m` 0)");
  }
  if (g_before_single_beam) {
    without.push_back(
        "dropping knee-height legs returned by a single beam, also beside a confirmed track "
        "(`shape.single_beam_legs` false)");
  }
  if (g_before_deep_pieces) {
    without.push_back(
        "measuring knee-height pieces deep along the line of sight but no wider across it than a "
        "pair of legs as wide objects, also where a leg fills no beam "
        "(`shape.drop_deep_mixed_pixel_pieces` false)");
  }
  if (g_before_deep_evidence) {
    without.push_back(
        "dropping those deep knee-height pieces by their shape alone, also where no surface stands "
        "behind them to mix with (`shape.deep_mixed_pixel_behind_ratio` 0)");
  }
  if (g_before_isotropic_bias) {
    without.push_back(
        "reporting the centre's shared error with the same sigma in every direction "
        "(`shape.centre_bias_along_ray` false)");
  }
  if (g_before_across_walk) {
    without.push_back(
        "measuring a walking track's single leg as the leg itself rather than hip_half_width_m "
        "across the walk from it (`shape.single_leg_across_walk` false)");
  }
  if (g_before_side_uncertainty) {
    without.push_back(
        "taking the side of the centre a walking track's single leg stands on as sure, however "
        "uncertain the prediction it is taken from (`shape.single_leg_side_uncertainty` false)");
  }
  if (g_before_side_from_view) {
    without.push_back(
        "taking the side of the centre a walking track's single leg stands on from the "
        "prediction alone, not from where the scan sees through the other leg's place "
        "(`shape.single_leg_side_from_view` false)");
  }
  if (g_before_lone_leg_standing) {
    without.push_back(
        "taking a walking track's single leg's centre along the walk as anywhere within the legs' "
        "reach, also where the hidden leg stood at the last two-leg measurement "
        "(`shape.single_leg_from_standing` false)");
  }
  if (g_before_few_point_legs) {
    without.push_back(
        "measuring a knee-height segment of two or three points wider than a leg as one leg "
        "rather than two legs side by side (`shape.split_few_point_legs` false)");
  }
  if (g_before_deep_legs) {
    without.push_back(
        "measuring a confirmed knee-height track's segment of two or three points deeper along "
        "the line of sight than a leg as one leg rather than its two legs "
        "(`shape.deep_legs_as_pair` false)");
  }
  if (g_before_legs_seen_through) {
    without.push_back(
        "reporting a knee-height coasting track also where the scan sees through every place its "
        "legs may stand (`shape.legs_seen_through` false)");
  }
  if (g_before_legs_report_coasting) {
    without.push_back(
        "reporting a knee-height coasting track for all of `tracking.report_coasting_s` "
        "(`shape.legs_report_coasting_s` 0)");
  }
  if (g_before_legs_coasting_sigma) {
    without.push_back(
        "reporting a knee-height coasting track whatever its position sigma "
        "(`shape.legs_coasting_max_sigma_m` 0)");
  }
  if (g_before_coasting_sigma) {
    without.push_back(
        "reporting an upper-body coasting track whatever its position sigma "
        "(`shape.coasting_max_sigma_m` 0)");
  }
  if (g_before_leg_edges) {
    without.push_back(
        "taking a knee-height leg's silhouette edge half a step beyond its last returning beam "
        "also where the beam beyond is a mixed echo of the leg and what lies behind it "
        "(`shape.leg_edge_in_mixed_beam` false)");
  }
  if (g_before_outline_departure) {
    without.push_back(
        "reporting an upper-body centre with the whole fixed allowances for the outline, not the "
        "departure its fit's residuals measure (`shape.outline_departure_gain` 0)");
  }
  if (g_before_partial_view) {
    without.push_back(
        "reporting an upper-body partial view (an occluder's edge at an end of the outline) as a "
        "whole one, without its fit's covariance (`shape.partial_view_shared` false)");
  }
  if (g_before_underdetermined_fit) {
    without.push_back(
        "reporting an upper-body fit of no more points and silhouette ends than its parameters as "
        "any other, without its fit's covariance (`shape.underdetermined_fit_shared` false)");
  }
  if (g_before_recent_veil) {
    without.push_back(
        "taking a knee-height leg-sized segment behind a nearer return its beams had in the last "
        "scans for a leg (`shape.recent_veil_s` 0)");
  }
  if (g_before_single_precision_fit) {
    without.push_back(
        "fitting a person's outline with every point in double precision, two at a time "
        "(`shape.single_precision_points` false)");
  }
  if (g_before_edge_sides) {
    without.push_back(
        "turning each silhouette edge of a fit away from its start (the track's prediction) "
        "instead of away from the points (`shape.edges_face_points` false)");
  }
  if (g_before_across_sway) {
    without.push_back(
        "reporting the centre with the sideways sway allowance across the ray as before "
        "(`shape.centre_bias_across_sigma_m` 0.006)");
  }
  if (g_before_receded_edges) {
    without.push_back(
        "taking a segment's end as a silhouette also where the beam beyond returned from the "
        "body's range over a background that receded there (`shape.receded_background_edge_m` 0)");
  }
  if (g_before_outside_start) {
    without.push_back(
        "starting a fit at the track's prediction also where it lies outside the silhouette "
        "(`shape.outside_guess_start` guess)");
  }
  if (g_before_stance_weight) {
    without.push_back(
        "measuring a walking knee-height track's two legs by their midpoint also where one "
        "stands and the other swings (`shape.stance_leg_weight` 0.5)");
  }
  if (g_before_adopt) {
    without.push_back(
        "leaving a track born beside a coasting one to itself while the coasting one is reported "
        "until its time is up (`tracking.adopt_successor_m` 0)");
  }
  if (g_before_inherit_moved) {
    without.push_back(
        "waiting for a track born where a moved track was just lost to move by itself before "
        "reporting it (`tracking.inherit_moved_s` 0)");
  }
  if (g_before_touching_legs) {
    without.push_back(
        "measuring a knee-height track's two legs that touch in the scan with a pair's "
        "covariance, not the farther leg's cut arc's along the line of sight "
        "(`shape.touching_legs_along_ray` false)");
  }
  if (g_before_occluded_gap) {
    without.push_back(
        "reporting a knee-height track's two legs with something nearer between them (an "
        "occluder's edge on both inner ends) with a pair's covariance, not one that allows the "
        "centre of an object whose face they may be behind them (`shape.occluded_gap_depth_m` 0)");
  }
  if (g_before_still_legs_cov) {
    without.push_back(
        "reporting a standing knee-height track's two legs seen still with a walking pair's "
        "covariance (`shape.still_legs_cov` false)");
  }
  if (g_before_walking_legs_cov) {
    without.push_back(
        "reporting a walking knee-height track's two legs with the gait allowance as noise the "
        "filter averages instead of an offset successive scans share (`shape.walking_legs_cov` "
        "false)");
  }
  if (g_before_still_legs) {
    without.push_back(
        "taking a still knee-height track for a person's whatever the depth of its legs along "
        "the line of sight (`shape.still_legs_max_depth_m` 0)");
  }
  if (g_before_mixed_legs) {
    without.push_back(
        "fitting a far knee-height leg to its points where each may be a mixed pixel with a near "
        "background (`shape.mixed_leg_max_gap_m` 0)");
  }
  if (g_before_mixed_leg_band) {
    without.push_back(
        "giving a knee-height leg measured from mixed pixels' range deficits the leg radius' "
        "share of the whole gap to the background along the line of sight, also where its "
        "nearest return may be the leg's own echo (`shape.mixed_leg_band_variance` false)");
  }
  if (g_before_single_beam_partner) {
    without.push_back(
        "pairing no knee-height leg of a segment with a lone beam within the pairing distance "
        "(`shape.single_beam_partner` false)");
  }
  if (g_before_range_noise) {
    without.push_back(
        "fitting with the range noise growing by 1 mm per metre (`shape.point_sigma_per_m` "
        "0.001)");
  }
  if (g_before_gain_covariance) {
    without.push_back(
        "reporting a measured track with the filter's own covariance, the fixed per-scan "
        "allowance it is given included (`tracking.report_gain_covariance` false)");
  }
  if (g_before_neighbour) {
    without.push_back(
        "reporting an upper-body person with another observation beside it as one alone "
        "(`shape.neighbour_sigma_m` 0)");
  }
  if (g_before_box_view_torso && !g_before_box_view) {
    without.push_back(
        "reporting an upper-body track fitted as a body and measured from a cart's long face "
        "as if the body were the cart (`shape.box_view_at_torso` false)");
  }
  if (g_before_box_view) {
    without.push_back(
        "reporting a track fitted as a body and measured from a box's outline (one face or two) "
        "as if the body were the box (`shape.box_view_shared` false)");
  }
  if (g_before_segment_excess) {
    without.push_back(
        "reporting an upper-body person whose segment is wider than the body as if the segment "
        "were the body's (`shape.segment_excess_shared` false)");
  }
  if (g_before_partial_extent) {
    without.push_back(
        "reporting an upper-body partial view's shared covariance with the size's own sigma "
        "(`shape.partial_view_size_sigma_m` 0)");
  }
  if (g_before_person_reach) {
    without.push_back(
        "fitting an upper-body person to every point of its segment, also to a run at its end "
        "beyond the reach of the predicted body (`shape.person_drop_beyond_reach` false)");
  }
  if (g_before_person_size) {
    without.push_back(
        "`shape.person_size_across_ray` the other way round from the default (on: each "
        "semi-axis of an upper-body person learnt only from views that show it across the ray)");
  }
  if (g_before_far_leg_birth) {
    without.push_back(
        "letting knee-height legs start tracks also where a leg covers at most half of a beam's "
        "footprint (`shape.far_legs_no_birth` false)");
  }
  if (g_before_lone_beam_echo) {
    without.push_back(
        "taking a knee-height lone beam beside a nearer return, that edge's mixed echo, for a leg "
        "(`shape.lone_beam_edge_echo` false)");
  }
  if (g_before_edge_echo_birth) {
    without.push_back(
        "letting a knee-height single leg beside a nearer edge, no wider than that edge's mixed "
        "echo, start a track (`shape.edge_echo_no_birth` false)");
  }
  if (g_before_box_occluders) {
    without.push_back(
        "fitting a box (a cart) to every point of its segment, also to those in front of it (its "
        "pusher's) (`shape.box_drop_occluders` false)");
  }
  if (g_before_box_unseen_cov) {
    without.push_back(
        "reporting a box's (a cart's) size error as the same in every direction, also along an "
        "axis whose semi-axis the scan does not show (`shape.box_unseen_depth_cov` false)");
  }
  if (g_before_box_seen_extent) {
    without.push_back(
        "widening a box's (a cart's) reported centre covariance only along an axis whose "
        "semi-axis the scan does not show, not along one the track never saw whole "
        "(`shape.box_seen_extent_cov` false)");
  }
  if (g_before_knee_box_faces) {
    without.push_back(
        "learning a knee-height box's (a cart's) semi-axes from every fit, also one whose scan "
        "does not show them (`shape.box_size_from_faces_seen_at_knee` false)");
  }
  if (g_before_torso_edge_echo) {
    without.push_back(
        "measuring an upper-body segment of a beam footprint's width beside a nearer return as a "
        "body, not as that edge's mixed echo (`shape.torso_edge_echo` false)");
  }
  if (g_before_step_seam) {
    without.push_back(
        "measuring a segment as one object also where its range steps between two bodies that "
        "touch in the view (`shape.split_step_seam` false)");
  }
  if (g_before_see_through) {
    without.push_back(
        "measuring every segment as one object, also where beams saw through it between objects "
        "side by side (`shape.split_see_through` false)");
  }
  if (g_before_box_rejoin) {
    without.push_back(
        "measuring every segment on its own, also the pieces the width limit cuts a box's "
        "outline into (`shape.box_rejoin_pieces` false)");
  }
  std::string text = "\"before\": the new tracker" + std::string(without.empty() ? "" : " ");
  for (std::size_t i = 0; i < without.size(); ++i) {
    text += (i == 0 ? "" : i + 1 == without.size() ? " and " : ", ") + without[i];
  }
  if (g_before_fusion_merge) {
    text +=
        std::string(without.empty() ? "" : ",") +
        " fused by a fusion that leaves a fused track without sources to coast beside the track "
        "that took its object and reports fused tracks no tracker holds any more "
        "(`fusion.merge_sourceless` false, `fusion.report_sourceless` true)";
  } else if (g_before_report_sourceless) {
    text += std::string(without.empty() ? "" : ",") +
            " fused by a fusion that reports fused tracks no tracker holds any more as coasting "
            "(`fusion.report_sourceless` true)";
  }
  const char* const same =
      g_before_single_precision_fit || g_before_edge_sides || g_before_outside_start ||
              g_before_across_sway || g_before_receded_edges
          ? ", on the same scans in the same run"
      : g_before_outline_departure || g_before_isotropic_bias || g_before_partial_view ||
              g_before_underdetermined_fit || g_before_partial_extent || g_before_neighbour ||
              g_before_segment_excess || g_before_box_view || g_before_box_view_torso ||
              g_before_gain_covariance
          ? ", on the same scans in the same run; upper-body tracks are the same by construction, "
            "their reported covariance (so NEES and what fusion makes of them) is not"
          : ", on the same scans in the same run; upper-body rows are the same by construction";
  return text + same +
         (g_before_box_size && !g_before_isotropic_bias
              ? " except for the boxes' (carts') covariance"
              : "") +
         (g_before_fusion_merge || g_before_report_sourceless
              ? " (per sensor; the fused rows differ by the fusion's options too)"
              : "") +
         ".\n\n";
}

int main(int argc, char** argv) {
  std::string scenarios_dir, out_path, only;
  std::vector<std::string> extra;
  int jobs = 1;
  bool explain = false, breakdown = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "%s needs a value\n", a.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--scenarios") {
      scenarios_dir = value();
    } else if (a == "--extra") {
      extra.push_back(value());
    } else if (a == "--out") {
      out_path = value();
    } else if (a == "--only") {
      only = value();
    } else if (a == "--explain") {
      explain = true;
      g_explain_coasting = true;
    } else if (a == "--breakdown") {
      breakdown = true;
    } else if (a == "--before-report-rules") {
      g_before_report_rules = true;
    } else if (a == "--before-evidence-coasting") {
      g_before_evidence_coasting = true;
    } else if (a == "--before-confirm-time") {
      g_before_confirm_time = true;
    } else if (a == "--before-whole-person") {
      g_before_whole_person = true;
    } else if (a == "--before-mixed-pixels") {
      g_before_mixed_pixels = true;
    } else if (a == "--before-far") {
      g_before_far = true;
    } else if (a == "--before-one-leg") {
      g_before_one_leg = true;
    } else if (a == "--before-box-size") {
      g_before_box_size = true;
    } else if (a == "--before-single-beam") {
      g_before_single_beam = true;
    } else if (a == "--before-single-beam-partner") {
      g_before_single_beam_partner = true;
    } else if (a == "--before-edge-echo-birth") {
      g_before_edge_echo_birth = true;
    } else if (a == "--before-lone-beam-echo") {
      g_before_lone_beam_echo = true;
    } else if (a == "--before-far-leg-birth") {
      g_before_far_leg_birth = true;
    } else if (a == "--before-person-size") {
      g_before_person_size = true;
    } else if (a == "--before-person-reach") {
      g_before_person_reach = true;
    } else if (a == "--before-partial-extent") {
      g_before_partial_extent = true;
    } else if (a == "--before-neighbour") {
      g_before_neighbour = true;
    } else if (a == "--before-segment-excess") {
      g_before_segment_excess = true;
    } else if (a == "--before-box-view") {
      g_before_box_view = true;
    } else if (a == "--before-box-view-torso") {
      g_before_box_view_torso = true;
    } else if (a == "--before-gain-covariance") {
      g_before_gain_covariance = true;
    } else if (a == "--before-range-noise") {
      g_before_range_noise = true;
    } else if (a == "--before-deep-pieces") {
      g_before_deep_pieces = true;
    } else if (a == "--before-deep-evidence") {
      g_before_deep_evidence = true;
    } else if (a == "--before-isotropic-bias") {
      g_before_isotropic_bias = true;
    } else if (a == "--before-across-walk") {
      g_before_across_walk = true;
    } else if (a == "--before-side-uncertainty") {
      g_before_side_uncertainty = true;
    } else if (a == "--before-side-from-view") {
      g_before_side_from_view = true;
    } else if (a == "--before-lone-leg-standing") {
      g_before_lone_leg_standing = true;
    } else if (a == "--before-few-point-legs") {
      g_before_few_point_legs = true;
    } else if (a == "--before-deep-legs") {
      g_before_deep_legs = true;
    } else if (a == "--before-legs-seen-through") {
      g_before_legs_seen_through = true;
    } else if (a == "--before-legs-report-coasting") {
      g_before_legs_report_coasting = true;
    } else if (a == "--before-legs-coasting-sigma") {
      g_before_legs_coasting_sigma = true;
    } else if (a == "--before-coasting-sigma") {
      g_before_coasting_sigma = true;
    } else if (a == "--before-leg-edges") {
      g_before_leg_edges = true;
    } else if (a == "--before-outline-departure") {
      g_before_outline_departure = true;
    } else if (a == "--before-partial-view") {
      g_before_partial_view = true;
    } else if (a == "--before-underdetermined-fit") {
      g_before_underdetermined_fit = true;
    } else if (a == "--before-recent-veil") {
      g_before_recent_veil = true;
    } else if (a == "--before-single-precision-fit") {
      g_before_single_precision_fit = true;
    } else if (a == "--before-edge-sides") {
      g_before_edge_sides = true;
    } else if (a == "--before-across-sway") {
      g_before_across_sway = true;
    } else if (a == "--before-receded-edges") {
      g_before_receded_edges = true;
    } else if (a == "--before-outside-start") {
      g_before_outside_start = true;
    } else if (a == "--before-stance-weight") {
      g_before_stance_weight = true;
    } else if (a == "--before-adopt") {
      g_before_adopt = true;
    } else if (a == "--before-inherit-moved") {
      g_before_inherit_moved = true;
    } else if (a == "--before-touching-legs") {
      g_before_touching_legs = true;
    } else if (a == "--before-occluded-gap") {
      g_before_occluded_gap = true;
    } else if (a == "--before-still-legs-cov") {
      g_before_still_legs_cov = true;
    } else if (a == "--before-walking-legs-cov") {
      g_before_walking_legs_cov = true;
    } else if (a == "--before-still-legs") {
      g_before_still_legs = true;
    } else if (a == "--before-mixed-legs") {
      g_before_mixed_legs = true;
    } else if (a == "--before-mixed-leg-band") {
      g_before_mixed_leg_band = true;
    } else if (a == "--before-box-occluders") {
      g_before_box_occluders = true;
    } else if (a == "--before-box-unseen-cov") {
      g_before_box_unseen_cov = true;
    } else if (a == "--before-box-seen-extent") {
      g_before_box_seen_extent = true;
    } else if (a == "--before-knee-box-faces") {
      g_before_knee_box_faces = true;
    } else if (a == "--before-box-rejoin") {
      g_before_box_rejoin = true;
    } else if (a == "--before-see-through") {
      g_before_see_through = true;
    } else if (a == "--before-torso-edge-echo") {
      g_before_torso_edge_echo = true;
    } else if (a == "--before-step-seam") {
      g_before_step_seam = true;
    } else if (a == "--before-deep-tail") {
      g_before_deep_tail = true;
    } else if (a == "--before-fusion-merge") {
      g_before_fusion_merge = true;
    } else if (a == "--before-report-sourceless") {
      g_before_report_sourceless = true;
    } else if (a == "--jobs") {
      jobs = std::max(1, std::atoi(value().c_str()));
    } else {
      std::fprintf(stderr,
                   "usage: tracking_benchmark --scenarios DIR [--extra DIR] [--only NAME] "
                   "[--out FILE] [--jobs N] [--explain] [--breakdown] "
                   "[--before-report-rules | [--before-mixed-pixels] [--before-far] "
                   "[--before-evidence-coasting] [--before-one-leg] [--before-confirm-time] "
                   "[--before-whole-person] [--before-box-size] [--before-single-beam] "
                   "[--before-deep-pieces] [--before-deep-evidence] [--before-isotropic-bias] "
                   "[--before-across-walk] [--before-side-uncertainty] "
                   "[--before-side-from-view] [--before-lone-leg-standing] "
                   "[--before-few-point-legs] [--before-deep-legs] "
                   "[--before-legs-seen-through] [--before-legs-report-coasting] "
                   "[--before-leg-edges] [--before-outline-departure] [--before-partial-view] "
                   "[--before-underdetermined-fit] "
                   "[--before-recent-veil] "
                   "[--before-single-precision-fit] [--before-edge-sides] "
                   "[--before-outside-start] [--before-across-sway] [--before-receded-edges] "
                   "[--before-stance-weight] [--before-adopt] [--before-inherit-moved] "
                   "[--before-touching-legs] [--before-still-legs-cov] "
                   "[--before-walking-legs-cov] [--before-occluded-gap] "
                   "[--before-still-legs] [--before-mixed-legs] [--before-mixed-leg-band] "
                   "[--before-box-occluders] [--before-box-rejoin] [--before-box-unseen-cov] "
                   "[--before-box-seen-extent] [--before-knee-box-faces] "
                   "[--before-see-through] [--before-step-seam] [--before-torso-edge-echo] "
                   "[--before-person-size] "
                   "[--before-person-reach] [--before-partial-extent] "
                   "[--before-fusion-merge] "
                   "[--before-report-sourceless]]\n");
      return 2;
    }
  }
  if (scenarios_dir.empty()) {
    std::fprintf(stderr, "tracking_benchmark: --scenarios DIR is required\n");
    return 2;
  }
  std::vector<Section> sections;
  sections.push_back(RunFolder("Shipped scenarios", scenarios_dir, only, jobs, explain));
  for (const std::string& dir : extra) {
    sections.push_back(RunFolder("More scenarios (" + fs::path(dir).filename().string() + ")", dir,
                                 only, jobs, explain));
  }
  std::string text;
  for (const Section& s : sections) {
    text += "## " + s.title + "\n\n" + s.table + "\n### " + s.title + ": all together\n\n" +
            Totals(s) + "\n### " + s.title + ": targets (per sensor)\n\n" + Targets(s) + "\n";
    if (breakdown) {
      text += "### " + s.title + ": where the per-sensor error comes from\n\n" + BreakdownTable(s) +
              "\n### " + s.title + ": a person's per-sensor error by source\n\n" +
              PersonSourceTable(s) + "\n";
    }
    if (explain) {
      text += "### " + s.title + ": what the false positives are\n\n" + kExplainText +
              ExplainTable(s.explain_totals, true, &s.explain_rows) + "\nPer scenario:\n\n" +
              ExplainTable(s.explain_rows, false, nullptr) + "\n";
    }
  }
  std::printf("%s", text.c_str());
  if (!out_path.empty()) {
    std::ofstream out(out_path);
    out << "# Tracking accuracy: the body-centre tracker against the previous one\n\n"
        << "Every shipped scenario through `lrfnet sim`'s simulator and the tracking pipeline "
           "(`tests/bench/tracking_benchmark`, run by `scripts/bench.sh`), scored with CLEAR-MOT "
           "against the simulator's truth (people's sizes drawn per person). \"old\": the "
           "previous tracker (fixed-axes ellipse, centre of mass below 5 points, no static-object "
           "handling or motion limits); \"new\": the shape fit with the size learned per track, "
           "the static-object rules and the motion limits, on the same scans. Per sensor: summed "
           "over the scenario's sensors, in each sensor's frame; fused: the daemon's fusion of all "
           "sensors' tracks in the world frame with the true poses, every 0.1 s. In the totals a "
           "sensor counts under its own mount (shop_floor as given: two at upper-body height, "
           "two at knee height); fused totals by the scenario's run. Match radius "
           "0.5 m; an object counts in a scan when at least 2 of its beams returned. NEES: "
           "position, 2 dof, mean over measured matches (2 is honest) and the share within the "
           "99 % bound. \"legs\": every sensor at knee height. How the numbers are made: the "
           "header of tests/bench/tracking_benchmark.cc.\n\n"
        << (!KneeHeightBefore().empty() ? KneeHeightBefore()
            : g_before_mixed_pixels && g_before_far
                ? "\"before\": the new tracker without its handling of mixed pixels: at knee "
                  "height taking them for legs (`shape.drop_mixed_pixel_legs` false), at "
                  "upper-body "
                  "height fitting a far body's mixed edge points "
                  "(`shape.mixed_pixel_min_footprint_m` "
                  "0), on the same scans in the same run.\n\n"
            : g_before_mixed_pixels
                ? "\"before\": the new tracker taking knee-height mixed pixels for legs "
                  "(`shape.drop_mixed_pixel_legs` false), on the same scans in the same run; "
                  "upper-body rows are the same by construction.\n\n"
            : g_before_far
                ? "\"before\": the new tracker without the mixed-pixel model of far edges "
                  "(`shape.mixed_pixel_min_footprint_m` 0), on the same scans in the same "
                  "run.\n\n"
            : g_before_evidence_coasting
                ? "\"before\": the new tracker reporting every coasting track for "
                  "`tracking.report_coasting_s` whatever its evidence "
                  "(`tracking.report_coasting_per_measured_s` 0), on the same scans in the same "
                  "run.\n\n"
            : g_before_report_rules
                ? "\"before\": the new tracker without the coasting and moving report rules "
                  "(`shape.unseen_coasting_m` 0, `tracking.moving_speed_mps` 0), on the same "
                  "scans in the same run.\n\n"
                : "")
        << text;
  }
  return 0;
}
