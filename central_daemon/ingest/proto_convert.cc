#include "central_daemon/ingest/proto_convert.h"

#include <algorithm>

namespace lrfnet::daemon {

TrackState ToTrackState(proto::TrackState state) {
  switch (state) {
    case proto::TRACK_STATE_CONFIRMED:
      return TrackState::kConfirmed;
    case proto::TRACK_STATE_COASTING:
      return TrackState::kCoasting;
    default:  // TENTATIVE; validation refuses the others
      return TrackState::kTentative;
  }
}

MeasurementKind ToMeasurementKind(proto::MeasurementKind kind) {
  switch (kind) {
    case proto::MEASUREMENT_KIND_CENTER_OF_MASS:
      return MeasurementKind::kCenterOfMass;
    case proto::MEASUREMENT_KIND_ELLIPSE:
      return MeasurementKind::kEllipse;
    case proto::MEASUREMENT_KIND_SHAPE_FIT:
      return MeasurementKind::kShapeFit;
    default:
      return MeasurementKind::kUnspecified;
  }
}

ObjectShape ToObjectShape(proto::ObjectShape shape) {
  switch (shape) {
    case proto::OBJECT_SHAPE_TORSO:
      return ObjectShape::kTorso;
    case proto::OBJECT_SHAPE_LEGS:
      return ObjectShape::kLegs;
    case proto::OBJECT_SHAPE_CYLINDER:
      return ObjectShape::kCylinder;
    case proto::OBJECT_SHAPE_BOX:
      return ObjectShape::kBox;
    default:
      return ObjectShape::kUnspecified;
  }
}

MountHeight ToMountHeight(proto::MountHeight mount) {
  switch (mount) {
    case proto::MOUNT_HEIGHT_TORSO:
      return MountHeight::kTorso;
    case proto::MOUNT_HEIGHT_LEGS:
      return MountHeight::kLegs;
    default:
      return MountHeight::kUnspecified;
  }
}

ClockSync ToClockSync(proto::ClockSyncState sync) {
  switch (sync) {
    case proto::CLOCK_SYNC_SYNCHRONIZED:
      return ClockSync::kSynchronized;
    case proto::CLOCK_SYNC_UNSYNCHRONIZED:
      return ClockSync::kUnsynchronized;
    case proto::CLOCK_SYNC_REPLAY:
      return ClockSync::kReplay;
    default:
      return ClockSync::kUnknown;
  }
}

void ToTrackFrame(const proto::Datagram& d, common::UtcNs receive_ns, TrackFrameData* out) {
  const proto::TrackFrame& f = d.track_frame();
  out->session_id = d.session_id();
  out->scan_start_ns = f.scan_start_ns();
  out->scan_period_s = f.scan_period_s();
  out->scan_counter = f.scan_counter();
  out->part = f.part();
  out->part_count = f.part_count();
  out->sent_ns = d.sent_ns();
  out->receive_ns = receive_ns;
  out->tracks.resize(static_cast<std::size_t>(f.tracks_size()));
  for (int i = 0; i < f.tracks_size(); ++i) {
    const proto::Track& t = f.tracks(i);
    TrackObservation& o = out->tracks[static_cast<std::size_t>(i)];
    o.track_id = t.track_id();
    o.state = ToTrackState(t.state());
    o.kind = ToMeasurementKind(t.kind());
    o.x_m = t.x_m();
    o.y_m = t.y_m();
    o.vx_mps = t.vx_mps();
    o.vy_mps = t.vy_mps();
    const int n = std::min<int>(t.covariance_size(), static_cast<int>(o.covariance.size()));
    o.covariance.fill(0.0f);
    std::copy_n(t.covariance().begin(), n, o.covariance.begin());
    o.age_scans = t.age_scans();
    o.points = t.points();
    o.ellipse_yaw_rad = t.ellipse_yaw_rad();
    o.shape = ToObjectShape(t.shape());
    o.size_major_m = t.size_major_m();
    o.size_minor_m = t.size_minor_m();
    o.size_sigma_m = t.size_sigma_m();
  }
}

BackgroundPart ToBackgroundPart(const proto::Datagram& d) {
  const proto::BackgroundSnapshot& s = d.background();
  BackgroundPart p;
  p.session_id = d.session_id();
  p.snapshot_id = s.snapshot_id();
  p.learned_until_ns = s.learned_until_ns();
  p.first_angle_rad = s.first_angle_rad();
  p.angle_step_rad = s.angle_step_rad();
  p.beam_count = s.beam_count();
  p.part = s.part();
  p.part_count = s.part_count();
  p.first_beam = s.first_beam();
  p.ranges_mm = std::span<const std::uint32_t>(s.ranges_mm().data(),
                                               static_cast<std::size_t>(s.ranges_mm_size()));
  return p;
}

SensorHealth ToSensorHealth(const proto::Datagram& d, common::UtcNs receive_ns) {
  const proto::Health& h = d.health();
  SensorHealth out;
  out.scans = h.scans();
  out.bad_frames = h.bad_frames();
  out.decode_errors = h.decode_errors();
  out.reconnects = h.reconnects();
  out.dropped_tracks = h.dropped_tracks();
  out.datagrams_sent = h.datagrams_sent();
  out.send_errors = h.send_errors();
  out.scan_cpu_us_mean = h.scan_cpu_us_mean();
  out.scan_cpu_us_max = h.scan_cpu_us_max();
  out.clock_sync = ToClockSync(h.clock_sync());
  out.clock_error_estimate_s = h.clock_error_estimate_s();
  out.tick_offset_s = h.tick_offset_s();
  out.tick_drift_ppm = h.tick_drift_ppm();
  out.device_restarts = h.device_restarts();
  out.sent_ns = d.sent_ns();
  out.receive_ns = receive_ns;
  return out;
}

SensorDescription ToSensorDescription(const proto::SensorInfo& s) {
  SensorDescription out;
  out.model = s.model();
  out.serial = s.serial();
  out.firmware = s.firmware();
  out.first_angle_rad = s.first_angle_rad();
  out.angle_step_rad = s.angle_step_rad();
  out.beam_count = s.beam_count();
  out.fov_rad = s.fov_rad();
  out.scan_frequency_hz = s.scan_frequency_hz();
  out.max_range_m = s.max_range_m();
  out.tracker_version = s.tracker_version();
  out.kind = ToMeasurementKind(s.kind());
  out.mount = ToMountHeight(s.mount());
  out.accel_psd_m2ps3 = s.accel_psd_m2ps3();
  out.max_speed_mps = s.max_speed_mps();
  return out;
}

}  // namespace lrfnet::daemon
