#pragma once
// Multi-target tracker of one sensor (Quenzel et al., section III-B: "for each segment, the center
// of mass (CoM) is tracked over time by an Extended Kalman Filter under the assumption of a
// constant velocity. If multiple segments are candidates for one track, we associate the
// geometrically closest.").
//
// Per scan, Step():
//  1. Time. Every track's filter lives at the time of its last measurement. A scan more than
//     max_time_gap_s away from the previous one (either direction) deletes every track (counted as
//     time resets): predicting across such a gap is meaningless and all tracks would have timed out
//     anyway. A smaller step backwards is counted and processed without prediction (filters are
//     never predicted backwards).
//  2. Gating. Track i and measurement j are a candidate pair when both
//       d2_ij = (z_j - H x_i)^T S_ij^-1 (z_j - H x_i) <= gate_mahalanobis_sq   (S = H P H^T + R_j)
//     (R_j: the measurement's covariance plus extra_measurement_sigma_m^2 I)
//     and |z_j - H x_i| <= max_gate_distance_m, with x_i, P_i predicted to the measurement's time.
//  3. Association, one measurement per track and one track per measurement, first for the
//     confirmed tracks, then for the tentative tracks on the remaining measurements (a young track
//     with its vague velocity must not take an established track's measurement):
//     - kGlobalNearestNeighbour: the assignment that pairs the most candidate pairs and, among
//       those, minimises sum(d2_ij + ln det S_ij) (the negative log-likelihood of the pairing up to
//       a constant; ln det S favours the confident track when a coasting one competes for the same
//       measurement). Solved exactly with the Hungarian method (shortest augmenting paths with
//       potentials, O(n^2 m)) on fixed kMaxTracks x kMaxSegments storage; non-candidate pairs cost
//       kUnassignableCost.
//     - kClosest: the paper's rule; greedily pairs the geometrically closest remaining candidate
//       pair (Euclidean distance of predicted position and measurement).
//  3b. Recovery: confirmed tracks still without a measurement that were measured in the previous
//     scan (a coasting track would take whatever comes near its growing covariance), and
//     measurements nobody took, are paired greedily by d2_ij within recover_gate_mahalanobis_sq
//     (and max_gate_distance_m), smallest first (counted).
//  4. Update of assigned tracks (a track whose measurement lies beyond inflate_nis_above first has
//     its covariance scaled, see there); the kind, orientation and point count of the measurement
//     are kept. With a MeasurementRefiner (the pipeline's shape fit), the associated measurement is
//     first replaced by the refiner's, made with what the track knows (its shape state, its
//     predicted position and velocity), with the refiner's covariance as it is (no extra sigma); a
//     refined measurement farther than 4x the gate from the prediction is not used (counted). The
//     speed of the filter's velocity is then limited to max_speed_mps (counted): the limits of the
//     objects a site has.
//  5. Lifecycle. A new track is tentative; it is confirmed when it was updated in confirm_hits of
//     its first confirm_window scans (M of N) and deleted as soon as that became impossible; with
//     confirm_min_s, it is confirmed only once its first and latest measurements lie that far
//     apart, and until then deleted as soon as its latest confirm_window scans hold fewer than
//     confirm_hits updates. A confirmed track without a measurement coasts (predicted only) and is
//     deleted when its last measurement is older than coast_timeout_s or its position sigma
//     (square root of the largest eigenvalue of the position covariance at scan time) exceeds
//     max_position_sigma_m.
//     Static objects: a track remembers where it was when it last moved (an anchor; it moved when
//     its position leaves still_radius_m around the anchor, or, confirmed and not yet moved, when
//     its speed exceeds moving_speed_mps and three sigma of it). A track that never moved for
//     never_moved_to_background_s (clutter, an object put down while the sensor was not looking),
//     and one that moved but is not person-like (the refiner says: flat like a door leaf or a
//     chair's backrest, legs thinner than a person's) and has stood still for
//     static_object_to_background_s (a door swung open, a chair moved and left) is deleted and its
//     measurement of this scan is handed back (absorbed_sources()) so the background takes it over.
//     A person who stops stays a track (until the background absorbs them after its
//     absorb_after_s).
//  3c. A measurement marked evidence_only (Measurement::evidence_only, e.g. a knee-height leg
//     returned by a single beam) is a candidate for confirmed tracks only (steps 3 and 3b) and
//     starts or resumes no track (step 6).
//  5b. Successors: a confirmed track that coasts in this scan takes over a track measured in this
//     scan, in adopt_after_hits of its last 32 scans, whose first measurement came after the
//     coasting track's last one, that the refiner did not take for another kind of object
//     (TrackShape's shape: a trolley's track does not take over its pusher's) and that lies within
//     adopt_successor_m of the coasting track's prediction (nearest pairs first): the coasting
//     track takes the younger one's filter, shape and measurement, keeps its id and its confirmed
//     and moved state, and the younger one is deleted (counted as adopted, not as a deletion).
//  5c. Heirs: a confirmed track that has not moved, born within inherit_moved_s after a moved
//     track was lost nearby (within that one's gate), counts as moved (see inherit_moved_s).
//  6. Births. A measurement that was not assigned starts a tentative track unless it lies within
//     the gate of an existing track or of a track born earlier in the same scan (a person split
//     into two segments must not become two tracks). Births beyond max_tracks are dropped and
//     counted. Before that, a measurement within the gate of a track deleted by the coast timeout
//     less than resume_window_s ago (predicted to its time) resumes that track (of several, the
//     one with the smallest d2; counted as resumed, not as created): same id, its shape, its filter
//     restarted from its last measurement, confirmed again by M of N.
//  7. Reports: one TrackReport per confirmed track that has moved (and per tentative track if
//     report_tentative; confirmed tracks that never moved count as tentative there), ordered by id,
//     state and covariance at scan_start_ns.
//
// Measurement times: measurement j was taken at scan_start_ns + time_offsets_s[j] (e.g. the beam
// time of the segment's middle beam); the filter is predicted to that instant for gating and
// update, and reports are extrapolated back to scan_start_ns with the constant-velocity model
// (no process noise is subtracted). Without offsets every measurement is taken at scan start.
//
// Ids: uint32, 1, 2, 3, ... per MultiTracker instance (one session), never reused (0 is skipped if
// the counter ever wraps, after 2^32 - 1 tracks).
//
// Frames: whatever frame the measurements are in (the sensor frame in the pipeline). Pure: time is
// an argument, no clock, no I/O, no logging. Fixed allocation: Step never allocates.
// Not thread-safe; one instance per sensor.

