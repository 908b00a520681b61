#pragma once
// The JSON messages lrfnetd publishes over MQTT (pure). Their schemas are
// central_daemon/schemas/*.schema.json, documented with examples in
// central_daemon/schemas/README.md. Every message is one JSON object with "type" and "site";
// positions in metres (millimetre precision) in the world frame of the calibration (the reference
// sensor at the origin), times as gateway UTC nanoseconds. Always valid JSON: non-finite numbers
// are written as null, invalid UTF-8 is replaced.

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "central_daemon/calibration/types.h"
#include "central_daemon/fusion/fusion.h"
#include "central_daemon/zones/zones.h"
#include "common/time.h"

namespace lrfnet::daemon {

// One fused object with what the object list adds to the fused track.
struct MqttObject {
  fusion::FusedTrack track;
  std::optional<double> length_m, width_m;  // full extent; absent when no sensor measured it
  struct PathPoint {
    double x_m = 0.0, y_m = 0.0;
    double t_s = 0.0;  // relative to the message's stamp, <= 0
  };
  std::vector<PathPoint> path;  // oldest first
};

// lrfnet/<site>/objects:
// {"type":"objects","site":..,"seq":..,"stamp_ns":..,"frame":"world","objects":[{"id":..,
//  "state":..,"x_m":..,"y_m":..,"vx_mps":..,"vy_mps":..,"covariance":[16, row-major (x, y, vx,
//  vy)], "size":{"length_m":..,"width_m":..}|null,"age_s":..,"sensors":[..],"path":[[x_m, y_m,
//  t_s]]}]}
std::string ObjectsJson(const std::string& site, std::uint64_t seq, common::UtcNs stamp_ns,
                        const std::vector<MqttObject>& objects);

// An object that left the object list for good (the fusion ended its id).
struct MqttEndedObject {
  std::uint64_t id = 0;
  std::string reason;             // "merged", or fusion::IdEndReason: "timed_out", ...
  std::uint64_t merged_into = 0;  // "merged": the id the object goes on as, else 0
  common::UtcNs ended_ns = 0;     // when the fusion ended it
};

// lrfnet/<site>/objects/ended (not retained), when objects of the list end:
// {"type":"objects_ended","site":..,"seq":..,"stamp_ns":..,"ended":[{"id":..,"reason":..,
//  "merged_into":..|null,"ended_ns":..}]}
std::string ObjectsEndedJson(const std::string& site, std::uint64_t seq, common::UtcNs stamp_ns,
                             const std::vector<MqttEndedObject>& ended);

// lrfnet/<site>/zones/<name>:
// {"type":"zone","site":..,"seq":..,"stamp_ns":..,"name":..,"kind":"line"|"polygon",
//  "occupancy":..,"present":[{"id":..,"dwell_s":..}],"inbound":..,"outbound":..,
//  "dwell":{"completed":..,"mean_s":..,"max_s":..},"lost_inside":..}
std::string ZoneJson(const std::string& site, std::uint64_t seq, common::UtcNs stamp_ns,
                     const zones::ZoneState& zone);

// lrfnet/<site>/calibration (retained): the poses with their standard deviations, each sensor's
// radial bias (radial_bias_m, sigma_radial_bias_m, radial_bias_estimated; null where the joint
// refinement did not place it), mount_looks_like_legs and flag.
std::string CalibrationJson(const std::string& site, common::UtcNs stamp_ns,
                            const calib::CalibrationResult& result);

// What is reported of a sensor's health. `state` is one of "waiting" (known, no tracks yet),
// "active", "silent", "moved", "settling" (see HealthReportOf); more states may be added
// (consumers should show unknown ones as they are).
struct SensorHealthReport {
  std::string sensor_id;
  std::string state;
  bool placed = false;  // has a calibrated pose
  std::string model;
  double datagram_rate_hz = 0.0;
  double loss = 0.0;  // fraction of datagrams lost, 0..1
  std::string clock_sync;
  std::uint64_t track_frames = 0;
  std::uint64_t rejected = 0;  // datagrams refused by validation
  std::uint64_t restarts = 0;  // tracker restarts seen
  common::UtcNs last_receive_ns = 0;
};
// lrfnet/<site>/sensors/<id>/health (retained).
std::string SensorHealthJson(const std::string& site, common::UtcNs stamp_ns,
                             const SensorHealthReport& health);

// lrfnet/<site>/status (retained): "online" while connected, "offline" at a clean stop and as the
// daemon's last will (then without stamp_ns).
std::string StatusJson(const std::string& site, const std::string& state,
                       const std::string& version, std::optional<common::UtcNs> stamp_ns);

}  // namespace lrfnet::daemon
