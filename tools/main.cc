// lrfnet: the tools binary. `lrfnet <subcommand> [options]`; see subcommands.h.

#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <cstdio>
#include <cstring>
#include <exception>
#include <iostream>
#include <string>

#include "tools/subcommands.h"

namespace lrfnet::tools {
namespace {

struct Subcommand {
  const char* name;
  const char* summary;
  int (*run)(int argc, char** argv);
};

constexpr Subcommand kSubcommands[] = {
    {"calibrate", "every sensor's pose from recordings or UDP captures of the tracks",
     RunCalibrate},
    {"dump", "scans of a capture, or datagrams of a recording or UDP capture, as JSON lines",
     RunDump},
    {"emulate", "serve a capture's scans (or synthetic ones) as a SICK device on TCP", RunEmulate},
    {"eval", "errors d_R, d_t of a calibration against the truth, per sensor", RunEval},
    {"export", "a calibration as ROS 2 static transforms, URDF or CSV", RunExport},
    {"keys", "site and sensor keys of authenticated datagrams, the live view's token", RunKeys},
    {"replay", "send a recording or UDP capture to HOST:PORT over UDP with its timing", RunReplay},
    {"sim", "simulate a scenario: per-sensor captures and ground truth, or live devices", RunSim},
};

std::string Names() {
  std::string names;
  for (const Subcommand& s : kSubcommands) names += std::string(names.empty() ? "" : "|") + s.name;
  return names;
}

void PrintUsage(std::FILE* out) {
  std::fprintf(out, "usage: lrfnet {%s} [options]   (lrfnet SUBCOMMAND --help for its options)\n\n",
               Names().c_str());
  for (const Subcommand& s : kSubcommands) std::fprintf(out, "  %-10s %s\n", s.name, s.summary);
}

}  // namespace

int UsageError(const std::string& subcommand, const std::string& message) {
  std::fprintf(stderr, "lrfnet %s: %s (see lrfnet %s --help)\n", subcommand.c_str(),
               message.c_str(), subcommand.c_str());
  return kExitUsage;
}

std::optional<int> ParseOptions(const std::string& subcommand, int argc, char** argv,
                                const boost::program_options::options_description& visible,
                                const std::string& positional,
                                boost::program_options::variables_map* vm) {
  namespace po = boost::program_options;
  po::options_description hidden;
  hidden.add_options()(positional.c_str(), po::value<std::string>(), "positional argument");
  po::options_description all;
  all.add(visible).add(hidden);
  po::positional_options_description positional_options;
  positional_options.add(positional.c_str(), 1);
  try {
    po::store(po::command_line_parser(argc, argv).options(all).positional(positional_options).run(),
              *vm);
    po::notify(*vm);
  } catch (const po::error& e) {
    return UsageError(subcommand, e.what());
  }
  if (vm->count("help") != 0) {
    std::cout << visible << "\n";
    return kExitOk;
  }
  return std::nullopt;
}

bool SetUpLogging(const std::string& level) {
  const spdlog::level::level_enum parsed = spdlog::level::from_str(level);
  // from_str maps unknown names to "off": accept "off" only when asked for.
  if (parsed == spdlog::level::off && level != "off") return false;
  auto logger = spdlog::stderr_color_mt("lrfnet");
  spdlog::set_default_logger(logger);
  spdlog::set_level(parsed);
  return true;
}

}  // namespace lrfnet::tools

int main(int argc, char** argv) {
  using namespace lrfnet::tools;
  if (argc < 2) {
    std::fprintf(stderr,
                 "lrfnet: missing subcommand; usage: lrfnet {%s} [options] (see lrfnet --help)\n",
                 Names().c_str());
    return kExitUsage;
  }
  const std::string name = argv[1];
  if (name == "--help" || name == "-h" || name == "help") {
    PrintUsage(stdout);
    return kExitOk;
  }
  for (const Subcommand& s : kSubcommands) {
    if (name != s.name) continue;
    try {
      return s.run(argc - 1, argv + 1);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "lrfnet %s: %s\n", s.name, e.what());
      return kExitFailure;
    }
  }
  std::fprintf(
      stderr, "lrfnet: unknown subcommand '%s'; usage: lrfnet {%s} [options] (see lrfnet --help)\n",
      name.c_str(), Names().c_str());
  return kExitUsage;
}
