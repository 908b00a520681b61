#include "firmware_tracker/app/tracker_node.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>

#ifndef LRFNET_VERSION
#define LRFNET_VERSION "unknown"
#endif

namespace lrfnet::tracker {
namespace {

io::DatagramEncoderOptions EncoderOptions(const TrackerConfig& config, std::uint64_t session_id) {
  io::DatagramEncoderOptions options;
  options.sensor_id = config.sensor_id;
  options.session_id = session_id;
  return options;
}

}  // namespace

TrackerNode::TrackerNode(const TrackerConfig& config, std::uint64_t session_id,
                         io::DatagramSink& sink)
    : config_(config),
      sink_(sink),
      encoder_(EncoderOptions(config, session_id)),
      clock_(config.clock),
      pipeline_(std::make_unique<tracking::TrackingPipeline>(config.tracking)),
      polar_(std::make_unique<cola::PolarScan>()) {
  if (auto e = Validate(config)) {
    std::abort();  // precondition: the caller validated the config
  }
  model_.reserve(64);
  serial_.reserve(32);
  firmware_.reserve(64);
}

TrackerNode::~TrackerNode() = default;

void TrackerNode::SetDeviceIdentity(std::string_view model, std::string_view serial,
                                    std::string_view firmware) {
  if (model == model_ && serial == serial_ && firmware == firmware_) return;
  model_.assign(model.substr(0, 64));
  serial_.assign(serial.substr(0, 32));
  firmware_.assign(firmware.substr(0, 64));
  identity_changed_ = true;
  // ShapeOptions::mixed_leg_max_gap_m: no mixed pixel of echoes this scanner reports apart.
  pipeline_->SetResolvedEchoSeparation(tracking::ResolvedEchoSeparationM(model));
}

void TrackerNode::OnScan(const cola::ScanTelegram& scan, common::UtcNs receive_ns,
                         common::UtcNs sent_ns) {
  ++counters_.scans;
  cola::PolarScan& polar = *polar_;
  if (!cola::ToPolarScan(scan, &polar) || polar.count == 0) {
    ++counters_.unusable_scans;
    return;
  }
  const tracking::ClockMapResult mapped =
      clock_.Map(polar.time_since_startup_us, polar.time_of_transmission_us, receive_ns);
  if (!mapped.valid) {
    ++counters_.unusable_scans;
    return;
  }

  tracking::ScanView view;
  view.first_angle_rad = polar.first_angle_rad;
  view.angle_step_rad = polar.angle_step_rad;
  view.range_m = std::span<const float>(polar.range_m.data(), polar.count);
  view.stamp_ns = mapped.scan_start_ns;
  view.scan_period_s = polar.scan_frequency_hz > 0.0 ? 1.0 / polar.scan_frequency_hz : 0.0;
  const tracking::ScanTracks& tracks = pipeline_->Process(view, polar.scan_counter);
  if (config_.tracking.method == tracking::MeasurementMethod::kShapeFit &&
      config_.tracking.shape.mount == tracking::Mount::kTorso) {
    for (const tracking::TrackReport& t : tracks.tracks) {
      if (t.state != tracking::TrackState::kConfirmed || t.shape == tracking::ObjectShape::kBox ||
          t.shape == tracking::ObjectShape::kLegs) {
        continue;
      }
      // The speed is compared with a threshold only: the root of the sum of squares (within an ulp
      // of hypot, a libm call).
      mount_watch_.Add(t.track_id, std::sqrt(t.vx_mps * t.vx_mps + t.vy_mps * t.vy_mps),
                       std::min(t.size_major_m, t.size_minor_m));
    }
    if (mount_watch_.EndScan()) ++counters_.mount_looks_like_legs;
  }

  // The scan's datagrams (sensor info, track frame, background snapshot) leave together where the
  // sink can send them in one call (DatagramSink::BeginBatch, EndBatch).
  sink_.BeginBatch();
  // Sensor info before the first frame of a new geometry, so a receiver can interpret it.
  if (polar.count != info_count_ || polar.first_angle_rad != info_first_angle_rad_ ||
      polar.angle_step_rad != info_step_rad_ || polar.scan_frequency_hz != scan_frequency_hz_) {
    info_count_ = polar.count;
    info_first_angle_rad_ = polar.first_angle_rad;
    info_step_rad_ = polar.angle_step_rad;
    scan_frequency_hz_ = polar.scan_frequency_hz;
    identity_changed_ = true;
  }
  if (identity_changed_ || sensor_info_requested_) PublishSensorInfo(sent_ns);

  if ((counters_.scans - 1) % config_.publish.frame_every_n_scans == 0) {
    encoder_.EncodeTracks(tracks, sent_ns, sink_);
    ++counters_.frames;
  }

  const tracking::BackgroundModel& background = pipeline_->background();
  if (background.learned()) {
    const double since_s = common::NsToSeconds(sent_ns - last_snapshot_ns_);
    // A clock stepping back must not silence snapshots: a negative age counts as due.
    const bool due = !background_sent_ || background_requested_ ||
                     since_s >= config_.publish.snapshot_period_s || since_s < 0.0 ||
                     (since_s >= config_.publish.snapshot_min_interval_s && BackgroundChanged());
    if (due) PublishBackground(sent_ns);
  }
  sink_.EndBatch();
}

bool TrackerNode::BackgroundChanged() const {
  const tracking::BackgroundModel& background = pipeline_->background();
  const std::size_t beams = background.background_range_m().size();
  if (beams != sent_background_m_.size()) return true;
  if (beams == 0) return false;
  return static_cast<double>(background.CountMovedBeams(sent_background_m_.span())) >=
         config_.publish.snapshot_change_fraction * static_cast<double>(beams);
}

void TrackerNode::PublishBackground(common::UtcNs sent_ns) {
  const std::span<const float> range_m = pipeline_->background().background_range_m();
  io::BackgroundSnapshotView view;
  view.learned_until_ns = pipeline_->last_tracks().scan_start_ns;
  view.first_angle_rad = polar_->first_angle_rad;
  view.angle_step_rad = polar_->angle_step_rad;
  view.range_m = range_m;
  if (encoder_.EncodeBackground(view, sent_ns, sink_) == 0) return;
  (void)sent_background_m_.resize(range_m.size());  // range_m.size() <= kMaxBeams
  std::copy(range_m.begin(), range_m.end(), sent_background_m_.begin());
  background_sent_ = true;
  background_requested_ = false;
  last_snapshot_ns_ = sent_ns;
  ++counters_.snapshots;
}

void TrackerNode::PublishSensorInfo(common::UtcNs sent_ns) {
  io::SensorInfoReport info;
  info.model = model_;
  info.serial = serial_;
  info.firmware = firmware_;
  info.first_angle_rad = info_first_angle_rad_;
  info.angle_step_rad = info_step_rad_;
  info.beam_count = info_count_;
  info.fov_rad = info_count_ > 1 ? std::abs(info_step_rad_) * (info_count_ - 1) : 0.0;
  info.scan_frequency_hz = scan_frequency_hz_;
  info.max_range_m = config_.tracking.background.max_range_m;
  info.tracker_version = LRFNET_VERSION;
  info.kind = tracking::KindOf(config_.tracking.method);
  info.mount = config_.tracking.shape.mount;
  info.accel_psd_m2ps3 = config_.tracking.tracking.ekf.accel_psd_m2ps3;
  info.max_speed_mps = config_.tracking.tracking.max_speed_mps;
  if (!encoder_.EncodeSensorInfo(info, sent_ns, sink_)) return;
  identity_changed_ = false;
  sensor_info_requested_ = false;
  ++counters_.sensor_infos;
}

void TrackerNode::RecordScanCpu(double microseconds) {
  if (!(microseconds >= 0.0) || !std::isfinite(microseconds)) return;
  cpu_sum_us_ += microseconds;
  cpu_max_us_ = std::max(cpu_max_us_, microseconds);
  ++cpu_samples_;
}

void TrackerNode::OnTick(common::UtcNs now_ns, const LinkHealth& link,
                         const io::ClockStatus& clock) {
  const common::DurationNs period_ns = common::SecondsToNs(config_.publish.health_period_s);
  // The first tick reports at once; a clock that stepped back by more than a period restarts the
  // schedule instead of silencing health until it catches up.
  if (health_started_ && now_ns < next_health_ns_ && next_health_ns_ - now_ns <= period_ns) return;
  health_started_ = true;

  io::HealthReport health;
  health.scans = counters_.scans;
  health.bad_frames = link.bad_frames;
  health.decode_errors = link.decode_errors + counters_.unusable_scans;
  health.reconnects = link.reconnects;
  health.dropped_tracks =
      pipeline_->tracker().counters().dropped_capacity + encoder_.counters().dropped_tracks;
  health.datagrams_sent = encoder_.counters().datagrams;
  health.send_errors = link.send_errors;
  if (cpu_samples_ > 0) {
    health.scan_cpu_us_mean = static_cast<float>(cpu_sum_us_ / static_cast<double>(cpu_samples_));
    health.scan_cpu_us_max = static_cast<float>(cpu_max_us_);
  }
  health.clock_sync = clock.sync;
  health.clock_error_estimate_s = static_cast<float>(clock.esterror_s);
  const tracking::ClockMapperStatus status = clock_.status();
  health.tick_offset_s = status.offset_s;
  health.tick_drift_ppm = status.drift_ppm;
  health.device_restarts = clock_.counters().device_restarts;
  if (encoder_.EncodeHealth(health, now_ns, sink_)) ++counters_.healths;

  cpu_sum_us_ = 0.0;
  cpu_max_us_ = 0.0;
  cpu_samples_ = 0;
  next_health_ns_ += period_ns;
  if (next_health_ns_ <= now_ns) next_health_ns_ = now_ns + period_ns;
}

}  // namespace lrfnet::tracker
