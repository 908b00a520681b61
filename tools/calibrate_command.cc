// lrfnet calibrate REC_OR_CAPTURE... --out calibration.yaml [--report DIR] [--truth truth.yaml]

#include <spdlog/spdlog.h>

#include <boost/program_options.hpp>
#include <chrono>
#include <cstdio>
#include <iostream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "central_daemon/app/auth_files.h"
#include "central_daemon/app/calibration_input.h"
#include "central_daemon/app/calibration_service.h"
#include "central_daemon/calibration/calibration_yaml.h"
#include "central_daemon/calibration/eval.h"
#include "central_daemon/calibration/pipeline.h"
#include "central_daemon/calibration/report.h"
#include "common/datagram_auth.h"
#include "tools/subcommands.h"

namespace lrfnet::tools {

namespace po = boost::program_options;

namespace {

void PrintSummary(const calib::CalibrationOutcome& outcome) {
  const calib::CalibrationResult& r = outcome.result;
  std::printf("method %s, reference %s\n", r.method.c_str(), r.reference.c_str());
  // The joint refinement's shared radial bias per sensor, where it ran: estimated from the data
  // ("est") or held at its prior ("prior"), +- one standard deviation.
  bool any_bias = false;
  for (const calib::SensorPose& s : r.sensors) any_bias = any_bias || s.radial_bias.has_value();
  std::printf("%-12s %10s %10s %9s %9s %9s%s\n", "sensor", "x_m", "y_m", "yaw_deg", "sigma_m",
              "sigma_deg", any_bias ? "  radial_bias_m" : "");
  for (const calib::SensorPose& s : r.sensors) {
    if (!s.calibrated) {
      std::printf("%-12s %10s%s%s\n", s.id.c_str(), "not calibrated", s.flag.empty() ? "" : ": ",
                  s.flag.c_str());
      continue;
    }
    const double sigma_m = std::sqrt(std::max(0.0, s.covariance(0, 0) + s.covariance(1, 1)));
    const double sigma_deg = common::RadToDeg(std::sqrt(std::max(0.0, s.covariance(2, 2))));
    char bias[64] = "";
    if (s.radial_bias) {
      std::snprintf(bias, sizeof bias, "  %+.4f+-%.4f %s", s.radial_bias->bias_m,
                    s.radial_bias->sigma_m, s.radial_bias->estimated ? "est" : "prior");
    } else if (any_bias) {
      std::snprintf(bias, sizeof bias, "  %-20s", "-");
    }
    // A flagged pose is printed with what is wrong with it (e.g. placed by a weak pair only).
    std::printf("%-12s %10.4f %10.4f %9.3f %9.4f %9.4f%s%s%s\n", s.id.c_str(),
                s.world_from_sensor.x_m, s.world_from_sensor.y_m,
                common::RadToDeg(s.world_from_sensor.yaw_rad), sigma_m, sigma_deg, bias,
                s.flag.empty() ? "" : "  ! ", s.flag.c_str());
  }
  if (!r.ambiguity.empty()) std::printf("not decided by the data: %s\n", r.ambiguity.c_str());
  if (!r.scale_note.empty()) std::printf("%s\n", r.scale_note.c_str());
  std::size_t used = 0, rejected = 0, outliers = 0;
  for (const calib::EdgeReport& e : r.edges) {
    if (e.used) {
      ++used;
    } else if (e.status.rfind("rejected", 0) == 0) {
      ++rejected;
    } else {
      ++outliers;
    }
  }
  std::printf("edges: %zu used, %zu outliers dropped, %zu pairs without an estimate; track "
              "residual %.3f m rms\n",
              used, outliers, rejected, r.track_residual_rms_m);
  if (r.refine_observations > 0) {
    std::printf("joint refinement: %s (cost %.1f -> %.1f over %zu observations)\n",
                r.refined ? "applied" : "not applied", r.refine_cost_before, r.refine_cost_after,
                r.refine_observations);
  }
  std::string times;
  for (const calib::StageTime& t : r.timings) {
    char buffer[96];
    std::snprintf(buffer, sizeof buffer, "%s%s %.3f s", times.empty() ? "" : ", ",
                  t.stage.c_str(), t.seconds);
    times += buffer;
  }
  if (!times.empty()) std::printf("time: %s\n", times.c_str());
  for (const std::string& w : r.warnings) std::printf("warning: %s\n", w.c_str());
}

nlohmann::json StatsJson(const calib::CalibrationOutcome& outcome,
                         const daemon::LoadCounters& load, const calib::EvalResult* eval) {
  nlohmann::json j;
  j["ok"] = outcome.ok;
  j["error"] = outcome.error;
  j["method"] = outcome.result.method;
  j["reference"] = outcome.result.reference;
  j["files"] = load.files;
  j["datagrams"] = load.datagrams;
  j["invalid_datagrams"] = load.invalid;
  j["verified_datagrams"] = load.verified;
  j["unverified_datagrams"] = load.unverified;
  j["track_residual_rms_m"] = outcome.result.track_residual_rms_m;
  j["refined"] = outcome.result.refined;
  j["scale_note"] = outcome.result.scale_note;
  j["refine_cost_before"] = outcome.result.refine_cost_before;
  j["refine_cost_after"] = outcome.result.refine_cost_after;
  nlohmann::json timings = nlohmann::json::object();
  for (const calib::StageTime& t : outcome.result.timings) timings[t.stage] = t.seconds;
  j["timings_s"] = timings;
  nlohmann::json edges = nlohmann::json::array();
  for (const calib::EdgeReport& e : outcome.result.edges) {
    edges.push_back({{"r", e.r},
                     {"s", e.s},
                     {"used", e.used},
                     {"status", e.status},
                     {"matches", e.matches},
                     {"rms_m", e.rms_m},
                     {"rotation_residual_deg", e.rotation_residual_deg},
                     {"translation_residual_m", e.translation_residual_m},
                     {"track_residual_rms_m", e.track_residual_rms_m},
                     {"icp_applied", e.icp_applied}});
  }
  j["edges"] = edges;
  if (eval != nullptr && eval->ok) {
    j["eval"] = nlohmann::json::parse(calib::EvalJson(*eval));
  }
  return j;
}

}  // namespace

int RunCalibrate(int argc, char** argv) {
  po::options_description visible(
      "lrfnet calibrate REC_OR_CAPTURE... --out calibration.yaml [options]\n"
      "Calibrates the poses of all sensors from their tracks and background snapshots: reads "
      "recordings (lrfnetd --record,\nlrfnet-tracker --out; with their rotation parts) or "
      "pcap/pcapng captures of the UDP stream, any number,\nin any order, then runs the "
      "calibration (Quenzel et al. by default) and writes calibration.yaml (poses, per-sensor\n"
      "uncertainty, quality) and optionally a report folder (pictures of the calibrated network "
      "and of the pairwise\ngraph, residuals per edge). Exit 0 on success, 1 when the data "
      "cannot calibrate every sensor (the error says\nwhat is missing; --partial writes the "
      "connected part anyway), 2 on bad arguments. Options",
      100, 50);
  std::string out_path;
  std::string report_dir;
  std::string truth_path;
  std::string method_name = "quenzel";
  std::string reference;
  std::string weights = "uniform";
  std::string stats_out;
  std::string log_level = "warn";
  int udp_port = 0;
  double grid_step_s = 0.0;
  double min_overlap_s = 0.0;
  daemon::InputWindow window;
  visible.add_options()("help,h", "this help")("out", po::value<std::string>(&out_path),
                                               "write the calibration here (YAML)")(
      "report", po::value<std::string>(&report_dir), "write the report into this folder")(
      "method", po::value<std::string>(&method_name)->default_value("quenzel"),
      "quenzel (robust: MSAC + verification, ICP, L1 rotation averaging, joint refinement), "
      "spectral (the same pairs, weighted spectral relaxation) or schenk (Schenk et al.)")(
      "reference", po::value<std::string>(&reference),
      "the sensor fixed at the origin (default: the best-connected one)")(
      "weights", po::value<std::string>(&weights)->default_value("uniform"),
      "edge weights of the global step: uniform or schenk (N/d)")(
      "no-icp", "skip the point-to-line ICP on the background scans")(
      "no-refine", "skip the joint refinement over all observations")(
      "grid-step-s", po::value<double>(&grid_step_s),
      "spacing of the common time grid the tracks are aligned on (default 0.05)")(
      "min-overlap-s", po::value<double>(&min_overlap_s),
      "seconds of simultaneous tracks a pair needs to count as linked (default 3)")(
      "partial", "also write the calibration of the sensors that could be connected on failure")(
      "received-until-ns", po::value<std::int64_t>(&window.received_until_ns),
      "only the datagrams received up to this time (UTC ns, the recording's receive clock): with "
      "--scan-from-ns, the input of a calibration lrfnetd made live (its `input_window`)")(
      "scan-from-ns", po::value<std::int64_t>(&window.scan_from_ns),
      "only the track frames from this scan time on (UTC ns)")(
      "truth", po::value<std::string>(&truth_path),
      "a truth.yaml (lrfnet sim): print the errors d_R, d_t per sensor as `lrfnet eval` does")(
      "stats-out", po::value<std::string>(&stats_out),
      "write a JSON summary (timings, edges, errors against --truth) to this file")(
      "udp-port", po::value<int>(&udp_port)->default_value(0),
      "captures: only UDP datagrams to this port (0 = any)")(
      "keys", po::value<std::string>(),
      "verify sealed datagrams with the sensor keys in this folder, as lrfnetd --keys does "
      "(without: sealed plain datagrams are read unverified, encrypted ones skipped)")(
      "log-level", po::value<std::string>(&log_level)->default_value("warn"),
      "trace, debug, info, warn, error or off (stderr)");
  po::options_description hidden;
  hidden.add_options()("inputs", po::value<std::vector<std::string>>(), "inputs");
  po::options_description all;
  all.add(visible).add(hidden);
  po::positional_options_description positional;
  positional.add("inputs", -1);
  po::variables_map vm;
  try {
    po::store(po::command_line_parser(argc, argv).options(all).positional(positional).run(), vm);
    po::notify(vm);
  } catch (const po::error& e) {
    return UsageError("calibrate", e.what());
  }
  if (vm.count("help") != 0) {
    std::cout << visible << "\n";
    return kExitOk;
  }
  if (vm.count("inputs") == 0)
    return UsageError("calibrate", "missing REC_OR_CAPTURE (recordings or UDP captures)");
  if (out_path.empty()) return UsageError("calibrate", "missing --out calibration.yaml");
  calib::CalibrationOptions options;
  const auto method = calib::ParseMethod(method_name);
  if (!method) return UsageError("calibrate", "unknown --method '" + method_name + "'");
  options.method = *method;
  options.reference = reference;
  if (weights == "schenk") {
    options.weighted = true;
  } else if (weights != "uniform") {
    return UsageError("calibrate", "unknown --weights '" + weights + "' (uniform or schenk)");
  }
  options.use_icp = vm.count("no-icp") == 0;
  options.refine = vm.count("no-refine") == 0;
  if (vm.count("grid-step-s") != 0) options.align.grid_step_s = grid_step_s;
  if (vm.count("min-overlap-s") != 0) options.min_pair_overlap_s = min_overlap_s;
  if (auto e = calib::Validate(options)) return UsageError("calibrate", *e);
  if (udp_port < 0 || udp_port > 65535)
    return UsageError("calibrate", "--udp-port must be 0..65535");
  if (!SetUpLogging(log_level))
    return UsageError("calibrate", "unknown --log-level '" + log_level + "'");

  std::optional<calib::PoseFile> truth;
  std::string error;
  if (!truth_path.empty()) {
    truth.emplace();
    if (!calib::ReadPoseFile(truth_path, &*truth, &error)) {
      std::fprintf(stderr, "lrfnet calibrate: %s\n", error.c_str());
      return kExitFailure;
    }
  }

  const std::vector<std::string> inputs = vm["inputs"].as<std::vector<std::string>>();
  calib::CalibrationInput input;
  daemon::LoadCounters load;
  daemon::AuthOptions auth_options;
  if (vm.count("keys") != 0) {
    if (!auth::Init()) return UsageError("calibrate", "--keys: libsodium cannot be initialised");
    if (auto e = daemon::LoadSensorKeys(vm["keys"].as<std::string>(), &auth_options))
      return UsageError("calibrate", "--keys " + *e);
  }
  if (!daemon::LoadCalibrationInput(inputs, static_cast<std::uint16_t>(udp_port), &input, &load,
                                    &error, auth_options, window)) {
    std::fprintf(stderr, "lrfnet calibrate: %s\n", error.c_str());
    return kExitFailure;
  }
  spdlog::info("read {} datagrams ({} invalid) from {} files: {} sensors", load.datagrams,
               load.invalid, load.files, input.sensors.size());
  if (load.unverified > 0) {
    spdlog::warn(
        "{} sealed datagrams were read without verifying them (no --keys): forged "
        "datagrams in the files would be used",
        load.unverified);
  }

  const auto start = std::chrono::steady_clock::now();
  const calib::StageClock clock = [start] {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  };
  const calib::CalibrationOutcome outcome = calib::Calibrate(input, options, clock);
  PrintSummary(outcome);

  int exit_code = kExitOk;
  if (!outcome.ok) {
    std::fprintf(stderr, "lrfnet calibrate: %s\n", outcome.error.c_str());
    exit_code = kExitFailure;
  }
  const bool have_poses = outcome.ok || (vm.count("partial") != 0 && !outcome.result.reference.empty());
  if (have_poses) {
    calib::YamlContext context;
    context.created_utc = daemon::UtcNowText();
    context.inputs = inputs;
    if (vm.count("received-until-ns") != 0 || vm.count("scan-from-ns") != 0) {
      context.received_until_ns = window.received_until_ns;
      context.scan_from_ns = window.scan_from_ns;
    }
    error = daemon::WriteFileAtomically(out_path, calib::CalibrationYaml(outcome.result, context));
    if (!error.empty()) {
      std::fprintf(stderr, "lrfnet calibrate: %s\n", error.c_str());
      return kExitFailure;
    }
    std::printf("wrote %s\n", out_path.c_str());
  }
  if (!report_dir.empty() && !outcome.result.reference.empty()) {
    calib::ReportInput report;
    report.result = &outcome.result;
    report.tracks = &outcome.tracks;
    report.pairs = outcome.pairs;
    report.truth = truth ? &*truth : nullptr;
    if (!calib::WriteReport(report_dir, report, &error)) {
      std::fprintf(stderr, "lrfnet calibrate: %s\n", error.c_str());
      return kExitFailure;
    }
    std::printf("report in %s\n", report_dir.c_str());
  }
  std::optional<calib::EvalResult> eval;
  if (truth && !outcome.result.reference.empty()) {
    eval = calib::Evaluate(calib::PoseFileOf(outcome.result), *truth, std::nullopt);
    if (eval->ok) {
      std::printf("%s", calib::EvalTable(*eval).c_str());
    } else {
      std::fprintf(stderr, "lrfnet calibrate: --truth: %s\n", eval->error.c_str());
    }
  }
  if (!stats_out.empty()) {
    error = daemon::WriteFileAtomically(
        stats_out, StatsJson(outcome, load, eval ? &*eval : nullptr).dump(2) + "\n");
    if (!error.empty()) {
      std::fprintf(stderr, "lrfnet calibrate: %s\n", error.c_str());
      return kExitFailure;
    }
  }
  std::fflush(stdout);
  return exit_code;
}

}  // namespace lrfnet::tools