#include <Eigen/Core>
#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>

#include "common/fixed_capacity.h"
#include "common/time.h"
#include "firmware_tracker/tracking/cv_ekf.h"
#include "firmware_tracker/tracking/measurement.h"
#include "firmware_tracker/tracking/segmentation.h"
#include "firmware_tracker/tracking/shape_fit.h"
#include "firmware_tracker/tracking/track_report.h"

namespace lrfnet::tracking {

enum class Association : std::uint8_t {
  kGlobalNearestNeighbour,  // optimal assignment on the gated costs
  kClosest,                 // greedy by Euclidean distance (the paper's "geometrically closest")
};

struct MultiTrackerOptions {
  CvEkfOptions ekf;
  Association association = Association::kGlobalNearestNeighbour;
  // Squared Mahalanobis distance; 9.21 = chi-square quantile for 2 degrees of freedom at 99 %.
  double gate_mahalanobis_sq = 9.21;
  // Recovery (step 3b): a confirmed track measured in the previous scan and left without a
  // measurement in this one takes the nearest one nobody took within this wider gate (and
  // max_gate_distance_m) before it may start a second track. 18.42 = chi-square 2 dof at 99.99 %. A
  // person who starts, stops or turns runs ahead of the constant-velocity prediction by 0.3 m
  // within a few scans; with the 99 % gate that measurement started a new track beside the old one
  // (an id switch and a ghost). 0 turns it off.
  double recover_gate_mahalanobis_sq = 18.42;
  // Manoeuvres (step 4): an associated measurement whose d2 (normalised innovation squared)
  // exceeds this scales the track's covariance by d2 / 2 before the update (a one-step fading
  // memory; 2 is d2's expectation for 2 dof). The filter then follows a start, stop or turn within
  // a scan or two instead of lagging behind it by 0.2-0.4 m (results/tracking_benchmark.md).
  // 0 turns it off; otherwise >= 2.
  double inflate_nis_above = 2.0;
  // The covariance reported with a measured scan: the one the gains the filter applied leave
  // (CvEkf::gain_covariance, Joseph form with the same gains) with the measurement noise across
  // the line of sight measured from the track's innovations instead of the R the filter is given
  // (covariance matching: Mehra, "Approaches to adaptive filtering", IEEE TAC 17(5), 1972; Myers
  // and Tapley, IEEE TAC 21(4), 1976): E[nu nu^T] = H P- H^T + R, so the noise across the ray is
  // the running mean over about measured_noise_memory_scans updates of (w^T nu)^2 - w^T P- w (w
  // across the ray, P- the gain covariance predicted), never below zero. The R the filter is given
  // holds a fixed ShapeOptions::centre_model_sigma_m (sway, the torso's turn, the outline) that
  // does not shrink where a clean outline of many points is seen: 1.5 cm per scan where such views
  // scatter across the ray by a few millimetres, and the filter reported ~1.1 cm per axis for a
  // centre 0.4 cm off across the ray (tracking_benchmark --breakdown, shipped scenes, upper body,
  // 20+ points within 5 m). Along the ray (the body's extent towards the sensor), and where another
  // object is beside the body, the outline departs from the model by more than that R allows per
  // scan, or the view rests on the priors, the errors are shared by successive scans and the
  // innovations do not show them: the filter's R stays. Until half the memory has been seen, too.
  // The tracks are the same (the gains are); a coasting report stays the filter's prediction.
  // Upper-body mount only (TrackingPipeline sets measured_noise_memory_scans 0 at knee height);
  // at either height a measurement may carry its own noise (Measurement::gain_relief_m2,
  // gain_still: two legs seen still, ShapeOptions::still_legs_cov), which the gain covariance
  // takes with this on.
  // false: the filter's own covariance, as before (tracking_benchmark --before-gain-covariance).
  bool report_gain_covariance = true;
  // 0: the gain covariance with the filter's R (the same as the filter's own).
  double measured_noise_memory_scans = 20.0;
  // Euclidean bound on top of the statistical gate: a coasting track's covariance grows quickly and
  // would otherwise swallow measurements of other people. 1 m is ~0.7 s of walking.
  double max_gate_distance_m = 1.0;
  // Added in quadrature to every measurement's covariance (sigma per axis): the centre of a person
  // moves by a few cm more than a fit's residuals show (sway, arm swing, the visible part changing
  // with the viewpoint; a fixed-axes ellipse fit on 5-8 points at 5 m flips between the end and the
  // side of the ellipse, ~10 cm). Without it, ellipse fits claiming 1 cm make an established track
  // reject its own person after such a jump and start a second track.
  double extra_measurement_sigma_m = 0.05;
  // M of N: confirmed when updated in confirm_hits of the first confirm_window scans (3 of 4 at
  // 25 Hz: confirmed 80-120 ms after the first detection, while single-scan clutter and 2-scan
  // flicker never confirm).
  std::uint32_t confirm_hits = 3;
  std::uint32_t confirm_window = 4;  // <= 32
  // ... and only once its first and latest measurements lie at least this far apart, M of N
  // holding in every window of confirm_window scans meanwhile (deleted as soon as one fails). A
  // time, not a scan count: M of N alone confirms after (confirm_hits - 1) scan periods, 40 ms at
  // 50 Hz, which leg-sized clutter at knee height (mixed pixels behind a person, flicker at
  // edges) reaches in short bursts, while a walking person's legs stay in view for as long as
  // they walk through it. Such bursts' lengths fall off steadily, with no gap to cut at
  // (tracking_benchmark, knee height, per sensor: false tracks 3.91 / 2.63 / 1.86 / 1.19 per
  // target-minute at 0 / 0.12 / 0.2 / 0.3 s, MOTA 0.608 / 0.600 / 0.601 / 0.589); 0.2 s halves
  // them for 160 ms more latency at 50 Hz, one scan more at 12.5 Hz (0.24 s). The cost: someone
  // seen in fewer than 3 of 4 scans for 0.2 s at a stretch (legs at 8-10 m that fill no beam's
  // footprint in most scans) is confirmed later or not at all, as sporadic clutter is. 0: M of N
  // alone. The pipeline applies it at knee height only (ShapeOptions::mount kLegs): at upper-body
  // height it removes little and costs missed scans.
  double confirm_min_s = 0.2;
  // A confirmed track survives this long without measurements. 1 s covers a person at walking
  // speed (1.2 m/s) passing behind a 0.4 m pillar half-way to the sensor (shadow ~0.8 m wide at
  // the person: ~0.5 s hidden, ~1 s partly hidden) and two people passing each other; longer
  // timeouts keep ghosts of people who left the field of view.
  double coast_timeout_s = 1.0;
  // A confirmed track deleted after coast_timeout_s (or for its covariance) is kept this much
  // longer, unreported and not associated, and resumed (same id, confirmed, its state and shape)
  // by a measurement no track took that lies within its gate (gate_mahalanobis_sq with its
  // coasted covariance, and max_gate_distance_m) instead of a new tentative track: a person hidden
  // behind a pillar or another person for 1-3 s comes back as themselves, reported at once
  // (a new track waits for confirm_hits and still_radius_m or moving_speed_mps: missed scans and,
  // for the evaluation, a fragment and an id switch). 0: off. The pipeline turns it off at knee
  // height (ShapeOptions::mount kLegs).
  double resume_window_s = 1.0;
  // Successors (step 5b): a confirmed track coasting since its last measurement takes over a track
  // born after that measurement (never measured beside it) within this distance of its prediction
  // once the younger one was measured in adopt_after_hits scans and is measured in this one: the
  // same id on the same person, reported at once. A person whose walk the constant-velocity
  // prediction lost (a turn, a stop, a step hidden by the other leg at knee height) is found
  // again by a new track beside the old one while the old one coasts on where nobody is: two
  // tracks of one person, one of them false, until the new one is confirmed and the old one times
  // out (an id switch and a fragment). 1 m: a walking person's reach within the report time of a
  // coasting track, the gate's Euclidean bound (tracking_benchmark, knee height per sensor,
  // precision: 0.9804 at 0.7 m, 0.9806 at 1 m, 0.9776 at 1.5 m with 2 scans, where the younger
  // track is more often someone else). 0: off. The pipeline applies it at knee height only
  // (ShapeOptions::mount kLegs).
  double adopt_successor_m = 1.0;
  // ... measured in this many scans: as many as confirm_hits asks of an object (tracking_benchmark,
  // knee height per sensor, 2 / 3 / 4: precision 0.9807 / 0.9806 / 0.9785, fused id switches per
  // target-minute 2.62 / 2.50 / 2.52). In [1, 32].
  std::uint32_t adopt_after_hits = 3;
  // Safety net for covariance growth (large coast_timeout_s, fresh tracks with the 1.5 m/s velocity
  // prior): a track whose position sigma exceeds this can no longer be associated sensibly.
  double max_position_sigma_m = 1.0;
  std::size_t max_tracks = 32;  // <= kMaxTracks
  // Steps between consecutive scans beyond this (forwards or backwards) delete all tracks.
  double max_time_gap_s = 2.0;
  bool report_tentative = false;
  // A coasting track is reported for this long after its last measurement, and kept (to be found
  // again) until coast_timeout_s: a person hidden for longer may have stopped or turned, and a
  // track reported where they are not is a false one.
  double report_coasting_s = 0.5;
  // ... and for no longer than this times how long it was seen (the time between its
  // measurements in consecutive scans, summed): a track with little evidence of an object is
  // reported coasting only briefly. Sporadic clutter at knee height (a leg-sized echo in 3-4
  // consecutive scans now and then: confirmed after 60 ms at 50 Hz, seen for 60 ms) was reported
  // for 0.5 s after each hit, 2.5-4 coasting reports per measured one; a person seen for
  // report_coasting_s / this or longer is not affected. A time, not a scan count: the same at every
  // scan rate. 0: off.
  double report_coasting_per_measured_s = 1.0;
  // Seen, for the above: the time between two of the track's measurements at most this far apart
  // (a person at the edge of the range is measured in some scans only; clutter comes in bursts).
  double seen_gap_s = 0.2;
  // Motion limit: the filter's speed is clamped to this. 2.5 m/s covers people walking fast; a site
  // with forklifts or running people raises it (with accel_psd_m2ps3, initial_velocity_sigma_mps
  // and max_gate_distance_m).
  double max_speed_mps = 2.5;
  // Static objects (step 5). Off: every confirmed track is reported, none is handed to the
  // background (the previous tracker's behaviour).
  bool static_objects = true;
  double still_radius_m = 0.25;
  // A confirmed track also counts as moved (and is reported from then on) when its filter's speed
  // exceeds this and three sigma of the speed along its direction: a person walking in is
  // reported from their confirmation instead of after still_radius_m (5 scans more at 1.2 m/s
  // and 25 Hz, each a missed scan and, after someone reappears, a fragment). 0: off.
  double moving_speed_mps = 0.5;
  double never_moved_to_background_s = 3.0;
  double static_object_to_background_s = 2.0;
  // Heirs (step 5c): a confirmed track that has not moved, first measured after the last
  // measurement of a moved track that was then lost (deleted by the coast timeout or for its
  // covariance, not handed to the background), at most this long after it (never measured beside
  // it: not an object that stood next to the person), counts as moved (reported from then on, not
  // absorbed as never moved) when its position lies within that track's gate: the lost track's
  // last measurement (not its coasted prediction: a track that drifted off along the ray before
  // it was lost coasts on away from the person) with its coasted covariance plus the heir's
  // (gate_mahalanobis_sq, and max_gate_distance_m). A person who was reported and stands still,
  // whose track ended (a short occlusion, a drift, an id swap) and restarted on them, has not left
  // still_radius_m since and was otherwise never reported again, then deleted by
  // never_moved_to_background_s. One heir per lost track; the heir must be person-like
  // (TrackShape::person_like): a chair a person moved and left does not inherit. 0: off.
  double inherit_moved_s = 3.0;
};

// nullopt when valid, else the reason, naming the field first (nested: "ekf.<field> ...").
std::optional<std::string> Validate(const MultiTrackerOptions& options);

struct MultiTrackerCounters {
  std::uint64_t scans = 0;
  std::uint64_t measurements = 0;  // accepted (finite, positive definite covariance)
  std::uint64_t associations = 0;  // track updates with a measurement
  std::uint64_t created = 0;
  std::uint64_t confirmed = 0;
  std::uint64_t deleted_tentative = 0;      // could no longer reach M of N
  std::uint64_t deleted_coast_timeout = 0;  // confirmed, no measurement for coast_timeout_s
  std::uint64_t deleted_covariance = 0;     // position sigma above max_position_sigma_m
  std::uint64_t deleted_time_reset = 0;     // removed by a time reset
  std::uint64_t dropped_capacity = 0;       // births refused: max_tracks reached
  std::uint64_t births_suppressed = 0;      // unassigned measurement inside a track's gate
  std::uint64_t rejected_measurements = 0;  // non-finite values or covariance not positive def.
  std::uint64_t measurements_over_capacity = 0;  // beyond kMaxSegments per scan, ignored
  std::uint64_t failed_updates = 0;              // filter refused an update (numerically)
  std::uint64_t time_steps_backwards = 0;
  std::uint64_t time_resets = 0;      // |scan gap| > max_time_gap_s
  std::uint64_t refine_failures = 0;  // the refiner had no measurement, or it was far off
  std::uint64_t speed_clamps = 0;     // updates whose speed exceeded max_speed_mps
  std::uint64_t deleted_static = 0;   // handed to the background (step 5)
  std::uint64_t recovered = 0;        // associations made in the wider gate (step 3b)
  std::uint64_t resumed = 0;          // deleted tracks found again (resume_window_s)
  std::uint64_t adopted = 0;          // younger tracks taken over by a coasting one (step 5b)
  std::uint64_t inherited_moved = 0;  // tracks counted as moved for a lost moved one (step 5c)
  // Confirmed coasting tracks' reports withheld: coasting for longer than report_coasting_s (or
  // report_coasting_per_measured_s times how long they were seen), per scan.
  std::uint64_t coasting_unreported = 0;

