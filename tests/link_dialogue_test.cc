// The start-up dialogue of SICK's sick_scan_xd driver (version 3.9, as it talks to each device
// family), played against `lrfnet emulate --synthetic` over TCP on loopback, in CoLa-B and in
// CoLa-A: every reply checked, the login levels, the state machine (configuration mode, busy after
// Run, polled until ready), the I/O and field-evaluation events, then scans that flow in the
// dialect they were subscribed in and stop on LMCstopmeas.

#include <gtest/gtest.h>

#include <array>
#include <boost/asio/connect.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/ip/tcp.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/write.hpp>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <functional>
#include <memory>
#include <set>
#include <string>
#include <thread>
#include <tuple>
#include <vector>

#include "firmware_tracker/cola/scan_telegram.h"
#include "firmware_tracker/cola/sopas_framer.h"
#include "firmware_tracker/cola/sopas_value.h"
#include "tools/emulator.h"
#include "tools/scan_source.h"
#include "tools/sopas_device.h"

namespace lrfnet {
namespace {

namespace asio = boost::asio;
using asio::ip::tcp;
using cola::CommandType;
using cola::Dialect;
using cola::SopasValues;
using S = cola::SopasScalar;
using std::chrono::milliseconds;
using Clock = std::chrono::steady_clock;

// The emulator on its own thread; the test talks to it with a blocking socket.
class EmulatorThread {
 public:
  explicit EmulatorThread(const std::string& model) {
    tools::EmulatorOptions options;
    options.port = 0;
    options.speed = 2;
    options.ready_after_run_s = 0.3;  // every family polls at least once busy, quickly
    tools::SyntheticScanOptions source;
    source.model = model;
    emulator_ =
        std::make_unique<tools::Emulator>(io_, options, tools::MakeSyntheticScanSource(source));
    std::string error;
    EXPECT_TRUE(emulator_->Start(&error)) << error;
    thread_ = std::thread([this] { io_.run(); });
  }
  ~EmulatorThread() { Stop(); }
  // Stops the emulator and joins its thread; afterwards its counters can be read.
  void Stop() {
    if (!thread_.joinable()) return;
    asio::post(io_, [this] { emulator_->Stop(); });
    thread_.join();
  }
  std::uint16_t port() const { return emulator_->port(); }
  // Read after the thread ended or for values that only grow (the test tolerates a stale read).
  const tools::Emulator& emulator() const { return *emulator_; }

 private:
  asio::io_context io_;
  std::unique_ptr<tools::Emulator> emulator_;
  std::thread thread_;
};

struct Received {
  Dialect dialect;
  std::vector<std::uint8_t> payload;
  std::string text() const { return std::string(payload.begin(), payload.end()); }
  bool Starts(std::string_view prefix) const {
    return payload.size() >= prefix.size() &&
           std::memcmp(payload.data(), prefix.data(), prefix.size()) == 0;
  }
};

class Client {
 public:
  Client(std::uint16_t port, Dialect dialect) : socket_(io_), dialect_(dialect) {
    socket_.connect(tcp::endpoint(asio::ip::make_address("127.0.0.1"), port));
    socket_.non_blocking(true);
  }

  // Sends a request and returns its reply; event telegrams met on the way are kept (events()).
  std::string Ask(CommandType type, std::string_view name, const SopasValues& args = {}) {
    const std::vector<std::uint8_t> payload = cola::EncodeSopasTelegram(dialect_, type, name, args);
    const std::vector<std::uint8_t> frame = cola::EncodeSopasFrame(dialect_, payload);
    asio::write(socket_, asio::buffer(frame));
    Received reply;
    if (!Next([](const Received& r) { return !r.Starts("sSN "); }, milliseconds(3000), &reply)) {
      ADD_FAILURE() << "no reply to " << name;
      return "";
    }
    EXPECT_EQ(reply.dialect, dialect_) << "reply to " << name << " in the other dialect";
    return reply.text();
  }

