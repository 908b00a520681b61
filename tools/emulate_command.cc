// lrfnet emulate [CAPTURE | --synthetic MODEL] [--port P] [--port-file F] [--speed X] [--loop]
// [faults...]

#include <spdlog/spdlog.h>

#include <boost/asio/io_context.hpp>
#include <boost/asio/signal_set.hpp>
#include <boost/program_options.hpp>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <memory>
#include <string>
#include <tuple>

#include "tools/emulator.h"
#include "tools/scan_source.h"
#include "tools/subcommands.h"

namespace lrfnet::tools {

namespace po = boost::program_options;

namespace {

// Written to F.tmp and renamed, so a script polling for F never reads a half-written number.
bool WritePortFile(const std::string& path, std::uint16_t port, std::string* error) {
  const std::string tmp = path + ".tmp";
  {
    std::ofstream out(tmp, std::ios::trunc);
    out << port << "\n";
    if (!out.good()) {
      *error = "cannot write " + tmp;
      return false;
    }
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    *error = "cannot rename " + tmp + " to " + path + ": " + ec.message();
    return false;
  }
  return true;
}

bool InPortRange(int port, int min) { return port >= min && port <= 65535; }

}  // namespace

int RunEmulate(int argc, char** argv) {
  po::options_description visible(
      "lrfnet emulate [CAPTURE] [options]\n"
      "A SICK scanner on TCP (CoLa-A and CoLa-B on one port): answers the whole SOPAS dialogue of "
      "its\n"
      "device family as the device does (SICK's own driver included) and streams the scans of "
      "CAPTURE\n"
      "(pcap/pcapng; the recorded device's answers are kept) at the recorded pace, or synthetic "
      "scans\n"
      "with --synthetic MODEL. Runs until SIGINT/SIGTERM. Options",
      100, 50);
  int port = 2112;
  int sensor_port = 2112;
  std::string bind = "127.0.0.1";
  std::string port_file;
  std::string synthetic;
  std::string model;
  std::string log_level = "info";
  std::string family;
  EmulatorOptions options;
  EmulatorFaults& faults = options.faults;
  long long fault_stall = 0, fault_close = 0, fault_garbage = 0, fault_sfa_times = 0,
            fault_restart = 0;
  visible.add_options()("help,h", "this help")(
      "synthetic", po::value<std::string>(&synthetic),
      "serve generated scans of MODEL (lms511, lms111, tim561, tim781, tim781s, mrs1104) instead "
      "of a capture")(
      "family", po::value<std::string>(&family),
      "device family whose dialogue to speak (LMS1xx, LMS5xx, TiM5xx, TiM7xx, TiM7xxS, MRS1xxx; "
      "default: from the device name)")(
      "ready-after", po::value<double>(&options.ready_after_run_s),
      "seconds from sMN Run until the device reports ready (default: the family's, MRS1xxx "
      "14.5)")("port", po::value<int>(&port)->default_value(2112),
               "TCP port to listen on (0: any free port)")(
      "bind", po::value<std::string>(&bind)->default_value("127.0.0.1"), "address to listen on")(
      "port-file", po::value<std::string>(&port_file),
      "write the port number to this file once listening")(
      "speed", po::value<double>(&options.speed)->default_value(1.0),
      "scan rate factor (2 = twice as fast)")(
      "loop", po::bool_switch(&options.loop),
      "restart the capture at its end (counters keep increasing)")(
      "model", po::value<std::string>(&model), "device name reported by DeviceIdent")(
      "sensor-port", po::value<int>(&sensor_port)->default_value(2112),
      "the scanner's TCP port inside CAPTURE")(
      "seed", po::value<std::uint64_t>(&options.seed)->default_value(1),
      "seed for noise and garbage bytes")("log-level",
                                          po::value<std::string>(&log_level)->default_value("info"),
                                          "trace, debug, info, warn, error or off (stderr)")(
      "fault-stall-after", po::value<long long>(&fault_stall),
      "on every connection: go silent after N scans (socket stays open)")(
      "fault-close-mid-frame-after", po::value<long long>(&fault_close),
      "on every connection: after N scans send half a scan frame and close")(
      "fault-garbage-every", po::value<long long>(&fault_garbage),
      "before every N-th scan send garbage bytes and a frame with a bad checksum")(
      "fault-sfa", po::value<std::string>(&faults.sfa_command),
      "answer this command (e.g. LMCstartmeas) with an sFA error")(
      "fault-sfa-times", po::value<long long>(&fault_sfa_times),
      "only the first N times (default: always)")("fault-restart-after",
                                                  po::value<long long>(&fault_restart),
                                                  "on every connection: after N scans the device "
                                                  "reboots (connection dropped, counters restart)");
  po::variables_map vm;
  if (auto exit_code = ParseOptions("emulate", argc, argv, visible, "capture", &vm))
    return *exit_code;
  const bool have_capture = vm.count("capture") != 0;
  if (have_capture == !synthetic.empty()) {
    return UsageError("emulate", "give either a CAPTURE file or --synthetic MODEL");
  }
  if (!InPortRange(port, 0)) return UsageError("emulate", "--port must be 0..65535");
  if (!InPortRange(sensor_port, 1)) return UsageError("emulate", "--sensor-port must be 1..65535");
  for (const auto& [value, name, field] :
       {std::tuple{fault_stall, "--fault-stall-after", &faults.stall_after_scans},
        std::tuple{fault_close, "--fault-close-mid-frame-after",
                   &faults.close_mid_frame_after_scans},
        std::tuple{fault_garbage, "--fault-garbage-every", &faults.garbage_every_scans},
        std::tuple{fault_sfa_times, "--fault-sfa-times", &faults.sfa_times},
        std::tuple{fault_restart, "--fault-restart-after", &faults.restart_after_scans}}) {
    if (value < 0 || value > std::numeric_limits<std::uint32_t>::max()) {
      return UsageError("emulate", std::string(name) + " must be a count >= 0");
    }
    *field = static_cast<std::uint32_t>(value);
  }
  options.port = static_cast<std::uint16_t>(port);
  options.bind_address = bind;
  if (!family.empty()) {
    options.family = ParseDeviceFamily(family);
    if (!options.family) return UsageError("emulate", "unknown --family '" + family + "'");
  }
  if (vm.count("ready-after") != 0 && !(options.ready_after_run_s >= 0.0)) {
    return UsageError("emulate", "--ready-after must be >= 0");
  }
  if (auto e = Validate(options)) return UsageError("emulate", *e);
  if (!SetUpLogging(log_level))
    return UsageError("emulate", "unknown --log-level '" + log_level + "'");

  std::unique_ptr<ScanSource> source;
  if (have_capture) {
    CaptureScanSourceOptions source_options;
    source_options.capture.sensor_port = static_cast<std::uint16_t>(sensor_port);
    source_options.model_name = model;
    std::string error;
    source = OpenCaptureScanSource(vm["capture"].as<std::string>(), source_options, &error);
    if (!source) {
      std::fprintf(stderr, "lrfnet emulate: %s\n", error.c_str());
      return kExitFailure;
    }
  } else {
    SyntheticScanOptions source_options;
    source_options.model = synthetic;
    source_options.seed = options.seed;
    if (auto e = Validate(source_options)) return UsageError("emulate", *e);
    source = MakeSyntheticScanSource(source_options);
    if (!model.empty()) {
      spdlog::warn("--model applies to captures only; the synthetic {} keeps its name", synthetic);
    }
  }

  boost::asio::io_context io;
  // Taken over before "listening" is printed: a signal from a script that reacts to that line must
  // not find the default action still in place (it would kill the process).
  boost::asio::signal_set signals(io, SIGINT, SIGTERM);
  Emulator emulator(io, options, std::move(source));
  std::string error;
  if (!emulator.Start(&error)) {
    std::fprintf(stderr, "lrfnet emulate: %s\n", error.c_str());
    return kExitFailure;
  }
  if (!port_file.empty() && !WritePortFile(port_file, emulator.port(), &error)) {
    std::fprintf(stderr, "lrfnet emulate: %s\n", error.c_str());
    return kExitFailure;
  }
  std::printf("lrfnet emulate: listening on %s:%u\n", bind.c_str(),
              static_cast<unsigned>(emulator.port()));
  std::fflush(stdout);

  signals.async_wait([&](const boost::system::error_code& ec, int signal_number) {
    if (ec) return;
    spdlog::info("signal {}: stopping", signal_number);
    emulator.Stop();
    io.stop();  // now, not after the cancelled handlers drained
  });
  io.run();
  const EmulatorCounters& c = emulator.counters();
  const SopasDeviceCounters& d = emulator.device_counters();
  spdlog::info(
      "emulator: {} connections, {} commands ({} in CoLa-A), {} scans sent, {} sFA ({} unknown, {} "
      "denied, {} bad arguments), {} bad frames, {} passes",
      c.connections, c.commands, d.requests_cola_a, c.scans_sent, c.sfa_sent, d.unknown_commands,
      d.access_denied, d.bad_arguments, c.bad_frames, c.passes);
  return kExitOk;
}

}  // namespace lrfnet::tools
