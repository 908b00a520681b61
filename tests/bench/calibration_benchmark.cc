// Calibration accuracy and speed over the shipped scenarios, through the whole chain:
// `lrfnet sim SCENARIO --seed N` → `lrfnet-tracker --replay` per capture (centre-of-mass,
// ellipse and shape-fit measurements, the last the tracker's default, also with each sensor's
// mount from the simulator's truth) → Calibrate (our method with and without ICP and joint
// refinement, with uniform and N/d weights; both baselines) → errors against the truth (as
// `lrfnet eval`).
//
//   calibration_benchmark --tool LRFNET --tracker LRFNET_TRACKER --scenarios DIR
//                         [--seeds 3] [--only NAME] [--out results/calibration_benchmark.md]
//                         [--cache DIR] [--variants SUBSTRING] [--diagnostic-variants]
//                         [--attempts 3]
//
// Every step of the chain is checked (calibration_chain.h): a sim or tracker run that fails is run
// again up to --attempts times, each tracker writes its recording under a temporary name renamed
// only on success (a cache never holds a partial one), and the loaded input must hold every sensor
// of the truth. A seed whose chain still lacks a sensor is not calibrated: it is listed under its
// scenario's table with the cause of every attempt, the chain's summary counts it, and the exit
// code is 1 (the table is still written).
//
// LRFNET_BENCH_VERBOSE=1 prints per run each sensor's error against its reported sigma, the edges
// and the accepted pairs against the truth; LRFNET_BENCH_VERBOSE=pairs adds the rejected pairs
// (their best hypothesis and the clearly different runner-up against the truth, the evidence of
// each and the negative-evidence counts per range band). --diagnostic-variants adds rows that
// take the joint refinement apart (its annealed gate, its size correction) and rows with the
// refinement's walls test on (refine_max_wall_residual_sigma 3.5, per measurement).
//
// Writes one table per scenario like Table III of Quenzel et al. (mean and median d_R [deg] and
// d_t [m] over all sensors of all seeds, sensors that could not be calibrated counted apart) and
// the mean time of each stage.

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "central_daemon/app/calibration_input.h"
#include "central_daemon/calibration/calibration_yaml.h"
#include "central_daemon/calibration/eval.h"
#include "central_daemon/calibration/pairwise.h"
#include "central_daemon/calibration/pipeline.h"
#include "tests/bench/bench_util.h"
#include "tests/bench/calibration_chain.h"
#include "yaml-cpp/yaml.h"

