#pragma once
// The tracker's per-scan core, shared by the live and the replay mode, the benchmark and the
// allocation test: scan telegram -> gateway time of the scan (ClockMapper) -> tracking pipeline ->
// datagrams (track frames, background snapshots, health, sensor info) into a DatagramSink.
//
// Publishing rules:
// - a track frame for every frame_every_n_scans-th mapped scan (also while the background is being
//   learned: empty frames tell the daemon the sensor is alive and which scans exist);
// - a background snapshot as soon as the model is learned, then whenever
//   snapshot_change_fraction of the beams moved by more than the model's margin (at most every
//   snapshot_min_interval_s), at least every snapshot_period_s, and on request;
// - sensor info with the first scan, when the device identity or the scan geometry changes, and on
//   request;
// - health every health_period_s (OnTick), with the per-scan processing time the caller measured.
//
// Time: every time is an argument (gateway UTC; in replay the capture's packet times). The node
// reads no clock and opens no socket. Nothing is allocated per scan: every buffer is sized at
// construction (the object is large: heap-allocate it once). Not thread-safe.

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>

#include "common/fixed_capacity.h"
#include "common/mount_check.h"
#include "common/time.h"
#include "firmware_tracker/app/config.h"
#include "firmware_tracker/cola/scan_telegram.h"
#include "firmware_tracker/io/datagram_encoder.h"
#include "firmware_tracker/io/system_clock.h"
#include "firmware_tracker/tracking/clock_mapper.h"
#include "firmware_tracker/tracking/pipeline.h"

namespace lrfnet::tracker {

// Counters of the link and the sinks that the node reports in Health but does not own.
struct LinkHealth {
  std::uint64_t bad_frames = 0;     // rejected CoLa-B frames
  std::uint64_t decode_errors = 0;  // undecodable telegrams
  std::uint64_t reconnects = 0;
  std::uint64_t send_errors = 0;    // UDP send and recording write failures
};

struct NodeCounters {
  std::uint64_t scans = 0;             // OnScan calls
  std::uint64_t unusable_scans = 0;    // no DIST1 channel or no usable time yet
  std::uint64_t frames = 0;            // track frames published
  std::uint64_t snapshots = 0;         // background snapshots published
  std::uint64_t sensor_infos = 0;
  std::uint64_t healths = 0;
  // Times the mount check (common/mount_check.h; shape.mount torso, shape-fit measurement) found
  // the tracks looking like legs: a knee-height scanner configured as upper body.
  std::uint64_t mount_looks_like_legs = 0;
};

class TrackerNode {
 public:
  // `config` must pass Validate and name a sensor id. `sink` must outlive the node.
  TrackerNode(const TrackerConfig& config, std::uint64_t session_id, io::DatagramSink& sink);
  ~TrackerNode();

  // The device's DeviceIdent name, serial number and firmware (live: from the start-up dialogue;
  // replay: from replies in the capture, else empty). Sensor info is re-sent when they change.
  void SetDeviceIdentity(std::string_view model, std::string_view serial,
                         std::string_view firmware);

  // One LMDscandata telegram received at receive_ns; sent_ns stamps the datagrams (live: the
  // gateway clock now; replay: receive_ns). The scan's datagrams go to the sink between one
  // BeginBatch() and EndBatch().
  void OnScan(const cola::ScanTelegram& scan, common::UtcNs receive_ns, common::UtcNs sent_ns);

  // Periodic work at gateway time now_ns (call after every scan and from a timer while no scans
  // arrive): health when due. `clock` is the kernel clock state (replay: ClockSync::kReplay).
  void OnTick(common::UtcNs now_ns, const LinkHealth& link, const io::ClockStatus& clock);

  // The processing time of the last OnScan, measured by the caller (mean and max over a health
  // period go into Health).
  void RecordScanCpu(double microseconds);

  // From the daemon (Request datagram): served with the next scan.
  void RequestSensorInfo() { sensor_info_requested_ = true; }
  void RequestBackground() { background_requested_ = true; }

  const tracking::TrackingPipeline& pipeline() const { return *pipeline_; }
  const tracking::ClockMapper& clock() const { return clock_; }
  const io::DatagramEncoder& encoder() const { return encoder_; }
  const NodeCounters& counters() const { return counters_; }
  // The mount check's latest verdict (undecided with shape.mount legs or another measurement).
  const common::MountCheck& mount_check() const { return mount_watch_.verdict(); }

 private:
  bool BackgroundChanged() const;
  void PublishBackground(common::UtcNs sent_ns);
  void PublishSensorInfo(common::UtcNs sent_ns);

  TrackerConfig config_;
  io::DatagramSink& sink_;
  io::DatagramEncoder encoder_;
  tracking::ClockMapper clock_;
  std::unique_ptr<tracking::TrackingPipeline> pipeline_;
  std::unique_ptr<cola::PolarScan> polar_;
  NodeCounters counters_;
  common::MountWatch<tracking::kMaxTracks, 32> mount_watch_;

  // Device identity and the geometry sensor info was last sent for.
  std::string model_;
  std::string serial_;
  std::string firmware_;
  bool identity_changed_ = true;
  std::uint16_t info_count_ = 0;
  double info_first_angle_rad_ = 0.0;
  double info_step_rad_ = 0.0;
  double scan_frequency_hz_ = 0.0;
  bool sensor_info_requested_ = false;

  // Background as last published.
  common::FixedVector<float, tracking::kMaxBeams> sent_background_m_;
  bool background_sent_ = false;
  bool background_requested_ = false;
  common::UtcNs last_snapshot_ns_ = 0;

  // Health period.
  bool health_started_ = false;
  common::UtcNs next_health_ns_ = 0;
  double cpu_sum_us_ = 0.0;
  double cpu_max_us_ = 0.0;
  std::uint64_t cpu_samples_ = 0;
};

}  // namespace lrfnet::tracker
