#pragma once
// What the live view shows, as plain values (pure): the daemon fills a LiveState on its io thread
// a few times a second, LiveStateJson turns it into the one JSON message the web page draws (sent
// over the WebSocket and served at GET /state).
//
// Frames: a sensor with `placed` has a world pose (after calibration); its background points and
// raw tracks are then in the world frame. Before calibration nothing is placed and everything of a
// sensor is in that sensor's own frame (the page lays the sensors out side by side).

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "common/geometry.h"
#include "common/time.h"

namespace lrfnet::daemon {

struct LiveSensor {
  std::string id;
  std::string model;
  bool placed = false;
  common::Pose2 world_from_sensor;  // valid when placed
  double first_angle_rad = 0.0;     // field of view in the sensor frame (x forward)
  double fov_rad = 0.0;
  double max_range_m = 0.0;
  std::string status;  // "active", "silent", "waiting" (no data yet)
  double datagram_rate_hz = 0.0;
  double loss = 0.0;       // fraction of datagrams lost, 0..1
  std::string clock_sync;  // "synchronized", "unsynchronized", "replay", "unknown"
  std::uint64_t track_frames = 0;
  std::vector<std::array<float, 2>> background_xy;  // static points (frame: see above)
  // The same background as a scan in the sensor frame (every k-th beam, k as for background_xy):
  // for Foxglove's LaserScan. Not in LiveStateJson.
  double background_first_angle_rad = 0.0;
  double background_angle_step_rad = 0.0;
  std::vector<float> background_ranges_m;  // 0: no static return
  // Monitoring once calibrated: "ok", "moved" (flagged, not fused until its pose is estimated
  // again), "settling" (corrected, fused again once its tracker has re-learned its background);
  // empty when not watched. `monitor_detail`: what was last found, one line.
  std::string monitor_state;
  std::string monitor_detail;
  // What the calibration in use says of this sensor (`calibrated` false: the daemon has none that
  // names it): the pose's standard deviations (placed only), its shared radial bias (the joint
  // refinement's, where it placed the sensor: metres towards the sensor along its line of sight,
  // its sigma, estimated or held at its prior), the mount check's verdict and the flag text.
  struct Calibration {
    bool calibrated = false;
    double sigma_x_m = 0.0, sigma_y_m = 0.0, sigma_yaw_rad = 0.0;
    bool has_radial_bias = false;
    double radial_bias_m = 0.0, sigma_radial_bias_m = 0.0;
    bool radial_bias_estimated = false;
    bool mount_looks_like_legs = false;
    std::string flag;
  };
  Calibration calibration;
};

struct LiveTrack {
  std::string sensor_id;
  std::uint32_t track_id = 0;
  std::string state;                                        // "tentative", "confirmed", "coasting"
  double x_m = 0.0, y_m = 0.0, vx_mps = 0.0, vy_mps = 0.0;  // frame: see above
  std::optional<std::uint64_t> fused_id;
};

struct LiveFusedTrack {
  std::uint64_t id = 0;
  std::string state;
  double x_m = 0.0, y_m = 0.0, vx_mps = 0.0, vy_mps = 0.0;  // world frame
  double cov_xx = 0.0, cov_xy = 0.0, cov_yy = 0.0;          // m^2
  std::vector<std::string> sensors;
};

// A person the fusion keeps without publishing them (fusion::HiddenFusedTrack): where and by which
// sensor they were last measured, and how long ago (the fused tracks' time).
struct LiveHiddenTrack {
  std::uint64_t id = 0;
  double x_m = 0.0, y_m = 0.0;  // world frame
  double age_s = 0.0;
  std::string sensor;  // "" when not known
};

struct LiveCalibration {
  std::string state;      // "collecting", "calibrating", "calibrated", "failed"
  double progress = 0.0;  // 0..1 towards the first calibration
  std::string message;    // e.g. what data is still missing, or the residual
  std::string reference;  // reference sensor once calibrated
  double track_residual_rms_m = 0.0;
};

// A zone (world frame) with its counts.
struct LiveZone {
  std::string name;
  std::string kind;  // "polygon", "line"
  std::vector<std::array<double, 2>> points;
  std::size_t occupancy = 0;
  std::uint64_t inbound = 0;
  std::uint64_t outbound = 0;
};

struct LiveState {
  common::UtcNs stamp_ns = 0;
  std::string version;
  // Keys configured (lrfnetd --keys): false makes the page warn that the network is
  // unauthenticated.
  bool authenticated = true;
  LiveCalibration calibration;
  std::vector<LiveSensor> sensors;
  std::vector<LiveTrack> tracks;
  std::vector<LiveFusedTrack> fused;
  std::vector<LiveHiddenTrack> hidden;
  std::vector<LiveZone> zones;
};

// One JSON object, e.g.
// {"type":"state","stamp_ns":..,"version":"..","authenticated":true,"calibration":{"state":"calibrated",...},
//  "sensors":[{"id":"s1","placed":true,"x_m":..,"y_m":..,"yaw_rad":..,"first_angle_rad":..,
//   "fov_rad":..,"max_range_m":..,"status":"active",...,"background":[[x,y],...],
//   "monitor":{"state":"moved","detail":".."} or null,
//   "calibration":{"sigma_x_m":..,"sigma_y_m":..,"sigma_yaw_deg":..,
//    "radial_bias":{"m":..,"sigma_m":..,"estimated":true} or null,"mount_looks_like_legs":false,
//    "flag":".."} or null}],
//  "tracks":[{"sensor":"s1","id":3,"state":"confirmed","x_m":..,...,"fused":7}],
//  "fused":[{"id":7,"state":"confirmed","x_m":..,...,"sensors":["s1","s2"]}],
//  "hidden":[{"id":5,"x_m":..,"y_m":..,"age_s":..,"sensor":"s1"}],
//  "zones":[{"name":"door","kind":"line","points":[[x,y],...],"occupancy":0,"inbound":3,
//   "outbound":1}]}
// Coordinates with millimetre precision; strings escaped; non-finite numbers written as null.
std::string LiveStateJson(const LiveState& state);

}  // namespace lrfnet::daemon