  // Reads telegrams until one satisfies `want` (returned in *out) or `timeout`; the others are
  // kept: scans are counted and decoded, events kept by name.
  bool Next(const std::function<bool(const Received&)>& want, milliseconds timeout, Received* out) {
    const auto deadline = Clock::now() + timeout;
    while (true) {
      while (!pending_.empty()) {
        Received r = std::move(pending_.front());
        pending_.erase(pending_.begin());
        const bool wanted = want(r);
        Keep(r);
        if (wanted) {
          if (out != nullptr) *out = std::move(r);
          return true;
        }
      }
      if (Clock::now() >= deadline) return false;
      std::array<std::uint8_t, 8192> buf;
      boost::system::error_code ec;
      const std::size_t n = socket_.read_some(asio::buffer(buf), ec);
      if (ec == asio::error::would_block) {
        std::this_thread::sleep_for(milliseconds(2));
        continue;
      }
      if (ec) return false;
      framer_.FeedAll(
          std::span<const std::uint8_t>(buf.data(), n),
          [this](Dialect d, std::span<const std::uint8_t> p) {
            pending_.push_back({d, std::vector<std::uint8_t>(p.begin(), p.end())});
          },
          [](const char* reason) { ADD_FAILURE() << "bad frame from the emulator: " << reason; });
    }
  }

  void Drain(milliseconds d) {
    Next([](const Received&) { return false; }, d, nullptr);
  }
  void SendRaw(const std::vector<std::uint8_t>& bytes) {
    asio::write(socket_, asio::buffer(bytes));
  }

  std::string Expect(CommandType type, std::string_view name, const SopasValues& v,
                     bool space = false) const {
    const auto p = cola::EncodeSopasTelegram(dialect_, type, name, v, space);
    return std::string(p.begin(), p.end());
  }
  std::string Error(std::uint16_t code) const {
    const auto p = cola::EncodeSopasError(dialect_, code);
    return std::string(p.begin(), p.end());
  }

  std::size_t scans() const { return scans_.size(); }
  const std::vector<std::unique_ptr<cola::ScanTelegram>>& scan_list() const { return scans_; }
  std::size_t events(std::string_view name) const {
    std::size_t n = 0;
    for (const std::string& e : events_) n += e == name;
    return n;
  }

 private:
  void Keep(const Received& r) {
    if (r.Starts("sSN LMDscandata ")) {
      EXPECT_EQ(r.dialect, dialect_) << "scans in the dialect they were subscribed in";
      // CoLa-A scans decode by the scan schema; their CoLa-B form is the binary telegram.
      std::vector<std::uint8_t> binary = r.payload;
      if (r.dialect == Dialect::kColaA) {
        SopasValues v;
        const auto args = std::span<const std::uint8_t>(r.payload).subspan(16);
        EXPECT_TRUE(cola::DecodeValues(cola::ScanTelegramSchema(), Dialect::kColaA, args, &v).ok());
        binary.assign(r.payload.begin(), r.payload.begin() + 16);
        EXPECT_TRUE(cola::AppendValues(v, Dialect::kColaB, &binary));
      }
      auto scan = std::make_unique<cola::ScanTelegram>();
      EXPECT_TRUE(cola::DecodeScanTelegram(binary, scan.get()).ok);
      scans_.push_back(std::move(scan));
    } else if (r.Starts("sSN ")) {
      const std::string t = r.text();
      events_.push_back(t.substr(4, t.find(' ', 4) - 4));
    }
  }

