// A site that stays calibrated: how soon lrfnetd flags a moved sensor, how well it corrects it,
// and how often it flags one that did not move. Per case and seed, through the whole chain:
//
//   `lrfnet sim` of a 12 x 8 m room (three TiM561, two people walking, two pieces of furniture)
//   for 40 s without a move → `lrfnet-tracker --replay` per sensor → `lrfnet calibrate` (the site's
//   calibration); then the same room for 100 s in which, at a random time between 35 s and 65 s,
//   s2 is turned (0.5, 2, 10 deg) or pushed (0.02, 0.1, 0.5 m in a random direction), or only the
//   furniture is moved (a cabinet removed, a cart parked) → trackers → `lrfnetd --input
//   --calibration-in` (monitoring on, default options) → its stats, fused tracks and calibration.
//
//   monitoring_benchmark --tool LRFNET --tracker TRACKER --daemon LRFNETD [--seeds 5]
//                        [--out results/monitoring_benchmark.md] [--only CASE] [--keep yes]
//                        [--seed K] [--duration-s 100] [--tracker-config FILE]
//
// --seed runs only seed K (a row's worst run again); --duration-s replays longer runs (the move
// still between 35 s and 65 s) to see what a correction becomes with more time;
// --tracker-config runs the trackers with other options (e.g. the track covariances of an
// earlier tracker, to see where an unmoved sensor's track chi^2 comes from).
//
// Per case: runs flagged, time from the move to the flag (gateway time), the method that flagged,
// the error of the corrected pose against the new truth (the motion the daemon applied to the
// site's calibration vs the true motion, so that the calibration's own error does not count; and
// the final pose against the new truth in absolute terms), fused track snapshots that held s2
// between the move and the flag and between the flag and the first correction (the latter should
// be none), false flags (any flag of a sensor that had not moved, or before the move) per
// sensor-hour.

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "central_daemon/calibration/calibration_yaml.h"
#include "central_daemon/calibration/eval.h"
#include "central_daemon/calibration/pose_history.h"
#include "common/geometry.h"
#include "tests/bench/bench_util.h"

namespace {

namespace fs = std::filesystem;
using namespace lrfnet;
using bench::Arg;
using bench::RunProcess;

std::string ReadText(const fs::path& path) {
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

constexpr double kCalibrationS = 40.0;

// The room; `s2_moves` and `changes` are YAML flow lists (possibly empty).
std::string Scenario(int seed, double duration_s, const std::string& s2_moves,
                     const std::string& changes) {
  std::ostringstream s;
  s << "name: monitoring_room\nseed: " << seed << "\nduration_s: " << duration_s << R"(
world:
  walls:
    - [[0, 0], [12, 0], [12, 8], [0, 8], [0, 0]]
  obstacles:
    - [[5.5, 7.0], [7.5, 7.0], [7.5, 7.6], [5.5, 7.6]]
    - [[2.0, 7.4], [3.5, 7.4], [3.5, 7.9], [2.0, 7.9]]
  changes: )"
    << changes << R"(
sensors:
  - {id: s1, model: tim561, x_m: 0.3, y_m: 0.3, yaw_deg: 40}
  - {id: s2, model: tim561, x_m: 11.7, y_m: 0.3, yaw_deg: 140, moves: )"
    << s2_moves << R"(}
  - {id: s3, model: tim561, x_m: 11.7, y_m: 7.7, yaw_deg: -140}
targets:
  - {shape: person, path: [[2.5, 2], [9.5, 2], [9.5, 5.5], [2.5, 5.5]], speed_mps: 1.2, loop: true}
  - {shape: person, path: [[4, 3.5], [8.5, 3.5], [6.5, 6]], speed_mps: 1.0, loop: true}
)";
  return s.str();
}

struct Case {
  std::string name;
  double yaw_deg = 0.0;        // turn of s2
  double translation_m = 0.0;  // push of s2 (random direction)
  bool furniture = false;      // only the furniture moves
  bool tracks_alone = false;   // the background never flags (only the tracks can)
};

