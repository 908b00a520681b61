#pragma once
// The per-scan tracking pipeline of one sensor (Quenzel et al., section III-B, with the body-centre
// measurement of shape_fit.h): background model -> segmentation of the foreground -> observations
// -> multi-target tracker -> ScanTracks.
//
// Observations (method kShapeFit, the default). What one person (or object) shows in a scan:
// - mount kTorso: one segment.
// - mount kLegs: one or two legs. A segment narrower than a leg pair (2 (hip + leg radius) + a
//   margin) holds one leg, or two that touch (split at the widest gap between its points); wider
//   segments are something else (a trolley) and stay whole. Legs are paired into people: first
//   around every live track's predicted position (the pair whose midpoint is nearest, within
//   leg_pairing_distance_m of each other, or a single leg when the other is hidden), confirmed
//   tracks first; the legs left over pair with their nearest neighbour within
//   leg_pairing_distance_m, the rest stay single (one track per person, not per leg). Mixed
//   pixels at a leg's edge are not legs (ShapeOptions::drop_mixed_pixel_legs), nor echoes behind
//   a nearer return their beams had a moment before (ShapeOptions::recent_veil_s).
// Each observation gets a cheap first position for association (the middle of its silhouette,
// behind the nearest point by the prior's extent, sigma association_sigma_m). The tracker then
// asks for the real measurement of every observation it associated or starts a track with
// (MeasurementRefiner): the shape fit with the track's size state as the prior, its walking
// direction as the yaw prior (the shoulders across it; a box's length along it) and its predicted
// position as the start; legs: a circle per leg with the track's leg radius, the body centre their
// midpoint (plus gait_sigma_m: the legs' midpoint swings about the body's centre as they step;
// weighted towards the standing leg, ShapeOptions::stance_leg_weight; two legs that touch in the
// scan with the farther leg's depth along the ray, ShapeOptions::touching_legs_along_ray), or
// one leg: hip_half_width_m behind it along the line of sight where it hides the other
// (ShapeOptions::hidden_leg_behind), a walking track's hip_half_width_m across the walk from it
// (ShapeOptions::single_leg_across_walk) and along the walk from the hidden leg that stood at the
// last two-leg measurement (ShapeOptions::single_leg_from_standing), else its centre (plus the hip
// and stride extent). The fit's
// size posterior becomes the track's size state (drifting by size_drift_m_per_sqrt_s between
// scans), and a track whose learned semi-axis a exceeds box_min_half_length_m is fitted as a box
// from then on. Whether an object is person-like (static objects, multi_tracker.h): torso: not flat
// (the points' distance to their principal line, range noise removed, averaged over the track's
// life, stays above flat_rms_m on outlines longer than flat_min_extent_m, of at least 4 points,
// over which a person's back would stand out of the range noise); legs: leg radius at least
// person_min_leg_radius_m.
//
// Methods kCenterOfMass / kEllipse: the previous tracker (measurement.h), one measurement per
// segment, no shape state (kept to compare against).
//
// Time: ScanView::stamp_ns is the time of beam 0 (scan start, gateway UTC). The mirror turns once
// per scan_period_s and the telegram lists beams in the order they were measured, so beam i is
// measured i * |angle_step_rad| / (2 pi) * scan_period_s after the scan start (an LMS1xx at 25 Hz
// and 0.5 deg: 55.6 us per beam, 30 ms across 270 deg; a person at 1.5 m/s moves 4.5 cm in that
// time). With correct_beam_time each measurement is stamped with the beam time of its
// observation's middle beam and the tracker predicts to that instant; without it, every
// measurement counts as taken at scan start. Either way all reported tracks are valid at the scan
// start.
//
// Coasting tracks (kShapeFit, torso mount): a coasting track's report is dropped where the scan
// sees through its predicted position (ShapeOptions::seen_through_margin_m), and, once it has
// coasted more than ShapeOptions::unseen_coasting_m, where the scan shows nothing of it.
//
// Rejected scans (CheckScan) and scans while the background is being learned produce no
// measurements; existing tracks coast through them. Static objects the tracker recognises are
// handed to the background model (BackgroundModel::Absorb).
//
// Fixed allocation: every buffer is a member sized at compile time (kMaxBeams, kMaxSegments,
// kMaxTracks); Process never allocates. The object is large (several hundred KiB; most of it the
// per-beam background model and the segment point pool): allocate it once at start-up (e.g.
// std::make_unique), not on the stack. Process itself needs about 30 KiB of stack (the ellipse
// fit's per-point scratch). Not thread-safe; one instance per sensor.

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>

#include "common/fixed_capacity.h"
#include "firmware_tracker/tracking/background_model.h"
#include "firmware_tracker/tracking/measurement.h"
#include "firmware_tracker/tracking/multi_tracker.h"
#include "firmware_tracker/tracking/scan_view.h"
#include "firmware_tracker/tracking/segmentation.h"
#include "firmware_tracker/tracking/shape_fit.h"
#include "firmware_tracker/tracking/track_report.h"