namespace {

namespace fs = std::filesystem;
using namespace lrfnet;
using bench::Arg;

// The tracker runs per sensor: the benchmark's name of each (in file names and Variant) and its
// measurement.kind in the tracker's configuration.
// "shape_fit_mount" is shape fit with each sensor's shape.mount as the simulator's truth says (a
// knee-height scanner configured for legs); the others run every sensor at the default mount
// (upper body), as a site that set only measurement.kind would.
constexpr const char* kMeasurements[] = {"ellipse", "com", "shape_fit", "shape_fit_mount"};

std::string TrackerKind(const std::string& measurement) {
  if (measurement == "com") return "center_of_mass";
  if (measurement == "shape_fit_mount") return "shape_fit";
  return measurement;
}

std::string MeasurementLabel(const std::string& measurement) {
  if (measurement == "com") return "CoM";
  if (measurement == "shape_fit") return "shape fit";
  if (measurement == "shape_fit_mount") return "shape fit at each sensor's mount";
  return measurement;
}

// The sensors the simulator mounted at knee height (`devices[].mount: legs` in its truth.yaml).
std::set<std::string> LegsMounted(const fs::path& truth_yaml) {
  std::set<std::string> out;
  try {
    const YAML::Node root = YAML::LoadFile(truth_yaml.string());
    for (const YAML::Node& d : root["devices"]) {
      if (d["mount"] && d["mount"].as<std::string>() == "legs") {
        out.insert(d["id"].as<std::string>());
      }
    }
  } catch (const YAML::Exception& e) {
    std::fprintf(stderr, "%s: %s\n", truth_yaml.string().c_str(), e.what());
  }
  return out;
}

struct Variant {
  std::string name;
  std::string measurement;  // "ellipse", "com" or "shape_fit": which tracker run
  calib::CalibrationOptions options;
};

std::vector<Variant> Variants(bool diagnostic) {
  std::vector<Variant> out;
  auto add = [&out](const std::string& name, const std::string& measurement,
                    calib::Method method, bool icp, bool refine, bool weighted) {
    Variant v;
    v.name = name;
    v.measurement = measurement;
    v.options.method = method;
    v.options.use_icp = icp;
    v.options.refine = refine;
    v.options.weighted = weighted;
    out.push_back(v);
  };
  add("ours, ellipse, ICP + refinement", "ellipse", calib::Method::kQuenzel, true, true, false);
  add("ours, ellipse, ICP", "ellipse", calib::Method::kQuenzel, true, false, false);
  add("ours, ellipse, refinement", "ellipse", calib::Method::kQuenzel, false, true, false);
  add("ours, ellipse, neither (paper w/o ICP)", "ellipse", calib::Method::kQuenzel, false, false,
      false);
  add("ours, ellipse, ICP + refinement, N/d weights", "ellipse", calib::Method::kQuenzel, true,
      true, true);
  // The same before walls won over biased tracks (no bias allowance in the ICP test, conflicts
  // not widened, the refinement kept whenever it lowers its own cost).
  for (const char* measurement : {"ellipse", "com", "shape_fit"}) {
    add(std::string("ours, ") + MeasurementLabel(measurement) +
            ", ICP + refinement, before (tracks over walls)",
        measurement, calib::Method::kQuenzel, true, true, false);
    out.back().options.icp_track_bias_sigma_m = 0.0;
    out.back().options.refine_max_disagreement_sigma = std::numeric_limits<double>::infinity();
    out.back().options.refine_max_wall_residual_sigma = std::numeric_limits<double>::infinity();
    out.back().options.conflicts_widen_covariance = false;
  }
  // The same with the joint refinement's pose taken for a sensor hanging on a weak pair whatever
  // the pair's own covariance says of the move.
  for (const char* measurement : {"ellipse", "com", "shape_fit"}) {
    add(std::string("ours, ") + MeasurementLabel(measurement) +
            ", ICP + refinement, before (refinement moves weak leaves)",
        measurement, calib::Method::kQuenzel, true, true, false);
    out.back().options.weak_refine_min_move_sigma = 0.0;
  }
  add("ours, CoM, ICP + refinement", "com", calib::Method::kQuenzel, true, true, false);
  add("ours, CoM, neither", "com", calib::Method::kQuenzel, false, false, false);
  // The tracker's default measurement (measurement.kind shape_fit).
  add("ours, shape fit, ICP + refinement", "shape_fit", calib::Method::kQuenzel, true, true, false);
  add("ours, shape fit, ICP", "shape_fit", calib::Method::kQuenzel, true, false, false);
  add("ours, shape fit, neither", "shape_fit", calib::Method::kQuenzel, false, false, false);
  // The same without the mount check (a knee-height sensor run as torso goes unnoticed).
  add("ours, shape fit, ICP + refinement, before (no mount check)", "shape_fit",
      calib::Method::kQuenzel, true, true, false);
  out.back().options.check_mount = false;
  // The same without each sensor's shared radial bias (refine.h, pairwise.h "Sensor bias"):
  // neither in the covariances nor estimated, the behaviour before it.
  for (const bool refine : {true, false}) {
    add(std::string("ours, shape fit, ICP") + (refine ? " + refinement" : "") +
            ", before (no sensor bias)",
        "shape_fit", calib::Method::kQuenzel, true, refine, false);
    out.back().options.joint.sensor_bias = false;
    out.back().options.pairwise.sensor_bias = false;
  }
  // With the shared biases in the covariances but never estimated (held at their prior).
  add("ours, shape fit, ICP + refinement, sensor bias held", "shape_fit", calib::Method::kQuenzel,
      true, true, false);
  out.back().options.joint.estimate_sensor_bias = false;
  add("ours, shape fit at each sensor's mount, ICP + refinement", "shape_fit_mount",
      calib::Method::kQuenzel, true, true, false);
  add("ours, shape fit at each sensor's mount, ICP", "shape_fit_mount", calib::Method::kQuenzel,
      true, false, false);
  add("spectral [21], ellipse, N/d weights", "ellipse", calib::Method::kSpectral, true, false,
      true);
  add("Schenk et al., ellipse", "ellipse", calib::Method::kSchenk, true, false, true);
  if (diagnostic) {
    // What of the joint refinement moves a sensor: its annealed association gate, its shared size
    // correction (--diagnostic-variants; not in the shipped table).
    add("ours, ellipse, ICP + refinement, gate 0.5 m from the start", "ellipse",
        calib::Method::kQuenzel, true, true, false);
    out.back().options.joint.initial_association_gate_m = 0.5;
    add("ours, ellipse, ICP + refinement, no size correction", "ellipse", calib::Method::kQuenzel,
        true, true, false);
    out.back().options.joint.estimate_size_correction = false;
    // The refinement not kept where it moves a pair aligned on walls beyond 3.5 sigma of that
    // alignment (CalibrationOptions::refine_max_wall_residual_sigma, off by default).
    for (const char* measurement : {"ellipse", "com", "shape_fit"}) {
      add(std::string("ours, ") + MeasurementLabel(measurement) +
              ", ICP + refinement, walls test on the refinement (3.5 sigma)",
          measurement, calib::Method::kQuenzel, true, true, false);
      out.back().options.refine_max_wall_residual_sigma = 3.5;
    }
  }
  return out;
}

struct Tally {
  std::vector<double> d_r_deg, d_t_m;
  // The same over the sensors placed without a flag, and the flagged placements.
  std::vector<double> d_r_unflagged_deg, d_t_unflagged_m;
  std::size_t flagged = 0;
  // runs: calibrated runs (the chain gave every sensor's tracks).
  std::size_t runs = 0, failed_runs = 0, sensors_missing = 0;
  // Seeds not calibrated: the chain did not give every sensor's tracks (listed with the cause).
  std::size_t not_run = 0;
  // Reported uncertainty against the error, per placed non-reference sensor: within 2 sigma
  // (d_t <= 2 sqrt(sigma_x^2 + sigma_y^2) and d_R <= 2 sigma_yaw), and the 2-dof NEES of the
  // position error; runs in which some sensor's error exceeds 3 times its reported sigma.
  std::size_t within_2sigma = 0, judged = 0;
  std::vector<double> nees;
  std::size_t beyond_3sigma_runs = 0;
  std::map<std::string, double> stage_s;  // summed over runs
};

// The mount check (calib::CheckMount) over the sensors of a group: how many it judged and
// flagged, and the spread of its statistics.
struct MountTally {
  std::size_t sensors = 0, decided = 0, flagged = 0;
  double share_min = 1.0, share_max = 0.0, median_min = 1e9, median_max = 0.0;
  void Add(const common::MountCheck& c) {
    ++sensors;
    if (!c.decided) return;
    ++decided;
    flagged += c.looks_like_legs ? 1 : 0;
    const double share = static_cast<double>(c.leg_sized) / static_cast<double>(c.tracks);
    share_min = std::min(share_min, share);
    share_max = std::max(share_max, share);
    median_min = std::min(median_min, c.median_half_width_m);
    median_max = std::max(median_max, c.median_half_width_m);
  }
};

struct Coverage {
  bool within_2sigma = false;
  bool beyond_3sigma = false;
  double nees = 0.0;
};

// The error of a calibrated sensor against the truth, both in the reference sensor's frame, and
// its reported covariance (the calibration's world is the reference's frame).
Coverage JudgeUncertainty(const calib::SensorPose& sensor, const common::Pose2& truth_ref_from_sensor) {
  Coverage c;
  const Eigen::Vector2d e = sensor.world_from_sensor.translation() - truth_ref_from_sensor.translation();
  const double d_yaw = std::abs(common::AngleDiff(sensor.world_from_sensor.yaw_rad, truth_ref_from_sensor.yaw_rad));
  const Eigen::Matrix2d cov = sensor.covariance.topLeftCorner<2, 2>();
  const double sigma_t = std::sqrt(std::max(0.0, cov.trace()));
  const double sigma_yaw = std::sqrt(std::max(0.0, sensor.covariance(2, 2)));
  c.within_2sigma = e.norm() <= 2.0 * sigma_t && d_yaw <= 2.0 * sigma_yaw;
  c.beyond_3sigma = e.norm() > 3.0 * sigma_t || d_yaw > 3.0 * sigma_yaw;
  const Eigen::LDLT<Eigen::Matrix2d> ldlt(cov);
  c.nees = ldlt.info() == Eigen::Success && ldlt.isPositive() && cov.determinant() > 0.0
               ? e.dot(ldlt.solve(e))
               : std::numeric_limits<double>::infinity();
  return c;
}

// `text` without the benchmark's work folder in front of the paths it names (the results file
// names files relative to it).
std::string WithoutFolder(std::string text, const fs::path& folder) {
  const std::string prefix = folder.string() + "/";
  for (std::size_t at; (at = text.find(prefix)) != std::string::npos;)
    text.erase(at, prefix.size());
  return text;
}

double Mean(const std::vector<double>& v) {
  if (v.empty()) return 0.0;
  double s = 0.0;
  for (double x : v) s += x;
  return s / static_cast<double>(v.size());
}
double Median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

}  // namespace

