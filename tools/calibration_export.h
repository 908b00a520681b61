#pragma once
// The poses of a calibration.yaml for other systems (pure): ROS 2 static transforms (a launch file
// with one tf2_ros static_transform_publisher per sensor), URDF (a robot of fixed joints) and CSV.
//
// Frames: the calibration's world frame (the reference sensor at the origin) is `parent_frame`;
// each sensor's frame is `frame_pattern` with {id} replaced by the sensor id. Each transform is
// parent_from_sensor: translation (x_m, y_m, z_m), rotation yaw about z (roll = pitch = 0), the
// usual ROS convention (REP 103: x forward, y left, z up) which is also the sensors' frame here.

#include <optional>
#include <string>

#include "central_daemon/calibration/calibration_yaml.h"

namespace lrfnet::tools {

enum class ExportFormat { kRos2StaticTf, kUrdf, kCsv };
// "ros2-static-tf", "urdf", "csv"; nullopt for others.
std::optional<ExportFormat> ParseExportFormat(const std::string& name);

struct ExportOptions {
  std::string parent_frame = "world";
  std::string frame_pattern = "{id}";      // e.g. "lrfnet_{id}_laser"
  double z_m = 0.0;                        // mounting height of every sensor above the parent frame
  std::string robot_name = "lrfnet_site";  // URDF
  bool include_uncalibrated = false;  // sensors the calibration could not place (at the origin!)
};
// Frame names of [A-Za-z0-9_/] (after the {id} replacement), finite z.
std::optional<std::string> Validate(const ExportOptions& options);

// The frame name of a sensor: the pattern with every {id} replaced. Characters of the id outside
// [A-Za-z0-9_] become '_'.
std::string SensorFrame(const ExportOptions& options, const std::string& sensor_id);

// The file text, or an error (two sensors with the same frame name, no sensor to export).
struct ExportResult {
  bool ok = false;
  std::string text;
  std::string error;
};
ExportResult ExportCalibration(const calib::PoseFile& poses, ExportFormat format,
                               const ExportOptions& options, const std::string& source_name);

}  // namespace lrfnet::tools