namespace lrfnet::tracking {

// The body-centre measurement (see the header comment). Defaults: people at upper-body or knee
// height.
struct ShapeOptions {
  Mount mount = Mount::kTorso;
  ShapeFitOptions fit;
  // Prior of a person's upper body (torso mount): semi-axes across the shoulders and front to back
  // (adults, arms included) and their sigma. Also the start of a cylinder's or cart's size.
  double person_major_m = 0.23;
  double person_minor_m = 0.14;
  double person_size_sigma_m = 0.04;
  // The upper body's outline: the superellipse |u/a|^p + |v/b|^p = 1 with this p (2: an ellipse;
  // a torso with arms lies between an ellipse and a rounded box). A track whose learned semi-axes
  // differ by less than a tenth is a cylinder, fitted with p = 2 from then on.
  double person_exponent = 2.5;
  // A track whose learned semi-axis a exceeds this is a cart or trolley: fitted as a box.
  double box_min_half_length_m = 0.36;
  // Sigma of a box's semi-axes when a track becomes one (its size state's variance raised to at
  // least this square): the person prior it learned from says little of a cart's size.
  double box_size_sigma_m = 0.2;
  // Legs mount: a leg's radius at knee height and its sigma; legs of one person are at most this
  // far apart (centre to centre); a leg thinner than person_min_leg_radius_m is not a person's
  // (a chair's).
  double leg_radius_m = 0.06;
  double leg_radius_sigma_m = 0.015;
  double leg_pairing_distance_m = 0.7;
  double person_min_leg_radius_m = 0.035;
  // Legs mount: a track that stands still (not walking: WalkingDirection) and is measured, in
  // more than half of its recent two-leg measurements (the last 20, at least 5; those while it
  // walked count as not deep), as two legs farther apart along the line of sight than this, the
  // nearer of them a single beam, is not a person's for the static-object rules
  // (MultiTrackerOptions::static_object_to_background_s). A standing person's legs stand side by side, their centres a hip's width (2
  // hip_half_width_m, 0.16-0.22 m) apart across the body, so along any ray at most that plus a
  // stance; a single beam this far in front of a still leg is a post too thin to fill a beam (a
  // chair's leg) with something standing behind it: every beam over the post returns a range
  // between the two (a mixed pixel), a leg-like pair that stands as still as they do, on which a
  // track sat until the background absorbed it (background.absorb_after_s); the person behind
  // stays hidden by the mixed echoes either way. Without the single-beam condition the
  // pusher of a parked trolley, their legs paired with the trolley's, was deleted as well.
  // Scenario test AStillKneeHeightPairDeepAlongTheRayBehindASingleBeamIsNotAPerson. 0: off (only
  // the legs' radius decides).
  double still_legs_max_depth_m = 0.4;
  double hip_half_width_m = 0.1;  // a leg's lateral offset from the body centre
  // Legs mount: mixed pixels are not legs. A beam that grazes a leg reports a range between the
  // leg and what lies behind it; where the beam's footprint (beam_divergence_rad times the range)
  // is as wide as a leg (an LMS1xx from 8 m on) no beam is filled by the leg, and its echoes form
  // leg-sized segments up to metres behind the person that walk with them (tracking_benchmark
  // --explain: 95 % of schenk_A's knee-height clutter scans lay straight behind the person, 2-4 m
  // back). Dropped: a leg-sized segment beside a return there (within
  // segmentation.max_missing_beams + 1 beams) that is nearer by more than the segmentation's jump
  // and leg_pairing_distance_m (not the same person's other leg), when the segment spans no more
  // beams than a footprint reaches beyond an edge (ceil(beam_divergence_rad / 2 / step) + 1) or
  // lies between two such returns (seen through the gap between two legs); and a leg no track
  // took that lies straight behind a confirmed track (across the ray within its legs' reach,
  // hip_half_width_m + leg_radius_m, plus half a footprint and a step; along it farther than
  // leg_pairing_distance_m). Someone behind a person at knee height is hidden anyway; they are
  // found once they step out of the shadow. false: the tree before this rule.
  bool drop_mixed_pixel_legs = true;
  // ... and a leg-sized segment whose bearing lies within leg_pairing_distance_m (across the ray,
  // at that return's range) of such a much nearer return: where one beam returns a person's leg,
  // their other leg, which may fill no beam, can be that far from it, and its mixed pixels lie
  // behind it (schenk_C / schenk_D: clutter 2-6 m behind people at 15-30 m who are returned by a
  // beam or two). false: beside the return only (max_missing_beams + 1 beams).
  bool drop_mixed_pixel_legs_whole_person = true;
  // ... and a piece wider than a pair of legs only along the line of sight: its points spread
  // across the ray through its middle no wider than a pair (2 (hip_half_width_m + leg_radius_m)
  // + 0.1 m) or than the beams one leg touches (2 leg_radius_m and a beam's footprint), where a
  // leg fills no beam's footprint (its nearest point's range times beam_divergence_rad at least
  // 2 leg_radius_m). Such a piece is no body's outline facing the sensor: a far leg grazed by two
  // or three beams whose echoes, each part leg and part what is behind, lie at different ranges
  // between the two (or a surface seen edge-on). Taken whole it was measured as a wide object (a
  // cart) up to metres behind the leg; it confirmed clutter tracks at 15-30 m (schenk_C: 553 of
  // 850 measured clutter scans were such 2-3 point pieces). Counted in
  // PipelineCounters::veiled_segments. false: measured as a wide object.
  bool drop_deep_mixed_pixel_pieces = true;
  // ... but only where a surface stands behind the piece to mix with: a mixed pixel's range is
  // its echoes' energy-weighted mean, each carrying at least a minor share s of the energy (else
  // the receiver reports the other one alone), so the surface behind lies at most (1 - s) / s times
  // the piece's depth (farthest minus nearest point) behind its farthest point. Taken as the
  // learned background of the piece's beams; this is that ratio (4: echoes under 20 % of the
  // energy are not merged). A piece within the beams one leg touches ((2 leg_radius_m +
  // footprint) / beam spacing + 1) needs no such evidence: all of it may be mixed. A piece with no
  // background there (legs in radial stride at 12 m before a wall at 30 m, an open hall, a bicycle
  // end-on) is kept and counted in PipelineCounters::deep_pieces_kept. 0: no surface behind
  // required (the piece's shape alone).
  double deep_mixed_pixel_behind_ratio = 4.0;
  // ... and a leg-sized segment behind a nearer return its beams had in the last recent_veil_s:
  // a mixed pixel's range is the energy-weighted mean of the leg's echo and the surface's behind
  // it, weighted by the leg's share of the beam, and that share changes from scan to scan as the
  // leg moves across the footprint; so where a leg fills no beam (the segment's nearest range
  // times beam_divergence_rad at least 2 leg_radius_m) its returns jump along the ray between the
  // leg and the background, and one of them lies behind the nearer one the same beam returned a
  // scan or two before, by more than a body moves along the ray meanwhile. Dropped: a segment
  // every beam of which (or a neighbour) returned a foreground echo within recent_veil_s that was
  // nearer than the segment's nearest point by more than the segmentation's jump and
  // leg_pairing_distance_m (not the same person's other leg) plus tracking.max_speed_mps times
  // its age (a body walking away along the ray was nearer before). A nearer return from a range
  // where a leg-wide object fills a beam (within 2 leg_radius_m / (angle step +
  // beam_divergence_rad)) counts only while a neighbour beam of this scan still returns nearer
  // than the segment by that margin: such an object, still partly in the beam's footprint, fills
  // a neighbour beam; once it has moved off (a near person walking past a far one) it cannot mix
  // into the echo and the far leg is real. Where one beam returns a leg
  // only in some scans (12-15 m at 0.5 deg), this catches the echoes metres behind it that no
  // nearer return of the same scan explains. Single-beam legs (single_beam_legs) likewise
  // (knee height per sensor precision 0.9783 -> 0.9796, fused 0.9548 -> 0.9573). The time: about
  // a leg's swing (~0.4 s of a ~1 s
  // gait cycle), within which the leg crosses the footprint and its share of the beam runs from
  // most to none (tracking_benchmark, knee height per sensor, precision 0.9701 -> 0.9783 at 0.3 s,
  // 0.9782 at 0.5 s with fragments 7.44 -> 7.47). Counted in PipelineCounters::recently_veiled.
  // 0: off.
  double recent_veil_s = 0.3;
  double gait_sigma_m = 0.05;
  // Legs mount: two legs of a walking track, one standing and the other swinging. A standing
  // foot is planted while the hip passes over it and the swinging foot comes from behind to ahead
  // of it; both pass the same half step either side of the hip, the standing one in the stance's
  // share of the gait cycle (~60 % in human walking), the swinging one in the swing's (~40 %), so
  // relative to the hip the swinging knee moves faster by the ratio of the two and the legs'
  // midpoint lies off the hip towards the swinging leg by (stance share - 1/2) of their spread
  // along the walk (zero where they pass each other, most a stride apart). The centre is taken
  // as the legs weighted by their phases' shares, this weight on the standing leg: along the walk
  // the hip's offsets from the two knees cancel, and across it the body leans over the standing
  // foot (a fifth of the hip's width at 0.6, about the pelvis' sway). Which leg stands: the
  // one whose centre moved less along the walk since the track's last two-leg measurement (at
  // most stance_memory_s ago; the standing knee moves at about half the body's speed, the
  // swinging one at one and a half times it or more), weighed by how sure that is against the
  // four leg fits' variance (internal::StanceWeightedCentre: the weight moves from 1/2 towards
  // this one as the two legs' displacements differ by more than their noise; legs that move
  // alike, both standing, keep the midpoint). Counted in PipelineCounters::stance_weighted_pairs.
  // 0.5: the midpoint always.
  double stance_leg_weight = 0.6;
  double stance_memory_s = 0.15;
  // Legs mount: one leg whose partner is hidden behind it. Walking legs are always
  // 2 hip_half_width_m apart across the walk, so where one leg hides the other, the other stands
  // straight behind it along the line of sight, at least that far: the body centre, their
  // midpoint, lies hip_half_width_m or more behind the seen leg (tracking_benchmark --breakdown
  // before this: one-leg measurements 0.09 m towards the sensor at 0-5 m). Taken as hidden where
  // every other beam passing within leg_pairing_distance_m of the leg passes through that disc
  // (no echo or a return beyond it) or returns from straight behind the leg (at least
  // 2 hip_half_width_m - leg_radius_m behind its centre, within 2 leg_radius_m and a beam's
  // spacing across the line of sight: the hidden leg's edge, a mixed pixel); a return in the
  // disc or in front of it, background or not, could be the other leg or hide it. And only where
  // a leg beside it would have returned a whole beam (the beams' spacing and footprint there
  // below 2 leg_radius_m). Then the centre is measured hip_half_width_m behind the leg,
  // with the legs' midpoint swing (gait_sigma_m) and the hidden leg's place across the shadow
  // (leg_radius_m / 2 either side) as its covariance; otherwise the leg itself, with the hip and
  // stride extent. false: every single leg as the latter (the tree before this rule).
  bool hidden_leg_behind = true;
  // Legs mount: one leg (its partner not hidden behind it) of a walking track. Walking legs stand
  // hip_half_width_m either side of the body centre across the walk, and ahead or behind it along
  // the walk by the stride's phase: a leg measured as the centre itself is off by the hip across
  // the walk and by that phase along it (tracking_benchmark --breakdown before this: one-leg raw
  // RMS 0.10 m along the motion, 0.085 m across it). Where the track's predicted speed is at least
  // walking_speed_mps (and twice its sigma) and the leg lies clearly to one side of the predicted
  // centre across the walk (more than hip_half_width_m / 2), the centre is measured
  // hip_half_width_m from the leg towards that side, across the walk; only the side is taken from
  // the prediction, not the distance. Its covariance across the walk: the sway and the hip's own
  // width (gait_sigma_m). Along the walk the leg says little: successive measurements of one leg
  // share its stride phase (a leg stays ahead or behind the body for half a gait cycle, tens of
  // scans), which a filter taking them as independent would average as if it were noise; so the
  // centre counts as anywhere within the legs' reach along the walk (sigma leg_pairing_distance_m
  // / 2) and the filter's prediction carries the position there. false: such a leg is measured as
  // the leg itself with the hip and stride extent in every direction (the tree before this rule).
  bool single_leg_across_walk = true;
  // ... and the side is weighed: the leg stands hip_half_width_m to one side of the centre or the
  // other, and the predicted centre tells which only as far as its own error across the walk is
  // small against the hip. With offset the predicted centre's distance from the leg across the
  // walk and s^2 that distance's variance without the +-hip of the two sides (the filter's
  // predicted position variance across the walk, the leg fit's and the sway's, gait_sigma_m^2),
  // the likelier side's probability is q = 1 / (1 + exp(-2 hip_half_width_m |offset| / s^2)); the
  // centre is measured on that side as above, with the other side's share of the two sides'
  // spread always added to its variance across the walk: the second moment about the likelier
  // side, 4 hip^2 (1 - q) = 2 hip^2 (1 - w), w = 2 q - 1 = tanh(hip |offset| / s^2), which
  // vanishes as the side grows sure. A track whose prediction has wandered across the walk (few
  // measurements yet, a run of single legs) takes the side it guesses loosely instead of as if
  // sure (a wrong side is 2 hip_half_width_m off). A side taken from the scan
  // (single_leg_side_from_view) is sure: nothing added. Counted (w below 0.95, the other side more
  // likely than 2.5 %) in PipelineCounters::legs_side_uncertain. false: the side taken as sure
  // (across the walk gait_sigma_m alone).
  bool single_leg_side_uncertainty = true;
  // ... and the side is first taken from what the scan shows: the hidden leg stands
  // 2 hip_half_width_m across the walk from the seen one, somewhere within the legs' reach along
  // it (reach = leg_pairing_distance_m / 2 either way; places a_i = -reach + i 2 reach / n,
  // i = 0..n, n = ceil(2 reach / leg_radius_m), at most 16). Where on one side every such place is
  // seen through (each beam over a leg there with an echo returned from more than
  // seen_through_margin_m beyond it, at least two did where two beams cross it) and on the other
  // side not, the other leg is on the latter and so is the centre: measured hip_half_width_m
  // towards it as sure. A place tells only where a leg there would have returned a beam: the beams
  // and their footprint, max(angle_step, beam_divergence_rad), narrower than a leg there, i.e.
  // within 2 leg_radius_m / max(angle_step, beam_divergence_rad) of the sensor (8 m with the
  // defaults); farther out the side comes from the prediction. This also holds where the
  // prediction has settled on the seen leg itself (no side to tell from it: the leg otherwise
  // measured as the centre with the hip and stride extent, the track staying a hip off). Where a
  // prediction sure of the opposite side (weight w, as for single_leg_side_uncertainty, at least
  // 0.95) contests the view, the view's side is taken not sure, with the other side's whole share
  // (w = 0): the prediction's confidence grows from its own past sides (a track that took the wrong
  // side is fed measurements there), the view is each scan's own. Counted in
  // PipelineCounters::legs_side_from_view (sure) and legs_side_view_contested. false: the side
  // from the prediction alone.
  bool single_leg_side_from_view = true;
  // ... and along the walk, where the track's last two-leg measurement (at most
  // standing_leg_memory_s ago) told which leg stood (internal::StanceWeightedCentre, at least
  // half sure) and the leg seen now is the other one (matched by its side across the walk: a leg
  // keeps its side): a standing foot does not move while the body passes over it, so the hidden
  // leg still stands where it was, its knee carried forward by about half the body's
  // displacement since (the knee lies about halfway between the moving hip and the planted foot).
  // The centre along the walk is then the two legs weighted as for two seen legs
  // (stance_leg_weight on the standing one) instead of anywhere within the legs' reach. Its
  // variance along the walk: the two legs' weighted fit variances, the midpoint's swing
  // (gait_sigma_m^2) and the knee's carried displacement known to half (sigma a quarter of the
  // body's displacement), which grows with the time since the leg was seen. How long the leg seen
  // standing still stands: a stance lasts about 0.6 s at walking cadence and the two-leg
  // measurement finds it anywhere within it, so after standing_leg_memory_s = 0.2 s it still
  // stands in about two cases of three (tracking_benchmark, knee height per sensor: MOTP 0.0465 ->
  // 0.0463 at 0.2 s, 0.0464 at 0.3 s, 0.0469 at 0.5 s); beyond it the reach as before. Counted in
  // PipelineCounters::legs_along_from_standing. false: along the walk the legs' reach.
  bool single_leg_from_standing = true;
  double standing_leg_memory_s = 0.2;
  // Legs mount: a leg's silhouette edge where the beam beyond it is a mixed echo. A beam returns
  // a leg cleanly only where nearly all of its footprint falls on it; where the leg's outline
  // runs through the footprint of the next beam with something behind it, that beam reports a
  // range between the two (the energy-weighted mean of the echoes), so the tangent lies about a
  // step beyond the last clean beam, not half a step: taken there the visible width is a step too
  // narrow, the leg radius learnt too small and the centre put towards the sensor
  // (tracking_benchmark: circle fits of two-leg parts within 5 m 0.010 m nearer than the true leg
  // centre, their radius 0.005-0.010 m small). true: such an edge (the beam beyond behind the
  // part's edge point and the beam after it farther still, each by three sigma of the range
  // noise, fit.point_sigma_m + fit.point_sigma_per_m R) is taken where that beam's share of the
  // leg, w = (r_beyond - r) / (r_beyond - r_edge), puts it: (w - 1/2) beam_divergence_rad from
  // the beam's centre towards the leg's outside, the beam's energy spread evenly across its
  // footprint; only where that footprint (beam_divergence_rad R + beam_exit_diameter_m) is
  // narrower than a leg (2 leg_radius_m), as one edge of the leg then lies within it. Counted in
  // PipelineCounters::leg_edges_in_mixed_beam. false: every edge half a step beyond the last
  // returning beam.
  bool leg_edge_in_mixed_beam = true;
  // Legs mount: a leg that fills no beam's footprint (its part's nearest range R times
  // beam_divergence_rad at least 2 leg_radius_m) in front of a learned background no more than
  // this behind each of its returns: every return may be a mixed pixel, the energy-weighted mean
  // r_b = s_b r_leg + (1 - s_b) f_b of the leg (share s_b of beam b's energy) and the surface f_b
  // behind it, so it lies between the two; a fit to those points put the leg up to the whole gap
  // behind the person (a stroll along a wall 1.2 m behind them at 11 m: tracked 0.5-0.8 m back
  // along the ray, the person left untracked). The shares of all beams sum to the leg's width
  // over the beams' spacing, 2 leg_radius_m / (r_leg step), whatever the beam's profile (each
  // beam's energy sums to one across the footprint): so the gaps d_b = f_b - r_b sum to
  // (f - r_leg) 2 leg_radius_m / (r_leg step), with f their d-weighted mean, and
  // r_leg = f / (1 + step sum(d_b) / (2 leg_radius_m)), the leg's centre leg_radius_m beyond it
  // on the d-weighted mean bearing; never farther than the nearest return (a mixed return lies
  // behind the leg). Along the ray its variance is the leg radius' share, (D leg_radius_sigma_m /
  // leg_radius_m)^2 with D = f - r_leg, and a tenth of D for a beam whose share is dominant
  // (reported as the leg alone) or minor (the surface alone). Only parts within the beams one leg
  // touches ((2 leg_radius_m + footprint) / (R step) + 1). Counted in
  // PipelineCounters::mixed_pixel_legs. The scanner must merge echoes that far apart: the
  // LMS1xx and TiM captures show merged echoes at every separation they hold (up to about 1 m)
  // and none resolved; 1.5 m assumes the same a little beyond, where no capture tells. An LMS5xx
  // resolves echoes beyond about 0.5 m and reports the first with half of the energy (the leg or
  // the surface alone), so 0.5 there (TrackingPipeline::SetResolvedEchoSeparation). Scenario test AFarLegSeenOnlyAsMixedPixelsBeforeANearWallIsMeasuredAtTheLeg. 0: off
  // (the circle fit to the points).
  double mixed_leg_max_gap_m = 1.5;
  // ... and the radius' share of that variance where a beam may return the leg alone: an echo
  // under 20 % of a beam's energy is not reported (as deep_mixed_pixel_behind_ratio), so a beam
  // the leg covers 80 % of returns the leg's range, not a mixed one. Where the footprint allows
  // that (0.8 (R beam_divergence_rad + beam_exit_diameter_m) <= 2 leg_radius_m, R the nearest
  // return's range: about 8-9.5 m at the defaults), the part has two returns or more (a lone one
  // shows no neighbour's mixing; such estimates lay 0.07-0.23 m behind the leg) and the deficits
  // would put a leg two sigmas thinner than the prior in front of the nearest return (else they
  // are too small for a leg there), the estimate is held at that return as above, and so is its
  // spread: the radius' share is half the distance between the fronts of legs one sigma thicker
  // and thinner, each held at the nearest return, not D leg_radius_sigma_m / leg_radius_m. Where
  // the deficits put the leg behind its nearest return, that return is the leg's own echo and the
  // radius' share vanishes; the tenth of D stays. Unheld, the variance was 3-5 times the error
  // (tracking_benchmark, office_semicircle at knee height, 8-9.5 m before walls 1.2 m behind:
  // estimates held at the nearest return 0.06 m RMS off along the ray, reported 0.32 m), the
  // filter's sigma at 8-9 m 0.077 m where 0.052 without mixed_leg_max_gap_m, and a track coasting
  // one scan passed legs_coasting_max_sigma_m and went unreported (one-scan fragments 43 -> 96).
  // false: the radius' share D leg_radius_sigma_m / leg_radius_m wherever the rule applies.
  bool mixed_leg_band_variance = true;
  // Legs mount: a leg-sized segment (no wider than a pair of legs) of two or three points whose
  // beams' centres spread across the line of sight wider than a leg two sigmas above the prior
  // (2 (leg_radius_m + 2 leg_radius_sigma_m)) holds two legs side by side: a beam returns a leg
  // only where its centre ray falls on it, so one leg's points span no more than its diameter
  // across the ray, and a mixed pixel beside a leg lies behind it, not beside it. It is split at
  // the widest gap between consecutive points into two legs (a part may be a single point),
  // measured as a pair. Segments of four points or more are split where wider than
  // 2 leg_radius_m + 0.08 m whatever this says. false: two or three points are one leg (fitted
  // as one circle through both legs' beams, or as a leg hiding its partner behind it).
  bool split_few_point_legs = true;
  // Legs mount: a leg-sized segment of two or three points (not split above) whose points spread
  // along the line of sight deeper than one leg can show: the visible half of a circle lies within
  // its radius of its nearest point, so one leg's points span at most leg_radius_m + 2
  // leg_radius_sigma_m in range, plus three sigma of the range noise (fit.point_sigma_m +
  // fit.point_sigma_per_m R). What lies deeper is the other leg standing behind it (the hip across
  // a walk that crosses the ray, the stride along one that follows it) or echoes mixed between the
  // two. Where such a segment is the leg a confirmed track takes and the track's predicted centre
  // lies beyond the near leg's front along the ray (the centre stands between the two legs, so
  // behind the nearer one), it is split at its widest gap and measured as the track's two legs:
  // their midpoint, with the gait sway, and along the ray half the two parts' depth apart as its
  // sigma (what lies behind may be echoes mixed between the legs, nearer than the far leg), not
  // as one circle through both. Only for a confirmed track: unclaimed, such pieces are as often
  // mixed pixels behind someone, and as a pair they confirm clutter tracks (tracking_benchmark,
  // splitting every such segment: knee-height precision 0.970 -> 0.962); where the prediction
  // lies in front of the near leg, the points behind it are more likely mixed echoes, which
  // pulled tracks off their person (splitting for every confirmed track: precision 0.9698 ->
  // 0.9686, fragments 7.43 -> 7.50). tracking_benchmark --breakdown before this: "one leg-sized
  // part wider than a leg" (2-3 points 0.2-0.4 m deep at 5-15 m), 5307 matches at MOTP 0.088 m,
  // NEES 3.0. Counted in PipelineCounters::deep_leg_pairs. false: one leg (a circle through all
  // its points).
  bool deep_legs_as_pair = true;
  // Legs mount: two legs that touch in the scan (no beam between the two parts, as where one
  // segment is split into two legs) and are not a deep pair (deep_legs_as_pair carries its own
  // depth): the farther leg is seen only beside the nearer one's occluding edge, its visible arc
  // cut there, and the beam at the junction may have returned from either leg or a mix of both
  // and what lies behind, so the farther leg's centre is known along the line of sight only to
  // within a leg's diameter of where its cut arc puts it (uniform over +-2 leg_radius_m: variance
  // 4 leg_radius_m^2 / 3), the midpoint a quarter of that, leg_radius_m^2 / 3, added along the
  // ray. tracking_benchmark --explain before this: two-leg measurements whose parts touch
  // 21,610 at radial NEES 1.21, separated ones 24,951 at 0.32; of those off by 0.1 m or more
  // along the ray 1,576 touched, 176 did not. Counted in PipelineCounters::touching_leg_pairs.
  // false: a touching pair's covariance as any pair's.
  bool touching_legs_along_ray = true;
  // Legs mount: two legs with something nearer between them (at least one beam between the two
  // parts, and the silhouette of neither ending on the side that faces the other: an occluder's
  // edge bounds both there) may be the two visible ends of one surface behind that occluder, not
  // two legs: a parked trolley's near face seen on both sides of its pusher's legs, the pusher
  // standing between it and the sensor. The scan cannot tell the two apart, and the centre of
  // such an object lies behind the face by up to its half-depth, up to this much (a trolley's
  // half-length). Reported along the ray with the track's measured scans, not given to the
  // filter (the same in every scan while it stands: averaging does not shrink it; as
  // box_view_shared): the second moment about the legs' midpoint of a centre uniform over
  // [0, this] behind it, this^2 / 3 (a person's legs seen either side of a nearer leg keep their
  // midpoint and their filter; only their reported covariance grows). Counted in
  // PipelineCounters::occluded_gap_widened.
  // tracking_benchmark --breakdown before this, knee height: of the two-leg measurements of
  // people in the shipped scenarios, 25 of 100441 had a beam between the parts and both inner
  // ends at an occluder's edge. Such a pair's radial error is the face's distance to the
  // object's centre: scenario test KneeHeightPairWithSomethingNearerBetweenCoversAnObjectBehindIt
  // (0.5 m; NEES 119 and more before this, at most 2.4 with it). 0: off (such a pair's
  // covariance as any pair's).
  double occluded_gap_depth_m = 0.5;
  // Legs mount: the covariance reported for two legs seen still. A track that stands (predicted
  // speed at most still_legs_max_speed_mps), measured as two legs that each stand where one of the
  // track's last two legs stood (at most stance_memory_s before; within the 99 % bound of the two
  // fits' variances, internal::LegsStill), with no other measurement of the scan within
  // leg_pairing_distance_m (nothing else a leg could have been paired with: a parked cart's posts
  // taken for legs stand still as well, and are not a body's legs): no step is being taken and
  // the body did not move. So (1) the legs' midpoint does not swing about the body's
  // centre with the gait, and what the filter's R allows for a walking body's centre beyond the
  // fits (gait_sigma_m, centre_model_sigma_m) is not in this measurement's error, only how the
  // feet stand about the centre, still_legs_sigma_m per axis; (2) the acceleration the filter's
  // process noise allows for since its last update was not realised; (3) of the allowances
  // successive scans share, the leg radius' floor (size_floor_sigma_m) and the outline's
  // (centre_bias_sigma_m) are cut to outline_fixed_share, as for an upper-body outline at the
  // range noise. The filter keeps its R and process noise (the tracks are the same): (1) and (2)
  // go into the gain covariance the report follows (Measurement::gain_relief_m2, gain_still;
  // Gelb, Applied Optimal Estimation, 1974, sec. 7.2; needs
  // MultiTrackerOptions::report_gain_covariance), (3) into the report of measured scans only.
  // tracking_benchmark --breakdown before this, shipped scenes: two-leg measurements of tracks
  // standing still (predicted speed below 0.05 m/s), 4,054 matches at NEES 0.35, the midpoint off
  // by 0.025 m along the ray and 0.012 m across it where 0.041 / 0.029 m were reported; where the
  // legs do not touch in the scan (2,915), 0.014 / 0.012 m off, reported as 0.040 / 0.029 m: the
  // shared 0.028 m along the ray (leg radius floor and outline, 0.02 m each, where the learned
  // radius was 0.006 m off, RMS) and the filter's 0.030 m per axis, most of it the gait allowance
  // and the process noise. After: NEES 0.75, reported 0.025 / 0.018 m. still_legs_sigma_m 0.01 m:
  // those pairs' raw measurements were 0.015 / 0.012 m off, the shared part included.
  // still_legs_max_speed_mps 0.05: below it the tracks of people standing were 0.018-0.030 m off
  // along the ray and 0.009-0.014 m across it; at 0.05-0.1 m/s (the filter still stopping behind
  // a person who stopped) 0.043 / 0.031 m. Counted in PipelineCounters::still_leg_pairs. false: a
  // still pair's covariance as a walking pair's.
  bool still_legs_cov = true;
  double still_legs_sigma_m = 0.01;
  double still_legs_max_speed_mps = 0.05;
  // Legs mount: the covariance reported for two legs of a walking track (WalkingDirection: the
  // stance weighting's condition) that are not still_legs_cov's, with no other measurement of the
  // scan within leg_pairing_distance_m + 2 hip_half_width_m (no other leg within pairing reach of
  // either leg: nothing the pairing could have taken instead). The legs' midpoint, stance-weighted
  // (stance_leg_weight), does not scatter about the body's centre from scan to scan as gait_sigma_m
  // in the filter's R says: it swings once per stride (~1 s), far slower than the few scans the
  // filter's gains average, so successive scans share that offset and the filter cannot average
  // it away. The gains stay (the tracks are the same); the covariance the report follows takes
  // this measurement's noise without gait_sigma_m, and without the process noise predicted since
  // the last update (the body's acceleration on a walk is the gait's sway about the stance foot,
  // counted below; a start, stop or turn shows in the innovation, which inflates the gain
  // covariance as the filter's: MultiTrackerOptions::inflate_nis_above; Measurement::
  // gain_relief_m2, gain_walking); the report of that scan adds the offset as a shared term,
  // walking_legs_sigma_m per axis. The next update that is not such a pair (one leg, a still pair,
  // a neighbour within reach) starts the gain covariance again from the filter's own
  // (Measurement::gain_restart): a lone leg's centre lies a stride phase and a hip's width from the
  // leg, errors that successive scans share as well, which the filter's R and process noise cover
  // and the relieved covariance would not. walking_legs_sigma_m 0.015 m: the stance-weighted
  // midpoint of a walker's knees about the body's centre, per axis: along the walk the knees'
  // weighted offset from the hip (with stance_leg_weight 0.6 and the stance's 60 % of the cycle,
  // about 0.0093 x the stride, 0.013 m at a 1.37 m stride, 1.25 m/s; the plain midpoint's is about
  // 0.021 x the stride, 0.028 m), across it half the body's sway over the standing foot (0.5-1.8 cm
  // amplitude, about 0.009 m RMS). tracking_benchmark --breakdown, walking two-leg matches: that
  // offset measured against the simulated truth's knees, 0.014-0.017 m RMS along and across the
  // ray on the shipped scenes and on others; the measurements were 0.040 / 0.025 m off along /
  // across the ray and the tracks 0.037 / 0.024 m where 0.043 / 0.030 m were reported (of it the
  // gain covariance 0.032 / 0.028 m, with R's 0.064 / 0.055 m, gait_sigma_m the most of it).
  // false: as before (tracking_benchmark --before-walking-legs-cov).
  bool walking_legs_cov = true;
  double walking_legs_sigma_m = 0.015;
  // Legs mount: a leg returned by a single beam (segmentation drops it: min_points) is evidence
  // for a confirmed track (Measurement::evidence_only): a foreground beam in no segment, at a
  // range where a leg is narrower than two beams' spacing (nearer, a lone beam is clutter or a
  // mixed pixel), within leg_pairing_distance_m of exactly one confirmed track's prediction whose
  // position sigma (root of half the trace) is within the legs' reach (hip_half_width_m +
  // leg_radius_m: a track coasting for long would follow any beam that flickers near it), not
  // veiled (drop_mixed_pixel_legs), is paired into that track's observation (two such legs, or
  // one) where the track found no leg of a segment; it never starts or resumes a track, nor feeds
  // a tentative one. Its covariance is the one- or two-leg measurement's (a circle fitted to one
  // point: the silhouette across the ray, the track's leg radius along it; one leg adds the hip
  // and stride extent). tracking_benchmark --explain before this: of the knee-height scans with a
  // track coasting beside a person the scan returned, 82 % had only single-beam returns near the
  // person. false: such beams are dropped.
  bool single_beam_legs = true;
  // Legs mount (with single_beam_legs): a lone beam is a confirmed track's second leg where the
  // track takes a single leg of a segment and the beam's leg lies within leg_pairing_distance_m of
  // it, at any range: there it is that person's other leg with its edge in one beam (nearer than
  // single_beam_legs' range a lone beam is dropped elsewhere: a thin thing or a mixed pixel). Not
  // a beam beside that leg's edge (within a footprint's beams) that returns from behind it: that
  // is the edge's mixed echo. The pair is measured as any pair (evidence only, as
  // single_beam_legs'); counted in PipelineCounters::single_beam_partners. false: a lone beam
  // partners no segment's leg.
  bool single_beam_partner = true;
  // Legs mount (with single_beam_legs): a lone beam within a footprint's beams
  // (ceil(beam_divergence_rad / 2 step) + 1) of a return nearer than it by more than the
  // segmentation's jump, and by no more than leg_pairing_distance_m + 2 leg_radius_m (near enough
  // to be paired with it; a leg beside a much nearer screen or wall's end is kept), is that
  // nearer edge's mixed echo, not a leg: its footprint holds part of
  // the nearer object and part of what lies behind, and its range is their energy-weighted mean
  // (the rule single_beam_partner applies to a segment leg's partner, here to every lone beam).
  // Where a leg fills no beam's footprint (an LMS1xx beyond 8 m) every beam at a leg's edge is
  // such a mix; taken as a leg, it is paired with the leg beside it (its range up to
  // leg_pairing_distance_m behind) and pulls the track's centre away from the sensor, and the
  // track's velocity with it, until the track leaves its person (tracking_benchmark --explain
  // before this, knee height per sensor: about two thirds of the 2,410 false scans lay straight
  // behind a person no track held, most at 10-20 m, measured on "two legs" of 2-3 points or
  // coasting right after). Dropped, counted in PipelineCounters::lone_beam_edge_echoes
  // (knee height per sensor, with far_legs_no_birth: precision 0.9844 -> 0.9879, NEES 1.67 ->
  // 1.58). false: such beams are legs.
  bool lone_beam_edge_echo = true;
  // Legs mount: legs where a leg covers at most half of a beam's footprint (the nearer leg's
  // range times beam_divergence_rad at least 4 leg_radius_m: 16 m at 15 mrad) are evidence for a
  // confirmed track (Measurement::evidence_only) but start no track and feed no tentative one.
  // There every echo a leg returns is a mix in which the surface behind carries at least half the
  // energy, its range anywhere between the leg and that surface, and such echoes walk with the
  // person metres behind them: tracks started on them were false ones straight behind people at
  // 15-25 m (tracking_benchmark --explain, knee height per sensor: "far from every object
  // (clutter)", measured on one or two legs of 1-3 points at 15 m and more, then coasting). A
  // person walking in from farther is found once nearer; a track that came from nearer keeps
  // them. Counted in PipelineCounters::far_leg_births. false: such legs may start tracks.
  bool far_legs_no_birth = true;
  // Legs mount: a single leg no wider than the beams whose footprint reaches past an edge
  // (ceil(beam_divergence_rad / 2 step) + 1), beside a nearer return by more than the
  // segmentation's jump, may be the mixed echo of that edge and what lies behind it (its range
  // between the two) where the learned background of one of its beams lies within the mixed
  // range's bound behind it (deep_mixed_pixel_behind_ratio, as SurfaceBehind): it is evidence
  // for a track (Measurement::evidence_only) but never starts one. tracking_benchmark: knee
  // per sensor false-positive scans -151, most of them second tracks beside a person (split).
  // Counted in PipelineCounters::edge_echo_births. false: such legs may start tracks.
  bool edge_echo_no_birth = true;
  // Yaw prior: faster than walking_speed_mps a person faces where they walk (sigma
  // walking_yaw_sigma_rad: the torso turns with the gait, people step sideways); standing, the last
  // orientation, less certain by yaw_drift_rad_per_s.
  double walking_speed_mps = 0.3;
  double walking_yaw_sigma_rad = 0.35;
  double yaw_drift_rad_per_s = 0.5;
  double size_drift_m_per_sqrt_s = 0.003;
  // The body centre's error that successive measurements of a track share, reported in the
  // track's covariance on top of the filter's (which averages its measurements as if they were
  // independent): centre_bias_sigma_m (the outline not being the model's, the beam width at the
  // silhouette) in quadrature with the size state's sigma, taken as at least size_floor_sigma_m.
  // A box's (a cart's) size state counts as no more certain than box_size_floor_sigma_m: its
  // size is learned from the few faces a sensor sees as it passes, each scan's fit of them
  // sharing that view's error (the unseen side's extent taken from the prior, the corners between
  // beams), so its learned variance, built from hundreds of such scans, would claim millimetres
  // while it is centimetres off; 0: size_floor_sigma_m alone, as before.
  // centre_bias_along_ray (the default): that shared error is built along the ray from the sensor
  // through the centre and across it. Along the ray: the body's extent towards the sensor h(n; a,
  // b) (the support function, shape_fit.h) is what puts the centre behind the visible side, so a
  // size error moves the centre by J dsize, variance J Sigma_size J^T (Sigma_size with its
  // diagonal floored as above), plus centre_bias_sigma_m^2 for the outline. Across it a symmetric
  // visible arc keeps its centre whatever the size: what is shared there is where the silhouette
  // ends between two beams (uniform over R x step: (R step)^2 / 12 per end, the centre the mean of
  // two ends), plus, where an end is an occluder's or the field of view's, the size's error
  // through the extent across the ray, plus centre_bias_across_sigma_m^2. A box (a cart) keeps
  // the form below: its learned size is the least certain part of it (box_size_floor_sigma_m).
  // tracking_benchmark --before-isotropic-bias alone: upper body per sensor NEES 1.31 -> 1.51, knee
  // height 1.88 -> 2.03 (99 % containment 0.98 -> 0.98, 0.97 -> 0.97); clean scenes stay far below
  // 2 (quenzel 0.24 -> 0.25), cluttered ones above 3 (computer_lab 2.54 -> 3.52; 5.20 without the
  // sway term). false: centre_bias_sigma_m^2 plus the larger size variance in every direction, as
  // before.
  double centre_bias_sigma_m = 0.02;
  bool centre_bias_along_ray = true;
  // Across the ray, also a walking person's sideways sway (the trunk swings about 2 cm either way
  // once per stride, RMS ~0.015 m), which a constant-velocity filter smooths away instead of
  // following: shared by every scan of a stride. 0: the silhouette's ends alone. 0.006 m: with
  // 0.015 m (as before) the shipped scenes' clear views (no other object within 2 m) were
  // reported about twice as wide as their error across the ray (upper body per sensor NEES 1.33
  // for the LMS151s, 0.52 for one person in schenk_B); what made cluttered scenes need more
  // (computer_lab 5.2 with 0 at the time) is now measured (outline_departure_gain,
  // neighbour_sigma_m). Upper body per sensor NEES with it 1.48 -> 1.51 over the shipped scenes.
  // 0.002 m since the fit's silhouette edges face away from the points (ShapeFitOptions::
  // edges_face_points): a prediction beside the silhouette had held fits beside it, errors across
  // the ray the sway term covered (shipped scenes, upper body per sensor: across-ray RMS 0.026 ->
  // 0.023 m, 0-5 m 0.023 -> 0.018 m; NEES 1.50 -> 1.49 with 0.006, 1.51 with 0.002;
  // tracking_benchmark --before-across-sway).
  double centre_bias_across_sigma_m = 0.002;
  double size_floor_sigma_m = 0.02;
  double box_size_floor_sigma_m = 0.06;
  // A box (a cart) with something standing in front of it: a trolley's pusher walks between the
  // sensor and the trolley going away from it, and their legs (or body), within the
  // segmentation's jump of the trolley's near face, join its segment; fitted as the box's outline
  // they pull its near face, and so its centre, towards the sensor by up to their distance from
  // the face (tracking_benchmark before this: trolley end-on going away, knee height, radial mean
  // -0.18 m). A beam returns the first surface it meets, so a return nearer than where its beam
  // enters the box, by more than three sigma of the range noise and the model error
  // (fit.point_sigma_m + fit.point_sigma_per_m R, fit.model_sigma_m), is not the box's. Tested
  // first against the track's predicted box (its centre, learned size and yaw prior; the margin
  // widened by three sigma of the predicted position along the ray), which holds where the
  // pusher returns as many beams as the face (a far trolley) and a fit of all of them would take
  // the pusher for the face; then against the box fitted to the rest. Only a run of such points
  // whose range steps from the box's neighbouring points by more than that noise where it meets
  // them (on one side at least: a mixed echo of the two may bridge the other) counts: something
  // in front is a surface of its own, while a run continuous with the face on every side it
  // meets it is the box turned from the expected yaw. Such points are left out and the box
  // fitted without them; where they are the segment's first or last point, that end is an
  // occluder's edge, not the box's silhouette. Counted in
  // PipelineCounters::box_occluded_fits. false: every point of the segment is the box's.
  bool box_drop_occluders = true;
  // A box's size is learned per semi-axis only from scans that show it: the half-length a from a
  // side facing the sensor, the half-width b from an end facing it, each with at least three
  // beams across it. Seen end-on, a trolley shows only its near end: its length says nothing
  // there, and what a fit makes of it comes from the yaw's coupling, the corners between beams or
  // something in front of the face (a pusher); learned, that wrong length, with the confidence of
  // hundreds of scans, puts the centre off along the ray by its error whenever the box is seen
  // end-on again (tracking_benchmark before this: trolley end-on, coming nearer, knee height,
  // radial mean -0.08 m, NEES 8). The axis not shown keeps its state (its uncertainty drifting as
  // size_drift_m_per_sqrt_s says), which the reported covariance carries along the ray. Counted
  // (fits with an axis not shown) in PipelineCounters::box_sizes_unseen. Off by default:
  // tracking_benchmark with it (box_drop_occluders on in both), knee height trolley end-on coming
  // nearer MOTP 0.090 -> 0.067 m,
  // but the upper-body trolley broadside 0.069 -> 0.103 m, and a flat piece at a wall's end that
  // grows beam by beam (a box showing its front only) is followed by several tracks in turn
  // instead of one (the unit test MixedPixelsWithinAPersonsReachOfANearerReturnAreNotLegs: 7
  // ids for 1). false (the default): both semi-axes learned from every box fit.
  bool box_size_from_faces_seen = false;
  // Knee height: box_size_from_faces_seen there whatever box_size_from_faces_seen says. At knee
  // height a semi-axis no scan shows, learned from every fit, shrinks towards nothing (a cart's
  // width to 0.01 m while only its side shows), and once the cart turns end-on its centre is put
  // that much behind the face it shows (the scenario test AKneeHeightCartSeenEndOn...: radial
  // mean -0.54 m without, -0.16 m with). The regressions above are upper-body ones.
  // tracking_benchmark --before-knee-box-faces, shipped scenes at knee height: MOTP 0.043 m,
  // p95 0.131 m unchanged, precision 0.9879 -> 0.9883, NEES 1.54 -> 1.58, the trolley's MOTP
  // 0.088 -> 0.089 m. false: box_size_from_faces_seen alone decides.
  bool box_size_from_faces_seen_at_knee = true;
  // Upper-body mount: the pieces segmentation.max_width_m cuts a large box's outline into (a
  // trolley seen obliquely spans up to its diagonal) are one observation again where they fall on
  // a confirmed box track's predicted outline. Consecutive segments that the segmentation would
  // have joined but for its width limit (points consecutive, beams at most max_missing_beams
  // apart, the jump within its limit), every point of them inside the track's predicted rectangle
  // (its centre predicted to the scan, its learned size and yaw) grown by box_rejoin_sigmas times
  // the root of the range noise, the model error, the size state's largest variance (at least
  // box_size_sigma_m^2: the pieces of a split view show part of the outline, and a size learned
  // from them is no better known than that) and the prediction's largest positional variance,
  // are measured as one segment. Without it each piece
  // is an observation of its own: one updates the box's track, the others start person-sized
  // tracks beside it. Counted (segments joined to the one before) in
  // PipelineCounters::box_pieces_rejoined. false: every segment is an observation.
  bool box_rejoin_pieces = true;
  double box_rejoin_sigmas = 3.0;
  // A box (a cart) seen on one face only: the semi-axis across that face (its depth along the
  // ray) is not in the scan; the fit puts the centre that learned semi-axis behind the face, so
  // the centre is off along the box's axis by the semi-axis's error, which the scans that showed
  // only this face did not measure. The reported centre covariance gets, along each box axis
  // whose semi-axis the scan does not show (internal::BoxFacesShown), the variance
  // max(size state's, box_unseen_sigma_m^2) instead of the isotropic size term below
  // (box_size_floor_sigma_m). A coasting box is reported while its sigma is within
  // coasting_max_sigma_m with that depth's share (box_unseen_sigma_m^2 / 2) added: it is no
  // uncertainty of where the box stands. Counted in PipelineCounters::box_unseen_widened. false:
  // the isotropic size term for every box.
  bool box_unseen_depth_cov = true;
  double box_unseen_sigma_m = 0.2;
  // What a box track has seen of each semi-axis, over all its scans rather than in this one
  // (replaces box_unseen_depth_cov's per-scan test where on). Per semi-axis the track keeps half
  // the longest extent its fitted points showed along that axis (a lower bound of the semi-axis)
  // and whether a complete view showed it whole (both ends of the outline its silhouette's, the
  // face across the semi-axis shown by internal::BoxFacesShown for the points' extents: then every
  // face in view is seen from corner to corner; upper body only: at knee height the outline is a
  // cart's castors and legs, not its faces). A semi-axis seen whole is as uncertain as its
  // size state differs from half the last such view's extent. A semi-axis never seen whole lies
  // anywhere between max(lower bound,
  // box_prior_min_half_m) and box_prior_max_half_m: the reported centre variance along its axis
  // is at least that uniform distribution's, (max - min)^2 / 12, shrinking as longer extents are
  // seen (the half-width's largest at most the half-length once that is bounded); once bounded,
  // the size state's alone (at least box_size_floor_sigma_m), per axis rather than the larger
  // semi-axis's variance in every direction. Counted in
  // PipelineCounters::box_unseen_widened (scans with an unbounded semi-axis) and
  // box_semi_axes_bounded (semi-axes that became bounded). false: box_unseen_depth_cov's per-scan
  // test.
  bool box_seen_extent_cov = true;
  double box_prior_min_half_m = 0.2;
  double box_prior_max_half_m = 0.9;
  // Upper-body mount: a person's size is learned only as far as the scan shows it across the ray.
  // The silhouette's two ends fix the body's width across the ray; its extent along the ray,
  // which puts the centre behind the visible side, a fit reads from the visible arc's curvature
  // alone, and there it reads the outline's departure from the model (a torso rounder or boxier
  // than the fixed exponent, ranges averaged over the beam's footprint on a curved front) more
  // than the size: fits of the benchmark's scenes put b 0.01-0.02 m above a prior of 0.14 m in
  // every view. Learned from each scan (kSizeLearningShare), a person walking towards or away
  // from a sensor for seconds (a sensor at a corridor's end) builds a depth semi-axis centimetres
  // too large with millimetres of claimed sigma, and the centre lies that much too far from the
  // sensor (the test APersonWalkingAlongTheRayKeepsTheDepthPrior: b 0.14 m learned as 0.19 m,
  // radial mean +0.051 m; with this 0.146 m, +0.024 m). tracking_benchmark --before-person-size,
  // upper body per sensor: MOTP 0.0284 -> 0.0274 m, p95 0.0773 -> 0.0703 m, precision 0.9904 ->
  // 0.9907, NEES 1.84 -> 1.68; knee height unchanged (not applied there). Each semi-axis
  // takes the fit's information and pull weighted by its share of the squared half-width across
  // the ray (an ellipse's h(w)^2 = a^2 (w.e_a)^2 + b^2 (w.e_b)^2, w across the ray): a by
  // 1 - c^2, b by c^2, c the cosine between axis a and the ray (PersonAxisWeights): front-on the
  // shoulders' half-width alone, from the side the half-depth alone, at 45 deg each half. What a
  // view does not show keeps its state (its sigma drifting as size_drift_m_per_sqrt_s says),
  // which the reported covariance carries along the ray (centre_bias_along_ray). Counted in
  // PipelineCounters::person_sizes_across_ray. Off by default: a round object (the cylinders of
  // calibration_benchmark's quenzel and schenk scenes, a person deeper than the prior) seen
  // mostly along the ray keeps the prior's depth, and its centre lies that much too near each
  // sensor; shape-fit calibration with it on, 3 seeds: quenzel_sim_far d_t 0.024 -> 0.064 m,
  // quenzel_sim 0.006 -> 0.016 m, schenk_B 0.014 -> 0.024 m, schenk_D d_R 0.127 -> 0.170 deg
  // (office_distributed and shop_floor better). false: both semi-axes learned in full from
  // every fit.
  bool person_size_across_ray = false;
  // A person's size is learned only from fits of at least person_size_min_points points (0: from
  // every fit). Two to four points show a sliver of the outline whose silhouette ends need not be
  // the body's: a back seen end-on at 9 m in two beams, one end where the background model held
  // the rest, teaches shoulders of a third (unit test
  // TwoPointsOfATruncatedBackDoNotShowThePersonsSize: 0.23 -> 0.08 m). Off: most few-point views
  // are far people whose size the prior does not know, and with 5 the shipped scenes' upper body
  // per sensor went MOTP 0.0261 -> 0.0289 m, p95 0.0710 -> 0.0796 m, NEES 1.51 -> 1.47
  // (receded_background_edge_m treats that view's cause instead). Counted in
  // PipelineCounters::person_sizes_kept_few_points.
  std::size_t person_size_min_points = 0;
  // Added in quadrature to every body-centre measurement (sigma per axis): what the fit cannot know
  // (sway, the torso's turn, an outline that is not the model's).
  double centre_model_sigma_m = 0.015;
  // Upper-body mount: the outline's departure from the model, measured. A fit whose residuals
  // exceed the range noise sees an outline that is not the model's (a second object in the segment,
  // a partial view, arms held out, a body unlike the prior), and its centre is off by a multiple of
  // that departure; where the residuals are at the range noise, the outline is the model's and the
  // centre is as good as the points. The departure's variance, gain^2 (rms^2 - noise^2) per axis
  // (noise: fit.point_sigma_m + fit.point_sigma_per_m R, never negative), or its running mean
  // (about the last 10 scans) if larger (what successive scans share), is added to the covariance
  // reported with measured scans (not the filter's: it does not average away; not to coasting
  // reports, the filter's prediction, from which the coasting checks take their reach). With it
  // measured, the fixed allowances for the outline are cut at upper-body height (knee height keeps
  // them whole): what successive scans share (centre_bias_sigma_m, size_floor_sigma_m) to
  // outline_fixed_share of their sigma, the per-scan centre_model_sigma_m (given to the filter) to
  // outline_model_share (1: the filter and so the tracks unchanged; 0.67, what is left of it being
  // the sway and the torso's turn, ~0.01 m, follows people closer but keeps more coasting reports
  // alive).
  // The gain: over the shipped scenes' upper-body matches, binned by residual RMS over the range
  // noise, the centre's error is 1.5-3 times the departure. outline_departure_gain 0: off, the
  // fixed allowances whole, as before.
  double outline_departure_gain = 2.0;
  // Upper-body mount, a partial view: where an end of the outline is an occluder's edge or the
  // field of view's (fewer than two silhouette ends), the fit places the hidden side from the
  // size and orientation priors, and its centre covariance (the fit's posterior, those priors
  // marginalised) is mostly theirs. Successive scans share it (the occluder stays, the priors are
  // the same), so the filter, averaging it as independent, claims a centre many times too
  // certain. The fit's centre covariance is added to the covariance reported with such measured
  // scans (not to the filter's, nor to coasting reports). tracking_benchmark --breakdown before
  // this, upper body per sensor, a nearer return beside the body with one silhouette end: NEES
  // 3.4 over the shipped scenes, 5-7.7 over scenes not in the repository (error RMS 0.09-0.17 m
  // against a reported sigma of 0.07-0.09 m). Counted in PipelineCounters::partial_view_widened.
  // false: a partial view reported as a whole one.
  bool partial_view_shared = true;
  // Upper-body mount, an underdetermined fit: where the outline's points and silhouette ends
  // together are no more than the fit's five parameters (centre, semi-axes, yaw; two to three
  // points at range or on a finer person), the fit's centre is what the priors make of them, and
  // its covariance the priors' marginalised: shared by successive scans as a partial view's is,
  // and reported the same way (the fit's centre covariance with measured scans, not the
  // filter's). tracking_benchmark --breakdown before this (partial_view_shared on), upper body per
  // sensor NEES over the shipped scenes 1.76, scenes not in the repository 4.25 and 3.11 (points
  // 2-4: 2.0, 5.4, 3.6). Counted in PipelineCounters::underdetermined_fit_widened. false: such a
  // fit reported as any other.
  bool underdetermined_fit_shared = true;
  // Upper-body mount, a person's track: a segment can hold another object's points beside the
  // person (within the segmentation's jump of its outline: another person, a pillar), and its end
  // is then that object's, not the person's silhouette; the fit takes both for one body and its
  // two "silhouette ends" for the person's (tracking_benchmark --explain, persons with a nearer
  // return beside them over scenes not in the repository: end point another object's, the end
  // taken for a silhouette, radial mean -0.155 m, NEES 49; two such views in three of those with
  // two ends and a nearer return beside them). A run of points at either end of the segment
  // beyond the reach of the track's predicted body (farther from its predicted centre than the
  // largest radius a superellipse of the track's size can have, by more than kOccluderSigmas of
  // the range noise, the model error and the prediction's sigma in that direction), whose range
  // steps from the person's neighbouring point by more than the noise, is left out of the fit;
  // that end is an occluder's edge where the run lies nearer than the person's end point, and the
  // person's silhouette (half a beam outside the end point's beam) where it lies behind it. At
  // least two points stay. Counted in PipelineCounters::person_beyond_reach_fits. false: every
  // point of the segment is the person's.
  bool person_drop_beyond_reach = true;
  // Upper-body mount: a segment wider than see_through_min_width_m whose points lie on either side
  // of beams that saw through it (no return, or one farther than both neighbouring points by more
  // than the segmentation's jump; SeeThroughCuts) is measured as one observation per piece. The
  // segmentation joins points across up to max_missing_beams beams, and people walking side by
  // side 0.6 m apart (centre to centre) leave one or two beams between them from a few metres on:
  // one segment, one track between the two and none for the other (tracking_benchmark --explain,
  // persons with another within 1 m: their segment holding both, the track's error towards the
  // other, that one untracked). The width keeps whole a single body whose dark side returned no
  // echo on a beam or two (at most 2 x 0.3 m across with the widest shoulders and arms), and two
  // people who overlap in the view (at 0.7 m such pairs in office_distributed were cut: p95 0.123
  // -> 0.117 m, but its NEES 2.39 -> 1.69 and that of all upper-body sensors 1.50 -> 1.46, below
  // the target band). Not where a point of the segment lies on a confirmed box track's predicted
  // rectangle (grown as for box_rejoin_pieces): a cart and its pusher are the box fit's
  // (box_drop_occluders; cut, shop_floor's upper-body precision 0.9912 -> 0.9902, p95 0.212 ->
  // 0.216 m). Counted (pieces added) in PipelineCounters::see_through_splits. false: every segment
  // is one observation.
  bool split_see_through = true;
  double see_through_min_width_m = 0.8;
  // Upper-body mount: a segment that split_see_through leaves whole is measured as one observation
  // per piece where the range steps between two convex bodies that touch in the view with no beam
  // between them (RangeStepCuts with step_seam: the outline receding to the step and approaching
  // after it, each piece body-sized). Two people walking side by side, the one's shoulder in front
  // of the other's, leave no beam that sees through. Not where a point of the segment lies on a
  // box track's predicted rectangle (as for split_see_through, confirmed or not: a cart and its
  // pusher), nor (step_seam_size_guard) on the outline of a track the tracker still learns as
  // another shape but whose learned size is beyond a person's.
  // tracking_benchmark --before-step-seam, upper body per sensor over the shipped scenes: p95
  // 0.0688 -> 0.0687, precision 0.9972, NEES 1.50 (both unchanged). Nearly all the cuts leave a
  // piece of 3 or 4 points (a far pair, or the farther one's sliver). Counted (pieces added) in
  // PipelineCounters::step_seam_splits. false: such a segment is one observation.
  bool split_step_seam = true;
  RangeStepCutOptions step_seam;
  // split_step_seam: no cut where a point of the segment lies within step_seam_size_margin_m of
  // the predicted bounding rectangle of a track (confirmed or not) not yet fitted as a box whose
  // learned semi-axes exceed a person's (a > step_seam_person_max_a_m or b >
  // step_seam_person_max_b_m; the person prior is 0.23 / 0.14 +- 0.04): a cart whose semi-axis
  // grows towards box_min_half_length_m. Cut from its pusher or a person beside it, the cart's
  // piece (at most max_piece_width_m across) keeps its learned size below that limit and the
  // track never becomes a box (scenario test ACartLearnedAsAPersonIsNotCutFromThePersonBesideIt:
  // 62 -> 0 cuts, a third track beside the two in 52 -> 0 scans). false: only box tracks keep a
  // segment whole.
  bool step_seam_size_guard = true;
  double step_seam_person_max_a_m = 0.30;
  double step_seam_person_max_b_m = 0.22;
  double step_seam_size_margin_m = 0.15;
  // Upper-body mount: a segment's first or last points that lie deeper than its nearest point by
  // more than deep_tail_depth_m belong to no body whose nearest point that is: a convex body's
  // outline recedes from its nearest point to its silhouette by at most its semi-axis along the
  // ray (a person's at most ~0.3 m, person_major_m + 2 person_size_sigma_m). Such a tail is the
  // range step to a body behind bridged by mixed pixels (a TiM reports one range between the two
  // where the footprint holds both) that the segmentation's jump limit (0.39 m at 8 m, 0.6 m at
  // 15 m) joins: people walking side by side seen nearly in line. Fitted with the body's points,
  // the tail put the centre behind it (0.2-0.5 m along the ray). The tails are left out (as their
  // own observations they started tracks beside the people), the cut end is the nearer body's
  // silhouette end, and the segment is neither cut where beams see through it nor at a step seam.
  // Where the tail made the segment wider than segmentation.max_width_m, which cut it (the body
  // too) in pieces, the pieces are taken together again if none lies wholly in a tail and the
  // body is no wider than max_width_m. At least segmentation.min_points points stay. Not on a box
  // track's outline, nor on one larger than a person (as split_step_seam). Counted in
  // PipelineCounters::deep_tail_cuts (ends cut).
  // tracking_benchmark --before-deep-tail, upper body per sensor over the shipped scenes: MOTP
  // 0.0259 -> 0.0247 m, p95 0.0689 -> 0.0633 m, precision 0.9972 (unchanged), NEES 1.54 with
  // deep_tail_centre_bias_sigma_m. false: such a segment is one observation.
  bool split_deep_tail = true;
  double deep_tail_depth_m = 0.35;
  // With split_deep_tail, upper-body mount: centre_bias_sigma_m (the outline's departure from the
  // model that successive scans share) is this instead: part of what that term covered was the
  // tails' pull along the ray (shipped scenes, upper body per sensor NEES 1.44 with 0.02 m, 1.51
  // with 0.015 m, 1.54 with 0.012 m, as before the cut).
  double deep_tail_centre_bias_sigma_m = 0.012;
  // Upper-body mount, a partial view (fewer than two silhouette ends): the centre across the ray
  // and along it rests on the body's extent towards the hidden side, which the scan does not
  // show; the size state the track learned (from scans whose errors are alike, floored at
  // size_floor_sigma_m, and a third of that where the outline is measured) says that extent to
  // millimetres. In the covariance successive scans share (centre_bias_along_ray) each
  // semi-axis's sigma is at least this for such a view (0.04 m: person_size_sigma_m, the
  // population's spread). tracking_benchmark before this, upper body per sensor, a nearer return
  // beside the body with one silhouette end: NEES 2.34 over the shipped scenes, 4.95 and 3.88
  // over the scenes not in the repository. Counted in PipelineCounters::partial_view_size_floored.
  // 0: the size's own sigma and floor, as for a whole view.
  double partial_view_size_sigma_m = 0.04;
  // Upper-body mount, a person with another object beside it: where another observation of the
  // scan lies within neighbour_distance_m of the person's (their first measurements' centres),
  // the segmentation may have joined part of the other object to the person's outline or cut
  // part of the person's off, an end taken for the silhouette may be the other object's, and the
  // two may trade measurements; the fit sees one body either way. What that does is shared by
  // the scans while the two stay close, so it is reported with measured scans (not given to the
  // filter): neighbour_sigma_m^2 per axis, scaled by how close the other is (1 - d /
  // neighbour_distance_m). tracking_benchmark --breakdown before this, upper body per sensor,
  // another object within 1 m: NEES 5.06 over the shipped scenes, 5.40 and 5.05 over scenes not in
  // the repository (error RMS 0.10-0.13 m against a reported sigma of 0.09-0.10 m); with it (0.06
  // m within 1 m) 4.75, 4.84 and 3.23, all upper-body matches 1.42 -> 1.40, 3.22 -> 3.08 and
  // 3.09 -> 2.74; with 0.1 m within 1.5 m (the default; another object 1-2 m away was at NEES 6.2
  // over one set of scenes not in the repository) 3.37, 4.02 and 2.36, all upper-body matches
  // 1.51, 2.95 and 2.09 (with the range noise and sway of this release; tracking_benchmark
  // --before-neighbour). Counted in PipelineCounters::neighbour_widened. neighbour_sigma_m 0: off.
  double neighbour_distance_m = 1.5;
  double neighbour_sigma_m = 0.1;
  // Upper-body mount, a person whose segment is wider than the body can be (its chord, first to
  // last reliable point, beyond twice the fitted outline's reach): the segment holds something
  // else too (a second person walking beside, a cart's handle), and which part of it is the
  // person's is not known. With the body equally likely anywhere along the chord's excess e, its
  // centre's variance along the chord is e^2 / 12 (a uniform distribution's); shared by the scans
  // while the segment stays joined, so it is reported with measured scans (not given to the
  // filter, whose positions are unchanged). Counted in PipelineCounters::segment_excess_widened.
  // false: not reported (as before).
  bool segment_excess_shared = true;
  // A track fitted as a body (not a box, not legs: a cart before its track learns a box's length,
  // a person merged with one) measured from a segment whose points are a box's outline, one
  // straight face (part of it perhaps behind the pusher's legs) or two at a corner
  // (internal::BoxViewCov): the fit puts a body at the points, the box's centre lies where the
  // rectangle puts it, behind one face by an unseen depth (uniform over the box prior's
  // half-lengths) or in the middle of the two faces' diagonal. The second moment of that centre
  // about the measurement is reported with measured scans (not given to the filter, whose
  // positions are unchanged). Counted in PipelineCounters::box_view_widened. false: not reported
  // (as before).
  bool box_view_shared = true;
  // box_view_shared at upper-body height too, where the longest face seen is longer than a body
  // can be (2 box_min_half_length_m, beyond which a track is a cart's): shorter straight runs and
  // corners are people's fronts too (arms beside a flat chest). false: knee height only.
  bool box_view_at_torso = true;
  double outline_fixed_share = 0.3;
  double outline_model_share = 1.0;
  // Flat objects (not person-like).
  double flat_rms_m = 0.015;
  double flat_min_extent_m = 0.25;
  // The beam's footprint at range R: R * beam_divergence_rad + beam_exit_diameter_m (full
  // divergence and exit diameter; LMS1xx: 15 mrad + 8 mm, LMS5xx: 11 mrad + 13 mm, TiM: 15 mrad,
  // SICK's operating instructions). A silhouette ends half a beam step beyond its last beam
  // whatever the divergence (see MakePart); the footprint decides where points are mixed pixels:
  // the legs' (drop_mixed_pixel_legs, divergence only) and a far body's edges (below).
  double beam_divergence_rad = 0.015;
  double beam_exit_diameter_m = 0.008;
  // Mixed pixels (torso mount). A beam that falls partly on the body and partly on something
  // behind it returns one range between the two, weighted by their shares of its energy: too far,
  // never too near. It happens at a segment's edge whose neighbour beam beyond returned from more
  // than mixed_pixel_min_gap_m behind the edge point, and it matters where the footprint is
  // comparable to the body: from mixed_pixel_min_footprint_m on (0.3 m, about two thirds of a
  // person's width: 19.5 m for an LMS1xx, 26 m for an LMS5xx; beyond ~25 m an LMS1xx's footprint
  // is wider than a torso and every return of it may be mixed). Such an edge point's range is a
  // bound only (the body is nearer): the fit leaves it out (its bearing stays in the silhouette);
  // where every point is such a one, the fit keeps the nearest. 0 (min footprint): off. Over the
  // shipped scenarios (tracking_benchmark --breakdown, upper body) 0.14 m (8.8 m) and 0.2 m (12.8
  // m) took the 10-20 m bin's MOTP from 0.034 to 0.036 m (all together 0.0309 m at 0.2 m); 0.25 m
  // and 0.3 m leave it at 0.033-0.034 m and take all together from 0.0305 to 0.0288 m.
  double mixed_pixel_min_footprint_m = 0.3;
  double mixed_pixel_min_gap_m = 0.2;
  // A segment's end is the outline's (a silhouette end for the fit) where the beam beyond saw
  // nothing nearer; but where that beam returned from within receded_background_edge_m of the end
  // point's range and was classed background only because the background model holds something
  // more than receded_background_margin_m nearer there (a person who stood there and has left: the
  // model has not yet learned the beam's new range), the body continues into that beam, and the
  // end is not a silhouette: taken as one, it held the body between the wrong pair of rays, its
  // learned size shrank and its centre came towards the sensor (scenario test
  // AWalkerLeavingTheirOwnLearnedPlaceIsMeasuredWhole: mean error 0.040 -> 0.028 m). 0: every
  // such end a silhouette, as before (tracking_benchmark --before-receded-edges).
  double receded_background_edge_m = 0.3;
  double receded_background_margin_m = 0.1;
  // Sigma of the first position used for association (per axis).
  double association_sigma_m = 0.08;
  // Torso mount: a coasting track is not reported where the scan sees through it: every beam with
  // an echo across its body (person_major_m to either side of its predicted position, widened by
  // two sigma of the position; at least 2 beams) returned from more than this beyond it, none
  // nearer. The person is not there (they turned, stopped or left while unseen); a person hidden
  // behind something or merely not detected stays reported for tracking.report_coasting_s. At
  // knee height the beams pass between the legs: there legs_seen_through instead. 0: off.
  double seen_through_margin_m = 0.5;
  // Torso mount: a segment of no more points than the beams whose footprint reaches past an edge
  // (ceil(beam_divergence_rad / 2 step) + 1), beside a return within as many beams that is nearer
  // than its nearest point by more than the segmentation's jump at that range, may be that nearer
  // edge's mixed echo: the footprint holds part of the nearer object (a person, a wall's end) and
  // part of what lies behind, and the receiver reports a range between them (the rule
  // edge_echo_no_birth applies to a knee-height leg). Beyond 15-20 m a person returns only 2-3
  // beams, so such echoes straight behind people are person-sized and walk with them: taken as
  // bodies they started tracks where nobody was (tracking_benchmark --explain, upper body per
  // sensor: "never matched: far from every object", measured on 1-2 points at 20 m and more,
  // then coasting). Such a segment is evidence for a confirmed track (Measurement::evidence_only)
  // but starts no track and feeds no tentative one; counted in PipelineCounters::
  // torso_edge_echoes. false: such segments may start tracks.
  bool torso_edge_echo = true;
  // ... where the learned background of its beams lies behind it: a mix's range lies between the
  // nearer return and that background, behind the nearer one by at least this share of their
  // distance (the least share of a beam's energy that makes the receiver report a mix rather than
  // one of the two). A person just behind the nearer one (two side by side seen almost in line)
  // lies nearer than that and is measured. In [0, 1).
  double torso_edge_echo_min_far_share = 0.2;
  // ... only where a body seen side-on (2 person_minor_m) spans no more beams than a footprint
  // reaches past an edge (16 m at 0.5 deg and 15 mrad): nearer, a person returns more beams than
  // an edge's mix, and a piece that small beside a nearer edge is a person coming into view from
  // behind it (tracking_benchmark, at every range: shipped upper body per sensor MOTA 0.926 ->
  // 0.923, more fragments on the harder scenes). false: at every range.
  bool torso_edge_echo_far_only = true;
  // Torso mount: a coasting track that has coasted farther than this (its speed times the time
  // since its last measurement) is reported only where the scan shows something of it: a
  // foreground return within person_major_m + 2 sigma of its predicted position. A walker who
  // turns a corner out of view (behind the corner's wall, the prediction runs straight on), or
  // stops or turns while hidden, is ~0.5 m from the straight prediction after ~0.35 m of it:
  // the report is a false track (most of the coasting ones in results/tracking_benchmark.md).
  // Kept (for tracking.report_coasting_s): someone there but not measured (merged with a
  // neighbour, too few points), a track standing or moving slowly, one outside the field of view;
  // someone hidden behind a pillar is reported for the first unseen_coasting_m and found again
  // by the same track (kept until tracking.coast_timeout_s). Not at knee height (a person not
  // measured for a scan or two there is mostly a leg pairing that failed: dropping the report
  // cost more fragments than it saved false tracks). 0: off.
  double unseen_coasting_m = 0.3;
  // Torso mount: a coasting track is reported only while its position sigma (the square root of
  // half the trace of its position covariance) is at most this: the body's half-depth
  // (person_minor_m), within which the prediction still tells where the body stands. Beyond it
  // the report is as likely beside the person as on them: tracking_benchmark --explain before
  // this, upper body per sensor, the coasting reports were most of the false scans ("left behind:
  // its object out of view", "far from every object"), and their matches the largest errors
  // (MOTP 0.10-0.12 m against 0.03 m measured). The track is kept to be found again (until
  // tracking.coast_timeout_s) and reported again when measured. Counted in
  // PipelineCounters::coasting_uncertain. 0: off.
  double coasting_max_sigma_m = 0.14;
  // Knee-height mount: a coasting track is not reported where the scan sees through every place
  // its legs may stand: the beams across leg_pairing_distance_m / 2 + leg_radius_m (a leg's
  // farthest reach from the body centre in a stride) widened by two sigma of the position, to
  // either side, all returned from more than seen_through_margin_m beyond it (at least 2, none
  // nearer, beams without an echo unknown), and the beams lie closer together there than a leg's
  // width (2 leg_radius_m at the far side of that region), so a leg standing there would have
  // returned at least one of them. The person is not there (they turned, stopped or left while
  // unmeasured). Where beams are farther apart than a leg's width (a far person's legs fall
  // between them) or something nearer hides the place, the track is reported for as long as
  // legs_report_coasting_s allows. false: off (the upper-body rule alone, which never applies
  // at knee height).
  bool legs_seen_through = true;
  // Knee-height mount: a coasting track is reported for at most this long after its last
  // measurement (tracking.report_coasting_s where that is shorter; the track is kept to be found
  // again until tracking.coast_timeout_s as at every mount). A knee-height track's velocity is
  // made from legs that stand still in turn, so its straight prediction leaves someone who turns,
  // stops or is hidden sooner than an upper-body track's does, while a person in view is measured
  // again within a few scans (their legs return in most of them): beyond this the report is
  // mostly where the person is not (tracking_benchmark, knee height, "left behind" false
  // positives). 0: off (tracking.report_coasting_s at every mount).
  double legs_report_coasting_s = 0.3;
  // Knee-height mount: a coasting track is reported only while its reported position sigma (root
  // of half the trace of its position covariance) is at most this: a leg's diameter
  // (2 leg_radius_m), within which the prediction still tells where one of its legs stands. A
  // knee-height track's velocity comes from legs that stand still in turn, and coasting at
  // 10-15 m (one or two beams per leg, often none) its uncertainty grows past a leg's width within
  // a few scans; reported beyond that, it lies beside its person, who is then measured by no
  // track (tracking_benchmark --explain before this, knee height per sensor: of 2,862 false
  // scans, 1,830 coasting, the largest class "left behind: its object visible, untracked"
  // coasting with foreground at it, 642). The track is kept to be found again, as at
  // legs_report_coasting_s. Not where a beam across its legs' reach (leg_pairing_distance_m / 2 +
  // leg_radius_m + 2 sigma) returns a foreground echo from nearer than that reach in front of it:
  // someone hidden behind a passer-by is found again there. Counted in
  // PipelineCounters::legs_coasting_uncertain. 0: off.
  double legs_coasting_max_sigma_m = 0.12;
};

std::optional<std::string> Validate(const ShapeOptions& options);

struct TrackerOptions {
  BackgroundOptions background;
  SegmentationOptions segmentation;
  MeasurementMethod method = MeasurementMethod::kShapeFit;
  MeasurementOptions measurement;  // kCenterOfMass / kEllipse (fit_ellipse follows method)
  ShapeOptions shape;              // kShapeFit
  MultiTrackerOptions tracking;
  // Stamp each measurement with its middle beam's time instead of the scan start (see above).
  bool correct_beam_time = true;
};

// nullopt when valid, else the reason prefixed by the section, e.g.
// "tracking.confirm_hits must be in [1, confirm_window]".
std::optional<std::string> Validate(const TrackerOptions& options);

// The wire's measurement kind of a method.
MeasurementKind KindOf(MeasurementMethod method);

struct PipelineCounters {
  std::uint64_t scans = 0;           // Process calls
  std::uint64_t rejected_scans = 0;  // failed CheckScan (reason: last_scan_error())
  std::uint64_t learning_scans = 0;  // accepted while the background was not yet learned
  std::uint64_t segments = 0;
  std::uint64_t dropped_segments = 0;  // did not fit into kMaxSegments
  std::uint64_t ellipse_measurements = 0;
  std::uint64_t com_measurements = 0;
  std::uint64_t shape_fits = 0;         // refined measurements (kShapeFit)
  std::uint64_t failed_shape_fits = 0;  // degenerate input
  std::uint64_t leg_pairs = 0;          // observations of two legs (kLegs)
  std::uint64_t single_legs = 0;        // observations of one leg
  std::uint64_t legs_behind = 0;        // of them: the other hidden behind (hidden_leg_behind)
  std::uint64_t single_beam_legs = 0;   // observations of single-beam legs (single_beam_legs)
  std::uint64_t single_beam_partners = 0;  // of them: a segment's leg and a lone beam (partner)
  std::uint64_t lone_beam_edge_echoes = 0;  // lone beams beside a nearer return: dropped
  std::uint64_t torso_edge_echoes = 0;      // upper-body edge echoes: no births
  std::uint64_t far_leg_births = 0;         // legs too far to fill half a footprint: no birth
  std::uint64_t edge_echo_births = 0;  // single legs beside a nearer edge: no birth (edge_echo_no_birth)
  std::uint64_t legs_across_walk = 0;   // one leg measured across the walk (single_leg_across_walk)
  std::uint64_t legs_side_uncertain = 0;  // of them: side uncertain (single_leg_side_uncertainty)
  std::uint64_t legs_side_from_view = 0;  // of them: side from the scan (single_leg_side_from_view)
  std::uint64_t legs_along_from_standing = 0;  // of them: along the walk from the standing leg
  std::uint64_t legs_side_view_contested = 0;   // scan's side against a sure prediction: weighed
  std::uint64_t outline_departure_widened = 0;  // body fits widened (outline_departure_gain)
  std::uint64_t partial_view_widened = 0;       // body fits reported wider (partial_view_shared)
  std::uint64_t underdetermined_fit_widened = 0;  // (underdetermined_fit_shared)
  std::uint64_t split_few_point_legs = 0;       // 2-3 point segments split into two legs
  std::uint64_t stance_weighted_pairs = 0;      // two legs weighted to the standing leg
  std::uint64_t touching_leg_pairs = 0;         // touching legs widened along the ray
  std::uint64_t still_leg_pairs = 0;            // two legs seen still (still_legs_cov)
  // Box refinements refitted without the points in front of the box (box_drop_occluders; counted
  // per refinement, also of candidates the tracker then does not take).
  std::uint64_t box_occluded_fits = 0;
  // Box refinements that did not show one of the semi-axes (box_size_from_faces_seen).
  std::uint64_t box_sizes_unseen = 0;
  // Segments measured together with the one before them as a box's outline (box_rejoin_pieces).
  std::uint64_t box_pieces_rejoined = 0;
  // Pieces measured on their own where a segment was cut at beams that saw through it
  // (split_see_through).
  std::uint64_t see_through_splits = 0;
  // Pieces added by cutting a segment at a range step between two bodies (split_step_seam).
  std::uint64_t step_seam_splits = 0;
  // Segment ends cut off as deeper than a body (split_deep_tail).
  std::uint64_t deep_tail_cuts = 0;
  // Box refinements whose reported covariance took an unseen semi-axis (box_unseen_depth_cov).
  std::uint64_t box_unseen_widened = 0;
  // Semi-axes of box tracks bounded by a complete view (box_seen_extent_cov).
  std::uint64_t box_semi_axes_bounded = 0;
  // Person (upper-body) refinements whose size was learned per semi-axis by its share across the
  // ray (person_size_across_ray).
  std::uint64_t person_sizes_across_ray = 0;
  // Person (upper-body) refinements without a run of points beyond the reach of the predicted
  // body at an end of the segment (person_drop_beyond_reach; counted per refinement).
  std::uint64_t person_beyond_reach_fits = 0;
  // Person (upper-body) refinements of a partial view whose shared covariance took the size's
  // sigma at partial_view_size_sigma_m (above the track's own and its floor).
  std::uint64_t partial_view_size_floored = 0;
  // Person fits with fewer than ShapeOptions::person_size_min_points points: size state kept.
  std::uint64_t person_sizes_kept_few_points = 0;
  // Measured upper-body fits reported wider for another observation within
  // ShapeOptions::neighbour_distance_m.
  std::uint64_t neighbour_widened = 0;
  // Upper-body person fits whose segment is wider than the body (ShapeOptions::
  // segment_excess_shared).
  std::uint64_t segment_excess_widened = 0;
  // Two-leg measurements reported with an object's centre behind them (ShapeOptions::
  // occluded_gap_depth_m).
  std::uint64_t occluded_gap_widened = 0;
  // Body fits measured from a box's outline (ShapeOptions::box_view_shared).
  std::uint64_t box_view_widened = 0;
  std::uint64_t deep_leg_pairs = 0;    // deep 2-3 point legs measured as a pair (deep_legs_as_pair)
  std::uint64_t veiled_segments = 0;   // legs: mixed pixels (beside a nearer edge, deep), dropped
  std::uint64_t deep_pieces_kept = 0;  // legs: deep pieces with no surface behind, kept
  std::uint64_t shadowed_legs = 0;     // legs: straight behind a confirmed track, dropped
  std::uint64_t recently_veiled = 0;   // legs: behind a recent nearer return (recent_veil_s)
  std::uint64_t absorbed_objects = 0;  // static objects handed to the background
  std::uint64_t seen_through = 0;      // coasting track reports dropped (seen through)
  std::uint64_t unseen_coasting = 0;   // coasting track reports dropped (nothing seen near)
  std::uint64_t legs_seen_through = 0;  // knee height: coasting reports dropped (legs seen through)
  // Upper body: coasting reports dropped, sigma above coasting_max_sigma_m.
  std::uint64_t coasting_uncertain = 0;
  // Knee height: coasting reports dropped, sigma above legs_coasting_max_sigma_m.
  std::uint64_t legs_coasting_uncertain = 0;
  // Leg silhouette edges placed within the mixed echo beyond them (leg_edge_in_mixed_beam).
  std::uint64_t leg_edges_in_mixed_beam = 0;
  // Leg parts measured as mixed pixels in front of a near background (mixed_leg_max_gap_m).
  std::uint64_t mixed_pixel_legs = 0;
  // Shape fits by the evaluations of their objective (ShapeFitResult::evaluations; each one pass
  // over the points): index e counts the fits with e, the last those with that many or more.
  std::array<std::uint64_t, 8> shape_fit_evaluations{};
};

// One piece of an observation: consecutive points of one segment and where its silhouette ends.
struct ObservationPart {
  std::size_t first_point = 0;  // into SegmentList::points_m
  std::size_t point_count = 0;
  std::size_t begin_beam = 0;
  std::size_t end_beam = 0;  // one past the last
  Silhouette silhouette;
  // Torso mount: the first / last point is a mixed pixel (ShapeOptions::mixed_pixel_min_*).
  bool first_mixed = false;
  bool last_mixed = false;
  // Legs mount: where the part's points are deeper along the ray than one leg, the index of the
  // point after its widest gap (ShapeOptions::deep_legs_as_pair), else 0.
  std::size_t deep_split = 0;
  // Legs mount: the first / last silhouette edge placed within the mixed echo beyond it
  // (ShapeOptions::leg_edge_in_mixed_beam).
  bool first_edge_in_mixed_beam = false;
  bool last_edge_in_mixed_beam = false;
  // Legs mount: every point may be a mixed pixel of a leg filling no footprint in front of a
  // near background (ShapeOptions::mixed_leg_max_gap_m): the leg's centre from the points' range
  // deficits and the variance along the ray that estimate carries (0: not such a part).
  Eigen::Vector2d mixed_leg_centre_m = Eigen::Vector2d::Zero();
  double mixed_leg_along_var_m2 = 0.0;
};

// What one object shows in a scan: one segment (torso), or one or two legs.
struct Observation {
  std::array<ObservationPart, 2> parts{};
  std::size_t part_count = 0;
  bool legs = false;  // parts are legs (kLegs mount)
  // One leg whose partner stands hidden behind it (ShapeOptions::hidden_leg_behind).
  bool partner_behind = false;
  // Two legs split along the line of sight from one segment (ShapeOptions::deep_legs_as_pair).
  bool deep_pair = false;
};

// The separation beyond which a SICK scanner family reports the echoes of two surfaces one behind
// the other apart (the first, or none) instead of one range between them (a mixed pixel), by its
// DeviceIdent name: the LMS5xx's echo filter separates echoes beyond about 0.5 m (the shared
// LMS511 capture: edges 0.4-0.5 m apart resolved at a third of them, farther ones at all); 0 for
// the LMS1xx, the TiMs and any other (their captures show merged ranges at every separation seen,
// up to about 1 m). For TrackingPipeline::SetResolvedEchoSeparation.
double ResolvedEchoSeparationM(std::string_view device_name);

class TrackingPipeline {
 public:
  // Precondition: Validate(options) is nullopt (checked; aborts otherwise).
  explicit TrackingPipeline(const TrackerOptions& options);
  // The scanner's echo separation (ResolvedEchoSeparationM of its DeviceIdent name; 0: it merges
  // two surfaces' echoes at every separation): ShapeOptions::mixed_leg_max_gap_m is the configured
  // value capped at it (no mixed pixel of two surfaces farther apart), the configured value where
  // it is 0. Called again for another device (a swapped scanner), it starts from the configured.
  void SetResolvedEchoSeparation(double resolved_echo_m);
  ~TrackingPipeline();

