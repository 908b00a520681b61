// lrfnet sim SCENARIO --out DIR | --serve [--speed X] [--loop] [--base-port P]
// [--duration S] [--seed N] [--jobs N]

#include <spdlog/spdlog.h>

#include <boost/asio/io_context.hpp>
#include <boost/asio/signal_set.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/program_options.hpp>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "tools/emulator.h"
#include "tools/sim/scenario.h"
#include "tools/sim/sim_output.h"
#include "tools/sim/sim_scan_source.h"
#include "tools/sim/simulator.h"
#include "tools/subcommands.h"

namespace lrfnet::tools {

namespace po = boost::program_options;

namespace {

// After the scenario's end (without --loop) the servers stay up this long, so clients read the
// last scans, then the command exits.
constexpr double kServeGraceS = 1.0;

int Serve(std::shared_ptr<const sim::Simulator> simulator, const EmulatorOptions& base_options,
          int base_port, const std::string& truth_dir) {
  const sim::Scenario& scenario = simulator->scenario();
  boost::asio::io_context io;
  // Taken over before the ports are printed: a signal from a script that reacts to them must not
  // find the default action still in place (it would kill the process).
  boost::asio::signal_set signals(io, SIGINT, SIGTERM);
  using Clock = std::chrono::steady_clock;
  Clock::time_point start = Clock::now();
  const double speed = base_options.speed;
  const auto now_s = [&start, speed]() {
    return std::chrono::duration<double>(Clock::now() - start).count() * speed;
  };
  if (base_port != 0 && base_port + static_cast<int>(simulator->sensor_count()) - 1 > 65535) {
    return UsageError("sim", "--base-port leaves no room for " +
                                 std::to_string(simulator->sensor_count()) + " ports");
  }
  std::vector<std::unique_ptr<Emulator>> emulators;
  for (std::size_t i = 0; i < simulator->sensor_count(); ++i) {
    EmulatorOptions options = base_options;
    options.port = base_port == 0 ? 0 : static_cast<std::uint16_t>(base_port + static_cast<int>(i));
    emulators.push_back(
        std::make_unique<Emulator>(io, options, sim::MakeSimScanSource(simulator, i, now_s)));
    std::string error;
    if (!emulators.back()->Start(&error)) {
      std::fprintf(stderr, "lrfnet sim: sensor %s: %s\n", simulator->sensor(i).id.c_str(),
                   error.c_str());
      return kExitFailure;
    }
  }
  // Scenario time 0 is now, for every sensor.
  start = Clock::now();
  const std::int64_t start_utc_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                                        std::chrono::system_clock::now().time_since_epoch())
                                        .count();
  for (std::size_t i = 0; i < emulators.size(); ++i) {
    std::printf("%s %s:%u\n", simulator->sensor(i).id.c_str(), base_options.bind_address.c_str(),
                static_cast<unsigned>(emulators[i]->port()));
  }
  std::fflush(stdout);
  if (!truth_dir.empty()) {
    std::string error;
    std::error_code ec;
    std::filesystem::create_directories(truth_dir, ec);
    const std::string truth_path = (std::filesystem::path(truth_dir) / "truth.yaml").string();
    std::ofstream truth(truth_path, std::ios::trunc);
    truth << sim::TruthYaml(*simulator, start_utc_ns, false);
    if (!truth.good() ||
        !sim::WriteTruthTracks(*simulator, start_utc_ns,
                               (std::filesystem::path(truth_dir) / "truth_tracks.csv").string(),
                               &error)) {
      std::fprintf(stderr, "lrfnet sim: cannot write the truth into %s %s\n", truth_dir.c_str(),
                   error.c_str());
      return kExitFailure;
    }
    if (speed != 1.0) {
      spdlog::warn(
          "truth times assume --speed 1; with --speed {} scenario time t is wall time t / {}",
          speed, speed);
    }
  }

  const auto stop_all = [&]() {
    for (auto& e : emulators) e->Stop();
  };
  boost::asio::steady_timer end_timer(io);
  signals.async_wait([&](const boost::system::error_code& ec, int signal_number) {
    if (ec) return;
    spdlog::info("signal {}: stopping", signal_number);
    stop_all();
    // Without --loop the end-of-scenario timer would keep the loop running to the scenario's end.
    end_timer.cancel();
    io.stop();
  });
  if (!base_options.loop) {
    const double end_s = (scenario.duration_s + kServeGraceS) / speed;
    end_timer.expires_after(
        std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(end_s)));
    end_timer.async_wait([&](const boost::system::error_code& ec) {
      if (ec) return;
      spdlog::info("scenario '{}' finished after {} s", scenario.name, scenario.duration_s);
      stop_all();
      signals.cancel();
    });
  }
  io.run();
  for (std::size_t i = 0; i < emulators.size(); ++i) {
    const EmulatorCounters& c = emulators[i]->counters();
    spdlog::info("{}: {} connections, {} scans sent", simulator->sensor(i).id, c.connections,
                 c.scans_sent);
  }
  return kExitOk;
}

}  // namespace

