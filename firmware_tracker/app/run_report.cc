#include "firmware_tracker/app/run_report.h"

#include <spdlog/fmt/fmt.h>
#include <spdlog/spdlog.h>

#include <cstdio>
#include <ctime>

namespace lrfnet::tracker {

std::string FormatUtc(common::UtcNs t_ns) {
  const std::time_t seconds =
      static_cast<std::time_t>(t_ns / common::kNsPerS) - (t_ns % common::kNsPerS < 0 ? 1 : 0);
  const auto micros =
      static_cast<long>(((t_ns % common::kNsPerS) + common::kNsPerS) % common::kNsPerS / 1000);
  std::tm tm{};
  gmtime_r(&seconds, &tm);
  return fmt::format("{:04}-{:02}-{:02}T{:02}:{:02}:{:02}.{:06}Z", tm.tm_year + 1900, tm.tm_mon + 1,
                     tm.tm_mday, tm.tm_hour, tm.tm_min, tm.tm_sec, micros);
}

std::string DecoderSummary(const cola::StreamCounters& c) {
  return fmt::format(
      "frames={} bad_checksums={} oversize_lengths={} garbage_bytes={} other_telegrams={} "
      "bad_headers={} scan_decode_errors={}",
      c.framer.frames, c.framer.bad_checksum, c.framer.oversize_length, c.framer.garbage_bytes,
      c.other_telegrams, c.bad_headers, c.scan_decode_errors);
}

std::string PipelineSummary(const tracking::PipelineCounters& c) {
  return fmt::format(
      "rejected_scans={} learning_scans={} segments={} dropped_segments={} "
      "ellipse_measurements={} com_measurements={} shape_fits={} failed_shape_fits={} "
      "leg_pairs={} single_legs={} legs_behind={} veiled_segments={} shadowed_legs={} "
      "absorbed_objects={} seen_through={} unseen_coasting={} single_beam_legs={} "
      "legs_across_walk={} split_few_point_legs={} legs_seen_through={} deep_pieces_kept={} "
      "outline_departure_widened={} legs_side_uncertain={} legs_side_from_view={} "
      "legs_side_view_contested={} deep_leg_pairs={} recently_veiled={} "
      "leg_edges_in_mixed_beam={} stance_weighted_pairs={} touching_leg_pairs={} "
      "box_occluded_fits={} box_sizes_unseen={} legs_along_from_standing={} "
      "single_beam_partners={} edge_echo_births={} person_sizes_across_ray={} "
      "partial_view_widened={} underdetermined_fit_widened={} box_pieces_rejoined={} "
      "legs_coasting_uncertain={} coasting_uncertain={} box_unseen_widened={} "
      "neighbour_widened={} lone_beam_edge_echoes={} far_leg_births={} see_through_splits={} "
      "torso_edge_echoes={} step_seam_splits={} mixed_pixel_legs={} segment_excess_widened={} "
      "box_view_widened={} still_leg_pairs={} occluded_gap_widened={} deep_tail_cuts={}",
      c.rejected_scans, c.learning_scans, c.segments, c.dropped_segments, c.ellipse_measurements,
      c.com_measurements, c.shape_fits, c.failed_shape_fits, c.leg_pairs, c.single_legs,
      c.legs_behind, c.veiled_segments, c.shadowed_legs, c.absorbed_objects, c.seen_through,
      c.unseen_coasting, c.single_beam_legs, c.legs_across_walk, c.split_few_point_legs,
      c.legs_seen_through, c.deep_pieces_kept, c.outline_departure_widened, c.legs_side_uncertain,
      c.legs_side_from_view, c.legs_side_view_contested, c.deep_leg_pairs, c.recently_veiled,
      c.leg_edges_in_mixed_beam, c.stance_weighted_pairs, c.touching_leg_pairs, c.box_occluded_fits,
      c.box_sizes_unseen, c.legs_along_from_standing, c.single_beam_partners, c.edge_echo_births,
      c.person_sizes_across_ray, c.partial_view_widened, c.underdetermined_fit_widened,
      c.box_pieces_rejoined, c.legs_coasting_uncertain, c.coasting_uncertain, c.box_unseen_widened,
      c.neighbour_widened, c.lone_beam_edge_echoes, c.far_leg_births, c.see_through_splits,
      c.torso_edge_echoes, c.step_seam_splits, c.mixed_pixel_legs, c.segment_excess_widened,
      c.box_view_widened, c.still_leg_pairs, c.occluded_gap_widened, c.deep_tail_cuts);
}

std::string MultiTrackerSummary(const tracking::MultiTrackerCounters& c) {
  return fmt::format(
      "measurements={} associations={} deleted_tentative={} deleted_coast_timeout={} "
      "deleted_covariance={} deleted_time_reset={} deleted_static={} dropped_capacity={} "
      "births_suppressed={} rejected_measurements={} measurements_over_capacity={} "
      "failed_updates={} time_steps_backwards={} time_resets={} refine_failures={} "
      "speed_clamps={} recovered={} resumed={} coasting_unreported={} adopted={}",
      c.measurements, c.associations, c.deleted_tentative, c.deleted_coast_timeout,
      c.deleted_covariance, c.deleted_time_reset, c.deleted_static, c.dropped_capacity,
      c.births_suppressed, c.rejected_measurements, c.measurements_over_capacity, c.failed_updates,
      c.time_steps_backwards, c.time_resets, c.refine_failures, c.speed_clamps, c.recovered,
      c.resumed, c.coasting_unreported, c.adopted);
}

std::string NodeSummary(const TrackerNode& node) {
  const tracking::MultiTrackerCounters& t = node.pipeline().tracker().counters();
  const io::DatagramEncoderCounters& e = node.encoder().counters();
  const tracking::ClockMapperStatus clock = node.clock().status();
  return fmt::format(
      "tracks_created={} tracks_confirmed={} datagrams={} datagram_bytes={} frames={} "
      "snapshots={} tick_offset_s={:.6f} drift_ppm={:.2f} device_restarts={} "
      "mount_looks_like_legs={} {} {}",
      t.created, t.confirmed, e.datagrams, e.bytes, node.counters().frames,
      node.counters().snapshots, clock.offset_s, clock.drift_ppm,
      node.clock().counters().device_restarts, node.counters().mount_looks_like_legs,
      PipelineSummary(node.pipeline().counters()), MultiTrackerSummary(t));
}

bool ScanLog::OnScan(const std::string& sensor_id, const cola::ScanTelegram& scan,
                     common::UtcNs receive_time_ns, const TrackerNode& node) {
  ++scans_;
  if (node.counters().mount_looks_like_legs > mount_warnings_) {
    mount_warnings_ = node.counters().mount_looks_like_legs;
    const common::MountCheck& m = node.mount_check();
    spdlog::warn(
        "{}: tracks look like legs ({} of {} people tracks leg-sized, median half-width {:.2f} m) "
        "but shape.mount is torso; a scanner at knee height needs shape.mount: legs",
        sensor_id, m.leg_sized, m.tracks, m.median_half_width_m);
  }
  if (print_every_ > 0 && (scans_ - 1) % print_every_ == 0) {
    const tracking::ScanTracks& tracks = node.pipeline().last_tracks();
    std::string list;
    for (const tracking::TrackReport& t : tracks.tracks) {
      list +=
          fmt::format("{}{}@({:.2f},{:.2f})", list.empty() ? "" : " ", t.track_id, t.x_m, t.y_m);
    }
    const cola::ScanChannel* dist = scan.FindChannel("DIST1");
    fmt::print("{} tc={} sc={} points={} rx={} scan_start={} tracks={} [{}]\n", sensor_id,
               scan.telegram_counter, scan.scan_counter, dist != nullptr ? dist->count : 0,
               FormatUtc(receive_time_ns), FormatUtc(tracks.scan_start_ns), tracks.tracks.size(),
               list);
    std::fflush(stdout);
  }
  return max_scans_ == 0 || scans_ < max_scans_;
}

}  // namespace lrfnet::tracker