struct Tally {
  int runs = 0, failed = 0, flagged = 0, corrected = 0;
  std::vector<double> flag_delay_s, motion_err_deg, motion_err_m, pose_err_deg, pose_err_m;
  std::map<std::string, int> methods;
  std::size_t fused_before_flag = 0, fused_while_flagged = 0, coasting_after_flag = 0;
  int false_flags = 0;
  int flagged_again = 0;          // the moved sensor flagged again after its first flag
  double max_track_chi2 = 0.0;    // largest track-check chi^2 of a sensor that had not moved
  double watched_sensor_s = 0.0;  // time of sensors that had not moved
};

double Mean(const std::vector<double>& v) {
  double s = 0.0;
  for (double x : v) s += x;
  return v.empty() ? std::nan("") : s / static_cast<double>(v.size());
}
double Max(const std::vector<double>& v) {
  return v.empty() ? std::nan("") : *std::max_element(v.begin(), v.end());
}
std::string Num(double v, const char* format) {
  if (std::isnan(v)) return "–";
  char buf[64];
  std::snprintf(buf, sizeof buf, format, v);
  return buf;
}

// Simulates `scenario` into dir/sim and replays each capture through the tracker into dir/ID.rec.
bool SimulateAndTrack(const fs::path& dir, const std::string& scenario, const std::string& tool,
                      const std::string& tracker, const std::string& log,
                      const std::string& tracker_config = "") {
  fs::create_directories(dir);
  std::ofstream(dir / "scenario.yaml") << scenario;
  if (RunProcess({tool, "sim", (dir / "scenario.yaml").string(), "--out", (dir / "sim").string(),
                  "--log-level", "warn"},
                 log) != 0) {
    return false;
  }
  for (const char* id : {"s1", "s2", "s3"}) {
    std::vector<std::string> args = {
        tracker, "--replay", (dir / "sim" / (std::string(id) + ".pcap")).string(), "--sensor-id",
        id,      "--out",    (dir / (std::string(id) + ".rec")).string(),          "--log-level",
        "warn"};
    if (!tracker_config.empty()) {
      args.push_back("--config");
      args.push_back(tracker_config);
    }
    if (RunProcess(args, log) != 0) {
      return false;
    }
  }
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  const std::string tool = Arg(argc, argv, "--tool", "");
  const std::string tracker = Arg(argc, argv, "--tracker", "");
  const std::string daemon = Arg(argc, argv, "--daemon", "");
  const int seeds = std::stoi(Arg(argc, argv, "--seeds", "5"));
  const int only_seed = std::stoi(Arg(argc, argv, "--seed", "0"));
  const std::string tracker_config = Arg(argc, argv, "--tracker-config", "");
  const double duration_s = std::stod(Arg(argc, argv, "--duration-s", "100"));
  if (!(duration_s >= 70.0 && duration_s <= 3600.0)) {
    std::fprintf(stderr, "--duration-s must be in [70, 3600]\n");
    return 2;
  }
  const std::string out_path = Arg(argc, argv, "--out", "");
  if (tool.empty() || tracker.empty() || daemon.empty()) {
    std::fprintf(stderr,
                 "usage: monitoring_benchmark --tool LRFNET --tracker TRACKER --daemon LRFNETD "
                 "[--seeds N] [--out FILE]\n");
    return 2;
  }
  const fs::path work =
      fs::temp_directory_path() / ("monitoring_benchmark_" + std::to_string(getpid()));
  fs::create_directories(work);
  const std::string log = (work / "log.txt").string();
  const std::string only = Arg(argc, argv, "--only", "");     // one case by name
  bool keep_work = Arg(argc, argv, "--keep", "no") == "yes";  // or for a look at what failed
  // Diagnostic: lrfnetd is given the site calibration's poses alone (no sigmas, no radial
  // biases), as it read a calibration.yaml before it kept them: the monitoring and the fusion
  // then take every placement as exact.
  const bool poses_only = Arg(argc, argv, "--poses-only", "no") == "yes";

  // The daemon's options for the tracks-alone cases: a background motion is never significant
  // (the snapshots still correct a pose once the tracks flagged it).
  const fs::path tracks_alone_config = work / "tracks_alone.yaml";
  std::ofstream(tracks_alone_config) << "monitoring:\n  background_min_chi2: 1.0e12\n";
  const std::vector<Case> cases = {
      {"turned 0.5°", 0.5, 0.0, false},  {"turned 2°", 2.0, 0.0, false},
      {"turned 10°", 10.0, 0.0, false},  {"pushed 0.02 m", 0.0, 0.02, false},
      {"pushed 0.1 m", 0.0, 0.1, false}, {"pushed 0.5 m", 0.0, 0.5, false},
      {"furniture only", 0.0, 0.0, true},
      // The same moves where the background cannot flag (a scene without structure in range):
      // what the track check alone detects.
      {"turned 2°, tracks alone", 2.0, 0.0, false, true},
      {"turned 5°, tracks alone", 5.0, 0.0, false, true},
      {"pushed 0.1 m, tracks alone", 0.0, 0.1, false, true},
      {"pushed 0.2 m, tracks alone", 0.0, 0.2, false, true}};
  const common::Pose2 s2_before{11.7, 0.3, common::DegToRad(140.0)};
  std::map<std::string, Tally> tallies;

  for (int seed = 1; seed <= seeds; ++seed) {
    if (only_seed != 0 && seed != only_seed) continue;
    // The site's calibration, from 40 s before any move (same room and seed).
    const fs::path calib_dir = work / ("calibration_" + std::to_string(seed));
    if (!SimulateAndTrack(calib_dir, Scenario(seed, kCalibrationS, "[]", "[]"), tool, tracker, log,
                          tracker_config) ||
        RunProcess(
            {tool, "calibrate", (calib_dir / "s1.rec").string(), (calib_dir / "s2.rec").string(),
             (calib_dir / "s3.rec").string(), "--out", (calib_dir / "calibration.yaml").string()},
            log) != 0) {
      std::fprintf(stderr, "seed %d: the site's calibration failed (see %s)\n", seed, log.c_str());
      for (const Case& c : cases) ++tallies[c.name].failed;
      continue;
    }
    calib::PoseFile initial;
    std::string error;
    if (!calib::ReadPoseFile((calib_dir / "calibration.yaml").string(), &initial, &error) ||
        !initial.Find("s2")) {
      std::fprintf(stderr, "seed %d: %s\n", seed, error.c_str());
      continue;
    }
    const common::Pose2 s2_calibrated = initial.sensors[*initial.Find("s2")].second;
    fs::path site_calibration = calib_dir / "calibration.yaml";
    if (poses_only) {
      site_calibration = calib_dir / "poses_only.yaml";
      std::ofstream poses(site_calibration);
      if (initial.reference) poses << "reference: \"" << *initial.reference << "\"\n";
      poses << "sensors:\n";
      for (std::size_t i = 0; i < initial.sensors.size(); ++i) {
        const auto& [id, pose] = initial.sensors[i];
        if (!initial.calibrated[i]) {
          poses << "  - {id: \"" << id << "\", calibrated: false}\n";
          continue;
        }
        char line[160];
        std::snprintf(line, sizeof line, "\", x_m: %.17g, y_m: %.17g, yaw_deg: %.17g}\n", pose.x_m,
                      pose.y_m, common::RadToDeg(pose.yaw_rad));
        poses << "  - {id: \"" << id << line;
      }
    }

    for (std::size_t ci = 0; ci < cases.size(); ++ci) {
      const Case& c = cases[ci];
      if (!only.empty() && c.name != only) continue;
      Tally& tally = tallies[c.name];
      std::mt19937 rng(static_cast<std::uint32_t>(seed * 1000 + static_cast<int>(ci)));
      // Whole tenths of a second, so that the scenario holds the time exactly.
      const double at_s =
          std::round(std::uniform_real_distribution<double>(35.0, 65.0)(rng) * 10.0) / 10.0;
      // Into the room (s2 stands in a corner): 146 deg (towards the room's middle) +- 45 deg.
      const double direction =
          common::DegToRad(146.0 + std::uniform_real_distribution<double>(-45.0, 45.0)(rng));
      common::Pose2 s2_after = s2_before;
      std::string moves = "[]", changes = "[]";
      char text[256];
      if (c.furniture) {
        std::snprintf(text, sizeof text,
                      "[{at_s: %.1f, remove: 1}, {at_s: %.1f, add: [[8.0, 0.8], [8.9, 0.8], "
                      "[8.9, 1.4], [8.0, 1.4]]}]",
                      at_s, at_s);
        changes = text;
      } else {
        s2_after = common::Pose2{s2_before.x_m + c.translation_m * std::cos(direction),
                                 s2_before.y_m + c.translation_m * std::sin(direction),
                                 s2_before.yaw_rad + common::DegToRad(c.yaw_deg)};
        std::snprintf(text, sizeof text, "[{at_s: %.1f, x_m: %.4f, y_m: %.4f, yaw_deg: %.4f}]",
                      at_s, s2_after.x_m, s2_after.y_m, common::RadToDeg(s2_after.yaw_rad));
        moves = text;
      }
      const fs::path dir = work / ("run_" + std::to_string(seed) + "_" + std::to_string(ci));
      ++tally.runs;
      std::vector<std::string> daemon_args = {
          daemon, "--input", (dir / "s1.rec").string(), (dir / "s2.rec").string(),
          (dir / "s3.rec").string(), "--calibration-in", site_calibration.string(),
          "--calibration-out", (dir / "calibration.yaml").string(), "--fused-out",
          (dir / "fused.jsonl").string(), "--stats-out", (dir / "stats.json").string(),
          "--log-level", "warn"};
      if (c.tracks_alone) {
        daemon_args.push_back("--config");
        daemon_args.push_back(tracks_alone_config.string());
      }
      if (!SimulateAndTrack(dir, Scenario(seed, duration_s, moves, changes), tool, tracker, log,
                            tracker_config) ||
          RunProcess(daemon_args, log) != 0) {
        std::fprintf(stderr, "%s seed %d: the chain failed (see %s)\n", c.name.c_str(), seed,
                     log.c_str());
        ++tally.failed;
        keep_work = true;
        continue;
      }
      // The run's start (gateway UTC): the first pose's from_utc_ns.
      const std::string truth_text = ReadText(dir / "sim/truth.yaml");
      const std::size_t start_at = truth_text.find("from_utc_ns: ");
      if (start_at == std::string::npos) {
        ++tally.failed;
        continue;
      }
      const std::int64_t start_ns = std::stoll(truth_text.substr(start_at + 13));
      const std::int64_t move_ns = start_ns + static_cast<std::int64_t>(std::llround(at_s * 1e9));

      const nlohmann::json stats =
          nlohmann::json::parse(ReadText(dir / "stats.json"), nullptr, false);
      if (!stats.is_object() || !stats["monitoring"].is_object()) {
        ++tally.failed;
        continue;
      }
      std::string run_chi2;
      for (const auto& [id, sensor] : stats["monitoring"]["sensors"].items()) {
        if (id == "s2" && !c.furniture) continue;
        const double chi2 = sensor.value("max_track_chi2", 0.0);
        tally.max_track_chi2 = std::max(tally.max_track_chi2, chi2);
        run_chi2 += " " + id + " " + Num(chi2, "%.1f");
      }
      std::int64_t flagged_ns = 0, corrected_ns = 0;
      for (const auto& e : stats["monitoring"]["history"]) {
        const std::int64_t stamp = e.value("stamp_ns", std::int64_t{0});
        const std::string sensor = e.value("sensor", "");
        const std::string event = e.value("event", "");
        if (event != "moved") {
          if (event == "corrected" && sensor == "s2" && flagged_ns != 0 && corrected_ns == 0) {
            corrected_ns = stamp;
          }
          continue;
        }
        const double at = static_cast<double>(stamp - start_ns) * 1e-9;
        const bool moved_sensor = !c.furniture && sensor == "s2" && stamp >= move_ns;
        if (moved_sensor && flagged_ns != 0) {
          ++tally.flagged_again;
          std::fprintf(stderr, "  %s flagged again at %.1f s: %s\n", sensor.c_str(), at,
                       e.value("detail", "").c_str());
          continue;
        }
        if (!moved_sensor) {
          ++tally.false_flags;
          std::fprintf(stderr, "  false flag of %s at %.1f s: %s\n", sensor.c_str(), at,
                       e.value("detail", "").c_str());
          continue;
        }
        flagged_ns = stamp;
        ++tally.methods[e.value("method", "?")];
      }
      tally.watched_sensor_s += c.furniture ? 3.0 * duration_s : 2.0 * duration_s + at_s;
      if (flagged_ns != 0) {
        ++tally.flagged;
        tally.flag_delay_s.push_back(static_cast<double>(flagged_ns - move_ns) * 1e-9);
      }
      if (corrected_ns != 0) ++tally.corrected;

      // Fused snapshots holding a track from s2 while its pose was wrong (a snapshot stamped at
      // the flag's own time was published before it), and fused tracks fed by s2 alone before the
      // flag that coast on after it (until fusion.max_coast_s).
      std::set<std::uint64_t> s2_only;
      std::istringstream fused(ReadText(dir / "fused.jsonl"));
      for (std::string line; std::getline(fused, line);) {
        const nlohmann::json f = nlohmann::json::parse(line, nullptr, false);
        if (!f.is_object() || c.furniture) continue;
        const std::int64_t stamp = f.value("stamp_ns", std::int64_t{0});
        if (stamp < move_ns) continue;
        const bool after_flag = flagged_ns != 0 && stamp > flagged_ns;
        bool with_s2 = false;
        for (const auto& t : f["tracks"]) {
          bool only_s2 = !t["sources"].empty();
          for (const auto& source : t["sources"]) {
            with_s2 = with_s2 || source["sensor"] == "s2";
            only_s2 = only_s2 && source["sensor"] == "s2";
          }
          const std::uint64_t id = t.value("id", std::uint64_t{0});
          if (!after_flag && only_s2) s2_only.insert(id);
          if (after_flag && (corrected_ns == 0 || stamp < corrected_ns) && t["sources"].empty() &&
              s2_only.count(id) != 0) {
            ++tally.coasting_after_flag;
          }
        }
        if (!with_s2) continue;
        if (!after_flag) {
          ++tally.fused_before_flag;
        } else if (corrected_ns == 0 || stamp < corrected_ns) {
          ++tally.fused_while_flagged;
        }
      }

      // The pose the daemon ends with against the new truth.
      double run_motion_err_deg = std::nan(""), run_motion_err_m = std::nan("");
      calib::PoseFile final_file;
      if (!c.furniture &&
          calib::ReadPoseFile((dir / "calibration.yaml").string(), &final_file, &error) &&
          final_file.Find("s2")) {
        const common::Pose2 s2_final = final_file.sensors[*final_file.Find("s2")].second;
        const common::Pose2 motion = s2_calibrated.inverse() * s2_final;
        const common::Pose2 true_motion = s2_before.inverse() * s2_after;
        // A move that was not flagged leaves the pose as calibrated: its error is the move.
        run_motion_err_deg = common::RadToDeg(common::RotationDistanceRad(motion, true_motion));
        run_motion_err_m = common::TranslationDistanceM(motion, true_motion);
        tally.motion_err_deg.push_back(run_motion_err_deg);
        tally.motion_err_m.push_back(run_motion_err_m);
        // Against the truth at the end, in s1's frame (the calibration's world is its reference
        // sensor's frame), as `lrfnet eval`.
        calib::PoseFile truth_end;
        if (calib::TruthPosesAt(truth_text, duration_s, &truth_end, &error)) {
          const calib::EvalResult eval = calib::Evaluate(final_file, truth_end, "s1");
          for (const calib::SensorError& se : eval.sensors) {
            if (se.id != "s2") continue;
            tally.pose_err_deg.push_back(se.d_r_deg);
            tally.pose_err_m.push_back(se.d_t_m);
          }
        }
      }
      std::fprintf(
          stderr,
          "%s seed %d: move at %.1f s, flagged %s, corrected %s, motion error %s / %s, track "
          "chi2 max of the unmoved:%s\n",
          c.name.c_str(), seed, at_s,
          flagged_ns ? Num(static_cast<double>(flagged_ns - move_ns) * 1e-9, "%.1f s after").c_str()
                     : "no",
          corrected_ns ? "yes" : "no", Num(run_motion_err_deg, "%.3f°").c_str(),
          Num(run_motion_err_m, "%.3f m").c_str(), run_chi2.c_str());
    }
  }

  std::ostringstream table;
  table << "# Monitoring benchmark\n\n"
        << "`tests/bench/monitoring_benchmark`, " << seeds
        << " seeds per case. Per seed: a 12 x 8 m room with three TiM561, two people walking "
           "loops and two pieces of furniture; the site is calibrated (`lrfnet calibrate`) from "
           "40 s without a move, then `lrfnetd --input --calibration-in` (monitoring on, default "
           "options) replays "
        << duration_s
        << " s of the same room in which, at a random time between 35 and "
           "65 s, s2 is turned or pushed (into the room, random direction within 45° of its "
           "middle), or only the furniture moves (a "
           "cabinet taken away, a cart parked). Times are gateway time from the move to the "
           "flag. *Motion error*: the correction the daemon applied to the site's calibration "
           "against the true motion (the calibration's own error does not count); *pose error*: "
           "the final pose against the new truth in s1's frame, as `lrfnet eval` (includes it). A "
           "move "
           "that is never flagged "
           "keeps its calibrated pose, so its error is the move itself. *Fused before flag*: "
           "fused snapshots (15 Hz) holding a track from s2 between the move and the flag; "
           "*while flagged*: after the flag and before the first correction (goal: 0). *Coasting "
           "after flag*: track-snapshots of fused tracks fed by s2 alone before the flag that "
           "coast on (no source, predicted) after it until the fusion drops them (0 where the "
           "fusion does not publish fused tracks without sources: fusion.report_sourceless off, "
           "the default). *Flagged again*: "
           "the moved sensor flagged once more after its first flag (its correction was doubted). "
           "*False flags*: flags of a sensor that had not moved (or before its move), per "
           "sensor-hour; *track χ² max*: the largest χ² of a track check of a sensor that had not "
           "moved (it flags at tracks_min_chi2 = 25, on two consecutive checks). *Tracks alone*: "
           "the background's motions are never significant (background_min_chi2 1e12, as in a "
           "scene without structure in range), so only the track check can flag; snapshots still "
           "correct the pose after the flag."
        << (poses_only ? " **--poses-only**: lrfnetd is given the site calibration's poses "
                         "alone (no sigmas, no radial biases), as it read a calibration.yaml "
                         "before it kept them."
                       : "")
        << "\n\n"
        << "| case | runs | flagged | move → flag mean / max [s] | flagged by | corrected | "
           "motion error mean / max [°] | [m] | pose error mean / max [°] | [m] | fused before "
           "flag | while flagged | coasting after flag | flagged again | false flags | per "
           "sensor-hour | track χ² max |\n"
        << "|---|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";
  for (const Case& c : cases) {
    if (!only.empty() && c.name != only) continue;
    const Tally& t = tallies[c.name];
    std::string methods;
    for (const auto& [m, n] : t.methods) {
      methods += (methods.empty() ? "" : ", ") + m + " ×" + std::to_string(n);
    }
    const double hours = t.watched_sensor_s / 3600.0;
    table << "| " << c.name << " | " << t.runs - t.failed
          << (t.failed ? " (+" + std::to_string(t.failed) + " failed)" : "") << " | "
          << (c.furniture ? "–" : std::to_string(t.flagged)) << " | "
          << Num(Mean(t.flag_delay_s), "%.1f") << " / " << Num(Max(t.flag_delay_s), "%.1f") << " | "
          << (methods.empty() ? "–" : methods) << " | "
          << (c.furniture ? "–" : std::to_string(t.corrected)) << " | "
          << Num(Mean(t.motion_err_deg), "%.3f") << " / " << Num(Max(t.motion_err_deg), "%.3f")
          << " | " << Num(Mean(t.motion_err_m), "%.3f") << " / " << Num(Max(t.motion_err_m), "%.3f")
          << " | " << Num(Mean(t.pose_err_deg), "%.3f") << " / " << Num(Max(t.pose_err_deg), "%.3f")
          << " | " << Num(Mean(t.pose_err_m), "%.3f") << " / " << Num(Max(t.pose_err_m), "%.3f")
          << " | " << (c.furniture ? "–" : std::to_string(t.fused_before_flag)) << " | "
          << (c.furniture ? "–" : std::to_string(t.fused_while_flagged)) << " | "
          << (c.furniture ? "–" : std::to_string(t.coasting_after_flag)) << " | "
          << (c.furniture ? "–" : std::to_string(t.flagged_again)) << " | " << t.false_flags
          << " | " << Num(hours > 0 ? t.false_flags / hours : std::nan(""), "%.1f") << " | "
          << Num(t.max_track_chi2, "%.1f") << " |\n";
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
  if (!keep_work) fs::remove_all(work);
  return 0;
}
