#pragma once
// Test-only: the built binaries as child processes (posix_spawn) with stdout and stderr captured in
// files, for the tests that run lrfnet, lrfnet-tracker and lrfnetd as a user does.

#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

extern char** environ;

namespace lrfnet::testing {

using std::chrono::milliseconds;
using std::chrono::seconds;

inline std::string ReadText(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

inline std::size_t CountLines(const std::string& text) {
  return static_cast<std::size_t>(std::count(text.begin(), text.end(), '\n'));
}

inline std::size_t CountPrefixed(const std::string& text, const std::string& prefix) {
  std::size_t n = 0;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) n += line.rfind(prefix, 0) == 0 ? 1 : 0;
  return n;
}

// A fresh folder under the test temp dir, removed with everything in it at the end of scope.
class ScratchDir {
 public:
  ScratchDir() {
    static int n = 0;
    path_ = std::filesystem::path(::testing::TempDir()) /
            ("lrfnet_test_" + std::to_string(::getpid()) + "_" + std::to_string(n++));
    std::filesystem::create_directories(path_);
  }
  ~ScratchDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  ScratchDir(const ScratchDir&) = delete;
  ScratchDir& operator=(const ScratchDir&) = delete;
  std::string operator/(const std::string& name) const { return (path_ / name).string(); }

 private:
  std::filesystem::path path_;
};

class Process {
 public:
  // Starts `binary args...` with stdout and stderr redirected to files in a fresh temp folder.
  Process(const std::string& binary, const std::vector<std::string>& args) {
    static int counter = 0;
    dir_ = std::filesystem::path(::testing::TempDir()) /
           ("lrfnet_cli_" + std::to_string(::getpid()) + "_" + std::to_string(counter++));
    std::filesystem::create_directories(dir_);
    out_path_ = (dir_ / "stdout").string();
    err_path_ = (dir_ / "stderr").string();
    std::vector<std::string> argv_strings = {binary};
    argv_strings.insert(argv_strings.end(), args.begin(), args.end());
    std::vector<char*> argv;
    for (std::string& s : argv_strings) argv.push_back(s.data());
    argv.push_back(nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, 1, out_path_.c_str(), O_WRONLY | O_CREAT | O_TRUNC,
                                     0644);
    posix_spawn_file_actions_addopen(&actions, 2, err_path_.c_str(), O_WRONLY | O_CREAT | O_TRUNC,
                                     0644);
    const int rc = posix_spawn(&pid_, binary.c_str(), &actions, nullptr, argv.data(), environ);
    posix_spawn_file_actions_destroy(&actions);
    EXPECT_EQ(rc, 0) << "cannot start " << binary;
    if (rc != 0) pid_ = -1;
  }
  ~Process() {
    if (pid_ > 0 && !exited_) {
      ::kill(pid_, SIGKILL);
      int status = 0;
      ::waitpid(pid_, &status, 0);
    }
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }

  // Exit code, or -1 on timeout (then the process is killed) / -2 when killed by a signal.
  int Wait(milliseconds timeout = milliseconds(20'000)) {
    if (pid_ <= 0) return -3;
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (true) {
      int status = 0;
      const pid_t r = ::waitpid(pid_, &status, WNOHANG);
      if (r == pid_) {
        exited_ = true;
        return WIFEXITED(status) ? WEXITSTATUS(status) : -2;
      }
      if (std::chrono::steady_clock::now() > deadline) {
        ::kill(pid_, SIGKILL);
        ::waitpid(pid_, &status, 0);
        exited_ = true;
        return -1;
      }
      std::this_thread::sleep_for(milliseconds(10));
    }
  }
  void Signal(int signal_number) { ::kill(pid_, signal_number); }
  std::string out() const { return ReadText(out_path_); }
  std::string err() const { return ReadText(err_path_); }
  std::string dir() const { return dir_.string(); }

  // Polls stdout until it contains `text`.
  bool WaitForOutput(const std::string& text, milliseconds timeout) {
    return WaitForText(out_path_, text, timeout);
  }
  // Polls stderr until it contains `text` `count` times (a signal's effect, logged: a second
  // signal sent before the first was handled may be merged with it by the kernel).
  bool WaitForError(const std::string& text, milliseconds timeout, std::size_t count = 1) {
    return WaitForText(err_path_, text, timeout, count);
  }

 private:
  static std::size_t Occurrences(const std::string& haystack, const std::string& text) {
    std::size_t n = 0;
    for (auto at = haystack.find(text); at != std::string::npos; at = haystack.find(text, at + 1)) {
      ++n;
    }
    return n;
  }
  static bool WaitForText(const std::string& path, const std::string& text, milliseconds timeout,
                          std::size_t count = 1) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    while (std::chrono::steady_clock::now() < deadline) {
      if (Occurrences(ReadText(path), text) >= count) return true;
      std::this_thread::sleep_for(milliseconds(20));
    }
    return false;
  }

  std::filesystem::path dir_;
  std::string out_path_, err_path_;
  pid_t pid_ = -1;
  bool exited_ = false;
};

}  // namespace lrfnet::testing