int RunSim(int argc, char** argv) {
  po::options_description visible(
      "lrfnet sim SCENARIO (--out DIR | --serve) [options]\n"
      "Simulates the sensors of a scenario (a YAML file, or the name of a shipped one such as "
      "quenzel_sim).\n"
      "--out DIR writes DIR/<sensor id>.pcap (each sensor's CoLa-B session as its gateway captures "
      "it),\n"
      "DIR/truth.yaml (sensor poses) and DIR/truth_tracks.csv (target positions). --serve runs one "
      "emulated\n"
      "SICK device per sensor on TCP and prints '<sensor id> <address>:<port>' per line. Options",
      100, 50);
  std::string out_dir;
  bool serve = false;
  double duration = 0;
  long long seed = -1;
  int jobs = 1;
  int base_port = 0;
  std::string log_level = "info";
  EmulatorOptions emulator_options;
  visible.add_options()("help,h", "this help")("out", po::value<std::string>(&out_dir),
                                               "write captures and truth into this folder")(
      "serve", po::bool_switch(&serve),
      "serve the sensors as emulated devices on TCP (loopback by default)")(
      "duration", po::value<double>(&duration), "override the scenario's duration_s")(
      "seed", po::value<long long>(&seed), "override the scenario's seed")(
      "jobs", po::value<int>(&jobs)->default_value(1), "sensors simulated in parallel (--out)")(
      "speed", po::value<double>(&emulator_options.speed)->default_value(1.0),
      "--serve: scenario seconds per wall-clock second")(
      "loop", po::bool_switch(&emulator_options.loop),
      "--serve: repeat the scenario instead of exiting at its end")(
      "base-port", po::value<int>(&base_port)->default_value(0),
      "--serve: sensor i listens on this port + i (0: any free ports)")(
      "bind", po::value<std::string>(&emulator_options.bind_address)->default_value("127.0.0.1"),
      "--serve: address to listen on")(
      "ready-after", po::value<double>(&emulator_options.ready_after_run_s),
      "--serve: seconds from sMN Run until a device reports ready (default: its family's)")(
      "log-level", po::value<std::string>(&log_level)->default_value("info"),
      "trace, debug, info, warn, error or off (stderr)");
  po::variables_map vm;
  if (auto exit_code = ParseOptions("sim", argc, argv, visible, "scenario", &vm)) return *exit_code;
  if (vm.count("scenario") == 0) return UsageError("sim", "missing SCENARIO");
  if (!serve && out_dir.empty()) return UsageError("sim", "give --out DIR or --serve");
  if (vm.count("duration") != 0 && !(duration > 0.0))
    return UsageError("sim", "--duration must be > 0");
  if (jobs < 1 || jobs > 256) return UsageError("sim", "--jobs must be 1..256");
  if (base_port < 0 || base_port > 65535) return UsageError("sim", "--base-port must be 0..65535");
  if (!serve && (vm["speed"].defaulted() == false || emulator_options.loop ||
                 !vm["base-port"].defaulted() || vm.count("ready-after") != 0)) {
    return UsageError("sim", "--speed, --loop, --base-port and --ready-after need --serve");
  }
  if (vm.count("ready-after") != 0 && !(emulator_options.ready_after_run_s >= 0.0)) {
    return UsageError("sim", "--ready-after must be >= 0");
  }
  if (auto e = Validate(emulator_options)) return UsageError("sim", *e);
  if (!SetUpLogging(log_level)) return UsageError("sim", "unknown --log-level '" + log_level + "'");

  const std::string argument = vm["scenario"].as<std::string>();
  const auto path = sim::FindScenarioFile(argument);
  if (!path) {
    std::fprintf(stderr,
                 "lrfnet sim: %s: no such scenario file (nor a shipped scenario of that name)\n",
                 argument.c_str());
    return kExitFailure;
  }
  sim::Scenario scenario;
  std::string error;
  if (!sim::LoadScenarioFile(*path, &scenario, &error)) {
    std::fprintf(stderr, "lrfnet sim: %s\n", error.c_str());
    return kExitUsage;
  }
  if (vm.count("duration") != 0) scenario.duration_s = duration;
  if (seed >= 0) scenario.seed = static_cast<std::uint64_t>(seed);
  if (auto e = sim::Validate(scenario)) {
    std::fprintf(stderr, "lrfnet sim: %s\n", e->c_str());
    return kExitUsage;
  }
  const auto started = std::chrono::steady_clock::now();
  std::shared_ptr<const sim::Simulator> simulator = sim::Simulator::Create(scenario, &error);
  if (!simulator) {
    std::fprintf(stderr, "lrfnet sim: %s\n", error.c_str());
    return kExitUsage;
  }
  if (serve) return Serve(simulator, emulator_options, base_port, out_dir);

  sim::OutputOptions output_options;
  output_options.jobs = jobs;
  std::vector<sim::CaptureSummary> summary;
  if (!sim::WriteSimulation(*simulator, out_dir, output_options, &summary, &error)) {
    std::fprintf(stderr, "lrfnet sim: %s\n", error.c_str());
    return kExitFailure;
  }
  const double wall_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  std::uint64_t scans = 0, bytes = 0;
  for (std::size_t i = 0; i < summary.size(); ++i) {
    std::printf("%s %s/%s.pcap %llu scans\n", simulator->sensor(i).id.c_str(), out_dir.c_str(),
                simulator->sensor(i).id.c_str(), static_cast<unsigned long long>(summary[i].scans));
    scans += summary[i].scans;
    bytes += summary[i].bytes;
  }
  std::printf(
      "lrfnet sim: %s: %zu sensors, %llu scans (%.1f MB of telegrams), %g s simulated in %.2f s\n",
      scenario.name.c_str(), summary.size(), static_cast<unsigned long long>(scans),
      static_cast<double>(bytes) / 1e6, scenario.duration_s, wall_s);
  return kExitOk;
}

}  // namespace lrfnet::tools
