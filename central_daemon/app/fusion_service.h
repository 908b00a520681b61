#pragma once
// lrfnetd's fusion (an adapter around fusion::Fuser): every accepted track frame goes to the fuser
// once the sensor has a calibrated pose; at fusion.publish_hz the fused tracks are sent as JSON
// datagrams over UDP (fusion.publish) and appended as JSON lines to fusion.record.
//
// Time: the fuser runs on the gateways' UTC scan times; "now" is the newest scan time received
// (so a recording replayed offline fuses exactly like the live stream).
// The trackers' motion models (SensorInfo.accel_psd_m2ps3) go to the fuser as they arrive.
// Thread-safety: every function is called on the io thread.

#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/udp.hpp>
#include <cstdio>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "central_daemon/app/config.h"
#include "central_daemon/app/daemon.h"
#include "central_daemon/calibration/types.h"
#include "central_daemon/fusion/fusion.h"

namespace lrfnet::daemon {

struct FusionServiceCounters {
  std::uint64_t publishes = 0;  // snapshots taken
  std::uint64_t datagrams_sent = 0;
  std::uint64_t send_errors = 0;
  std::uint64_t lines_recorded = 0;
  std::uint64_t record_errors = 0;
  std::uint64_t calibrations = 0;  // placements applied
  // Fuser outputs computed (Output): one per output time and fuser state, however many
  // consumers read it.
  std::uint64_t outputs_computed = 0;
};

// The placements of the calibrated sensors of a calibration result.
std::vector<fusion::SensorPlacement> PlacementsOf(const calib::CalibrationResult& result);

class FusionService final : public FrameListener {
 public:
  FusionService(boost::asio::io_context& io, const DaemonConfig& config);
  ~FusionService() override;
  FusionService(const FusionService&) = delete;
  FusionService& operator=(const FusionService&) = delete;

  // Opens the UDP socket and the record file. Returns "" or the error.
  std::string Open();
  // Applies what may change at run time (not publish / record). Changed fusion options, or
  // fusion_enabled turned off, start a new fuser (every fused id ends; its ids go on from the
  // old one's) with the current placements and tracker models; a change of
  // fusion.ended_report_s alone keeps the fuser.
  void Reconfigure(const DaemonConfig& config);
  // A new calibration: its calibrated sensors are placed (fused ids are kept).
  void SetCalibration(const calib::CalibrationResult& result);
  bool calibrated() const { return calibrated_; }
  // Sensors whose frames are not fused (the monitoring found them moved): from now on their frames
  // do not reach the fuser and their bindings are dropped at once (they lose their placement).
  // Replaces the previous set; a sensor left out of it is placed again.
  void SetExcluded(const std::set<std::string>& sensor_ids);
  const std::set<std::string>& excluded() const { return excluded_; }

  void OnFrame(const std::string& sensor_id, const TrackFrameData& frame) override;
  void OnSensorInfo(const std::string& sensor_id, const SensorDescription& info) override;
  // Publishes when due (monotonic now_s).
  void OnTick(double now_s);
  // Flushes the record file.
  void Close();

  // The newest scan time received (gateway UTC), 0 before the first frame.
  common::UtcNs now_ns() const { return now_ns_; }
  const fusion::Fuser& fuser() const { return fuser_; }
  // The fuser's Output at now_ns() (fusion::Fuser::Output: the published tracks, the hidden
  // and the ended ids), computed once and handed to every consumer (the publish, the zones,
  // MQTT, the live view) until the fuser's input changes: a frame, a Tick, placements, tracker
  // models or options (another fuser: the generation). The reference is valid until then.
  // Output is for the consumers that follow ids (the zones, MQTT objects): it marks the ends it
  // lists as read (their ended_report_s runs from then). PeekOutput is for the ones that only
  // look (the publish, the live view, the status line): it marks nothing, so a look cannot take
  // an end away before the followers read it (the same cached output serves both).
  const fusion::FusionOutput& Output() const;
  const fusion::FusionOutput& PeekOutput() const;
  // +1 each time a new fuser starts (Reconfigure with changed options, or fusion_enabled turned
  // off): the ids known from the previous one are no longer its ids, every one of them ended.
  std::uint64_t generation() const { return generation_; }
  const FusionServiceCounters& counters() const { return counters_; }
  // The service's and the fuser's counters and what the fuser has learnt of each sensor (the
  // centre offset per measurement kind and the placement error, with their sigmas): the
  // "fusion" object of --stats-out.
  nlohmann::json StatsJson() const;

 private:
  void Publish();
  // Replaces the fuser by a new one with config_.fusion (the placements and tracker models kept).
  void Restart();
  // The fuser's input changed: the next Output is computed afresh.
  void Invalidate() { output_.reset(); }

  boost::asio::io_context& io_;
  DaemonConfig config_;
  fusion::Fuser fuser_;
  std::uint64_t generation_ = 0;
  std::vector<fusion::SensorPlacement> placements_;  // of the latest calibration, excluded ones too
  std::map<std::string, double> tracker_accel_psd_;  // per sensor, from its SensorInfo
  bool calibrated_ = false;
  std::set<std::string> excluded_;
  common::UtcNs now_ns_ = 0;
  std::optional<double> last_publish_s_;
  std::optional<boost::asio::ip::udp::socket> socket_;
  boost::asio::ip::udp::endpoint destination_;
  std::FILE* record_ = nullptr;
  // The cached output, computed afresh when its input changed; mark: its ends are marked read.
  const fusion::FusionOutput& CachedOrFresh(bool mark) const;
  // Output's cache: the output, what it was computed for (now_ns_, generation_) and whether its
  // ends were marked read.
  struct CachedOutput {
    common::UtcNs now_ns = 0;
    std::uint64_t generation = 0;
    fusion::FusionOutput output;
    bool ends_marked = false;
  };
  mutable std::optional<CachedOutput> output_;
  mutable FusionServiceCounters counters_;  // outputs_computed counts in Output
};

}  // namespace lrfnet::daemon
