// Small pieces the benchmarks that drive the programs share: run one to completion with its output
// appended to a log, and read a "--name value" argument.
#pragma once

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>

#include <string>
#include <vector>

extern char** environ;

namespace lrfnet::bench {

// Starts args[0] (a path) with args, stdout and stderr appended to `log`: posix_spawn's result (0:
// started, *pid set; else the error, e.g. ETXTBSY for a binary being relinked).
inline int SpawnLogged(const std::vector<std::string>& args, const std::string& log, pid_t* pid) {
  std::vector<std::string> copy = args;
  std::vector<char*> argv;
  for (std::string& s : copy) argv.push_back(s.data());
  argv.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 1, log.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
  posix_spawn_file_actions_addopen(&actions, 2, log.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
  const int rc = posix_spawn(pid, copy[0].c_str(), &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  return rc;
}

// Runs args[0] (a path) with args, stdout and stderr appended to `log`; its exit code, -1 when it
// could not start, -2 when a signal ended it.
inline int RunProcess(const std::vector<std::string>& args, const std::string& log) {
  pid_t pid = 0;
  if (SpawnLogged(args, log, &pid) != 0) return -1;
  int status = 0;
  waitpid(pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -2;
}

// The value after `name` on the command line, else `fallback`.
inline std::string Arg(int argc, char** argv, const std::string& name, const std::string& fallback) {
  for (int i = 1; i + 1 < argc; ++i) {
    if (argv[i] == name) return argv[i + 1];
  }
  return fallback;
}

}  // namespace lrfnet::bench
