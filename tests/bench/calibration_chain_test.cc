#include "tests/bench/calibration_chain.h"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace lrfnet::bench {
namespace {

namespace fs = std::filesystem;

fs::path Scratch(const std::string& name) {
  const fs::path dir = fs::path(::testing::TempDir()) /
                       ("calibration_chain_test_" + std::to_string(::getpid()) + "_" + name);
  fs::create_directories(dir);
  return dir;
}

ProcessExit Exited(int code) {
  ProcessExit e;
  e.exited = true;
  e.exit_code = code;
  return e;
}

TEST(RunChildTest, SaysHowTheChildEnded) {
  const fs::path dir = Scratch("ended");
  const std::string log = (dir / "log.txt").string();
  const ProcessExit ok = RunChild({"/bin/sh", "-c", "echo hello"}, log);
  EXPECT_TRUE(Succeeded(ok));
  const ProcessExit code = RunChild({"/bin/sh", "-c", "exit 3"}, log);
  EXPECT_FALSE(Succeeded(code));
  EXPECT_EQ(Describe(code), "exit code 3");
  const ProcessExit killed = RunChild({"/bin/sh", "-c", "kill -9 $$"}, log);
  EXPECT_FALSE(Succeeded(killed));
  EXPECT_EQ(killed.signal, SIGKILL);
  EXPECT_NE(Describe(killed).find("signal 9"), std::string::npos) << Describe(killed);
  const ProcessExit absent = RunChild({(dir / "no_such_binary").string()}, log);
  EXPECT_FALSE(Succeeded(absent));
  EXPECT_EQ(absent.spawn_errno, ENOENT);
  EXPECT_NE(Describe(absent).find("could not start"), std::string::npos) << Describe(absent);
  std::ifstream in(log);
  std::string first;
  std::getline(in, first);
  EXPECT_EQ(first, "hello");  // the child's output went to the log
  fs::remove_all(dir);
}

TEST(RunStepTest, RepeatsAFailedRunAndKeepsEveryCause) {
  int calls = 0;
  std::vector<double> slept;
  const StepReport r = RunStep(
      "lrfnet-tracker l3 (ellipse)", [&] { return Exited(++calls < 3 ? 1 : 0); },
      [] { return std::optional<std::string>(); }, ChainOptions{},
      [&](double s) { slept.push_back(s); });
  EXPECT_TRUE(r.ok);
  EXPECT_EQ(r.attempts, 3);
  EXPECT_EQ(calls, 3);
  ASSERT_EQ(r.causes.size(), 2u);
  EXPECT_EQ(r.causes[0], "exit code 1");
  EXPECT_EQ(slept, (std::vector<double>{0.5, 1.0}));
  EXPECT_EQ(Describe(r), "lrfnet-tracker l3 (ellipse): exit code 1; exit code 1; ok at attempt 3");
}

TEST(RunStepTest, NamesAStepThatStillFailsAfterItsAttempts) {
  int calls = 0;
  ChainOptions options;
  options.attempts = 2;
  const StepReport r = RunStep(
      "lrfnet-tracker l3 (ellipse)",
      [&] {
        ++calls;
        return Exited(0);
      },
      [] { return std::optional<std::string>("l3.ellipse.rec.part: empty"); }, options,
      [](double) {});
  EXPECT_FALSE(r.ok);
  EXPECT_EQ(calls, 2);
  EXPECT_EQ(Describe(r),
            "lrfnet-tracker l3 (ellipse): failed 2 times: l3.ellipse.rec.part: empty; "
            "l3.ellipse.rec.part: empty");
  options.attempts = 1;
  calls = 0;
  EXPECT_FALSE(RunStep(
                   "s", [&] { return Exited(++calls > 1 ? 0 : 1); },
                   [] { return std::optional<std::string>(); }, options, [](double) {})
                   .ok);
  EXPECT_EQ(calls, 1);  // one attempt: not repeated
}

// The run that lost a whole seed: the tracker's binary was being written (relinked) while the
// benchmark started it, so every start in that window failed (ETXTBSY) and the seed's input lacked
// sensors. The step now tries again once the binary is whole.
TEST(RunStepTest, ABinaryBeingWrittenIsStartedOnceItIsWhole) {
  const fs::path dir = Scratch("relink");
  const fs::path binary = dir / "tracker";
  fs::copy_file("/bin/true", binary);
  ::chmod(binary.c_str(), 0755);
  int writer = ::open(binary.c_str(), O_WRONLY);  // as the linker holds it
  ASSERT_GE(writer, 0);
  const std::string log = (dir / "log.txt").string();
  const ProcessExit busy = RunChild({binary.string()}, log);
  EXPECT_EQ(busy.spawn_errno, ETXTBSY) << Describe(busy);
  const StepReport r = RunStep(
      "lrfnet-tracker l3 (ellipse)", [&] { return RunChild({binary.string()}, log); },
      [] { return std::optional<std::string>(); }, ChainOptions{},
      [&](double) {
        if (writer >= 0) ::close(writer);  // the link finishes while the step waits
        writer = -1;
      });
  EXPECT_TRUE(r.ok);
  EXPECT_EQ(r.attempts, 2);
  ASSERT_EQ(r.causes.size(), 1u);
  EXPECT_NE(r.causes[0].find("could not start"), std::string::npos) << r.causes[0];
  if (writer >= 0) ::close(writer);
  fs::remove_all(dir);
}

TEST(CheckOutputFileTest, AMissingOrEmptyFileIsNamed) {
  const fs::path dir = Scratch("output");
  const std::string path = (dir / "l3.ellipse.rec").string();
  ASSERT_TRUE(CheckOutputFile(path).has_value());
  std::ofstream(path).close();
  ASSERT_TRUE(CheckOutputFile(path).has_value());
  EXPECT_NE(CheckOutputFile(path)->find("empty"), std::string::npos);
  std::ofstream(path) << "x";
  EXPECT_FALSE(CheckOutputFile(path).has_value());
  fs::remove_all(dir);
}

TEST(MissingSensorsTest, NamesTheSensorsWithoutFrames) {
  calib::CalibrationInput input;
  for (const char* id : {"l1", "l2", "l3", "l5"}) {
    calib::SensorRecording s;
    s.id = id;
    if (std::string(id) != "l3") s.frames.resize(2);  // l3: a background, no frames
    input.sensors.push_back(s);
  }
  EXPECT_EQ(MissingSensors({"l1", "l2", "l3", "l4", "l5"}, input),
            (std::vector<std::string>{"l3", "l4"}));
  EXPECT_TRUE(MissingSensors({"l1", "l5"}, input).empty());
}

TEST(ChainOptionsTest, Validate) {
  EXPECT_FALSE(Validate(ChainOptions{}).has_value());
  ChainOptions o;
  o.attempts = 0;
  EXPECT_TRUE(Validate(o).has_value());
  o = ChainOptions{};
  o.retry_delay_s = -1.0;
  EXPECT_TRUE(Validate(o).has_value());
}

}  // namespace
}  // namespace lrfnet::bench
