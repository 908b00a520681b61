#pragma once
// The `lrfnet` subcommands. Each lives in its own <name>_command.cc, parses its own options (Boost
// program_options, --help on every one) and returns the process exit code. Adding one: write the
// file, declare its Run function here, add a row to kSubcommands in main.cc and the file to
// tools/CMakeLists.txt.

#include <boost/program_options.hpp>
#include <optional>
#include <string>

namespace lrfnet::tools {

inline constexpr int kExitOk = 0;
inline constexpr int kExitFailure = 1;  // unreadable input, runtime failure
inline constexpr int kExitUsage = 2;    // bad arguments

// argv[0] is the subcommand name; the options follow.
int RunCalibrate(int argc, char** argv);
int RunDump(int argc, char** argv);
int RunEmulate(int argc, char** argv);
int RunEval(int argc, char** argv);
int RunExport(int argc, char** argv);
int RunKeys(int argc, char** argv);
int RunReplay(int argc, char** argv);
int RunSim(int argc, char** argv);

// Prints "lrfnet <subcommand>: <message> (see lrfnet <subcommand> --help)" as one line on stderr
// and returns kExitUsage.
int UsageError(const std::string& subcommand, const std::string& message);

// Parses the subcommand's options (`visible`, shown by --help) plus one positional argument stored
// under `positional` (e.g. "capture"). Returns nullopt when the subcommand should go on, else the
// exit code to return: kExitOk after printing --help, kExitUsage after a one-line parse error.
std::optional<int> ParseOptions(const std::string& subcommand, int argc, char** argv,
                                const boost::program_options::options_description& visible,
                                const std::string& positional,
                                boost::program_options::variables_map* vm);

// Sends spdlog's default logger to stderr (stdout carries the subcommand's output) at `level`
// ("trace", "debug", "info", "warn", "error", "off"). False for an unknown level name.
bool SetUpLogging(const std::string& level);

}  // namespace lrfnet::tools