  // Runs one scan; scans must come in time order. The result (tracks at scan.stamp_ns, with
  // scan_counter and scan.scan_period_s copied in; scan_period_s is 0 for a rejected scan) stays
  // valid until the next call. The scan's ranges are read during the call only.
  const ScanTracks& Process(const ScanView& scan, std::uint32_t scan_counter);

  const TrackerOptions& options() const { return options_; }
  const BackgroundModel& background() const { return background_; }
  const MultiTracker& tracker() const { return tracker_; }
  const PipelineCounters& counters() const { return counters_; }
  const ScanTracks& last_tracks() const { return tracks_; }
  ScanError last_scan_error() const { return last_scan_error_; }
  // Of the last scan: segments, the observations and their first measurements (same order) and the
  // measurements' times after the scan start in seconds.
  const SegmentList& segments() const { return segments_; }
  std::span<const Observation> observations() const { return observations_.span(); }
  std::span<const Measurement> measurements() const { return measurements_.span(); }
  std::span<const double> measurement_offsets_s() const { return offsets_s_.span(); }
  std::size_t last_segment_count() const { return segments_.segments.size(); }
  // Diagnostics of observation `observation` (shape fit): the covariance of the measurement
  // refined from it in the last scan (nullopt where none was), and the fitted radius and centre of
  // its leg `part` (knee height; 0 where none). The legs' values are written when an observation
  // is refined and not cleared between scans: valid for the last scan's observations that were
  // refined in it (each measured one was), an earlier scan's values for the others.
  std::optional<Eigen::Matrix2d> RefinedCovariance(std::size_t observation) const;
  double LegRadius(std::size_t observation, std::size_t part) const;
  Eigen::Vector2d LegCentre(std::size_t observation, std::size_t part) const;