  asio::io_context io_;
  tcp::socket socket_;
  Dialect dialect_;
  cola::SopasFramer framer_;
  std::vector<Received> pending_;
  std::vector<std::unique_ptr<cola::ScanTelegram>> scans_;
  std::vector<std::string> events_;
};

struct FamilyCase {
  const char* model;          // lrfnet emulate --synthetic MODEL
  std::uint32_t client_hash;  // SetAccessMode level 3 of the family
  std::uint32_t other_hash;   // another family's level-3 hash: refused
  int fields;                 // fieldNNN the driver reads
  int structured_fields;      // of them with the field layout (the others: one 0 byte)
  bool io;                    // LIDinputstate, LFErec / LIDoutputstate / LIDinputstate events
  bool lferec_read;           // sRN LFErec (TiM7xx)
  bool scancfg;               // mLMPsetscancfg + sRN LMPscancfg (LMS1xx, LMS5xx)
  bool mrs;                   // the MRS1xxx's own requests
};

constexpr std::uint32_t kClient = 0xF4724744;
constexpr std::uint32_t kSafetyClient = 0x6FD62C05;

class DialogueTest : public ::testing::TestWithParam<std::tuple<FamilyCase, Dialect>> {};

TEST_P(DialogueTest, DriverStartUpRepliesStateMachineScansAndStop) {
  const auto& [f, dialect] = GetParam();
  tools::SyntheticScanOptions source_options;
  source_options.model = f.model;
  const tools::DeviceIdentity id = tools::MakeSyntheticScanSource(source_options)->identity();
  const tools::ScanGeometry& g = id.geometry;
  // The same device model, here in the test thread, for the values it starts with.
  tools::SopasDeviceOptions ref_options;
  ref_options.family = *tools::FamilyFromDeviceName(id.name);
  ref_options.identity = id;
  const tools::SopasDevice reference(ref_options);

  EmulatorThread emulator(f.model);
  Client c(emulator.port(), dialect);
  using CT = CommandType;
  const auto R = [&](CT t, std::string_view n, const SopasValues& v = {}, bool space = false) {
    return c.Expect(t, n, v, space);
  };
  const SopasValues ready = {S::U8(1)}, busy = {S::U8(0)}, ok0 = {S::U8(0)}, ok1 = {S::U8(1)};

  // sick_scan_xd's dialect probe, then the login: the other family's hash is refused.
  EXPECT_EQ(c.Ask(CT::kRead, "SCdevicestate"), R(CT::kReadAnswer, "SCdevicestate", ready));
  EXPECT_EQ(c.Ask(CT::kMethod, "SetAccessMode", {S::U8(3), S::U32(f.other_hash)}),
            R(CT::kMethodAnswer, "SetAccessMode", ok0));
  EXPECT_EQ(c.Ask(CT::kWrite, "EIHstCola", {S::U8(1)}), c.Error(10)) << "no user level yet";
  EXPECT_EQ(c.Ask(CT::kMethod, "SetAccessMode", {S::U8(3), S::U32(f.client_hash)}),
            R(CT::kMethodAnswer, "SetAccessMode", ok1));
  EXPECT_EQ(c.Ask(CT::kWrite, "EIHstCola", {S::U8(dialect == Dialect::kColaB ? 1 : 0)}),
            R(CT::kWriteAnswer, "EIHstCola", {}, true));
  if (f.mrs) {
    EXPECT_EQ(c.Ask(CT::kMethod, "LMCstopmeas"), R(CT::kMethodAnswer, "LMCstopmeas", ok0));
    EXPECT_EQ(c.Ask(CT::kRead, "SetActiveApplications"),
              R(CT::kReadAnswer, "SetActiveApplications",
                {S::U16(2), S::Fixed("FEVL", 4), S::U8(0), S::Fixed("RANG", 4), S::U8(1)}));
    EXPECT_EQ(c.Ask(CT::kRead, "DeviceIdent"),
              R(CT::kReadAnswer, "DeviceIdent", {S::Str(id.name), S::Str(id.version)}));
    EXPECT_EQ(
        c.Ask(CT::kWrite, "SetActiveApplications", {S::U16(1), S::Fixed("FEVL", 4), S::U8(0)}),
        R(CT::kWriteAnswer, "SetActiveApplications"));
    EXPECT_EQ(
        c.Ask(CT::kWrite, "SetActiveApplications", {S::U16(1), S::Fixed("RANG", 4), S::U8(1)}),
        R(CT::kWriteAnswer, "SetActiveApplications"));
    EXPECT_EQ(c.Ask(CT::kRead, "SerialNumber"),
              R(CT::kReadAnswer, "SerialNumber", {S::Str(id.serial_number)}));
  }
  EXPECT_EQ(c.Ask(CT::kRead, "FirmwareVersion"),
            R(CT::kReadAnswer, "FirmwareVersion", {S::Str(id.firmware_version)}));
  EXPECT_EQ(c.Ask(CT::kRead, "SCdevicestate"), R(CT::kReadAnswer, "SCdevicestate", busy))
      << "configuration mode";
  EXPECT_EQ(c.Ask(CT::kRead, "ODoprh"), R(CT::kReadAnswer, "ODoprh", {S::U32(1234)}));
  EXPECT_EQ(c.Ask(CT::kRead, "ODpwrc"), R(CT::kReadAnswer, "ODpwrc", {S::U32(42)}));
  EXPECT_EQ(c.Ask(CT::kRead, "LocationName"),
            R(CT::kReadAnswer, "LocationName", {S::Str("not defined")}));
  if (f.mrs) {
    EXPECT_EQ(
        c.Ask(CT::kWrite, "ScanLayerFilter", {S::U16(4), S::U8(1), S::U8(1), S::U8(1), S::U8(1)}),
        R(CT::kWriteAnswer, "ScanLayerFilter", {}, true));
    EXPECT_EQ(c.Ask(CT::kMethod, "Run"), R(CT::kMethodAnswer, "Run", ok1));
    EXPECT_EQ(c.Ask(CT::kMethod, "SetAccessMode", {S::U8(3), S::U32(f.client_hash)}),
              R(CT::kMethodAnswer, "SetAccessMode", ok1));
  }
  const SopasValues range = *reference.Value("LMPoutputRange");
  ASSERT_EQ(range.size(), 4u);
  EXPECT_EQ(range[1].AsInt(), g.angle_step_raw);
  EXPECT_EQ(range[2].AsInt(), g.start_angle_raw);
  EXPECT_EQ(c.Ask(CT::kRead, "LMPoutputRange"), R(CT::kReadAnswer, "LMPoutputRange", range));
  EXPECT_EQ(c.Ask(CT::kWrite, "LMPoutputRange", range),
            R(CT::kWriteAnswer, "LMPoutputRange", {}, true));
  EXPECT_EQ(c.Ask(CT::kRead, "LMPoutputRange"), R(CT::kReadAnswer, "LMPoutputRange", range));
  for (int i = 0; i < f.fields; ++i) {
    char name[16];
    std::snprintf(name, sizeof name, "field%03d", i);
    const SopasValues expected =
        i < f.structured_fields ? *reference.Value(name) : SopasValues{S::U8(0)};
    EXPECT_EQ(c.Ask(CT::kRead, name), R(CT::kReadAnswer, name, expected));
  }
  if (f.fields > 0 && f.fields < 48) {
    EXPECT_EQ(c.Ask(CT::kRead, "field030"), c.Error(3));
  }
  if (f.io) {
    const std::string r = c.Ask(CT::kRead, "LIDinputstate");
    SopasValues v;
    EXPECT_TRUE(
        cola::DecodeValues(cola::SopasSchema::Compile(tools::kInputStateSchema), dialect,
                           std::span(reinterpret_cast<const std::uint8_t*>(r.data()), r.size())
                               .subspan(std::min<std::size_t>(18, r.size())),
                           &v)
            .ok())
        << r;
  }
  const SopasValues cfg = {S::U8(1),
                           S::U8(0),
                           S::U8(g.rssi_bits ? 1 : 0),
                           S::U8(g.rssi_bits == 16 ? 1 : 0),
                           S::U8(0),
                           S::U8(0),
                           S::U8(0),
                           S::U8(0),
                           S::U8(0),
                           S::U8(0),
                           S::U8(1),
                           S::U16(1)};
  EXPECT_EQ(c.Ask(CT::kWrite, "LMDscandatacfg", cfg),
            R(CT::kWriteAnswer, "LMDscandatacfg", {}, true));
  EXPECT_EQ(c.Ask(CT::kRead, "LMDscandatacfg"), R(CT::kReadAnswer, "LMDscandatacfg", cfg));
  if (f.scancfg) {
    const SopasValues scancfg = {S::U32(g.scan_frequency_raw), S::U16(1), S::U32(g.angle_step_raw),
                                 range[2], range[3]};
    SopasValues answer = {S::U8(0)};
    answer.insert(answer.end(), scancfg.begin(), scancfg.end());
    EXPECT_EQ(c.Ask(CT::kMethod, "mLMPsetscancfg", scancfg),
              R(CT::kMethodAnswer, "mLMPsetscancfg", answer));
    EXPECT_EQ(c.Ask(CT::kRead, "LMPscancfg"), R(CT::kReadAnswer, "LMPscancfg", scancfg));
  }
  if (f.mrs) {
    EXPECT_EQ(c.Ask(CT::kWrite, "FREchoFilter", {S::U8(2)}), R(CT::kWriteAnswer, "FREchoFilter"));
  }
  if (f.io) {
    for (const char* e : {"LFErec", "LIDoutputstate", "LIDinputstate"}) {
      EXPECT_EQ(c.Ask(CT::kEvent, e, ok1), R(CT::kEventAnswer, e, ok1));
    }
  }
  if (f.lferec_read) {
    const std::string r = c.Ask(CT::kRead, "LFErec");
    SopasValues v;
    ASSERT_TRUE(
        cola::DecodeValues(cola::SopasSchema::Compile(tools::kLfeRecSchema), dialect,
                           std::span(reinterpret_cast<const std::uint8_t*>(r.data()), r.size())
                               .subspan(std::min<std::size_t>(11, r.size())),
                           &v)
            .ok())
        << r;
    EXPECT_EQ(v[0].AsInt(), 3) << "the active field set's three fields";
  }
  EXPECT_EQ(c.Ask(CT::kMethod, "LMCstartmeas"), R(CT::kMethodAnswer, "LMCstartmeas", ok0));
  EXPECT_EQ(c.Ask(CT::kMethod, "Run"), R(CT::kMethodAnswer, "Run", ok1));
  // Busy after Run, then ready (0.3 s here; the MRS1104 takes 15 s): polled as the driver does.
  int busy_polls = 0;
  const auto poll_deadline = Clock::now() + std::chrono::seconds(5);
  while (c.Ask(CT::kRead, "SCdevicestate") == R(CT::kReadAnswer, "SCdevicestate", busy) &&
         Clock::now() < poll_deadline) {
    ++busy_polls;
    std::this_thread::sleep_for(milliseconds(50));
  }
  EXPECT_GE(busy_polls, 1);
  EXPECT_EQ(c.Ask(CT::kRead, "SCdevicestate"), R(CT::kReadAnswer, "SCdevicestate", ready));
  EXPECT_EQ(c.Ask(CT::kEvent, "LMDscandata", ok1), R(CT::kEventAnswer, "LMDscandata", ok1));
  if (f.mrs) {
    EXPECT_EQ(c.Ask(CT::kEvent, "InertialMeasurementUnit", ok1), c.Error(15));
  }

  // Scans flow, in this dialect, with the family's geometry.
  ASSERT_TRUE(c.Next([&](const Received&) { return c.scans() >= 6; }, milliseconds(8000), nullptr))
      << c.scans() << " scans";
  for (const auto& scan : c.scan_list()) {
    const cola::ScanChannel* dist = scan->FindChannel("DIST1");
    ASSERT_NE(dist, nullptr);
    EXPECT_EQ(dist->count, g.count);
    EXPECT_EQ(dist->start_angle_raw, g.start_angle_raw);
    EXPECT_EQ(dist->angle_step_raw, g.angle_step_raw);
    EXPECT_EQ(scan->FindChannel("RSSI1") != nullptr, g.rssi_bits != 0);
    EXPECT_TRUE(scan->has_time);
  }
  if (f.mrs) {
    std::set<int> layers;
    for (const auto& scan : c.scan_list()) layers.insert(scan->layer_angle_raw);
    EXPECT_EQ(layers.size(), 4u) << "four layers, one per telegram";
  }
  if (f.io) {
    EXPECT_GE(c.events("LIDoutputstate"), 1u) << "sent with its subscription";
  }

  // LMCstopmeas stops them (one already on its way may still arrive).
  EXPECT_EQ(c.Ask(CT::kMethod, "SetAccessMode", {S::U8(3), S::U32(f.client_hash)}),
            R(CT::kMethodAnswer, "SetAccessMode", ok1));
  EXPECT_EQ(c.Ask(CT::kMethod, "LMCstopmeas"), R(CT::kMethodAnswer, "LMCstopmeas", ok0));
  EXPECT_EQ(c.Ask(CT::kMethod, "Run"), R(CT::kMethodAnswer, "Run", ok1));
  c.Drain(milliseconds(100));
  const std::size_t after_stop = c.scans();
  c.Drain(milliseconds(600));
  EXPECT_EQ(c.scans(), after_stop) << "scans after LMCstopmeas";
}

// Bytes no device should have to take: each request refused with its sFA code and counted,
// broken frames dropped and counted, and the device still answers the next request at once.
TEST(HostileClientTest, GarbageBrokenFramesAndUnknownCommandsNeverStopTheDevice) {
  EmulatorThread emulator("lms511");
  Client c(emulator.port(), Dialect::kColaB);
  std::vector<std::uint8_t> junk = {'x', 'y', 0x03, 0x7F, 0x00};
  std::vector<std::uint8_t> bad =
      cola::EncodeSopasFrame(Dialect::kColaB, std::vector<std::uint8_t>{'s', 'R', 'N', ' ', 'X'});
  bad.back() ^= 0xFF;  // the checksum
  junk.insert(junk.end(), bad.begin(), bad.end());
  std::vector<std::uint8_t> huge(70000, 'a');
  huge[0] = 0x02;  // a CoLa-A frame that does not end within the bound
  junk.insert(junk.end(), huge.begin(), huge.end());
  c.SendRaw(junk);
  using CT = CommandType;
  EXPECT_EQ(c.Ask(CT::kRead, "NoSuchVariable"), c.Error(3));
  EXPECT_EQ(c.Ask(CT::kMethod, "NoSuchMethod"), c.Error(2));
  EXPECT_EQ(c.Ask(CT::kEvent, "NoSuchEvent", {S::U8(1)}), c.Error(15));
  EXPECT_EQ(c.Ask(CT::kWrite, "LMPoutputRange", {S::U16(1)}), c.Error(10)) << "no user level";
  EXPECT_EQ(c.Ask(CT::kMethod, "SetAccessMode", {S::U8(3)}), c.Error(8)) << "arguments too short";
  c.SendRaw(std::vector<std::uint8_t>{0x02, 's', 'X', 'Y', ' ', 'Z', 0x03});
  Received reply;
  ASSERT_TRUE(c.Next([](const Received&) { return true; }, milliseconds(3000), &reply));
  EXPECT_EQ(reply.text(), "sFA C") << "an unknown CoLa-A command";
  EXPECT_EQ(c.Ask(CT::kRead, "SCdevicestate"),
            c.Expect(CT::kReadAnswer, "SCdevicestate", {S::U8(1)}));
  emulator.Stop();
  const auto& framer = emulator.emulator().framer_counters();
  EXPECT_EQ(framer.bad_checksum, 1u);
  // The unending one, and (after the rejected CoLa-B start) the remains of that frame, which look
  // like a CoLa-A start until the next STX cuts them.
  EXPECT_GE(framer.bad_cola_a, 1u);
  EXPECT_GT(framer.garbage_bytes, 70000u);
  const auto& device = emulator.emulator().device_counters();
  EXPECT_EQ(device.unknown_commands, 4u);
  EXPECT_EQ(device.access_denied, 1u);
  EXPECT_EQ(device.bad_arguments, 1u);
  EXPECT_EQ(device.sfa, 6u);
  EXPECT_EQ(emulator.emulator().counters().sfa_sent, 6u);
  EXPECT_EQ(emulator.emulator().counters().bad_frames,
            framer.bad_checksum + framer.oversize_length + framer.bad_cola_a);
}

const FamilyCase kFamilies[] = {
    {"lms111", kClient, kSafetyClient, 30, 10, true, false, true, false},
    {"lms511", kClient, kSafetyClient, 30, 10, true, false, true, false},
    {"tim561", kClient, kSafetyClient, 0, 0, false, false, false, false},
    {"tim781", kClient, kSafetyClient, 48, 48, true, true, false, false},
    {"tim781s", kSafetyClient, kClient, 48, 48, true, true, false, false},
    {"mrs1104", kClient, kSafetyClient, 0, 0, false, false, false, true},
};

INSTANTIATE_TEST_SUITE_P(
    Families, DialogueTest,
    ::testing::Combine(::testing::ValuesIn(kFamilies),
                       ::testing::Values(Dialect::kColaB, Dialect::kColaA)),
    [](const ::testing::TestParamInfo<std::tuple<FamilyCase, Dialect>>& param_info) {
      return std::string(std::get<0>(param_info.param).model) +
             (std::get<1>(param_info.param) == Dialect::kColaA ? "_ColaA" : "_ColaB");
    });

}  // namespace
}  // namespace lrfnet