int main(int argc, char** argv) {
  const std::string tool = Arg(argc, argv, "--tool", "");
  const std::string tracker = Arg(argc, argv, "--tracker", "");
  const std::string scenarios_dir = Arg(argc, argv, "--scenarios", "tools/scenarios");
  const int seeds = std::stoi(Arg(argc, argv, "--seeds", "3"));
  const std::string only = Arg(argc, argv, "--only", "");
  const std::string out_path = Arg(argc, argv, "--out", "");
  const std::string cache = Arg(argc, argv, "--cache", "");
  const std::string variant_filter = Arg(argc, argv, "--variants", "");
  bench::ChainOptions chain_options;
  chain_options.attempts = std::stoi(Arg(argc, argv, "--attempts", "3"));
  if (auto e = bench::Validate(chain_options)) {
    std::fprintf(stderr, "calibration_benchmark: --attempts: %s\n", e->c_str());
    return 2;
  }
  const auto sleep_s = [](double seconds) {
    std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
  };
  // The chain over all scenarios: steps run, steps that needed more than one attempt, and the
  // calibrations (variant and seed) not run because a sensor's tracks were still missing.
  std::size_t chain_steps = 0, chain_retried = 0, chain_not_calibrated = 0;
  if (tool.empty() || tracker.empty()) {
    std::fprintf(stderr,
                 "usage: calibration_benchmark --tool LRFNET --tracker TRACKER [--scenarios DIR] "
                 "[--seeds N] [--only NAME] [--out FILE]\n");
    return 2;
  }
  std::vector<std::string> scenarios;
  for (const auto& entry : fs::directory_iterator(scenarios_dir)) {
    if (entry.path().extension() == ".yaml") scenarios.push_back(entry.path().stem().string());
  }
  std::sort(scenarios.begin(), scenarios.end());
  const fs::path work = !cache.empty() ? fs::path(cache)
                                        : fs::temp_directory_path() /
                                              ("calibration_benchmark_" + std::to_string(getpid()));
  const std::string log = (work / "log.txt").string();
  fs::create_directories(work);
  bool diagnostic = false;
  for (int i = 1; i < argc; ++i) diagnostic |= std::string(argv[i]) == "--diagnostic-variants";
  const std::vector<Variant> variants = Variants(diagnostic);

  std::ostringstream table;
  table << "# Calibration benchmark\n\n"
        << "Whole chain per scenario and seed: `lrfnet sim` → `lrfnet-tracker --replay` per "
           "sensor (centre-of-mass, ellipse and shape-fit measurements; shape fit is the tracker's "
           "default; every sensor at the default mount, upper-body height, but in the rows "
           "`shape fit at each sensor's mount`, where a knee-height sensor runs with `shape.mount: "
           "legs`) → calibration → errors against "
           "the truth in the reference sensor's frame (d_R [deg], d_t [m], over all non-reference "
           "sensors of all seeds; Quenzel et al. Table III). Seeds per scenario: "
        << seeds << ". Every step of the chain is checked and a failed one run again (up to "
        << chain_options.attempts
        << " times); a seed whose chain still lacks a sensor's tracks is not calibrated "
           "and is listed under its table with the cause (see `## Chain`). `failed` counts "
           "calibrated runs that did not connect every sensor; their sensors "
           "that were placed still count, the others are `missing`. `no flag`: the "
           "means over the sensors placed without a flag (not hanging on weak pairs), "
           "`flagged` the flagged placements over all seeds. The reported "
           "uncertainty against the error, per placed non-reference sensor: `within 2σ` "
           "is the share with d_t ≤ 2 sqrt(σx² + σy²) and d_R ≤ 2 σyaw, `NEES` the mean "
           "2-dof normalised squared position error (2 expected when the covariance is "
           "right; inf where a method reports none), `> 3σ` the runs in which some "
           "sensor's error exceeds 3 times its reported σ: each such run is a failure "
           "(a silent wrong answer).\n\n";
  std::map<std::string, std::map<std::string, double>> stage_means;  // variant → stage → mean s
  // scenario → group ("upper body", "knee height run as torso", "knee height run as legs").
  std::map<std::string, std::map<std::string, MountTally>> mount_tallies;

  for (const std::string& scenario : scenarios) {
    if (!only.empty() && scenario != only) continue;
    std::map<std::string, Tally> tallies;
    // What the chain needed more than one attempt for, and the seeds it could not complete.
    std::vector<std::string> chain_notes;
    const auto step = [&](const std::string& name, const std::vector<std::string>& args,
                          const std::function<std::optional<std::string>()>& check) {
      const bench::StepReport report = bench::RunStep(
          name, [&] { return bench::RunChild(args, log); }, check, chain_options, sleep_s);
      ++chain_steps;
      if (report.attempts > 1) {
        ++chain_retried;
        chain_notes.push_back(WithoutFolder(bench::Describe(report), work));
        std::fprintf(stderr, "%s: %s\n", scenario.c_str(), chain_notes.back().c_str());
      }
      return report.ok;
    };
    for (int seed = 1; seed <= seeds; ++seed) {
      const fs::path dir = work / (scenario + "_" + std::to_string(seed));
      fs::create_directories(dir);
      const std::string seed_name = "seed " + std::to_string(seed);
      const bool cached = !cache.empty() && fs::exists(dir / "sim/truth.yaml");
      if (!cached &&
          !step(seed_name + ": lrfnet sim",
                {tool, "sim", (fs::path(scenarios_dir) / (scenario + ".yaml")).string(), "--out",
                 (dir / "sim").string(), "--seed", std::to_string(seed), "--jobs", "2",
                 "--log-level", "warn"},
                [&] { return bench::CheckOutputFile((dir / "sim/truth.yaml").string()); })) {
        chain_notes.push_back(seed_name + " not calibrated: lrfnet sim failed");
        std::fprintf(stderr, "%s: %s (log %s)\n", scenario.c_str(), chain_notes.back().c_str(),
                     log.c_str());
        for (const Variant& v : variants) {
          if (!variant_filter.empty() && v.name.find(variant_filter) == std::string::npos) continue;
          ++tallies[v.name].not_run;
          ++chain_not_calibrated;
        }
        continue;
      }
      calib::PoseFile truth;
      std::string error;
      if (!calib::ReadPoseFile((dir / "sim/truth.yaml").string(), &truth, &error)) {
        std::fprintf(stderr, "%s\n", error.c_str());
        continue;
      }
      std::map<std::string, calib::CalibrationInput> inputs;
      // Per measurement: why its input lacks a sensor (empty: complete).
      std::map<std::string, std::string> incomplete;
      const std::set<std::string> legs = LegsMounted(dir / "sim/truth.yaml");
      std::vector<std::string> expected_ids;
      for (const auto& [id, pose] : truth.sensors) expected_ids.push_back(id);
      for (const std::string measurement : kMeasurements) {
        if (measurement == "shape_fit_mount" && legs.empty()) {
          inputs[measurement] = inputs["shape_fit"];  // every sensor at the default mount
          incomplete[measurement] = incomplete["shape_fit"];
          continue;
        }
        const fs::path config = dir / (measurement + ".yaml");
        std::ofstream(config) << "measurement:\n  kind: " << TrackerKind(measurement) << "\n";
        const fs::path legs_config = dir / (measurement + ".legs.yaml");
        std::ofstream(legs_config)
            << "measurement:\n  kind: " << TrackerKind(measurement) << "\nshape:\n  mount: legs\n";
        std::vector<std::string> recordings;
        std::string failed_steps;
        for (const auto& [id, pose] : truth.sensors) {
          const bool at_legs = measurement == "shape_fit_mount" && legs.count(id) != 0;
          const std::string rec = (dir / (id + "." + measurement + ".rec")).string();
          // Written under another name and renamed once the tracker exited 0 with a recording:
          // a run cut short leaves nothing a later --cache run would take for a whole one.
          const std::string part = rec + ".part";
          const std::string name =
              seed_name + ": lrfnet-tracker " + id + " (" + MeasurementLabel(measurement) + ")";
          if (!(cached && fs::exists(rec)) &&
              !step(name,
                    {tracker, "--replay", (dir / ("sim/" + id + ".pcap")).string(), "--sensor-id",
                     id, "--out", part, "--config", (at_legs ? legs_config : config).string(),
                     "--log-level", "warn"},
                    [&]() -> std::optional<std::string> {
                      if (auto bad = bench::CheckOutputFile(part)) return bad;
                      std::error_code ec;
                      fs::rename(part, rec, ec);
                      if (ec) return rec + ": " + ec.message();
                      return std::nullopt;
                    })) {
            failed_steps += (failed_steps.empty() ? "" : ", ") + id;
            continue;
          }
          recordings.push_back(rec);
        }
        daemon::LoadCounters counters;
        if (!daemon::LoadCalibrationInput(recordings, 0, &inputs[measurement], &counters, &error)) {
          incomplete[measurement] = "the recordings could not be loaded: " + error;
          inputs[measurement] = {};
        } else if (const std::vector<std::string> missing =
                       bench::MissingSensors(expected_ids, inputs[measurement]);
                   !missing.empty()) {
          std::string ids;
          for (const std::string& id : missing) ids += (ids.empty() ? "" : ", ") + id;
          incomplete[measurement] =
              "no tracks of " + ids +
              (failed_steps.empty() ? std::string(" in the recordings")
                                    : " (lrfnet-tracker failed for " + failed_steps + ")");
        }
        if (!incomplete[measurement].empty()) {
          chain_notes.push_back(WithoutFolder(seed_name + " not calibrated with " +
                                                  MeasurementLabel(measurement) +
                                                  " tracks: " + incomplete[measurement],
                                              work));
          std::fprintf(stderr, "%s: %s (log %s)\n", scenario.c_str(), chain_notes.back().c_str(),
                       log.c_str());
        }
      }
      // The mount check on the shape-fit runs, per sensor, against the simulator's mount.
      for (const char* measurement : {"shape_fit", "shape_fit_mount"}) {
        for (const calib::SensorRecording& rec : inputs[measurement].sensors) {
          const bool knee = legs.count(rec.id) != 0;
          if (std::string(measurement) == "shape_fit_mount" && !knee) continue;
          const std::string group = !knee ? "upper body, run as torso"
                                    : std::string(measurement) == "shape_fit"
                                        ? "knee height, run as torso"
                                        : "knee height, run as legs";
          mount_tallies[scenario][group].Add(calib::CheckMount(rec, common::MountCheckOptions{}));
        }
      }
      for (const Variant& v : variants) {
        if (!variant_filter.empty() && v.name.find(variant_filter) == std::string::npos) continue;
        if (!incomplete[v.measurement].empty()) {
          ++tallies[v.name].not_run;
          ++chain_not_calibrated;
          continue;
        }
        const auto start = std::chrono::steady_clock::now();
        const calib::CalibrationOutcome outcome = calib::Calibrate(
            inputs[v.measurement], v.options, [start] {
              return std::chrono::duration<double>(std::chrono::steady_clock::now() - start)
                  .count();
            });
        Tally& tally = tallies[v.name];
        ++tally.runs;
        if (!outcome.ok) ++tally.failed_runs;
        for (const calib::StageTime& t : outcome.result.timings) tally.stage_s[t.stage] += t.seconds;
        if (outcome.result.reference.empty()) {
          tally.sensors_missing += truth.sensors.size() - 1;
          continue;
        }
        const calib::EvalResult eval =
            calib::Evaluate(calib::PoseFileOf(outcome.result), truth, std::nullopt);
        if (!eval.ok) {
          tally.sensors_missing += truth.sensors.size() - 1;
          continue;
        }
        for (const calib::SensorError& e : eval.sensors) {
          tally.d_r_deg.push_back(e.d_r_deg);
          tally.d_t_m.push_back(e.d_t_m);
          bool flagged = false;
          for (const calib::SensorPose& sp : outcome.result.sensors) {
            flagged |= sp.id == e.id && !sp.flag.empty();
          }
          if (flagged) {
            ++tally.flagged;
          } else {
            tally.d_r_unflagged_deg.push_back(e.d_r_deg);
            tally.d_t_unflagged_m.push_back(e.d_t_m);
          }
        }
        tally.sensors_missing += eval.missing.size();
        const auto ref_in_truth = truth.Find(eval.reference);
        bool beyond = false;
        for (const calib::SensorPose& sp : outcome.result.sensors) {
          const auto t = truth.Find(sp.id);
          if (!sp.calibrated || sp.id == eval.reference || !t || !ref_in_truth) continue;
          const common::Pose2 truth_rel =
              truth.sensors[*ref_in_truth].second.inverse() * truth.sensors[*t].second;
          const Coverage c = JudgeUncertainty(sp, truth_rel);
          ++tally.judged;
          tally.within_2sigma += c.within_2sigma ? 1 : 0;
          tally.nees.push_back(c.nees);
          beyond |= c.beyond_3sigma;
        }
        if (beyond) ++tally.beyond_3sigma_runs;
        if (std::getenv("LRFNET_BENCH_VERBOSE") != nullptr) {
          std::fprintf(stderr, "%s seed %d %s: ok %d %s\n", scenario.c_str(), seed, v.name.c_str(),
                       outcome.ok ? 1 : 0, outcome.error.c_str());
          std::fprintf(stderr,
                       "  size correction %.3f %.3f estimated %d %d (scale correlation %.3f %.3f, "
                       "data sigma %.3f %.3f)\n",
                       outcome.result.size_correction_m.x(), outcome.result.size_correction_m.y(),
                       outcome.result.size_estimated[0] ? 1 : 0,
                       outcome.result.size_estimated[1] ? 1 : 0,
                       outcome.result.size_scale_correlation[0],
                       outcome.result.size_scale_correlation[1],
                       outcome.result.size_data_sigma_m[0], outcome.result.size_data_sigma_m[1]);
          for (const calib::SensorPose& sp : outcome.result.sensors) {
            const auto t = truth.Find(sp.id);
            if (!sp.calibrated || !t || !ref_in_truth) continue;
            const common::Pose2 truth_rel =
                truth.sensors[*ref_in_truth].second.inverse() * truth.sensors[*t].second;
            const Coverage c = JudgeUncertainty(sp, truth_rel);
            std::fprintf(stderr,
                         "  %-10s dt %.4f (sigma %.4f) dR %.4f (sigma %.4f) nees %.2f%s\n",
                         sp.id.c_str(),
                         (sp.world_from_sensor.translation() - truth_rel.translation()).norm(),
                         std::sqrt(sp.covariance(0, 0) + sp.covariance(1, 1)),
                         common::RadToDeg(std::abs(common::AngleDiff(sp.world_from_sensor.yaw_rad,
                                                                     truth_rel.yaw_rad))),
                         common::RadToDeg(std::sqrt(std::max(0.0, sp.covariance(2, 2)))), c.nees,
                         c.beyond_3sigma ? "  > 3 sigma" : "");
            if (!sp.flag.empty()) std::fprintf(stderr, "    flag: %s\n", sp.flag.c_str());
          }
          for (const calib::EdgeReport& e : outcome.result.edges) {
            std::fprintf(stderr, "  edge %s-%s: %s (matches %zu rms %.3f)\n", e.r.c_str(),
                         e.s.c_str(), e.status.c_str(), e.matches, e.rms_m);
          }
          const bool all_pairs = std::string(std::getenv("LRFNET_BENCH_VERBOSE")) == "pairs";
          for (const calib::PairEstimate& p : outcome.pairs) {
            if (!p.accepted && !all_pairs) continue;
            const auto tr = truth.Find(outcome.tracks.sensors[p.r].id);
            const auto ts = truth.Find(outcome.tracks.sensors[p.s].id);
            if (!tr || !ts) continue;
            const common::Pose2 truth_s_from_r =
                truth.sensors[*ts].second.inverse() * truth.sensors[*tr].second;
            std::fprintf(stderr,
                         "  pair %s-%s: %s icp %d (score %.3f -> %.3f) dt %.4f (sigma %.4f) dR "
                         "%.3f (sigma %.3f)\n",
                         outcome.tracks.sensors[p.r].id.c_str(),
                         outcome.tracks.sensors[p.s].id.c_str(),
                         !p.accepted ? "rejected"
                         : p.weak    ? "weak"
                                     : "strong",
                         p.icp_applied ? 1 : 0, p.icp_score_before, p.icp_score_after,
                         common::TranslationDistanceM(p.s_from_r, truth_s_from_r),
                         std::sqrt(p.covariance(0, 0) + p.covariance(1, 1)),
                         common::RadToDeg(common::RotationDistanceRad(p.s_from_r, truth_s_from_r)),
                         common::RadToDeg(std::sqrt(std::max(0.0, p.covariance(2, 2)))));
            if (!p.accepted) std::fprintf(stderr, "    %s\n", p.reason.c_str());
            if (!p.accepted && all_pairs) {
              // The runner-up hypothesis against the truth (ambiguity), and the evidence counts.
              calib::PairDiagnostics diag;
              calib::EstimatePair(outcome.tracks, p.r, p.s, v.options.pairwise, &diag);
              std::fprintf(stderr, "    best gain %.2f second gain %.2f", diag.best_gain,
                           diag.second_gain);
              if (diag.second_s_from_r) {
                std::fprintf(stderr, "; second: dt %.4f dR %.3f",
                             common::TranslationDistanceM(*diag.second_s_from_r, truth_s_from_r),
                             common::RadToDeg(common::RotationDistanceRad(*diag.second_s_from_r,
                                                                          truth_s_from_r)));
              }
              std::fprintf(stderr, "\n");
              for (std::size_t b = 0; b < calib::kRangeBands; ++b) {
                std::fprintf(stderr, "    band %zu: r in s %zu/%zu, s in r %zu/%zu\n", b,
                             diag.r_in_s.matched[b], diag.r_in_s.visible[b], diag.s_in_r.matched[b],
                             diag.s_in_r.visible[b]);
              }
            }
          }
          for (const std::string& w : outcome.result.warnings) {
            std::fprintf(stderr, "  warning: %s\n", w.c_str());
          }
        }
      }
      std::fprintf(stderr, "%s seed %d done\n", scenario.c_str(), seed);
    }
    table << "## " << scenario << "\n\n"
          << "| method | d_R mean | d_R median | d_t mean | d_t median | d_R / d_t mean, no flag | "
             "flagged | within 2σ | NEES | failed | > 3σ | missing | time [s] |\n"
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";
    for (const Variant& v : variants) {
      const Tally& t = tallies[v.name];
      char row[512];
      const double runs = static_cast<double>(t.runs);
      const double total = t.runs > 0 && t.stage_s.count("total") ? t.stage_s.at("total") / runs : 0.0;
      const std::string within =
          t.judged > 0 ? std::to_string(static_cast<int>(std::lround(
                             100.0 * static_cast<double>(t.within_2sigma) / static_cast<double>(t.judged)))) +
                             " %"
                       : "-";
      char unflagged[64] = "-";  // no sensor placed without a flag
      if (!t.d_r_unflagged_deg.empty()) {
        std::snprintf(unflagged, sizeof unflagged, "%.4f / %.4f", Mean(t.d_r_unflagged_deg),
                      Mean(t.d_t_unflagged_m));
      }
      char nees[32] = "-";
      if (!t.nees.empty()) std::snprintf(nees, sizeof nees, "%.2f", Mean(t.nees));
      std::snprintf(row, sizeof row,
                    "| %s | %.4f | %.4f | %.4f | %.4f | %s | %zu | %s | %s | %zu/%zu | "
                    "%zu/%zu | %zu | %.3f |\n",
                    v.name.c_str(), Mean(t.d_r_deg), Median(t.d_r_deg), Mean(t.d_t_m),
                    Median(t.d_t_m), unflagged, t.flagged, within.c_str(), nees, t.failed_runs,
                    t.runs, t.beyond_3sigma_runs, t.runs, t.sensors_missing, total);
      table << row;
      for (const auto& [stage, s] : t.stage_s) {
        stage_means[v.name][stage] += t.runs > 0 ? s / runs : 0.0;
      }
    }
    table << "\n";
    for (const std::string& note : chain_notes) table << "- " << note << "\n";
    if (!chain_notes.empty()) table << "\n";
  }
  table << "## Chain\n\n"
        << "Steps run (lrfnet sim, lrfnet-tracker per sensor and measurement): " << chain_steps
        << "; run more than once: " << chain_retried
        << "; calibrations not run because a sensor's tracks were missing: " << chain_not_calibrated
        << ".\n\n";
  // The mount check: every sensor of the shape-fit runs, grouped by the simulator's mount.
  table << "## Mount check\n\n"
        << "The check of a sensor configured for upper-body height (common/mount_check.h): its "
           "walking person tracks' median learned half-width; flagged when at least 30 % of them "
           "are below 0.09 m (at least 5 tracks). Per scenario over all seeds, the shape-fit "
           "runs, by the simulator's mount; `share` is the leg-sized share of a sensor's tracks, "
           "`median` its tracks' median half-width [m] (min - max over the sensors judged). A "
           "sensor configured for legs is not checked.\n\n"
        << "| scenario | scanners | sensors | judged | flagged | share | median |\n"
           "|---|---|---:|---:|---:|---:|---:|\n";
  for (const auto& [scenario, groups] : mount_tallies) {
    for (const auto& [group, m] : groups) {
      char row[320];
      if (m.decided == 0) {
        std::snprintf(row, sizeof row, "| %s | %s | %zu | 0 | 0 | - | - |\n", scenario.c_str(),
                      group.c_str(), m.sensors);
      } else {
        std::snprintf(row, sizeof row,
                      "| %s | %s | %zu | %zu | %zu | %.0f - %.0f %% | %.3f - %.3f |\n",
                      scenario.c_str(), group.c_str(), m.sensors, m.decided, m.flagged,
                      100.0 * m.share_min, 100.0 * m.share_max, m.median_min, m.median_max);
      }
      table << row;
    }
  }
  table << "\n";
  // Stage times of the ellipse and of the tracker's default measurement (shape fit), our method
  // with ICP and refinement, averaged over the scenarios' mean times.
  const std::string main_variant = variants.front().name;
  const std::string shape_variant = "ours, shape fit, ICP + refinement";
  std::size_t scenario_count = only.empty() ? scenarios.size() : 1;
  table << "## Time per stage (ours, ICP + refinement, mean over scenarios)\n\n"
        << "| stage | ellipse [s] | shape fit [s] |\n|---|---:|---:|\n";
  std::set<std::string> stages;
  for (const std::string& v : {main_variant, shape_variant}) {
    for (const auto& [stage, sec] : stage_means[v]) stages.insert(stage);
  }
  for (const std::string& stage : stages) {
    const auto mean_of = [&](const std::string& v) {
      const auto it = stage_means[v].find(stage);
      return it == stage_means[v].end() ? 0.0 : it->second / static_cast<double>(scenario_count);
    };
    char row[200];
    std::snprintf(row, sizeof row, "| %s | %.4f | %.4f |\n", stage.c_str(), mean_of(main_variant),
                  mean_of(shape_variant));
    table << row;
  }
  std::printf("%s", table.str().c_str());
  if (!out_path.empty()) {
    std::ofstream out(out_path, std::ios::trunc);
    out << table.str();
    if (!out.good()) {
      std::fprintf(stderr, "cannot write %s\n", out_path.c_str());
      return 1;
    }
  }
  std::error_code ec;
  if (cache.empty()) fs::remove_all(work, ec);
  if (chain_not_calibrated > 0) {
    std::fprintf(stderr,
                 "calibration_benchmark: %zu calibrations not run: the chain lacked a sensor's "
                 "tracks (causes under the tables)\n",
                 chain_not_calibrated);
    return 1;
  }
  return 0;
}