  std::uint64_t deleted() const {
    return deleted_tentative + deleted_coast_timeout + deleted_covariance + deleted_time_reset +
           deleted_static;
  }
};

// What a track has learned of its object (shape-fit measurements, see shape_fit.h and pipeline.h);
// the refiner reads and updates it, the tracker keeps it and reports it.
struct TrackShape {
  ObjectShape shape = ObjectShape::kUnspecified;
  ShapeModel model = ShapeModel::kSuperellipse;
  Eigen::Vector2d size_m = Eigen::Vector2d::Zero();           // (a, b), see TrackReport
  Eigen::Matrix2d size_cov_m2 = Eigen::Matrix2d::Identity();  // of size_m
  double yaw_rad = 0.0;                                       // direction of axis a
  double yaw_sigma_rad = kUnknownYawSigmaRad;
  double exponent = 2.0;       // superellipse exponent (2: ellipse or cylinder)
  common::UtcNs stamp_ns = 0;  // time of the state (the last refined measurement)
  std::uint32_t updates = 0;
  // Two legs of a walking track (ShapeOptions::walking_legs_cov): the variance per axis of the
  // legs' midpoint about the body's centre that successive scans share, reported with the track's
  // measured scans; zero otherwise (a float: it fits beside `updates`, and the shape is copied
  // with every update). walking_relieved: the track's last update was such a pair's
  // (Measurement::gain_walking; the next other one sets Measurement::gain_restart).
  float reported_gait_m2 = 0.0F;
  // Running evidence of what the object is: a flat outline (door leaf, board) or legs thinner than
  // a person's make it not person-like.
  double flatness_m2 = 0.0;
  std::uint32_t evidence_updates = 0;  // updates that carried such evidence
  // Legs mount: the share of a still track's recent two-leg measurements whose legs lay deeper
  // along the ray than a standing person's (ShapeOptions::still_legs_max_depth_m), and how many
  // such still two-leg measurements it had.
  double still_deep_pair_share = 0.0;
  std::uint32_t still_pair_updates = 0;
  bool person_like = true;
  bool walking_relieved = false;
  // What the measurements share and the filter cannot average away (the size state's error, the
  // outline not being the model's): added to the reported position covariance, not to the
  // filter's.
  Eigen::Matrix2d centre_bias_cov_m2 = Eigen::Matrix2d::Zero();
  // A box's semi-axes as seen (ShapeOptions::box_seen_extent_cov): half the longest extent its
  // fitted points showed along each axis, and half the extent the last complete view that showed
  // the semi-axis whole did (0: none yet).
  Eigen::Vector2d box_seen_half_m = Eigen::Vector2d::Zero();
  Eigen::Vector2d box_whole_half_m = Eigen::Vector2d::Zero();
  // Mean over recent scans of the variance the outline's departure from the model adds
  // (ShapeOptions::outline_departure_gain).
  double departure_m2 = 0.0;
  // The departure's variance reported with the track's measured scans (the larger of this scan's
  // and the mean), per axis. Not with coasting reports: see MultiTracker's Report.
  double reported_departure_m2 = 0.0;
  // A partial view's fit covariance, reported with the track's measured scans
  // (ShapeOptions::partial_view_shared); zero otherwise. Not with coasting reports.
  Eigen::Matrix2d reported_partial_cov_m2 = Eigen::Matrix2d::Zero();
  // Another object beside the body (ShapeOptions::neighbour_sigma_m): the variance per axis
  // reported with the track's measured scans; zero otherwise. Not with coasting reports.
  double reported_neighbour_m2 = 0.0;
  // A segment wider than the body (ShapeOptions::segment_excess_shared): the covariance of where
  // along the segment the body lies, reported with the track's measured scans; zero otherwise.
  Eigen::Matrix2d reported_excess_cov_m2 = Eigen::Matrix2d::Zero();
  // A body fit's segment that is a box's outline (ShapeOptions::box_view_shared): the second
  // moment of where the box's centre lies about the measurement, reported with the track's
  // measured scans; zero otherwise. Not given to the filter's measured noise.
  Eigen::Matrix2d reported_box_view_cov_m2 = Eigen::Matrix2d::Zero();
  // Two legs seen still (ShapeOptions::still_legs_cov): what centre_bias_cov_m2 holds beyond the
  // shared allowances of a still pair, taken out of the reports of measured scans (not of coasting
  // ones: the coasting checks take their reach from those); zero otherwise.
  Eigen::Matrix2d reported_bias_relief_m2 = Eigen::Matrix2d::Zero();
  // Knee height: the leg centres of the track's last two-leg measurement, their fits' variance
  // (mean over the axes) and its time, 0: none (ShapeOptions::stance_leg_weight).
  std::array<Eigen::Vector2d, 2> legs_m{Eigen::Vector2d::Zero(), Eigen::Vector2d::Zero()};
  std::array<double, 2> legs_var_m2{};
  common::UtcNs legs_ns = 0;
  // Which of legs_m stood then (-1: not known at least half sure; ShapeOptions::
  // single_leg_from_standing).
  int legs_standing = -1;
};

// Replaces an associated measurement with one made with what its track knows (the pipeline's shape
// fit). `source`: index of the measurement as given to Step; `at_ns`: its time. `predicted` and
// `predicted_cov`: the track's (x, y, vx, vy) at that time and its covariance, nullptr for a new
// track. `shape`: in, the track's state (default-constructed for a new track); out, updated.
// `measurement`: in, the scan's measurement; out, the refined one. False: nothing usable (the
// track is not updated, or not started).
class MeasurementRefiner {
 public:
  virtual ~MeasurementRefiner() = default;
  virtual bool Refine(std::size_t source, common::UtcNs at_ns, const Eigen::Vector4d* predicted,
                      const Eigen::Matrix4d* predicted_cov, TrackShape& shape,
                      Measurement& measurement) = 0;
};

// A live track's position predicted to some time (for the pipeline's pairing of legs and its
// rejoining of a box's pieces).
struct TrackPrediction {
  std::uint32_t id = 0;
  bool confirmed = false;
  Eigen::Vector2d position_m = Eigen::Vector2d::Zero();
  Eigen::Matrix2d covariance_m2 = Eigen::Matrix2d::Identity();
  // The track's shape state (TrackShape): its model, learned size, its covariance and yaw.
  ShapeModel model = ShapeModel::kSuperellipse;
  Eigen::Vector2d size_m = Eigen::Vector2d::Zero();
  Eigen::Matrix2d size_cov_m2 = Eigen::Matrix2d::Zero();
  double yaw_rad = 0.0;
};

namespace internal {
// Outside the class: nested types with member initializers are not yet default-constructible where
// the class body instantiates FixedVector of them.
struct Track {
  CvEkf filter;
  common::UtcNs filter_ns = 0;        // time the filter state refers to
  common::UtcNs last_update_ns = 0;   // time of the last measurement
  common::UtcNs first_update_ns = 0;  // time of the first measurement (restarted when resumed)
  // Time between its measurements in consecutive scans, summed (kept when resumed): how long it
  // was seen, for report_coasting_per_measured_s.
  double measured_s = 0.0;
  std::uint32_t id = 0;
  bool confirmed = false;
  bool updated = false;         // in the current scan
  std::uint32_t hits = 0;       // bit k: updated k scans ago (bit 0 = current scan)
  std::uint32_t age_scans = 0;  // scans since creation (0 in the creation scan)
  MeasurementKind kind = MeasurementKind::kCenterOfMass;
  double ellipse_yaw_rad = 0.0;
  std::uint32_t points = 0;  // of the measurement of the current scan, 0 if none
  TrackShape shape;
  // Static objects: where the track was when it last moved, and since when it stays near there.
  Eigen::Vector2d anchor_m = Eigen::Vector2d::Zero();
  common::UtcNs anchor_ns = 0;
  bool moved = false;
  std::size_t source = 0;                         // measurement of the current scan (when updated)
  Eigen::Vector2d z_m = Eigen::Vector2d::Zero();  // its position as used (refined), sensor frame
  double z_offset_s = 0.0;                        // its time after the scan start
  // MultiTrackerOptions::measured_noise_memory_scans: the running mean of innovation nu nu^T less
  // the predicted gain covariance's position block, and how many updates it holds.
  double innovation_excess_m2 = 0.0;
  double innovation_updates = 0.0;
};
// An accepted measurement of the current scan.
struct Candidate {
  Eigen::Vector2d z_m = Eigen::Vector2d::Zero();
  Eigen::Matrix2d r_m2 = Eigen::Matrix2d::Identity();
  double offset_s = 0.0;
  std::size_t source = 0;      // index into the caller's measurements
  bool evidence_only = false;  // Measurement::evidence_only
};
// Where a moved track was lost (step 5c): its last measurement, its position covariance at the
// scan start it was lost at.
struct LostMoved {
  Eigen::Vector2d position_m = Eigen::Vector2d::Zero();
  Eigen::Matrix2d cov_m2 = Eigen::Matrix2d::Identity();
  common::UtcNs lost_ns = 0;
  common::UtcNs last_update_ns = 0;  // its last measurement
};
// State and covariance of a constant-velocity filter moved by dt_s without process noise: used to
// move a just-updated track from its measurement time back to the scan start (a few ms).
void Extrapolate(double dt_s, Eigen::Vector4d& x, Eigen::Matrix4d& p);
}  // namespace internal

class MultiTracker {
 public:
  // Cost of a pair outside the gate in the assignment problem; far above any sum of gated costs.
  static constexpr double kUnassignableCost = 1e9;

