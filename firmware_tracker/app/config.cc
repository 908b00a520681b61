#include "firmware_tracker/app/config.h"

#include <array>
#include <cmath>

#include "common/one_line.h"
#include "firmware_tracker/io/datagram_encoder.h"

namespace lrfnet::tracker {
namespace {

using common::LoadYamlConfig;
using common::PrintYamlConfig;
using common::VisitEnum;
using common::VisitInteger;
using common::VisitMs;

std::optional<std::string> Prefixed(const std::string& section,
                                    const std::optional<std::string>& error) {
  if (!error) return std::nullopt;
  return section + ": " + *error;
}

void VisitSensor(TrackerConfig& c, ConfigVisitor& v) {
  v.Section("sensor", "The scanner this tracker serves. Command-line flags override these.");
  v.Field("id", c.sensor_id,
          "Name of the sensor in every datagram and in the daemon: 1 to 32 letters, digits, "
          "'_', '.' or '-'. --sensor-id.");
  v.Field("address", c.sensor_address,
          "The scanner's address, HOST or HOST:PORT (port 2112), for the live mode. --sensor.");
  v.Field("uplink", c.uplink_address,
          "Where the UDP datagrams go: HOST:PORT of lrfnetd (IPv4, IPv6 in brackets, or a name). "
          "Empty: no UDP. --uplink.");
}

void VisitAuth(TrackerConfig& c, ConfigVisitor& v) {
  v.Section("auth",
            "Authenticated datagrams: with a key, every datagram is sealed (key epoch, counter and "
            "a 16-byte tag; lrfnet.proto) and only sealed Requests from lrfnetd are served.");
  v.Field("key", c.key_file,
          "This sensor's key file (lrfnet keys derive; mode 0600), or "
          "$CREDENTIALS_DIRECTORY/NAME for a systemd credential. Empty: not authenticated. --key.");
  v.Field("encrypt", c.encrypt,
          "Also encrypt the datagrams' content (tracks of people can be personal data); needs a "
          "key. --encrypt.");
}

void VisitLink(io::SickClientOptions& o, ConfigVisitor& v) {
  v.Section("link", "The CoLa-B session with the scanner (live mode).");
  VisitMs(v, "connect_timeout_ms", o.connect_timeout,
          "Name resolution and TCP connect must finish within this.");
  VisitMs(v, "reply_timeout_ms", o.reply_timeout,
          "Each start-up command (log-in, device ident, start of measurement) must be answered "
          "within this.");
  VisitMs(v, "first_scan_timeout_ms", o.first_scan_timeout,
          "After the scan stream was enabled, the first scan must arrive within this.");
  v.Field("read_deadline_scan_periods", o.read_deadline_scan_periods,
          "No scan for this many scan periods: the session is dead and the tracker reconnects.");
  VisitMs(v, "min_read_deadline_ms", o.min_read_deadline, "Lower bound of that read deadline.");
  VisitMs(v, "backoff_initial_ms", o.backoff.initial,
          "First reconnect delay; doubled (backoff_multiplier) after every failed attempt.");
  VisitMs(v, "backoff_max_ms", o.backoff.max, "Longest reconnect delay.");
  v.Field("backoff_multiplier", o.backoff.multiplier, "Growth of the reconnect delay per failure.");
  v.Field("backoff_jitter", o.backoff.jitter,
          "Random fraction of the delay added or removed, in [0, 1), so many trackers do not "
          "reconnect in lockstep.");
  v.Field("configure_scan_data", o.configure_scan_data,
          "Send sWN LMDscandatacfg (first echo, 16-bit RSSI, time block) before starting; off "
          "keeps the device's stored output configuration.");
  VisitInteger(v, "read_buffer_bytes", o.read_buffer_bytes, "Bytes per socket read.");
}

void VisitClock(tracking::ClockMapperOptions& o, double& max_error_s, ConfigVisitor& v) {
  v.Section("clock",
            "Mapping the scanner's microsecond tick to the gateway's UTC clock: offset = minimum "
            "of (receive time - tick) over recent scans (Schenk et al.), drift from the lower "
            "envelope.");
  v.Field("window_s", o.window_s, "Window of the minimum-offset rule, seconds.");
  v.Field("estimate_drift", o.estimate_drift,
          "Track the drift of the scanner's oscillator against the gateway clock.");
  v.Field("drift_window_s", o.drift_window_s,
          "Device time over which the drift slope is fitted to the lower envelope.");
  v.Field("min_drift_span_s", o.min_drift_span_s,
          "Samples must span this much device time before a slope is fitted.");
  v.Field("max_drift_ppm", o.max_drift_ppm, "Slope estimates are clamped to +- this.");
  v.Field("bin_s", o.bin_s, "Resolution of the lower envelope: one minimum per bin.");
  v.Field("restart_threshold_s", o.restart_threshold_s,
          "The tick stepping back by more than this is a scanner restart (the model resets).");
  v.Field("step_threshold_s", o.step_threshold_s,
          "Offsets this far from the model are clock-step candidates.");
  v.Field("settle_s", o.settle_s,
          "A model younger than this accepts every sample without step detection.");
  v.Field("step_forward_confirm_s", o.step_forward_confirm_s,
          "Every sample above the model for this long: the gateway clock stepped forward.");
  VisitInteger(v, "step_back_confirm_scans", o.step_back_confirm_scans,
               "This many samples below the model in a row: the gateway clock stepped back.");
  v.Field("max_device_delay_s", o.max_device_delay_s,
          "Transmission tick minus stamp tick beyond this: the transmission tick is not trusted.");
  v.Field("max_error_s", max_error_s,
          "The kernel clock (adjtimex) counts as synchronized when its estimated error is below "
          "this; reported in every Health datagram.");
}

void VisitBackground(tracking::BackgroundOptions& o, ConfigVisitor& v) {
  v.Section("background",
            "Per-beam background model: learned at start-up, then updated slowly. Foreground = "
            "nearer than the background by more than base_margin_m + noise_margin_k * "
            "(range_noise_m + range_noise_per_m * range).");
  v.Field("learn_duration_s", o.learn_duration_s,
          "Start-up learning time; no tracks are reported while learning.");
  v.Field("min_range_m", o.min_range_m, "Nearer returns count as no echo (near-field values).");
  v.Field("max_range_m", o.max_range_m, "Farther returns count as no echo.");
  v.Field("base_margin_m", o.base_margin_m, "Constant part of the foreground margin.");
  v.Field("range_noise_m", o.range_noise_m, "1-sigma range noise at 0 m.");
  v.Field("range_noise_per_m", o.range_noise_per_m, "Added 1-sigma range noise per metre.");
  v.Field("noise_margin_k", o.noise_margin_k, "Margin in range-noise sigmas.");
  v.Field("absorb_after_s", o.absorb_after_s,
          "A nearer object standing still this long becomes background (a parked cart); a person "
          "standing for a few seconds does not.");
  v.Field("recede_after_s", o.recede_after_s,
          "A farther return or no echo persisting this long replaces the background (a door "
          "opened, the cart left).");
  v.Field("track_time_constant_s", o.track_time_constant_s,
          "Time constant with which the background follows returns within its margin.");
  v.Field("free_fraction", o.free_fraction,
          "During learning, a beam without echo in more than this fraction of scans is free.");
  v.Field("max_scan_gap_s", o.max_scan_gap_s,
          "Time steps between scans are clamped to this, so a pause neither absorbs nor recedes.");
}

void VisitSegmentation(tracking::SegmentationOptions& o, ConfigVisitor& v) {
  v.Section("segmentation",
            "Jump-distance clustering of foreground beams: a point joins the open segment when "
            "it is within jump_base_m + jump_per_m * range of the segment's last point.");
  v.Field("jump_base_m", o.jump_base_m, "Constant part of the jump threshold.");
  v.Field("jump_per_m", o.jump_per_m, "Range-proportional part of the jump threshold.");
  VisitInteger(v, "max_missing_beams", o.max_missing_beams,
               "Background beams allowed inside one segment.");
  VisitInteger(v, "min_points", o.min_points, "Fewer points: dropped as noise.");
  VisitInteger(v, "max_points", o.max_points, "More points: the segment is closed and split.");
  v.Field("min_width_m", o.min_width_m, "Narrower segments are dropped.");
  v.Field("max_width_m", o.max_width_m, "Wider segments are split.");
}

constexpr std::array<std::string_view, 3> kKindNames = {"center_of_mass", "ellipse", "shape_fit"};

void VisitMeasurement(tracking::TrackerOptions& p, ConfigVisitor& v) {
  tracking::MeasurementOptions& o = p.measurement;
  v.Section("measurement",
            "One position per object. shape_fit: the centre of the body from a fit of its known "
            "shape with the size learned per track (section shape). center_of_mass / ellipse: "
            "the previous estimators, kept to compare: the centre of mass of the visible points, "
            "or the fixed-axes ellipse of Quenzel et al. eqs. 3-4 (started from a direct "
            "least-squares fit), both biased towards the sensor. The kind is carried in every "
            "track.");
  VisitEnum(v, "kind", p.method, kKindNames,
            "Measurement kind; with ellipse, a fit that fails its checks falls back to the centre "
            "of mass for that segment.");
  v.Field("ellipse_major_m", o.ellipse_major_m, "kind ellipse: semi-major axis a of eq. 4.");
  v.Field("ellipse_minor_m", o.ellipse_minor_m, "kind ellipse: semi-minor axis b of eq. 4.");
  VisitInteger(v, "min_ellipse_points", o.min_ellipse_points,
               "kind ellipse: fewer points give the centre of mass instead.");
  VisitInteger(v, "max_iterations", o.max_iterations,
               "kind ellipse: Levenberg-Marquardt iterations of eq. 3.");
  v.Field("com_sigma_m", o.com_sigma_m, "1-sigma of a centre-of-mass measurement per axis.");
  v.Field("min_point_sigma_m", o.min_point_sigma_m,
          "kind ellipse: floor of the fit's residual sigma.");
  v.Field("min_position_sigma_m", o.min_position_sigma_m,
          "kind ellipse: floor of the centre's sigma per axis.");
  v.Field("max_position_sigma_m", o.max_position_sigma_m,
          "kind ellipse: centres less certain than this fall back to the centre of mass.");
  v.Field("max_centre_offset_m", o.max_centre_offset_m,
          "kind ellipse: centres farther than this from the centre of mass fall back to it.");
}

constexpr std::array<std::string_view, 2> kMountNames = {"torso", "legs"};
constexpr std::array<std::string_view, 3> kOutsideGuessStartNames = {"guess", "silhouette",
                                                                     "better"};

void VisitShape(tracking::ShapeOptions& o, ConfigVisitor& v) {
  v.Section("shape",
            "measurement.kind shape_fit: the body centre from a fit of the object's shape (a "
            "person's upper body an ellipse, a cart a rectangle, a leg a circle) with its size a "
            "state of the track, learned over its life from this prior; the silhouette's ends and "
            "the walking direction (shoulders across it) constrain it too. With 2-4 points the "
            "prior and the direction to the sensor still give the centre, with a covariance that "
            "says what is open.");
  VisitEnum(v, "mount", o.mount, kMountNames,
            "Height of the scan plane: torso (upper body, about 1 m and above) or legs (knee "
            "height, 0.3-0.6 m: a person shows two legs, paired into one track).");
  v.Field("person_major_m", o.person_major_m,
          "Prior semi-axis of a person's upper body across the shoulders (arms included).");
  v.Field("person_minor_m", o.person_minor_m, "Prior semi-axis front to back.");
  v.Field("person_size_sigma_m", o.person_size_sigma_m,
          "1-sigma of that prior (people differ); a cylinder's or cart's size is learned from it.");
  v.Field("person_exponent", o.person_exponent,
          "Exponent p of the upper body's outline |u/a|^p + |v/b|^p = 1 (2: an ellipse; a torso "
          "with arms lies between an ellipse and a rounded box). Round tracks (learned axes "
          "within a tenth) are cylinders, fitted with p = 2.");
  v.Field("box_min_half_length_m", o.box_min_half_length_m,
          "A track whose learned semi-axis exceeds this is a cart: fitted as a rectangle.");
  v.Field("leg_radius_m", o.leg_radius_m, "mount legs: prior radius of a leg at knee height.");
  v.Field("leg_radius_sigma_m", o.leg_radius_sigma_m, "mount legs: 1-sigma of that prior.");
  v.Field("leg_pairing_distance_m", o.leg_pairing_distance_m,
          "mount legs: two legs this close (centre to centre) can be one person's.");
  v.Field("person_min_leg_radius_m", o.person_min_leg_radius_m,
          "mount legs: thinner legs are not a person's (a chair's) for the static-object rules.");
  v.Field("still_legs_max_depth_m", o.still_legs_max_depth_m,
          "mount legs: a still track measured in most of its two-leg scans as legs farther apart "
          "along the line of sight than this, the nearer a single beam, is not a person's for "
          "the static-object rules (the mixed echoes of a chair's leg and someone standing "
          "behind it; 0: off).");
  v.Field("mixed_leg_max_gap_m", o.mixed_leg_max_gap_m,
          "mount legs: a leg filling no beam footprint with a learned background no more than "
          "this behind each of its returns is measured from the returns' range deficits (each "
          "may be a mixed pixel between leg and background), not fitted to them; the largest gap "
          "the scanner merges echoes over (LMS1xx, TiM: their captures show merged echoes up to "
          "about 1 m and none resolved, 1.5 assumes the same a little beyond; an LMS5xx, which "
          "resolves echoes beyond ~0.5 m, caps it at 0.5 by itself, from its DeviceIdent name; "
          "0: off).");
  v.Field("mixed_leg_band_variance", o.mixed_leg_band_variance,
          "mount legs: where a beam may return a leg alone (its footprint at most 1.25 leg "
          "diameters), a leg of two returns or more measured from range deficits no deeper than "
          "its nearest return reports the leg radius' share of its variance along the ray as the "
          "spread of the fronts one radius sigma either side, each held at that return (false: "
          "the whole gap to the background times the radius' relative sigma).");
  v.Field("hip_half_width_m", o.hip_half_width_m,
          "mount legs: a leg's lateral offset from the body centre (a single leg's uncertainty).");
  v.Field("drop_mixed_pixel_legs", o.drop_mixed_pixel_legs,
          "mount legs: mixed pixels are not legs. Where a leg fills no beam footprint (divergence "
          "times range above a leg's width) a beam that grazes it reports a range between the leg "
          "and what is behind: leg-sized pieces beside a much nearer return, and legs straight "
          "behind a confirmed track, are dropped.");
  v.Field("drop_mixed_pixel_legs_whole_person", o.drop_mixed_pixel_legs_whole_person,
          "mount legs: ... also leg-sized pieces within leg_pairing_distance_m (across the ray) "
          "of a much nearer return: the other leg of a person one beam returns may fill no beam, "
          "its mixed pixels lie behind it.");
  v.Field("drop_deep_mixed_pixel_pieces", o.drop_deep_mixed_pixel_pieces,
          "mount legs: ... also pieces wider than a pair of legs only along the line of sight "
          "(across it no wider than a pair, or than a leg and a beam footprint) where a leg fills "
          "no beam footprint: a far leg's mixed pixels at ranges between the leg and what is "
          "behind, no body's outline.");
  v.Field("deep_mixed_pixel_behind_ratio", o.deep_mixed_pixel_behind_ratio,
          "mount legs: ... only where the learned background of the piece's beams lies behind it "
          "within this many times the piece's depth (a mixed pixel's echoes each carry at least "
          "a fifth of the energy: 4); elsewhere nothing stands behind to mix with and the piece "
          "is kept (two legs in radial stride, an object end-on). 0: no surface behind "
          "required.");
  v.Field("recent_veil_s", o.recent_veil_s,
          "mount legs: ... also leg-sized pieces, where a leg fills no beam footprint, behind a "
          "foreground return their beams (each, or a neighbour) had within this time, nearer by "
          "more than the segmentation's jump and leg_pairing_distance_m plus "
          "tracking.max_speed_mps times its age: a mixed pixel's range runs between the leg's "
          "and the background's as the leg's share of the beam changes from scan to scan. About "
          "a leg's swing. 0: off.");
  v.Field("gait_sigma_m", o.gait_sigma_m,
          "mount legs: how far the midpoint of the legs strays from the body centre while "
          "walking (1 sigma).");
  v.Field("stance_leg_weight", o.stance_leg_weight,
          "mount legs: two legs of a walking track, one standing (it moved less along the walk "
          "since the track's last two-leg measurement) and one swinging: the body centre is "
          "taken with this weight on the standing leg and the rest on the swinging one (the "
          "stance's share of the gait cycle: along the walk the hip's offsets from the two knees "
          "cancel, across it the body leans over the standing foot); the weight moves from 0.5 "
          "to this one as the legs' displacements differ by more than the leg fits' noise (legs "
          "that move alike keep the midpoint). 0.5: the midpoint always.");
  v.Field("stance_memory_s", o.stance_memory_s,
          "mount legs: with stance_leg_weight, the track's last two-leg measurement counts for "
          "telling the standing leg from the swinging one for at most this long.");
  v.Field("hidden_leg_behind", o.hidden_leg_behind,
          "mount legs: a single leg whose neighbouring beams all pass leg_pairing_distance_m "
          "around it (or return from straight behind it), where a leg beside would have returned "
          "a beam, hides the other leg behind it: the body centre is measured hip_half_width_m "
          "farther along the line of sight (false: at the leg, with the hip and stride extent).");
  v.Field("single_leg_across_walk", o.single_leg_across_walk,
          "mount legs: one leg (its partner not hidden behind it) of a track walking faster than "
          "walking_speed_mps, clearly to one side of the predicted centre across the walk: the "
          "body centre is measured hip_half_width_m across the walk from it on that side, "
          "anywhere within the legs' reach along the walk (sigma leg_pairing_distance_m / 2: "
          "successive scans share the stride's phase) (false: at the leg, with the hip and stride "
          "extent).");
  v.Field("single_leg_side_uncertainty", o.single_leg_side_uncertainty,
          "mount legs: with single_leg_across_walk, the side of the centre the leg stands on is "
          "weighed, not taken as sure: the other side's share of the two sides' spread "
          "(2 hip^2 (1 - tanh(hip |offset| / s^2)), s^2 the predicted centre's variance across the "
          "walk, the leg's and gait_sigma_m^2) is always added to the centre's variance across the "
          "walk, vanishing as the prediction grows sure of the side; a side taken from the scan "
          "(single_leg_side_from_view) is sure, nothing added (false: the side taken as sure).");
  v.Field("single_leg_side_from_view", o.single_leg_side_from_view,
          "mount legs: with single_leg_across_walk, where the scan sees through every place the "
          "other leg may stand on one side of the seen one (2 hip_half_width_m across the walk, "
          "within leg_pairing_distance_m / 2 along it) and not on the other, the centre is on the "
          "latter side, sure; only where the beams and their footprint (max(angle_step, "
          "beam_divergence_rad)) are narrower than a leg, within 2 leg_radius_m / that footprint "
          "of the sensor; against a prediction sure of the other side (weight at least 0.95) the "
          "scan's side is taken with the other side's whole share (false: the side from the "
          "prediction alone).");
  v.Field("single_leg_from_standing", o.single_leg_from_standing,
          "mount legs: with single_leg_across_walk, where the track's last two-leg measurement "
          "(at most standing_leg_memory_s ago) told which leg stood and the leg seen now is the "
          "other one (by its side across the walk), the centre along the walk is taken from the "
          "two: the hidden standing leg's knee carried forward by half the body's displacement "
          "since, weighted by stance_leg_weight against the seen leg, its variance growing with "
          "the time since (false: along the walk anywhere within the legs' reach).");
  v.Field("standing_leg_memory_s", o.standing_leg_memory_s,
          "mount legs: with single_leg_from_standing, the leg that stood at the track's last "
          "two-leg measurement counts as still standing for at most this long (the rest of a "
          "stance).");
  v.Field("leg_edge_in_mixed_beam", o.leg_edge_in_mixed_beam,
          "mount legs: where the beam beyond a leg's edge returned from between the leg and what "
          "the beam after it sees (each farther by three sigma of the range noise), a mixed echo "
          "of the two, the leg's tangent is taken within that beam's footprint, (w - 1/2) "
          "beam_divergence_rad from its centre towards the outside, w = (r_beyond - r) / "
          "(r_beyond - r_edge) its share of the leg; only where the footprint is narrower than a "
          "leg (2 leg_radius_m) (false: every edge half a step beyond the last returning beam).");
  v.Field("split_few_point_legs", o.split_few_point_legs,
          "mount legs: a leg-sized segment of two or three points spread across the line of "
          "sight wider than one leg can be (2 (leg_radius_m + 2 leg_radius_sigma_m)) is two legs "
          "side by side: split at its widest gap into two legs measured as a pair (false: one "
          "leg; four points or more are split by their width either way).");
  v.Field("deep_legs_as_pair", o.deep_legs_as_pair,
          "mount legs: a leg-sized segment of two or three points spread along the line of "
          "sight deeper than one leg's visible half can be (leg_radius_m + 2 leg_radius_sigma_m "
          "+ 3 sigma of the range noise), taken by a confirmed track whose predicted centre lies "
          "beyond the near leg's front, is that track's two legs (the nearer, and the other or "
          "the echoes mixed between them behind it): split at its widest gap and measured as a "
          "pair, half the parts' depth apart as its sigma along the ray (false: one leg).");
  v.Field("touching_legs_along_ray", o.touching_legs_along_ray,
          "mount legs: two legs that touch in the scan (no beam between them) and are not a "
          "deep pair: the farther leg is seen only beside the nearer one's occluding edge, so "
          "its centre is known along the line of sight only to within a leg's diameter; the "
          "midpoint's variance along the ray grows by leg_radius_m^2 / 3 (false: a touching "
          "pair's covariance as any pair's).");
  v.Field("occluded_gap_depth_m", o.occluded_gap_depth_m,
          "mount legs: two legs with something nearer between them (a beam between the parts, "
          "an occluder's edge on both inner ends) may be the two ends of one surface behind it "
          "(a parked trolley's face either side of its pusher's legs): the reported covariance "
          "grows along the ray by this^2 / 3, the centre anywhere up to this behind it; the "
          "filter is left as it is (m; 0: off).");
  v.Field("still_legs_cov", o.still_legs_cov,
          "mount legs: two legs of a standing track (predicted speed at most "
          "still_legs_max_speed_mps) each where one of its last two legs stood (within "
          "stance_memory_s, the 99 % bound of the fits' variances), nothing else within "
          "leg_pairing_distance_m: the covariance reported follows the filter's gains with the "
          "gait and centre model allowance replaced by still_legs_sigma_m, without the process "
          "noise since the last update, and with the leg radius floor and outline allowance cut "
          "to outline_fixed_share; the filter and the tracks are unchanged (needs "
          "tracking.report_gain_covariance; false: as a walking pair's).");
  v.Field("still_legs_sigma_m", o.still_legs_sigma_m,
          "mount legs, still_legs_cov: 1-sigma per axis of a still pair's midpoint about the "
          "body's centre (how the feet stand), in place of gait_sigma_m and "
          "centre_model_sigma_m; at most gait_sigma_m.");
  v.Field("still_legs_max_speed_mps", o.still_legs_max_speed_mps,
          "mount legs, still_legs_cov: a track counts as standing up to this predicted speed "
          "(faster, the filter may still be stopping behind a person who stopped).");
  v.Field("walking_legs_cov", o.walking_legs_cov,
          "mount legs: two legs of a walking track that are not a still pair, no other "
          "measurement within leg_pairing_distance_m + 2 hip_half_width_m: the covariance "
          "reported follows the filter's gains without gait_sigma_m and without the process "
          "noise since the last update, plus walking_legs_sigma_m per axis (the stance-weighted "
          "midpoint's offset from the body's centre, which swings once per stride and is shared "
          "by successive scans); the next other update starts it again from the filter's "
          "covariance; the filter and the tracks are unchanged (needs "
          "tracking.report_gain_covariance; false: the filter's gait allowance as per-scan "
          "noise).");
  v.Field("walking_legs_sigma_m", o.walking_legs_sigma_m,
          "mount legs, walking_legs_cov: 1-sigma per axis of a walking pair's stance-weighted "
          "midpoint about the body's centre, reported as shared by successive scans; at most "
          "gait_sigma_m.");
  v.Field("single_beam_legs", o.single_beam_legs,
          "mount legs: a leg returned by a single beam (below segmentation.min_points), where "
          "a leg is narrower than two beams' spacing, within leg_pairing_distance_m of one "
          "confirmed track that still knows where it is, updates that track where it found no "
          "other leg; it never starts a track (false: such beams are dropped).");
  v.Field("single_beam_partner", o.single_beam_partner,
          "mount legs (with single_beam_legs): a lone beam, at any range, is the second leg of a "
          "confirmed track that takes a single leg of a segment where it lies within "
          "leg_pairing_distance_m of that leg (the person's other leg with its edge in one "
          "beam); not a beam beside the leg's edge returning from behind it (its mixed echo) "
          "(false: a lone beam partners no segment's leg).");
  v.Field("lone_beam_edge_echo", o.lone_beam_edge_echo,
          "mount legs (with single_beam_legs): a lone beam within a footprint's beams of a "
          "return nearer than it by more than the segmentation's jump (and by no more than "
          "leg_pairing_distance_m + 2 leg_radius_m) is that edge's mixed echo and no leg "
          "(false: such beams are legs).");
  v.Field("far_legs_no_birth", o.far_legs_no_birth,
          "mount legs: legs where a leg covers at most half of a beam's footprint (range times "
          "beam_divergence_rad at least 4 leg_radius_m), whose echoes are mixed with what lies "
          "behind, update a confirmed track but start none (false: such legs may start "
          "tracks).");
  v.Field("edge_echo_no_birth", o.edge_echo_no_birth,
          "mount legs: a single leg no wider than the beams whose footprint reaches past an "
          "edge, beside a return nearer by more than the segmentation's jump, with the learned "
          "background of one of its beams within deep_mixed_pixel_behind_ratio's bound behind "
          "it, may be the mixed echo of that edge and that surface: it updates a track but "
          "never starts one (false: such legs may start tracks).");
  v.Field("walking_speed_mps", o.walking_speed_mps,
          "Faster than this a person faces where they walk (the yaw prior of the fit).");
  v.Field("walking_yaw_sigma_rad", o.walking_yaw_sigma_rad,
          "1-sigma of that yaw prior (the torso turns with the gait, people step sideways).");
  v.Field("yaw_drift_rad_per_s", o.yaw_drift_rad_per_s,
          "Standing, the orientation becomes this much less certain per second.");
  v.Field("size_drift_m_per_sqrt_s", o.size_drift_m_per_sqrt_s,
          "Random-walk drift of the size state (a person lifts a bag, turns the shoulders).");
  v.Field("centre_bias_sigma_m", o.centre_bias_sigma_m,
          "The centre's error successive measurements share (the outline is not the model's, the "
          "beam width at the silhouette): added, with the size state's sigma, to the reported "
          "covariance, which the filter alone would make too small.");
  v.Field("centre_bias_along_ray", o.centre_bias_along_ray,
          "true: that shared error is built along the ray from the sensor and across it: along it "
          "centre_bias_sigma_m and the size's error through the body's extent towards the "
          "sensor, across it centre_bias_across_sigma_m, the silhouette's beam step (range x "
          "step / sqrt(12), halved in variance with both ends a silhouette) and, with an end "
          "occluded, the size's error through the extent across; a box (cart) keeps the form of "
          "false. false: centre_bias_sigma_m and the size's sigma in every direction.");
  v.Field("centre_bias_across_sigma_m", o.centre_bias_across_sigma_m,
          "With centre_bias_along_ray: a shared error across the ray added to the silhouette's (a "
          "walking person's sideways sway, which the constant-velocity filter smooths away).");
  v.Field("size_floor_sigma_m", o.size_floor_sigma_m,
          "The size state counts as no more certain than this in that shared error.");
  v.Field("box_size_floor_sigma_m", o.box_size_floor_sigma_m,
          "A box's (cart's) size state counts as no more certain than this in that shared error: "
          "learned from the few faces a passing cart shows, each scan sharing that view's error.");
  v.Field("box_drop_occluders", o.box_drop_occluders,
          "A box's (cart's) points nearer than where their beam enters the fitted box (by three "
          "sigma of the range noise and model error) are something in front of it (its pusher): "
          "left out and the box refitted without them. false: every point is the box's.");
  v.Field("box_size_sigma_m", o.box_size_sigma_m,
          "Sigma of a box's (cart's) semi-axes when a track becomes one.");
  v.Field("box_rejoin_pieces", o.box_rejoin_pieces,
          "Upper-body mount: consecutive segments cut apart only by segmentation.max_width_m "
          "whose points all lie on a confirmed box track's predicted rectangle (grown by "
          "box_rejoin_sigmas of its uncertainty, the size's at least box_size_sigma_m) are "
          "measured as one segment. false: every segment is an observation.");
  v.Field("box_rejoin_sigmas", o.box_rejoin_sigmas,
          "With box_rejoin_pieces: sigmas of the range noise, model error, size state and "
          "predicted position by which the box's rectangle is grown.");
  v.Field("box_unseen_depth_cov", o.box_unseen_depth_cov,
          "A box (cart) whose scan does not show one of its semi-axes (one face seen): its "
          "reported centre covariance along that axis is at least box_unseen_sigma_m^2 (or the "
          "size state's variance). false: the same size term in every direction.");
  v.Field("box_unseen_sigma_m", o.box_unseen_sigma_m,
          "With box_unseen_depth_cov: sigma of a box's semi-axis the scan does not show.");
  v.Field("box_seen_extent_cov", o.box_seen_extent_cov,
          "A box's (cart's) reported centre covariance along an axis whose semi-axis the track "
          "never saw whole (a complete view showing the face across it) is at least a uniform "
          "distribution's between the longest half extent seen (at least box_prior_min_half_m) "
          "and box_prior_max_half_m. false: box_unseen_depth_cov's test of each scan alone.");
  v.Field("box_prior_min_half_m", o.box_prior_min_half_m,
          "With box_seen_extent_cov: the least semi-axis a box may have.");
  v.Field("box_prior_max_half_m", o.box_prior_max_half_m,
          "With box_seen_extent_cov: the largest semi-axis a box may have.");
  v.Field("box_size_from_faces_seen", o.box_size_from_faces_seen,
          "A box's half-length is learned only from scans that show one of its sides, its "
          "half-width only from scans that show one of its ends (at least three beams across the "
          "face). Default false: both from every box fit.");
  v.Field("box_size_from_faces_seen_at_knee", o.box_size_from_faces_seen_at_knee,
          "Knee height: box_size_from_faces_seen there whatever it says (a cart's width is not "
          "learned from its side, its length not from its end). false: box_size_from_faces_seen "
          "alone decides.");
  v.Field("person_size_across_ray", o.person_size_across_ray,
          "Upper-body mount: a person's semi-axes learn from each fit by their share of the "
          "width across the ray (the shoulders' half-width from a front-on or back-on view, the "
          "half-depth from a side view); the extent along the ray that a fit reads from the "
          "visible arc's curvature is the outline's departure from the model more than the size. "
          "false: both from every fit.");
  v.Field("partial_view_shared", o.partial_view_shared,
          "Upper-body mount: a fit that sees fewer than two real silhouette ends (one is an "
          "occluder's edge) reports its own centre covariance with its measured scans, since "
          "successive scans share that view's error. false: a partial view reported as a whole one.");
  v.Field("underdetermined_fit_shared", o.underdetermined_fit_shared,
          "Upper-body mount: a fit whose points and silhouette ends are no more than its five "
          "parameters (centre, semi-axes, yaw) reports its own centre covariance (the priors') "
          "with its measured scans. false: such a fit reported as any other.");
  v.Field("person_drop_beyond_reach", o.person_drop_beyond_reach,
          "Upper-body mount, a person's track: a run of points at an end of its segment beyond "
          "the reach of the predicted body (another object beside the person, within the "
          "segmentation's jump), whose range steps from the person's points, is left out of the "
          "fit; that end is an occluder's edge where the run is nearer, the person's silhouette "
          "where it is behind. false: every point of the segment is the person's.");
  v.Field("split_see_through", o.split_see_through,
          "Upper-body mount: a segment wider than see_through_min_width_m is measured as one "
          "object per piece where beams between its points saw through it (no return, or one "
          "farther than both points around it by more than the segmentation's jump): people side "
          "by side that the segmentation joined across its missing beams; not where the segment "
          "touches a confirmed cart's predicted outline. false: every segment is one object.");
  v.Field("see_through_min_width_m", o.see_through_min_width_m,
          "With split_see_through: only segments wider than this (m, first to last point) are "
          "cut.");
  v.Field("split_step_seam", o.split_step_seam,
          "Upper-body mount: a segment that split_see_through leaves whole is measured as one "
          "object per piece where its range steps by more than step_seam_min_step_m between two "
          "curved body-sized pieces that touch in the view with no beam between them (two people "
          "side by side, one partly behind the other); not where the segment touches a cart's "
          "predicted outline (a box track, confirmed or not, or with step_seam_size_guard a track "
          "larger than a person). false: such a segment is one object.");
  v.Field("step_seam_min_width_m", o.step_seam.min_width_m,
          "With split_step_seam: only segments wider than this (m, first to last point) are cut.");
  v.Field("step_seam_min_step_m", o.step_seam.min_step_m,
          "With split_step_seam: a cut only where the range of neighbouring points steps by more "
          "than this (m).");
  VisitInteger(v, "step_seam_min_piece_points", o.step_seam.min_piece_points,
               "With split_step_seam: each piece holds at least this many points.");
  v.Field("step_seam_min_piece_width_m", o.step_seam.min_piece_width_m,
          "With split_step_seam: each piece is at least this wide (m, first to last point).");
  v.Field("step_seam_max_piece_width_m", o.step_seam.max_piece_width_m,
          "With split_step_seam: each piece is at most this wide (m, first to last point).");
  v.Field("step_seam_min_turn_m", o.step_seam.min_turn_m,
          "With split_step_seam: a piece's end at the cut lies farther than its nearest point by "
          "more than this (m): its outline turns away there.");
  v.Field("step_seam_min_bulge_m", o.step_seam.min_bulge_m,
          "With split_step_seam: a point of each piece lies nearer the sensor than the chord of "
          "its ends by more than this (m): curved like a body, not a cart's straight face.");
  v.Field("step_seam_hidden_far_piece", o.step_seam.hidden_far_piece,
          "With split_step_seam: the piece on the farther side of the step need not turn there "
          "(the nearer body hides part of it). false: both pieces turn at the step.");
  v.Field("step_seam_size_guard", o.step_seam_size_guard,
          "With split_step_seam: no cut where the segment touches (within "
          "step_seam_size_margin_m) a track not yet fitted as a box whose learned semi-axes "
          "exceed a person's (step_seam_person_max_a_m, step_seam_person_max_b_m): a cart still "
          "learned as another shape, whose size a cut would keep below box_min_half_length_m. "
          "false: only box tracks keep a segment whole.");
  v.Field("step_seam_person_max_a_m", o.step_seam_person_max_a_m,
          "With step_seam_size_guard: a learned semi-axis a (along the shoulders) beyond this (m) "
          "is not a person's.");
  v.Field("step_seam_person_max_b_m", o.step_seam_person_max_b_m,
          "With step_seam_size_guard: a learned semi-axis b (front to back) beyond this (m) is "
          "not a person's.");
  v.Field("step_seam_size_margin_m", o.step_seam_size_margin_m,
          "With step_seam_size_guard: the track's predicted bounding rectangle grown by this (m).");
  v.Field("split_deep_tail", o.split_deep_tail,
          "Upper-body mount: a segment's first or last points deeper than its nearest point by "
          "more than deep_tail_depth_m (a body behind, joined through mixed pixels) are left out "
          "of its observation. Not on a box track's outline nor one larger than a person. false: "
          "one observation.");
  v.Field("deep_tail_centre_bias_sigma_m", o.deep_tail_centre_bias_sigma_m,
          "With split_deep_tail, upper-body mount: centre_bias_sigma_m is this (m) instead (the "
          "tails' pull along the ray was part of it).");
  v.Field("deep_tail_depth_m", o.deep_tail_depth_m,
          "With split_deep_tail: how much deeper than the segment's nearest point (m) an end "
          "point lies to be cut off (a person's outline recedes by at most ~0.3 m).");
  v.Field("partial_view_size_sigma_m", o.partial_view_size_sigma_m,
          "Upper-body mount, a partial view (fewer than two silhouette ends): in the centre "
          "covariance successive scans share, each semi-axis's sigma is at least this (m), since "
          "the scan does not show the extent towards the hidden side. 0: the size's own sigma.");
  v.Field("neighbour_distance_m", o.neighbour_distance_m,
          "Upper-body mount: another observation of the scan within this of a person's (their "
          "first measurements' centres) is an object beside the person (neighbour_sigma_m).");
  v.Field("neighbour_sigma_m", o.neighbour_sigma_m,
          "Upper-body mount, a person with another object within neighbour_distance_m: what the "
          "segmentation and the fit may make of the two together (points joined or cut off, an "
          "end taken for the silhouette), shared by the scans while they stay close: this "
          "squared, times 1 - distance / neighbour_distance_m, per axis, is reported with the "
          "person's measured scans (m). 0: off.");
  v.Field("segment_excess_shared", o.segment_excess_shared,
          "Upper-body mount, a person whose points extend across the ray beyond twice the fitted "
          "outline's reach, or along it beyond its reach, by more than their range noise: where "
          "in them the body lies is not known, and the excess squared over 12 along that "
          "direction is reported with the measured scans (not given to the filter). false: not "
          "reported.");
  v.Field("box_view_shared", o.box_view_shared,
          "A track fitted as a body (not a box, not legs) measured from a segment whose points "
          "are a box's outline (one straight face, or two at a corner): the second moment about "
          "the measurement of where the box's centre lies (behind one face by a depth uniform "
          "over box_prior_min_half_m..box_prior_max_half_m, or in the middle of the two faces' "
          "diagonal) is reported with the measured scans (not given to the filter). false: not "
          "reported.");
  v.Field("box_view_at_torso", o.box_view_at_torso,
          "box_view_shared at upper-body height too, where the longest face seen is longer than "
          "twice box_min_half_length_m (shorter ones are people's fronts too). false: knee "
          "height only.");
  v.Field("beam_divergence_rad", o.beam_divergence_rad,
          "Full beam divergence of the scanner (LMS1xx, TiM: 0.015; LMS5xx: 0.011); the beam's "
          "footprint at range R is R times this plus beam_exit_diameter_m (mixed pixels of legs "
          "and of a far body's edges).");
  v.Field("beam_exit_diameter_m", o.beam_exit_diameter_m,
          "The beam's diameter at the scanner (LMS1xx: 0.008; LMS5xx: 0.013).");
  v.Field("mixed_pixel_min_footprint_m", o.mixed_pixel_min_footprint_m,
          "Mount torso: where the beam's footprint is at least this wide, a segment's edge point "
          "whose neighbour beam beyond returned from more than mixed_pixel_min_gap_m behind it "
          "is a mixed pixel (a range between the body and what is behind): the fit leaves it "
          "out. 0: off.");
  v.Field("mixed_pixel_min_gap_m", o.mixed_pixel_min_gap_m,
          "How far behind an edge point the neighbour beam must have returned for the edge point "
          "to be a mixed pixel.");
  v.Field("receded_background_edge_m", o.receded_background_edge_m,
          "A segment's end is no silhouette where the beam beyond returned from within this of "
          "the end point's range and was classed background only because the background model "
          "holds something more than receded_background_margin_m nearer there (someone who stood "
          "there and left). 0: off.");
  v.Field("receded_background_margin_m", o.receded_background_margin_m,
          "How much nearer than the beam's return the background model must hold something for "
          "receded_background_edge_m.");
  v.Field("centre_model_sigma_m", o.centre_model_sigma_m,
          "Added in quadrature to every centre measurement's sigma: what the fit cannot know "
          "(sway, an outline that is not the model's).");
  v.Field(
      "outline_departure_gain", o.outline_departure_gain,
      "Mount torso: the fit's residuals beyond the range noise measure the outline's departure "
      "from the model (a second object in the segment, a partial view, a body unlike the "
      "prior); gain^2 (rms^2 - noise^2) per axis, or its running mean (about the last 10 scans) "
      "if larger, is added to the covariance reported with measured scans, and the fixed "
      "allowances for the outline are cut (outline_fixed_share, outline_model_share). 0: off.");
  v.Field("outline_fixed_share", o.outline_fixed_share,
          "With outline_departure_gain > 0, mount torso: centre_bias_sigma_m and "
          "size_floor_sigma_m are taken at this share of their sigma (0 < share <= 1).");
  v.Field("outline_model_share", o.outline_model_share,
          "With outline_departure_gain > 0, mount torso: centre_model_sigma_m (given to the "
          "filter) is taken at this share (1: tracks unchanged; 0 < share <= 1).");
  v.Field("flat_rms_m", o.flat_rms_m,
          "Outlines whose points stay closer than this to a straight line (noise removed) are "
          "flat: not a person (a door leaf, a board).");
  v.Field("flat_min_extent_m", o.flat_min_extent_m,
          "Only outlines longer than this count as evidence of flatness.");
  v.Field("association_sigma_m", o.association_sigma_m,
          "1-sigma per axis of the rough position used to associate before the fit.");
  v.Field("seen_through_margin_m", o.seen_through_margin_m,
          "A coasting track is not reported where the scan sees through it (every beam with an "
          "echo across the middle of its body returned from more than this beyond it); a person "
          "hidden behind something stays reported. 0: off.");
  v.Field("unseen_coasting_m", o.unseen_coasting_m,
          "A coasting track that has coasted farther than this (speed times time since its "
          "last measurement) is reported only where the scan shows something of it (a "
          "foreground return within its body's reach): someone who turned out of view is off "
          "the straight prediction. Torso mount. 0: off.");
  v.Field("coasting_max_sigma_m", o.coasting_max_sigma_m,
          "Torso mount: a coasting track is reported only while its position sigma is at most "
          "this (the body's half-depth: the prediction still tells where the body stands). "
          "0: off.");
  v.Field("legs_seen_through", o.legs_seen_through,
          "Knee-height mount: a coasting track is not reported where the scan sees through "
          "every place its legs may stand (every beam with an echo within half "
          "leg_pairing_distance_m plus leg_radius_m of it returned from more than "
          "seen_through_margin_m beyond it), where the beams and their footprint are narrower "
          "than a leg; a person hidden behind something stays reported.");
  v.Field("legs_coasting_max_sigma_m", o.legs_coasting_max_sigma_m,
          "Knee-height mount: a coasting track is reported only while its position sigma is at "
          "most this (a leg's diameter: the prediction still tells where a leg stands). "
          "0: off.");
  v.Field("legs_report_coasting_s", o.legs_report_coasting_s,
          "Knee-height mount: a coasting track is sent for at most this long after its last "
          "measurement (tracking.report_coasting_s where that is shorter): a track predicted "
          "from legs leaves someone who turns or stops unseen sooner. 0: off.");
  v.Field("point_sigma_m", o.fit.point_sigma_m, "Range noise of a point at 0 m (1 sigma).");
  v.Field("point_sigma_per_m", o.fit.point_sigma_per_m,
          "Growth of the range noise per metre (LMS1xx, TiM: none; LMS5xx: ~0.0003-0.0004).");
  v.Field("model_sigma_m", o.fit.model_sigma_m,
          "How far a real outline departs from the model shape, per point (1 sigma).");
  v.Field("effective_points", o.fit.effective_points,
          "Points beyond this many count as correlated (model errors of neighbours are alike).");
  VisitInteger(v, "max_points", o.fit.max_points,
               "At most this many points of a segment go into the fit (evenly spaced).");
  VisitInteger(v, "max_iterations", o.fit.max_iterations, "Gauss-Newton iterations per fit.");
  v.Field("single_precision_points", o.fit.single_precision_points,
          "A person's outline fit takes its points in single precision, four at a time (a "
          "distance rounded to about 1e-8 m, far below the range noise). false: double, two at "
          "a time.");
  v.Field("edges_face_points", o.fit.edges_face_points,
          "Each silhouette edge of a fit faces away from the segment's points. false: away from "
          "the fit's start (the track's prediction), which may lie beyond the edge.");
  VisitEnum(v, "outside_guess_start", o.fit.outside_guess_start, kOutsideGuessStartNames,
            "Where a fit starts when the track's prediction lies outside the silhouette: guess "
            "(there), silhouette (behind the points, as without a prediction) "
            "or better (from both, the lower cost of points, silhouette and size prior).");
  VisitInteger(v, "outside_guess_max_points", o.fit.outside_guess_max_points,
               "outside_guess_start applies to fits of at most this many points.");
}

constexpr std::array<std::string_view, 2> kAssociationNames = {"global_nearest_neighbour",
                                                               "closest"};

void VisitTracking(tracking::TrackerOptions& p, ConfigVisitor& v) {
  tracking::MultiTrackerOptions& o = p.tracking;
  v.Section("tracking",
            "Constant-velocity Kalman filter per track, Mahalanobis gating, association, "
            "lifecycle tentative -> confirmed (M of N) -> coasting -> deleted.");
  v.Field("accel_psd_m2ps3", o.ekf.accel_psd_m2ps3,
          "Process noise: white acceleration spectral density per axis, m^2/s^3 (walking people: "
          "0.5; forklifts and runners more).");
  v.Field("initial_velocity_sigma_mps", o.ekf.initial_velocity_sigma_mps,
          "Velocity prior of a new track, 1 sigma.");
  VisitEnum(v, "association", o.association, kAssociationNames,
            "global_nearest_neighbour: optimal assignment on the gated costs; closest: greedy by "
            "Euclidean distance (the paper's rule).");
  v.Field("gate_mahalanobis_sq", o.gate_mahalanobis_sq,
          "Gate, squared Mahalanobis distance (9.21: chi-square, 2 dof, 99 %).");
  v.Field("max_gate_distance_m", o.max_gate_distance_m, "Euclidean bound on top of the gate.");
  v.Field("recover_gate_mahalanobis_sq", o.recover_gate_mahalanobis_sq,
          "A confirmed track left without a measurement takes the nearest one nobody took within "
          "this wider gate (18.42: 2 dof, 99.99 %) before it can start a second track on the same "
          "person; 0: off.");
  v.Field("inflate_nis_above", o.inflate_nis_above,
          "A measurement whose squared Mahalanobis distance exceeds this scales the track's "
          "covariance by d2 / 2 before the update, so a track follows a start, stop or turn "
          "instead of lagging behind; 0: off, else >= 2.");
  v.Field("report_gain_covariance", o.report_gain_covariance,
          "The covariance sent with a measured track: the one the filter's gains leave with "
          "the measurement noise across the ray measured from the track's innovations (at "
          "upper-body height, where nothing beside the body, no outline departure beyond "
          "the filter's allowance and no partial view make the errors shared) instead of "
          "the filter's own; the tracks are the same. false: the filter's own covariance.");
  v.Field("measured_noise_memory_scans", o.measured_noise_memory_scans,
          "Updates over which report_gain_covariance measures the noise across the ray from "
          "the innovations (covariance matching); 0: the filter's noise.");
  v.Field("extra_measurement_sigma_m", o.extra_measurement_sigma_m,
          "Added in quadrature to every centre_of_mass / ellipse measurement's sigma and to the "
          "rough position of shape_fit's association (sway, viewpoint changes).");
  VisitInteger(v, "confirm_hits", o.confirm_hits, "M of the M-of-N confirmation.");
  VisitInteger(v, "confirm_window", o.confirm_window, "N of the M-of-N confirmation (<= 32).");
  v.Field("confirm_min_s", o.confirm_min_s,
          "... and a track is confirmed only once its first and latest measurements lie this far "
          "apart, M of N holding meanwhile: bursts of leg-sized clutter (mixed pixels behind a "
          "person) reach M of N within a few scans at 50 Hz, walking legs stay in view. A time, "
          "the same at every scan rate. 0: M of N alone. Knee height only (shape.mount: legs).");
  v.Field("coast_timeout_s", o.coast_timeout_s,
          "A confirmed track without measurements is deleted after this (occlusions shorter "
          "than this keep their id).");
  v.Field("max_position_sigma_m", o.max_position_sigma_m,
          "A track whose position sigma grows beyond this is deleted.");
  VisitInteger(v, "max_tracks", o.max_tracks, "Simultaneous tracks (at most 64).");
  v.Field("resume_window_s", o.resume_window_s,
          "A track deleted after coast_timeout_s is kept this much longer, unreported, and "
          "resumed with its id by a measurement within its gate: someone hidden for a moment "
          "comes back as themselves (confirmed again as a new track is). 0: off. Not at knee "
          "height (shape.mount: legs).");
  v.Field("adopt_successor_m", o.adopt_successor_m,
          "A confirmed track coasting since its last measurement takes over a track born after "
          "it within this distance of its prediction (once that one was measured in "
          "adopt_after_hits scans): someone the prediction lost and a new track found again keeps "
          "one track and their id instead of a new one beside a coasting one. 0: off. Knee "
          "height only (shape.mount: legs).");
  VisitInteger(v, "adopt_after_hits", o.adopt_after_hits,
               "Measured scans of the younger track before adopt_successor_m takes it over.");
  v.Field("max_time_gap_s", o.max_time_gap_s,
          "A jump between consecutive scans beyond this (either way) deletes all tracks.");
  v.Field("report_tentative", o.report_tentative, "Also send tentative (unconfirmed) tracks.");
  v.Field("report_coasting_s", o.report_coasting_s,
          "A coasting track is sent for this long after its last measurement (and kept until "
          "coast_timeout_s, to be found again): someone hidden longer may have stopped or "
          "turned.");
  v.Field("report_coasting_per_measured_s", o.report_coasting_per_measured_s,
          "... and for no longer than this times how long the track was seen (measured in "
          "consecutive scans): a track with little evidence (sporadic clutter confirmed within "
          "a few scans) is sent coasting only briefly. 0: off.");
  v.Field("seen_gap_s", o.seen_gap_s,
          "Seen, for report_coasting_per_measured_s: the time between two of a track's "
          "measurements at most this far apart (someone far away is measured in some scans "
          "only; clutter comes in bursts).");
  v.Field("max_speed_mps", o.max_speed_mps,
          "Motion limit: a track's speed is clamped to this. 2.5 covers walking people; a site "
          "with forklifts raises it (to ~6), with accel_psd_m2ps3 (~2), "
          "initial_velocity_sigma_mps and max_gate_distance_m.");
  v.Field("static_objects", o.static_objects,
          "Static objects become background: a track that never moved (after "
          "never_moved_to_background_s), or one that moved but is not person-like (flat like a "
          "door leaf, thin legs like a chair's) and stands still (after "
          "static_object_to_background_s). Tracks are reported once they moved. A person who "
          "stops stays a track. Off: every confirmed track is reported until the background "
          "absorbs it (background.absorb_after_s).");
  v.Field("still_radius_m", o.still_radius_m,
          "A track moves when it leaves a circle of this radius around where it last stood.");
  v.Field("moving_speed_mps", o.moving_speed_mps,
          "A confirmed track also counts as moved when its speed exceeds this and three sigma "
          "of it: someone walking in is reported from their confirmation. 0: off.");
  v.Field("never_moved_to_background_s", o.never_moved_to_background_s,
          "A track that never moved becomes background after this.");
  v.Field("static_object_to_background_s", o.static_object_to_background_s,
          "A not person-like track standing still becomes background after this.");
  v.Field("inherit_moved_s", o.inherit_moved_s,
          "A track that has not moved, first measured after the last measurement of a moved "
          "track that was then lost (coast timeout) and at most this long after it, within that "
          "one's gate, counts as moved: someone standing whose track ended (an occlusion, a "
          "drift) and restarted on them stays reported instead of waiting to move and becoming "
          "background. 0: off.");
  v.Field("correct_beam_time", p.correct_beam_time,
          "Stamp each measurement with its middle beam's time within the scan instead of the "
          "scan start.");
}

void VisitPublish(PublishOptions& o, ConfigVisitor& v) {
  v.Section("publish",
            "What goes over UDP (and into --out): track frames, background snapshots, health, "
            "sensor info. No datagram exceeds 1400 bytes; frames and snapshots are split.");
  VisitInteger(v, "frame_every_n_scans", o.frame_every_n_scans,
               "Track frames of every n-th scan (1: every scan).");
  v.Field("health_period_s", o.health_period_s, "Health datagram period.");
  v.Field("snapshot_period_s", o.snapshot_period_s,
          "A background snapshot at least this often (also at start and on request).");
  v.Field("snapshot_min_interval_s", o.snapshot_min_interval_s,
          "At most this often when the background changes.");
  v.Field("snapshot_change_fraction", o.snapshot_change_fraction,
          "A new snapshot when this fraction of beams changed by more than the background margin "
          "since the last one.");
}

}  // namespace

std::optional<std::string> Validate(const PublishOptions& o) {
  if (o.frame_every_n_scans < 1) return "frame_every_n_scans must be >= 1";
  if (!(o.health_period_s >= 0.1 && o.health_period_s <= 3600.0))
    return "health_period_s must be in [0.1, 3600]";
  if (!(o.snapshot_period_s >= 1.0 && o.snapshot_period_s <= 86400.0))
    return "snapshot_period_s must be in [1, 86400]";
  if (!(o.snapshot_min_interval_s >= 0.0 && o.snapshot_min_interval_s <= o.snapshot_period_s))
    return "snapshot_min_interval_s must be in [0, snapshot_period_s]";
  if (!(o.snapshot_change_fraction > 0.0 && o.snapshot_change_fraction <= 1.0))
    return "snapshot_change_fraction must be in (0, 1]";
  return std::nullopt;
}

void VisitTrackerConfig(TrackerConfig& c, ConfigVisitor& v) {
  VisitSensor(c, v);
  VisitAuth(c, v);
  VisitLink(c.link, v);
  VisitClock(c.clock, c.clock_status.max_esterror_s, v);
  VisitBackground(c.tracking.background, v);
  VisitSegmentation(c.tracking.segmentation, v);
  VisitMeasurement(c.tracking, v);
  VisitShape(c.tracking.shape, v);
  VisitTracking(c.tracking, v);
  VisitPublish(c.publish, v);
}

std::optional<std::string> Validate(const TrackerConfig& c) {
  if (!c.sensor_id.empty() && !io::IsValidSensorId(c.sensor_id))
    return "sensor.id: '" + common::OneLine(c.sensor_id, 40) + "' is not 1 to 32 letters, digits, '_', '.' or '-'";
  if (c.encrypt && c.key_file.empty()) return "auth.encrypt: needs auth.key (--key)";
  // The link's host is checked where it is set (the live mode); validate the rest with a
  // placeholder so a config without an address passes.
  io::SickClientOptions link = c.link;
  if (link.host.empty()) link.host = "localhost";
  if (auto e = Prefixed("link", io::Validate(link))) return e;
  if (auto e = tracking::Validate(c.clock)) return e;  // already says "clock: ..."
  if (auto e = tracking::Validate(c.tracking)) return e;
  if (auto e = Validate(c.publish)) return "publish." + *e;
  if (auto e = io::Validate(c.clock_status)) return "clock.max_error_s: " + *e;
  return std::nullopt;
}

std::optional<std::string> LoadTrackerConfig(std::string_view yaml_text, TrackerConfig& config) {
  if (auto e = LoadYamlConfig(yaml_text, [&](ConfigVisitor& v) { VisitTrackerConfig(config, v); }))
    return e;
  // Validate quotes values of the file (the sensor id): one line whatever they hold.
  if (auto e = Validate(config)) return common::OneLine(*e, 1000);
  return std::nullopt;
}

std::string PrintTrackerConfig(const TrackerConfig& config) {
  TrackerConfig copy = config;
  return PrintYamlConfig(
      [&](ConfigVisitor& v) { VisitTrackerConfig(copy, v); },
      "lrfnet-tracker configuration (YAML). Every option with its default; lrfnet-tracker\n"
      "--print-config prints this file, --config FILE reads one. Keys left out keep their\n"
      "defaults; unknown keys are errors. Units are in the names (_s, _m, _ms, _ppm).");
}

}  // namespace lrfnet::tracker
