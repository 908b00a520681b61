#pragma once
// Poses over time: the `history` of a calibration.yaml (what happened to the calibration while
// the site ran: sensors found moved, corrected, backgrounds re-learned) and the `poses` of the
// simulator's truth.yaml (every sensor's pose with its time range).
//
// calibration.yaml, appended after the sections of CalibrationYaml (a reader that does not know
// `history` ignores it, ParsePoseYaml among them):
//
//   history:
//     - {time_utc: "2024-05-01T12:00:03Z", stamp_ns: 1714564803000000000, sensor: "s2",
//        event: "moved", method: "background", detail: "...",
//        before: {x_m: 1, y_m: 2, yaw_deg: 30}, after: {x_m: 1.02, y_m: 2, yaw_deg: 32},
//        motion: {dx_m: 0.02, dy_m: 0, dyaw_deg: 2}}
//
// `before` / `after` are world_from_sensor in the calibration's frame; `motion` is after minus
// before (position in the world frame, yaw wrapped to (-180, 180]); both are absent when the event
// has no pose (a re-learned background). Oldest first.
//
// truth.yaml `poses`: [{id, from_s, to_s, from_utc_ns, x_m, y_m, yaw_deg}, ...], scenario seconds,
// the pose holds on [from_s, to_s).

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "central_daemon/calibration/calibration_yaml.h"
#include "common/geometry.h"
#include "common/time.h"

namespace lrfnet::calib {

struct CalibrationEvent {
  std::string time_utc;        // wall clock of the daemon when it happened ("" = unknown)
  common::UtcNs stamp_ns = 0;  // gateway UTC of the data that showed it (0 = unknown)
  std::string sensor;
  // "calibrated" (a full calibration), "moved" (the sensor was found moved and left out of the
  // fusion), "corrected" (its pose was estimated again; fused again once its tracker has re-learned
  // its background),
  // "background_relearned" (its scene changed, the sensor did not: the reference background was
  // replaced).
  std::string event;
  std::string method;  // how it was found or estimated: "background", "tracks", ""
  std::string detail;  // one line for a person
  std::optional<Pose2> before;
  std::optional<Pose2> after;
};

// The `history` section (an empty list as `history: []`).
std::string HistoryYaml(const std::vector<CalibrationEvent>& events);

// Reads the `history` of a calibration.yaml; a file without one gives an empty list. False with a
// one-line *error naming the line and the key when an entry is malformed; *out only written on
// success. At most kMaxHistoryEvents are read (the oldest are dropped beyond that).
inline constexpr std::size_t kMaxHistoryEvents = 10000;
bool ParseHistoryYaml(const std::string& text, std::vector<CalibrationEvent>* out,
                      std::string* error);

// The poses of truth.yaml's `poses` valid at scenario time t_s (from_s <= t_s < to_s; at or after
// the end of the run, the last pose), as a PoseFile in the order of first appearance. False with a
// one-line *error when the text has no `poses` or an entry is malformed.
bool TruthPosesAt(const std::string& text, double t_s, PoseFile* out, std::string* error);

}  // namespace lrfnet::calib