  // Precondition: Validate(options) is nullopt (checked; aborts otherwise).
  explicit MultiTracker(const MultiTrackerOptions& options);

  // One scan: measurements (at most kMaxSegments are used) taken at scan_start_ns. `out` is
  // overwritten: scan_start_ns and tracks (scan_period_s and scan_counter are left to the caller).
  void Step(common::UtcNs scan_start_ns, std::span<const Measurement> measurements,
            ScanTracks& out);
  // As above; time_offsets_s[j] (seconds, >= 0, finite, else treated as 0) is the time of
  // measurement j after scan_start_ns. An empty span means all zero; otherwise same size as
  // measurements.
  void Step(common::UtcNs scan_start_ns, std::span<const Measurement> measurements,
            std::span<const double> time_offsets_s, ScanTracks& out);
  // As above, with `refiner` (not null) making every update's and every birth's measurement.
  void Step(common::UtcNs scan_start_ns, std::span<const Measurement> measurements,
            std::span<const double> time_offsets_s, MeasurementRefiner* refiner, ScanTracks& out);

  // Every live track's position predicted to t_ns (without changing it), confirmed tracks first;
  // returns how many were written (at most out.size()).
  std::size_t Predict(common::UtcNs t_ns, std::span<TrackPrediction> out) const;
  // Measurements (indices as given to Step) of the tracks the last Step handed to the background.
  std::span<const std::size_t> absorbed_sources() const { return absorbed_.span(); }

