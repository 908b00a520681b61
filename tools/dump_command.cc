// lrfnet dump CAPTURE [--summary] [--port P]

#include <boost/program_options.hpp>
#include <cstdio>
#include <iostream>
#include <string>

#include "tools/dump.h"
#include "tools/subcommands.h"

namespace lrfnet::tools {

namespace po = boost::program_options;

int RunDump(int argc, char** argv) {
  po::options_description visible(
      "lrfnet dump CAPTURE [options]\n"
      "Prints one JSON object per sSN LMDscandata telegram of the scanner -> client TCP stream of "
      "a pcap or\n"
      "pcapng capture (keys sorted, as the golden files of the shared data). Options",
      100, 50);
  int port = 2112;
  std::string log_level = "warn";
  visible.add_options()("help,h", "this help")(
      "summary", "print one JSON object with frame, telegram and TCP counts instead of the scans")(
      "port", po::value<int>(&port)->default_value(2112), "the scanner's TCP port in the capture")(
      "log-level", po::value<std::string>(&log_level)->default_value("warn"),
      "trace, debug, info, warn, error or off (stderr)");
  po::variables_map vm;
  if (auto exit_code = ParseOptions("dump", argc, argv, visible, "capture", &vm)) return *exit_code;
  if (vm.count("capture") == 0)
    return UsageError("dump", "missing CAPTURE (a .pcap or .pcapng file)");
  if (port < 1 || port > 65535) return UsageError("dump", "--port must be 1..65535");
  if (!SetUpLogging(log_level))
    return UsageError("dump", "unknown --log-level '" + log_level + "'");

  DumpOptions options;
  options.capture.sensor_port = static_cast<std::uint16_t>(port);
  if (auto e = io::Validate(options.capture)) return UsageError("dump", *e);
  const bool summary_only = vm.count("summary") != 0;
  const std::string path = vm["capture"].as<std::string>();

  DumpSummary summary;
  std::string error;
  std::ios::sync_with_stdio(false);
  const bool ok = DumpCapture(path, options, summary_only ? nullptr : &std::cout, &summary, &error);
  if (summary_only && (ok || summary.capture.packets > 0))
    std::cout << SummaryJson(summary) << "\n";
  std::cout.flush();
  if (!ok) {
    std::fprintf(stderr, "lrfnet dump: %s\n", error.c_str());
    return kExitFailure;
  }
  return kExitOk;
}

}  // namespace lrfnet::tools
