// `lrfnet emulate` and `lrfnet sim --serve` as processes, with a client streaming scans: SIGINT or
// SIGTERM ends them at once with exit code 0 (before, `sim --serve` without --loop ran on to the
// scenario's end). The bound below is generous for a loaded 2-core machine; the commands stop
// their io loop in the signal handler itself.

#include <gtest/gtest.h>

#include <boost/asio/connect.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/read.hpp>
#include <boost/asio/write.hpp>
#include <chrono>
#include <csignal>
#include <fstream>
#include <string>
#include <vector>

#include "tests/process_harness.h"

namespace lrfnet {
namespace {

namespace asio = boost::asio;
using asio::ip::tcp;
using std::chrono::milliseconds;
using std::chrono::seconds;

constexpr auto kStopBound = milliseconds(3000);

// Subscribes to scans in CoLa-A and waits for some bytes of them.
void StreamFrom(std::uint16_t port, asio::io_context& io, tcp::socket& socket) {
  socket.connect(tcp::endpoint(asio::ip::make_address("127.0.0.1"), port));
  const std::string request = "\x02sEN LMDscandata 1\x03";
  asio::write(socket, asio::buffer(request));
  std::vector<char> buf(4096);
  std::size_t got = 0;
  while (got < buf.size())
    got += socket.read_some(asio::buffer(buf.data() + got, buf.size() - got));
  (void)io;
}

std::uint16_t PortAfter(const std::string& text, const std::string& prefix) {
  const auto at = text.find(prefix);
  if (at == std::string::npos) return 0;
  return static_cast<std::uint16_t>(std::stoi(text.substr(at + prefix.size())));
}

// The time from the signal until the process has exited, and its exit code.
std::pair<milliseconds, int> StopWith(testing::Process& p, int signal_number) {
  const auto t0 = std::chrono::steady_clock::now();
  p.Signal(signal_number);
  const int code = p.Wait(seconds(20));
  return {std::chrono::duration_cast<milliseconds>(std::chrono::steady_clock::now() - t0), code};
}

TEST(EmulatorProcessTest, EmulateStopsAtOnceOnSigintAndSigterm) {
  for (const int signal_number : {SIGINT, SIGTERM}) {
    testing::Process emulator(LRFNET_TOOL_BINARY,
                              {"emulate", "--synthetic", "mrs1104", "--port", "0"});
    ASSERT_TRUE(emulator.WaitForOutput("listening on", seconds(10))) << emulator.err();
    const std::uint16_t port = PortAfter(emulator.out(), "127.0.0.1:");
    ASSERT_NE(port, 0);
    asio::io_context io;
    tcp::socket socket(io);
    StreamFrom(port, io, socket);
    const auto [elapsed, code] = StopWith(emulator, signal_number);
    EXPECT_EQ(code, 0) << emulator.err();
    EXPECT_LT(elapsed, kStopBound) << "signal " << signal_number;
  }
}

TEST(EmulatorProcessTest, SimServeStopsAtOnceOnSigtermWithoutLoop) {
  testing::ScratchDir dir;
  std::ofstream(dir / "one.yaml") << R"(name: one_sensor
seed: 3
duration_s: 60
world:
  walls: [[[0, 0], [10, 0], [10, 8], [0, 8], [0, 0]]]
sensors:
  - {id: s1, model: tim561, x_m: 0.5, y_m: 0.5, yaw_deg: 45}
targets:
  - {shape: person, a_m: 0.25, b_m: 0.15, path: [[2, 2], [8, 6]], speed_mps: 1.2, loop: true}
)";
  for (const bool loop : {false, true}) {
    std::vector<std::string> args = {"sim", dir / "one.yaml", "--serve"};
    if (loop) args.push_back("--loop");
    testing::Process sim(LRFNET_TOOL_BINARY, args);
    ASSERT_TRUE(sim.WaitForOutput("s1 127.0.0.1:", seconds(20))) << sim.err();
    const std::uint16_t port = PortAfter(sim.out(), "s1 127.0.0.1:");
    ASSERT_NE(port, 0);
    asio::io_context io;
    tcp::socket socket(io);
    StreamFrom(port, io, socket);
    const auto [elapsed, code] = StopWith(sim, loop ? SIGINT : SIGTERM);
    EXPECT_EQ(code, 0) << sim.err();
    EXPECT_LT(elapsed, kStopBound) << (loop ? "--loop, SIGINT" : "SIGTERM");
    EXPECT_NE(sim.err().find("stopping"), std::string::npos);
  }
}

}  // namespace
}  // namespace lrfnet