  // Deletes all tracks (not counted as deletions); ids keep counting.
  void Clear();

  const MultiTrackerOptions& options() const { return options_; }
  const MultiTrackerCounters& counters() const { return counters_; }
  std::size_t track_count() const { return tracks_.size(); }
  std::size_t confirmed_count() const;
  std::uint32_t next_id() const { return next_id_; }

 private:
  using Track = internal::Track;
  using Candidate = internal::Candidate;

  void HandleTime(common::UtcNs scan_start_ns);
  void AcceptMeasurements(std::span<const Measurement> measurements,
                          std::span<const double> time_offsets_s);
  void Gate(common::UtcNs scan_start_ns);
  void Associate(bool confirmed);
  void Recover();
  void UpdateAssigned(common::UtcNs scan_start_ns, std::span<const Measurement> measurements,
                      MeasurementRefiner* refiner);
  void ManageLifecycle(common::UtcNs scan_start_ns);
  void AdoptSuccessors(common::UtcNs scan_start_ns);
  // Step 5c: notes a moved track lost at scan_start_ns; Inherit: true when t (confirmed, not
  // moved, updated) lies where such a track was lost (the record is used up).
  void NoteLostMoved(const Track& t, common::UtcNs scan_start_ns);
  bool Inherit(const Track& t, common::UtcNs scan_start_ns);
  void StartTracks(common::UtcNs scan_start_ns, std::span<const Measurement> measurements,
                   MeasurementRefiner* refiner);
  // Step 6's resumption: true when candidate c resumed a lost track (moved back into tracks_).
  bool Resume(common::UtcNs scan_start_ns, const Candidate& c,
              std::span<const Measurement> measurements, MeasurementRefiner* refiner);
  // Candidate c's measurement for track t at at_ns, in *m, *z, *r: with a refiner, its fit made
  // from what t knows (t's shape updated), which must be finite and, for a finite max_d2, within
  // max_d2 of t's prediction (false otherwise, t unchanged); without one, c's own.
  // MultiTrackerOptions::measured_noise_memory_scans: the measurement noise the gain covariance
  // takes for this update (z_m: the measurement, r_m2: the filter's R), the track's innovation
  // statistics updated with it.
  Eigen::Matrix2d MeasuredNoise(Track& t, const Eigen::Vector2d& z_m,
                                const Eigen::Matrix2d& r_m2) const;
  // MultiTrackerOptions::report_gain_covariance with measured noise: a confirmed track's filter
  // keeps its gain covariance (CvEkf::StartGainCovariance), from its confirmation on.
  bool GainCovariance() const {
    return options_.report_gain_covariance && options_.measured_noise_memory_scans > 0.0;
  }
  // ... or a measurement's own noise (Measurement::gain_relief_m2, gain_still): with
  // report_gain_covariance a confirmed track keeps its gain covariance either way (equal to the
  // filter's own, and not formed apart, until an update's noise differs from R).
  bool KeepGainCovariance() const { return options_.report_gain_covariance; }
  bool MeasureForTrack(Track& t, const Candidate& c, common::UtcNs at_ns,
                       std::span<const Measurement> measurements, MeasurementRefiner* refiner,
                       double max_d2, Measurement* m, Eigen::Vector2d* z, Eigen::Matrix2d* r) const;
  // What a track keeps of the measurement its filter just took.
  void NoteUpdate(Track& t, const Measurement& m, const Candidate& c, const Eigen::Vector2d& z,
                  common::UtcNs at_ns, common::UtcNs scan_start_ns);
  void Lose(const Track& t, common::UtcNs scan_start_ns);
  void LimitSpeed(Track& t);
  void Report(common::UtcNs scan_start_ns, ScanTracks& out);
  bool InsideGate(const Eigen::Vector2d& predicted_m, const Eigen::Matrix2d& predicted_cov_m2,
                  const Candidate& c, double* d2, double* log_det) const;
  // y^T S^-1 y of the pair (infinity beyond max_gate_distance_m or for a degenerate S); det: S's
  // determinant where finite (its log only where a pair is inside the gate: one log per gated pair
  // instead of one per pair within max_gate_distance_m).
  double MahalanobisSq(const Eigen::Vector2d& predicted_m, const Eigen::Matrix2d& predicted_cov_m2,
                       const Candidate& c, double* det) const;
  std::uint32_t NewId();