 private:
  class Refiner;
  friend class Refiner;

  void MeasureLegacy(const ScanView& scan);
  void BuildObservations(const ScanView& scan);
  // Segments first..last of the scan (consecutive pieces the segmentation cut) as the one segment
  // they would have been.
  Segment JoinedPieces(std::size_t first, std::size_t last) const;
  // The last of the run of segments from `first` that the segmentation cut only for their width
  // or point count (each next piece continues within the jump limit), `first` where none.
  std::size_t WidthPiecesEnd(std::size_t first) const;
  // ShapeOptions::box_rejoin_pieces: the last of the segments from `first` on that are pieces of
  // one outline lying on a confirmed box track's predicted rectangle (predictions_, `tracks` of
  // them, predicted at `stamp_ns` on the first run of pieces of the scan); `first` where none
  // follows.
  std::size_t BoxPiecesEnd(std::size_t first, common::UtcNs stamp_ns,
                           std::optional<std::size_t>& tracks);
  // ShapeOptions::split_see_through: whether a point of segment s lies on a confirmed box track's
  // predicted rectangle (grown as for box_rejoin_pieces); predicts the tracks once per scan.
  // seam (ShapeOptions::split_step_seam): on any box track, confirmed or not, or
  // (step_seam_size_guard) near any track larger than a person.
  bool OnConfirmedBox(const Segment& s, common::UtcNs stamp_ns, std::optional<std::size_t>& tracks,
                      bool seam = false);
  // tracks: the live tracks' predictions at the scan's time, in predictions_ (predicted once).
  void PairLegs(const ScanView& scan, std::size_t tracks);
  // Where a leg-sized segment splits into two legs: the index of the second
  // leg's first point, 0 for one leg (ShapeOptions::split_few_point_legs for 2-3 points).
  std::size_t LegSplit(const Segment& segment, std::span<const Eigen::Vector2d> pts);
  void AddSingleBeamLegs(const ScanView& scan, std::size_t tracks);
  bool NearSegmentLeg(const Eigen::Vector2d& p) const;
  bool BesideNearerEdge(const ScanView& scan, const ObservationPart& part) const;
  // ShapeOptions::lone_beam_edge_echo: lone beam b lies beside a nearer return.
  bool LoneBeamBesideNearer(const ScanView& scan, std::size_t b) const;
  // ShapeOptions::torso_edge_echo: segment s (of segments_) is a nearer edge's mixed echo.
  bool TorsoEdgeEcho(const ScanView& scan, const Segment& s) const;
  double NearerReturnBeside(const ScanView& scan, std::size_t begin_beam, std::size_t end_beam,
                            double nearest_m, std::size_t footprint_beams) const;
  std::size_t SingleBeamPartner(const ScanView& scan, const Eigen::Vector2d& c,
                                std::size_t a) const;
  void AddObservation(const ScanView& scan, const Observation& observation);
  // AddObservation's measurement and beam time for an observation already stored as the last of
  // observations_ (built in place: not copied in).
  void MeasureObservation(const ScanView& scan, const Observation& observation);
  ObservationPart MakePart(const ScanView& scan, const Segment& segment, std::size_t first,
                           std::size_t count) const;
  // MakePart into `part`, built in place instead of copied there. Precondition: `part` holds a
  // default ObservationPart (an observation's slot just emplaced: FixedVector::emplace_slot assigns
  // a default Observation): the fields set only where they apply (deep_split, the edges'
  // *_in_mixed_beam, mixed_leg_centre_m and mixed_leg_along_var_m2) are left as they are, so a
  // reused part would keep another's.
  void MakePartIn(const ScanView& scan, const Segment& segment, std::size_t first,
                  std::size_t count, ObservationPart& part) const;
  void MarkMixedPixels(const ScanView& scan, std::span<const Eigen::Vector2d> points,
                       ObservationPart& part) const;
  // ShapeOptions::mixed_leg_max_gap_m: sets part's mixed_leg_* where it applies.
  void MixedPixelLeg(const ScanView& scan, std::span<const Eigen::Vector2d> points,
                     ObservationPart& part) const;
  void AbsorbStatic(const ScanView& scan);
  void DropCoasting(const ScanView& scan);
  // Every beam with an echo within half_width_m of position_m (either side, at least 2) returned
  // from more than shape.seen_through_margin_m beyond it; with max_beam_gap_m > 0, also the beams
  // lie at most that far apart at range + half_width_m (else false: unknown).
  bool SeenThrough(const ScanView& scan, const Eigen::Vector2d& position_m, double half_width_m,
                   double max_beam_gap_m) const;
  bool DeepMixedPixels(std::span<const Eigen::Vector2d> pts, double pair_width_m) const;
  bool SurfaceBehind(const ScanView& scan, const Segment& segment) const;
  bool Veiled(const ScanView& scan, const Segment& segment) const;
  // ShapeOptions::recent_veil_s: every beam of the segment (or a neighbour) returned, within that
  // time before this scan, a foreground echo nearer than the segment by the margin there (from a
  // near object wide enough to fill a beam: only while a neighbour beam still returns it).
  bool RecentlyVeiled(const ScanView& scan, const Segment& segment) const;
  // Keeps, per beam, the nearest foreground return of the last recent_veil_s (and its time).
  void NoteRecentReturns(const ScanView& scan);
  bool PartnerBehind(const ScanView& scan, const ObservationPart& part,
                     const Eigen::Vector2d& centre_m) const;
  // ShapeOptions::single_leg_side_from_view: the beams over a leg at leg_m with an echo (at least
  // two, or the one beam where only one crosses it) all returned from more than
  // seen_through_margin_m beyond it, where the beams and their footprint (max(angle_step,
  // beam_divergence_rad)) are narrower than a leg there (within 2 leg_radius_m / that footprint of
  // the sensor).
  bool OtherLegSeenThrough(const ScanView& scan, const Eigen::Vector2d& leg_m) const;
  bool ForegroundNear(const ScanView& scan, const Eigen::Vector2d& position_m,
                      double sigma_m) const;
  // A foreground beam within reach_m of position_m (across the ray) returned from nearer than its
  // range less reach_m: something in front may hide it (ShapeOptions::legs_coasting_max_sigma_m).
  bool HiddenBehindNearer(const ScanView& scan, const Eigen::Vector2d& position_m,
                          double reach_m) const;

