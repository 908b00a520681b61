// lrfnet eval CALIBRATION TRUTH [--reference ID] [--at SECONDS] [--json]

#include <boost/program_options.hpp>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <optional>
#include <sstream>
#include <string>

#include "central_daemon/calibration/calibration_yaml.h"
#include "central_daemon/calibration/eval.h"
#include "central_daemon/calibration/pose_history.h"
#include "tools/subcommands.h"

namespace lrfnet::tools {

namespace po = boost::program_options;

int RunEval(int argc, char** argv) {
  po::options_description visible(
      "lrfnet eval CALIBRATION TRUTH [options]\n"
      "Compares the sensor poses of CALIBRATION (a calibration.yaml) with TRUTH (the truth.yaml "
      "of lrfnet sim,\nor any file with the same `sensors` list) like Tables II-III of Quenzel et "
      "al.: both pose sets are\nexpressed in the frame of the reference sensor, then per sensor "
      "d_R = |yaw difference| [deg] and\nd_t = position distance [m], with their mean and median. "
      "Sensors of the truth that are not\ncalibrated are listed. A sensor the scenario moves "
      "during the run is in TRUTH's `sensors` with\nits last pose (what a calibration kept up to "
      "date by lrfnetd ends with); --at compares with the\nposes at a given scenario time "
      "instead. Exit 0, or 1 when a file is unreadable or the two do not\nmatch. Options",
      100, 50);
  std::string reference;
  visible.add_options()("help,h", "this help")(
      "reference", po::value<std::string>(&reference),
      "the sensor both pose sets are expressed in (default: the calibration's `reference`)")(
      "json", "print one JSON object instead of the table")(
      "at", po::value<double>(),
      "compare with the truth poses at this scenario time [s] (TRUTH's `poses` list)");
  po::options_description hidden;
  hidden.add_options()("files", po::value<std::vector<std::string>>(), "CALIBRATION TRUTH");
  po::options_description all;
  all.add(visible).add(hidden);
  po::positional_options_description positional;
  positional.add("files", -1);
  po::variables_map vm;
  try {
    po::store(po::command_line_parser(argc, argv).options(all).positional(positional).run(), vm);
    po::notify(vm);
  } catch (const po::error& e) {
    return UsageError("eval", e.what());
  }
  if (vm.count("help") != 0) {
    std::cout << visible << "\n";
    return kExitOk;
  }
  const std::vector<std::string> files = vm.count("files") != 0
                                             ? vm["files"].as<std::vector<std::string>>()
                                             : std::vector<std::string>{};
  if (files.size() != 2) {
    return UsageError("eval", files.size() < 2
                                  ? "expected CALIBRATION and TRUTH"
                                  : "expected exactly two files, CALIBRATION and TRUTH");
  }
  if (vm.count("reference") != 0 && reference.empty())
    return UsageError("eval", "--reference needs a sensor id");

  calib::PoseFile calibration, truth;
  std::string error;
  if (!calib::ReadPoseFile(files[0], &calibration, &error) ||
      !calib::ReadPoseFile(files[1], &truth, &error)) {
    std::fprintf(stderr, "lrfnet eval: %s\n", error.c_str());
    return kExitFailure;
  }
  if (vm.count("at") != 0) {
    // ReadPoseFile above has checked the file and its size.
    std::ifstream in(files[1], std::ios::binary);
    std::stringstream text;
    text << in.rdbuf();
    if (!calib::TruthPosesAt(text.str(), vm["at"].as<double>(), &truth, &error)) {
      std::fprintf(stderr, "lrfnet eval: %s: %s\n", files[1].c_str(), error.c_str());
      return kExitFailure;
    }
  }
  const calib::EvalResult result = calib::Evaluate(
      calibration, truth, reference.empty() ? std::nullopt : std::optional<std::string>(reference));
  if (!result.ok) {
    std::fprintf(stderr, "lrfnet eval: %s vs %s: %s\n", files[0].c_str(), files[1].c_str(),
                 result.error.c_str());
    return kExitFailure;
  }
  if (vm.count("json") != 0) {
    std::cout << calib::EvalJson(result) << "\n";
  } else {
    std::cout << calib::EvalTable(result);
  }
  std::cout.flush();
  return std::cout.good() ? kExitOk : kExitFailure;
}

}  // namespace lrfnet::tools