  MultiTrackerOptions options_;
  MultiTrackerCounters counters_;
  bool has_time_ = false;
  common::UtcNs last_scan_ns_ = 0;
  std::uint32_t next_id_ = 1;
  common::FixedVector<Track, kMaxTracks> tracks_;
  // Confirmed tracks deleted by the coast timeout within resume_window_s (step 6).
  common::FixedVector<Track, kMaxTracks> lost_;
  // Step 5c: where moved tracks were lost (inherit_moved_s).
  common::FixedVector<internal::LostMoved, kMaxTracks> lost_moved_;

  // Per-scan scratch, sized at compile time.
  common::FixedVector<Candidate, kMaxSegments> candidates_;
  std::array<std::array<double, kMaxSegments>, kMaxTracks> cost_{};      // gated or unassignable
  std::array<std::array<double, kMaxSegments>, kMaxTracks> distance_{};  // metres; where gated_
  std::array<std::array<bool, kMaxSegments>, kMaxTracks> gated_{};
  std::array<std::array<double, kMaxSegments>, kMaxTracks> d2_{};  // Mahalanobis^2, inf: none
  std::array<bool, kMaxSegments> gated_any_{};  // per candidate: gated_ set in any track's row
  std::array<int, kMaxTracks> track_to_candidate_{};               // -1: none
  std::array<int, kMaxSegments> candidate_to_track_{};             // -1: none
  common::FixedVector<std::size_t, kMaxTracks> absorbed_;
};

}  // namespace lrfnet::tracking
