// lrfnet dump FILE [--summary] [--port P] [--datagrams] [--udp-port P]

#include <boost/program_options.hpp>
#include <cstdio>
#include <iostream>
#include <memory>
#include <string>

#include "central_daemon/app/auth_files.h"
#include "central_daemon/io/datagram_source.h"
#include "common/datagram_auth.h"
#include "tools/datagram_json.h"
#include "tools/dump.h"
#include "tools/subcommands.h"

namespace lrfnet::tools {

namespace po = boost::program_options;

namespace {

int DumpScans(const std::string& path, std::uint16_t port, bool summary_only) {
  DumpOptions options;
  options.capture.sensor_port = port;
  if (auto e = capture::Validate(options.capture)) return UsageError("dump", *e);
  DumpSummary summary;
  std::string error;
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

int DumpDatagramFile(const std::string& path, std::uint16_t udp_port, bool summary_only,
                     daemon::DatagramVerifier* verifier) {
  daemon::DatagramSourceOptions options;
  options.udp_port = udp_port;
  std::string error;
  std::unique_ptr<daemon::DatagramSource> source = daemon::OpenDatagramFile(path, options, &error);
  if (!source) {
    if (error.find(path) == std::string::npos) error = path + ": " + error;
    std::fprintf(stderr, "lrfnet dump: %s\n", error.c_str());
    return kExitFailure;
  }
  DatagramSummary summary;
  const bool ok =
      DumpDatagrams(*source, summary_only ? nullptr : &std::cout, &summary, &error, verifier);
  if (summary_only) std::cout << DatagramSummaryJson(summary, *source) << "\n";
  std::cout.flush();
  if (!ok) {
    std::fprintf(stderr, "lrfnet dump: %s\n", error.c_str());
    return kExitFailure;
  }
  return kExitOk;
}

}  // namespace

int RunDump(int argc, char** argv) {
  po::options_description visible(
      "lrfnet dump FILE [options]\n"
      "Prints the content of FILE as JSON lines (keys sorted):\n"
      "- a pcap/pcapng capture of the scanner's TCP stream (packets to or from --port): one "
      "object per\n"
      "  sSN LMDscandata telegram, as the golden files of the shared data;\n"
      "- a recording (lrfnetd --record, lrfnet-tracker --out; rotation parts REC.1, ... "
      "included) or a\n"
      "  pcap/pcapng capture of UDP datagrams (and no scanner TCP stream): one object per "
      "datagram,\n"
      "  {receive_ns, source, size, version, sensor_id, sequence, sent_ns, session_id, kind, "
      "<payload>},\n"
      "  field names as in lrfnet.proto, or {..., \"error\": \"not a lrfnet datagram\"}; sealed "
      "datagrams\n  also {\"auth\": {sensor_id, epoch, counter, encrypted, verified, ...}}.\n"
      "Options",
      100, 50);
  int port = 2112;
  int udp_port = 0;
  std::string log_level = "warn";
  visible.add_options()("help,h", "this help")(
      "summary",
      "print one JSON object with counts instead of the lines (scans: frame, telegram and TCP "
      "counts; datagrams: per sensor and kind, parse errors, first/last receive_ns, file "
      "counters)")("port", po::value<int>(&port)->default_value(2112),
                   "the scanner's TCP port in a capture")(
      "datagrams", "print the UDP datagrams of a capture even when it holds a scanner stream")(
      "udp-port", po::value<int>(&udp_port)->default_value(0),
      "captures: only UDP datagrams to this port (0 = any)")(
      "keys", po::value<std::string>(),
      "verify sealed datagrams with the sensor keys in this folder (and decrypt them); without, "
      "their header is shown and a plain payload read unverified")(
      "log-level", po::value<std::string>(&log_level)->default_value("warn"),
      "trace, debug, info, warn, error or off (stderr)");
  po::variables_map vm;
  if (auto exit_code = ParseOptions("dump", argc, argv, visible, "capture", &vm)) return *exit_code;
  if (vm.count("capture") == 0)
    return UsageError("dump", "missing FILE (a .pcap or .pcapng capture or a recording)");
  if (port < 1 || port > 65535) return UsageError("dump", "--port must be 1..65535");
  if (udp_port < 0 || udp_port > 65535) return UsageError("dump", "--udp-port must be 0..65535");
  if (!SetUpLogging(log_level))
    return UsageError("dump", "unknown --log-level '" + log_level + "'");

  const bool summary_only = vm.count("summary") != 0;
  const std::string path = vm["capture"].as<std::string>();
  const auto tcp_port = static_cast<std::uint16_t>(port);
  const auto datagram_port = static_cast<std::uint16_t>(udp_port);
  std::ios::sync_with_stdio(false);
  const DumpInput input = vm.count("datagrams") != 0
                              ? DumpInput::kDatagrams
                              : ChooseDumpInput(InspectCapture(path, tcp_port, datagram_port));
  if (input == DumpInput::kScans) return DumpScans(path, tcp_port, summary_only);
  std::unique_ptr<daemon::DatagramVerifier> verifier;
  if (vm.count("keys") != 0) {
    daemon::AuthOptions auth_options;
    if (!auth::Init()) return UsageError("dump", "--keys: libsodium cannot be initialised");
    if (auto e = daemon::LoadSensorKeys(vm["keys"].as<std::string>(), &auth_options))
      return UsageError("dump", "--keys " + *e);
    verifier = std::make_unique<daemon::DatagramVerifier>(auth_options);
  }
  return DumpDatagramFile(path, datagram_port, summary_only, verifier.get());
}

}  // namespace lrfnet::tools
