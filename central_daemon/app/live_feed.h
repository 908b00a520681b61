#pragma once
// Fills the live view's LiveState from the daemon's parts (sensors, health, backgrounds,
// calibration state, raw and fused tracks, where the people the fusion keeps unpublished were
// last seen). Keeps the counters of the previous call to give rates.
// Thread-safety: called on the io thread.

#include <map>
#include <string>

#include "central_daemon/app/calibration_service.h"
#include "central_daemon/app/daemon.h"
#include "central_daemon/app/fusion_service.h"
#include "central_daemon/app/live_state.h"
#include "central_daemon/app/zone_service.h"

namespace lrfnet::daemon {

// What the live view shows of one sensor's calibration (pose sigmas where placed, radial bias,
// mount verdict, flag).
LiveSensor::Calibration LiveCalibrationOf(const calib::SensorPose& pose);

class LiveFeed {
 public:
  explicit LiveFeed(std::size_t background_points) : background_points_(background_points) {}

  // now_ns: the daemon's clock (rates); the track times come from the fusion service.
  // zones: may be null (none).
  LiveState Build(const Daemon& daemon, const CalibrationService& calibration,
                  const FusionService& fusion, common::UtcNs now_ns, const std::string& version,
                  const ZoneService* zones = nullptr);

 private:
  struct Mark {
    std::uint64_t datagrams = 0;
    common::UtcNs at_ns = 0;
    double rate_hz = 0.0;
  };
  std::size_t background_points_;
  std::map<std::string, Mark, std::less<>> marks_;
};

}  // namespace lrfnet::daemon
