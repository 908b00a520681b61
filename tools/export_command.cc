// lrfnet export CALIBRATION --format ros2-static-tf|urdf|csv [--out FILE] [--parent-frame NAME]
// [--frame PATTERN] [--z-m Z] [--robot-name NAME] [--include-uncalibrated]

#include <boost/program_options.hpp>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <string>

#include "central_daemon/app/calibration_service.h"
#include "tools/calibration_export.h"
#include "tools/subcommands.h"

namespace lrfnet::tools {

namespace po = boost::program_options;

int RunExport(int argc, char** argv) {
  po::options_description visible(
      "lrfnet export CALIBRATION --format ros2-static-tf|urdf|csv [options]\n"
      "Writes the sensor poses of CALIBRATION (a calibration.yaml) for other systems: "
      "ros2-static-tf, a ROS 2\nlaunch file with one tf2_ros static_transform_publisher per "
      "sensor; urdf, a URDF robot of fixed\njoints; csv, one row per sensor (position, yaw, "
      "quaternion). Every transform is parent_from_sensor.\nOptions",
      100, 50);
  std::string format_name;
  std::string out_path;
  ExportOptions options;
  visible.add_options()("help,h", "this help")("format", po::value<std::string>(&format_name),
                                               "ros2-static-tf, urdf or csv")(
      "out", po::value<std::string>(&out_path),
      "write to this file (replaced atomically); default: stdout")(
      "parent-frame", po::value<std::string>(&options.parent_frame)->default_value("world"),
      "the calibration's world frame (the reference sensor at its origin)")(
      "frame", po::value<std::string>(&options.frame_pattern)->default_value("{id}"),
      "each sensor's frame name; {id} is the sensor id, e.g. lrfnet_{id}_laser")(
      "z-m", po::value<double>(&options.z_m)->default_value(0.0),
      "the sensors' height above the parent frame, metres")(
      "robot-name", po::value<std::string>(&options.robot_name)->default_value("lrfnet_site"),
      "the URDF robot's name")("include-uncalibrated",
                               "also the sensors the calibration could not place (at the origin)");
  po::variables_map vm;
  if (const auto code = ParseOptions("export", argc, argv, visible, "calibration", &vm))
    return *code;
  if (vm.count("calibration") == 0) return UsageError("export", "expected CALIBRATION");
  if (format_name.empty())
    return UsageError("export", "--format is required (ros2-static-tf, urdf, csv)");
  const auto format = ParseExportFormat(format_name);
  if (!format)
    return UsageError("export",
                      "unknown --format '" + format_name + "' (ros2-static-tf, urdf, csv)");
  options.include_uncalibrated = vm.count("include-uncalibrated") != 0;
  if (auto e = Validate(options)) return UsageError("export", *e);

  const std::string path = vm["calibration"].as<std::string>();
  calib::PoseFile poses;
  std::string error;
  if (!calib::ReadPoseFile(path, &poses, &error)) {
    std::fprintf(stderr, "lrfnet export: %s\n", error.c_str());
    return kExitFailure;
  }
  const ExportResult result =
      ExportCalibration(poses, *format, options, std::filesystem::path(path).filename().string());
  if (!result.ok) {
    std::fprintf(stderr, "lrfnet export: %s: %s\n", path.c_str(), result.error.c_str());
    return kExitFailure;
  }
  if (out_path.empty()) {
    std::cout << result.text;
    std::cout.flush();
    return std::cout.good() ? kExitOk : kExitFailure;
  }
  if (const std::string e = daemon::WriteFileAtomically(out_path, result.text); !e.empty()) {
    std::fprintf(stderr, "lrfnet export: %s\n", e.c_str());
    return kExitFailure;
  }
  return kExitOk;
}

}  // namespace lrfnet::tools