  TrackerOptions options_;
  double configured_mixed_leg_max_gap_m_ = 0.0;  // SetResolvedEchoSeparation
  PipelineCounters counters_;
  ScanError last_scan_error_ = ScanError::kNone;
  BackgroundModel background_;
  SegmentList segments_;
  common::FixedVector<Observation, kMaxSegments> observations_;
  common::FixedVector<Measurement, kMaxSegments> measurements_;
  common::FixedVector<double, kMaxSegments> offsets_s_;
  // Legs: the single legs of the scan, and the live tracks' predictions used to pair them.
  common::FixedVector<ObservationPart, 2 * kMaxSegments> leg_parts_;
  std::array<Eigen::Vector2d, 2 * kMaxSegments> leg_centres_m_{};
  std::array<bool, 2 * kMaxSegments> leg_used_{};
  // A single-beam leg nearer than a lone leg may be: only a segment leg's partner
  // (ShapeOptions::single_beam_partner).
  std::array<bool, 2 * kMaxSegments> leg_partner_only_{};
  // leg_parts_ from this index on are single-beam legs (ShapeOptions::single_beam_legs).
  std::size_t single_beam_first_ = 0;
  std::array<TrackPrediction, kMaxTracks> predictions_{};
  // ShapeOptions::recent_veil_s: per beam the nearest foreground range of the recent scans (0:
  // none) and its scan's time; recent_beams_ the scan's beam count they were kept for.
  std::array<float, kMaxBeams> recent_near_m_{};
  std::array<common::UtcNs, kMaxBeams> recent_near_ns_{};
  std::size_t recent_beams_ = 0;
  MultiTracker tracker_;
  const ScanView* scan_ = nullptr;  // the scan being processed (for the refiner), else null
  std::unique_ptr<Refiner> refiner_;
  ScanTracks tracks_;
};

namespace internal {

// ShapeOptions::outline_departure_gain: the variance (per axis) the outline's departure from the
// model adds to an upper-body centre, from its fit's residual RMS rms_m at range_m: gain^2 (rms^2
// - noise^2), noise = fit.point_sigma_m + fit.point_sigma_per_m range_m; 0 where the residuals are
// within the range noise (the outline is the model's).
double OutlineDepartureVar(const ShapeOptions& o, double rms_m, double range_m);

// ShapeOptions::box_drop_occluders: copies into kept the points not in front of the box (centre_m,
// half-lengths size_m along yaw_rad and across it), in order, and returns their count; a point is
// in front where its range is less than where its beam enters the box by more than
// kOccluderSigmas of the range noise and the model error plus extra_margin_m (the box's own
// uncertainty along the ray), in a run of such points whose range steps by more than that noise
// (without extra_margin_m) from a neighbouring point not in front, on one side at least.
// Where the first or last point is in front, that silhouette end is
// cleared in *silhouette. Precondition: kept.size() >= points.size(); kept may be points' storage.
std::size_t BoxUnoccludedPoints(const ShapeOptions& o, const Eigen::Vector2d& centre_m,
                                const Eigen::Vector2d& size_m, double yaw_rad,
                                std::span<const Eigen::Vector2d> points,
                                std::span<Eigen::Vector2d> kept, Silhouette* silhouette,
                                double extra_margin_m = 0.0);

// ShapeOptions::person_drop_beyond_reach: copies into kept the points of the segment (in beam
// order, beams step_rad apart, signed as the scan's) without a run at either end that lies beyond
// reach_m of centre_m (the predicted centre, covariance centre_cov_m2) by more than
// kOccluderSigmas of hypot(range noise, model error, the centre's sigma towards the point) and
// whose range steps from its neighbouring point by more than kOccluderSigmas of the noise; returns
// their count (points.size(), kept left as it was, where fewer than two would stay or nothing is
// left out; the first kMaxSegmentPoints of a longer segment copied into kept). An end whose run
// was dropped is an occluder's edge in *silhouette where the run's nearest point lies nearer than
// the kept end point, else a silhouette half a step outside the kept end point's beam.
// Precondition: kept.size() >= points.size(); kept is not points' storage.
std::size_t PersonReachablePoints(const ShapeOptions& o, const Eigen::Vector2d& centre_m,
                                  const Eigen::Matrix2d& centre_cov_m2, double reach_m,
                                  std::span<const Eigen::Vector2d> points, double step_rad,
                                  std::span<Eigen::Vector2d> kept, Silhouette* silhouette);

// ShapeOptions::partial_view_size_sigma_m: the size's sigma floor in the centre's shared
// covariance of a fit (floor_m that of a whole view): at least partial_view_size_sigma_m for an
// upper-body person's fit (body) with fewer than two silhouette ends, else floor_m.
double PartialViewSizeFloor(const ShapeOptions& o, bool body, int edges, double floor_m);

// ShapeOptions::neighbour_sigma_m: the variance (per axis) reported with an upper-body person's
// measured scan whose nearest other observation lies distance_m away:
// neighbour_sigma_m^2 (1 - distance_m / neighbour_distance_m) within neighbour_distance_m, else 0.
double NeighbourVar(const ShapeOptions& o, double distance_m);
// ShapeOptions::segment_excess_shared: for a segment's points and a body centred at centre_m
// reaching reach_m from its centre, the centre's covariance from where in the segment the body
// lies: e^2 / 12 (uniform over the excess e) across the ray for the points' extent across it
// beyond 2 reach_m, and along the ray for their extent along it beyond reach_m (the near half
// shows), each less 4 noise_m (the points' range sigma, two at either end); zero where the body
// can hold them all.
Eigen::Matrix2d SegmentExcessCov(std::span<const Eigen::Vector2d> points,
                                 const Eigen::Vector2d& centre_m, double reach_m, double noise_m);
// SegmentExcessCov in two steps: the points' extents along and across the ray through centre_m
// (zero for fewer than two points or a centre at the origin), then the covariance from them.
struct SegmentExtent {
  Eigen::Vector2d along_dir = Eigen::Vector2d::Zero();  // unit vector along the ray
  double along_m = 0.0;
  double across_m = 0.0;
};
SegmentExtent SegmentExtents(std::span<const Eigen::Vector2d> points,
                             const Eigen::Vector2d& centre_m);
Eigen::Matrix2d SegmentExcessCov(const SegmentExtent& extent, double reach_m, double noise_m);
// ShapeOptions::box_view_shared: where a segment's points (in scan order, the sensor at the
// origin; at least kMinFlatnessPoints over at least flat_min_extent_m) are a box's outline, the
// second moment about centre_m of where the box's centre lies, and *faces 1 or 2 (else zero and
// 0). One face (the points within 2 noise_m RMS of their principal line): the centre half the
// box's depth h behind the face's middle, h uniform over [box_prior_min_half_m,
// box_prior_max_half_m]. Two faces (split at the point farthest from the chord, each side within
// 2 noise_m of its line, the corner nearer the sensor than the chord's middle, the sides at least
// 60 degrees apart, each with at least three points of its own besides the corner): the centre in
// the middle of the diagonal between the outer ends (a side of one or two points beyond the
// corner: the other face alone, the corner its end). Neither: one face with something in front of
// part of it (a pusher's legs): the points nearer than its line by more than three noise_m left
// out (at least half kept). An outer end not seen to end (not a silhouette; the beam beyond it on
// the face's line within two noise_m, beyond the field of view, or the face's outermost point
// left out as in front) lets the face go on by e, uniform over [0, e_max], e_max =
// 2 box_prior_max_half_m - the face's seen length: the centre moves by e / 2 towards that end,
// mean e_max / 4 and variance e_max^2 / 48 along it. The result is (delta + mu)(delta + mu)^T + V:
// delta from centre_m to the face's middle (or the diagonal's), mu the mean offsets (the depth's
// along the normal, the ends' along the face: two unseen ends of one face cancel), V their
// variances.
struct OutlineEnd {
  bool silhouette = false;            // not an occluder's edge (Silhouette::first/last_valid)
  bool beyond_valid = false;          // the beam beside the end returned beyond_m
  bool beyond_returned_none = false;  // ... returned nothing (false too at the field's end)
  Eigen::Vector2d beyond_m = Eigen::Vector2d::Zero();
};
Eigen::Matrix2d BoxViewCov(const ShapeOptions& o, std::span<const Eigen::Vector2d> points,
                           const Eigen::Vector2d& centre_m, double noise_m,
                           const OutlineEnd& first_end, const OutlineEnd& last_end, int* faces,
                           double* longest_m);

// The largest distance from its centre of a superellipse |u / a|^p + |v / b|^p = 1 with semi-axes
// at most size_m's larger one and exponent p >= 2: max(a, b) 2^(1/2 - 1/p) (its diagonal where
// a = b; an upper bound otherwise).
double SuperellipseReach(const Eigen::Vector2d& size_m, double exponent);
// SuperellipseReach's factor 2^(1/2 - 1/p) (exponent p, at least 2): SuperellipseReach(size_m, p)
// is max(size_m) times it, bit for bit (a caller keeps it per exponent instead of a pow per fit).
double SuperellipseReachFactor(double exponent);

// ShapeOptions::box_size_from_faces_seen: whether a box (centre_m, half-lengths size_m along
// yaw_rad and across it) seen from the sensor at the origin with beams step_rad apart shows its
// half-length a (a side faces the sensor, at least kFaceMinBeams beams across it) and its
// half-width b (an end faces it, likewise). Both true where the range or the step is not positive.
std::array<bool, 2> BoxFacesShown(const Eigen::Vector2d& centre_m, const Eigen::Vector2d& size_m,
                                  double yaw_rad, double step_rad);

// ShapeOptions::box_unseen_depth_cov: the box's (semi-axes a along yaw_rad, b across it) centre
// covariance cov_m2 (the isotropic size term size_var_m2 in it) with, along each box axis whose
// semi-axis is not shown, the variance raised from size_var_m2 to max(size_cov_m2(k, k),
// unseen_sigma_m^2) (never lowered).
Eigen::Matrix2d BoxUnseenCentreCov(const Eigen::Matrix2d& cov_m2, double size_var_m2,
                                   const Eigen::Matrix2d& size_cov_m2, double yaw_rad,
                                   const std::array<bool, 2>& shown, double unseen_sigma_m);

// ShapeOptions::box_seen_extent_cov: half the extent of the points along the box's axis e1
// (yaw_rad) and across it e2: (max - min) / 2 of their projections on each; zero for no points.
Eigen::Vector2d BoxHalfExtents(std::span<const Eigen::Vector2d> points, double yaw_rad);
// The same along the unit vector e1 and across it (e1 turned by +90 degrees).
Eigen::Vector2d HalfExtentsAlong(std::span<const Eigen::Vector2d> points,
                                 const Eigen::Vector2d& e1);

// ShapeOptions::neighbour_sigma_m: each out[i] lowered to the least squared distance from point
// i to another, (x[k] - x[i])^2 + (y[k] - y[i])^2 for k != i, where that is less (out all
// infinite on entry: the nearest other's; left so where there is none). Precondition: x, y and
// out of one size, finite.
void NearestOtherSquares(std::span<const double> x, std::span<const double> y,
                         std::span<double> out);

// The least of start and the points' projections pts[i].dot(ray) (the nearest point along a
// part's ray), two points at a time: each lane x ray.x + y ray.y, p.dot(ray)'s products and sum,
// so the same minimum as std::min's one point at a time (bit for bit on x86-64; where multiply-adds
// are fused, e.g. aarch64, the lanes and the scalar tail may round differently in the last bit).
// Eigen's min of two lanes is x86's minpd in std::min's operand order; NEON's fmin would take a
// NaN and order -0 below +0, but neither reaches here (the caller's points are finite and in
// front of the sensor, start a range > 0). In the header so that it is inlined into the per-part
// loop (a call per part cost ~18 instructions more than the loop).
inline double NearestAlong(std::span<const Eigen::Vector2d> pts, const Eigen::Vector2d& ray,
                           double start) {
  Eigen::Array2d nearest_pair = Eigen::Array2d::Constant(start);
  std::size_t i = 0;
  for (; i + 2 <= pts.size(); i += 2) {
    const Eigen::Array2d x(pts[i].x(), pts[i + 1].x());
    const Eigen::Array2d y(pts[i].y(), pts[i + 1].y());
    nearest_pair = nearest_pair.min(x * ray.x() + y * ray.y());
  }
  double nearest = std::min(nearest_pair(0), nearest_pair(1));
  for (; i < pts.size(); ++i) nearest = std::min(nearest, pts[i].dot(ray));
  return nearest;
}

// ShapeOptions::box_seen_extent_cov: the variance of a box's semi-axis (its size state size_half_m)
// seen to at least seen_half_m: where a complete view showed it whole (whole_half_m > 0, half that
// view's extent), the squared difference of the state from it; else uniform between
// max(seen_half_m, min_half_m) and max(max_half_m, that): (max - min)^2 / 12.
double BoxHalfVar(double seen_half_m, double whole_half_m, double size_half_m, double min_half_m,
                  double max_half_m);

// ShapeOptions::box_seen_extent_cov: the centre covariance of a box (semi-axes a along yaw_rad, b
// across it): bias_var_m2 in every direction plus, along each box axis k,
// max(floor_var_m2, size_cov_m2(k, k), half_var_m2[k]).
Eigen::Matrix2d BoxSeenCentreCov(double bias_var_m2, double floor_var_m2,
                                 const Eigen::Matrix2d& size_cov_m2, double yaw_rad,
                                 const std::array<double, 2>& half_var_m2);

// ShapeOptions::box_rejoin_pieces: whether every point lies inside the box (centre_m, half-lengths
// size_m along yaw_rad and across it) grown by margin_m on every side; false for no points.
bool InsideGrownBox(const Eigen::Vector2d& centre_m, const Eigen::Vector2d& size_m, double yaw_rad,
                    double margin_m, std::span<const Eigen::Vector2d> points);
// Whether any of the points lies inside that grown box (false for no points).
bool AnyInsideGrownBox(const Eigen::Vector2d& centre_m, const Eigen::Vector2d& size_m,
                       double yaw_rad, double margin_m, std::span<const Eigen::Vector2d> points);

// ShapeOptions::person_size_across_ray: the weights of a body's semi-axes (a along yaw_rad, b
// across it) centred at centre_m (sensor at the origin) in what a scan shows across the ray:
// {1 - c^2, c^2}, c the cosine of the angle between axis a and the ray. {1, 1} where centre_m is
// at the origin.
std::array<double, 2> PersonAxisWeights(const Eigen::Vector2d& centre_m, double yaw_rad);

// ShapeOptions::person_size_across_ray: LearnSize with the fit's information beyond the prior
// taken as D share (post - prior) D, D = diag(sqrt(weights)), and its pull on each semi-axis
// (innovation form, share post (size - state)) scaled by that semi-axis's weight: weights {1, 1}
// are LearnSize with both semi-axes shown, a weight 0 is LearnSize with that one not shown.
void LearnSizeWeighted(const Eigen::Vector2d& size, const Eigen::Matrix2d& size_cov, double share,
                       const std::array<double, 2>& weights, TrackShape& shape);

// A track's size state after a fit whose posterior (prior: the state) is (size, size_cov): the
// fit's information beyond the prior, scaled by share, added to the state (information form).
// shown: per semi-axis whether the scan showed it (ShapeOptions::box_size_from_faces_seen): on one
// it did not show, neither the information gained nor the pull of the fit's size is taken, so its
// mean and variance stay. Unchanged where either covariance is singular or the mean not positive.
void LearnSize(const Eigen::Vector2d& size, const Eigen::Matrix2d& size_cov, double share,
               const std::array<bool, 2>& shown, TrackShape& shape);

// ShapeOptions::single_leg_side_uncertainty. A leg stands hip_m to one side of the body centre or
// the other across the walk; the predicted centre lies offset_m from it there, with variance s2_m2
// (the prediction's, the leg's and the sway's). The weight w = 2 q - 1 of the likelier side,
// q = 1 / (1 + exp(-2 hip |offset| / s2)) its probability (two Gaussians of variance s2 at +-hip):
// tanh(hip |offset| / s2); 1 for s2 <= 0.
double SingleLegSideWeight(double hip_m, double offset_m, double s2_m2);
// The variance across the walk the other side adds to a centre measured on the likelier side:
// (2 hip)^2 (1 - q) = 2 hip^2 (1 - w), w clamped to [0, 1].
double SingleLegOtherSideVar(double hip_m, double weight);
// A single leg's side counts as uncertain (PipelineCounters::legs_side_uncertain) below this weight
// w = 2 q - 1, the other side more likely than 2.5 % (q below 0.975); a prediction at least this
// sure of the side against the scan's (single_leg_side_from_view) contests it.
inline constexpr double kSideKnownWeight = 0.95;

// ShapeOptions::deep_legs_as_pair: how much deeper along the line of sight the points of one leg
// spread (farthest minus nearest range) than one leg can show: leg_radius_m + 2
// leg_radius_sigma_m + 3 (fit.point_sigma_m + fit.point_sigma_per_m R), R the nearest range; 0
// for fewer than two points or within that.
double DeepLegExcessDepth(const ShapeOptions& o, std::span<const Eigen::Vector2d> pts);

// ShapeOptions::touching_legs_along_ray: the variance along the line of sight added to the
// midpoint of two legs `first` and `second` (in scan order): leg_radius_m^2 / 3 where no beam lies
// between them (second.begin_beam <= first.end_beam) and they are not a deep pair
// (Observation::deep_pair), else 0 (and 0 with the option off).
double TouchingLegsAlongRayVar(const ShapeOptions& o, const ObservationPart& first,
                               const ObservationPart& second, bool deep_pair);

// ShapeOptions::occluded_gap_depth_m: the variance along the line of sight added to the midpoint
// of two legs `a` and `b` (in either order): occluded_gap_depth_m^2 / 3 where at least one beam
// lies between them and the silhouette of neither ends on the side facing the other (an
// occluder's edge there), else 0 (and 0 with the option 0).
double OccludedGapAlongRayVar(const ShapeOptions& o, const ObservationPart& a,
                              const ObservationPart& b);

// ShapeOptions::still_legs_cov: whether two legs legs_m (fit variances legs_var_m2, mean over the
// axes) stand where the track's last two legs last_m (last_var_m2) stood dt_s before: dt_s within
// (0, stance_memory_s], and each leg, matched to the last ones in the order (straight or swapped)
// that moved them less, displaced by d with d^2 <= kStillLegsChi2 (its variance + the last one's).
inline constexpr double kStillLegsChi2 = 9.21;  // 99 % of chi-square with 2 dof
bool LegsStill(const ShapeOptions& o, const std::array<Eigen::Vector2d, 2>& legs_m,
               const std::array<double, 2>& legs_var_m2,
               const std::array<Eigen::Vector2d, 2>& last_m,
               const std::array<double, 2>& last_var_m2, double dt_s);

// ShapeOptions::stance_leg_weight: the body centre from two legs legs_m (fit variances legs_var_m2,
// mean over the axes) of a track walking along the unit vector forward, step_m in dt_s (its
// speed times dt_s), with the track's last two-leg measurement last_m (last_var_m2) dt_s before.
// The legs are matched to the last ones by their order across the walk (a leg keeps its side);
// the one that moved less along the walk stands with probability q = 1 / (1 + exp(-2 step_m |d| /
// s2)), d the two displacements' difference, s2 the four variances summed (two hypotheses: the
// difference +-step_m). The centre: weight w = 1/2 + (2 q - 1) (stance_leg_weight - 1/2) on the
// standing leg and 1 - w on the other; standing is its index, weight w and m the matrices that
// map each leg to the centre (centre = m[0] legs_m[0] + m[1] legs_m[1]). Else (dt_s outside (0,
// stance_memory_s], stance_leg_weight 1/2 or d = 0) the midpoint, standing -1.
struct StanceCentre {
  Eigen::Vector2d centre_m = Eigen::Vector2d::Zero();
  std::array<Eigen::Matrix2d, 2> m{0.5 * Eigen::Matrix2d::Identity(),
                                   0.5 * Eigen::Matrix2d::Identity()};
  int standing = -1;
  double weight = 0.5;
};
StanceCentre StanceWeightedCentre(const ShapeOptions& o, const Eigen::Vector2d& forward,
                                  const std::array<Eigen::Vector2d, 2>& legs_m,
                                  const std::array<double, 2>& legs_var_m2,
                                  const std::array<Eigen::Vector2d, 2>& last_m,
                                  const std::array<double, 2>& last_var_m2, double dt_s,
                                  double step_m);

// ShapeOptions::single_leg_from_standing: the body centre along the walk (unit vector forward,
// velocity velocity_mps) from the seen swinging leg leg_m (fit variance along the walk
// leg_var_m2) and the hidden standing leg last seen at standing_m (variance standing_var_m2)
// dt_s ago: the standing knee now at standing_m + velocity dt / 2, the centre w of the way from
// the seen leg to it (w = stance_leg_weight). Returns the centre (its component across the walk
// the seen leg's) and *along_var_m2 its variance along the walk:
// w^2 (standing_var + (|velocity| dt / 4)^2) + (1 - w)^2 leg_var + gait_sigma_m^2.
Eigen::Vector2d LoneLegCentreFromStanding(const ShapeOptions& o, const Eigen::Vector2d& forward,
                                          const Eigen::Vector2d& velocity_mps,
                                          const Eigen::Vector2d& leg_m, double leg_var_m2,
                                          const Eigen::Vector2d& standing_m,
                                          double standing_var_m2, double dt_s,
                                          double* along_var_m2);

// What the points of a person's back spread over extent_m show of their principal line (RMS
// distance, m), and whether it exceeds threshold_m (the same test without the root).
double PersonBackLineRms(const ShapeOptions& o, double extent_m);
bool PersonBackLineRmsAbove(const ShapeOptions& o, double extent_m, double threshold_m);

}  // namespace internal

}  // namespace lrfnet::tracking
