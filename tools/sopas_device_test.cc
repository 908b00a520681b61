// The SOPAS device model without sockets: every family's dialogue, login levels, state machine,
// output configuration and field evaluation, in both dialects.

#include "tools/sopas_device.h"

#include <gtest/gtest.h>

#include <cstring>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "firmware_tracker/cola/scan_telegram.h"

namespace lrfnet::tools {
namespace {

using cola::CommandType;
using cola::Dialect;
using cola::SopasValues;
using S = cola::SopasScalar;
using common::kNsPerMs;
using common::kNsPerS;

DeviceIdentity Identity(std::string name, ScanGeometry geometry = {}) {
  DeviceIdentity id;
  id.name = std::move(name);
  id.version = "test";
  id.firmware_version = "V9.99";
  id.serial_number = "12345678";
  id.geometry = geometry;
  return id;
}

// Talks to a device in one dialect; requests are given as values so that both dialects carry the
// same request.
class Client {
 public:
  Client(SopasDevice* device, Dialect dialect) : device_(device), dialect_(dialect) {}

  // The reply to one request at `now` (events after it go to events()).
  std::string Ask(CommandType type, std::string_view name, const SopasValues& args = {},
                  common::DurationNs now = 0) {
    return Raw(cola::EncodeSopasTelegram(dialect_, type, name, args), now);
  }
  std::string Raw(const std::vector<std::uint8_t>& payload, common::DurationNs now = 0) {
    std::vector<SopasOutput> out;
    device_->HandleRequest(dialect_, payload, now, &out);
    EXPECT_GE(out.size(), 1u);
    if (out.empty()) return "";
    for (const SopasOutput& o : out) EXPECT_EQ(o.dialect, dialect_);
    events_.clear();
    for (std::size_t i = 1; i < out.size(); ++i) {
      events_.emplace_back(out[i].payload.begin(), out[i].payload.end());
    }
    return std::string(out[0].payload.begin(), out[0].payload.end());
  }
  bool Login(std::uint8_t level, std::uint32_t hash, common::DurationNs now = 0) {
    const std::string r =
        Ask(CommandType::kMethod, "SetAccessMode", {S::U8(level), S::U32(hash)}, now);
    return r == Expect(CommandType::kMethodAnswer, "SetAccessMode", {S::U8(1)});
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
  const std::vector<std::string>& events() const { return events_; }

 private:
  SopasDevice* device_;
  Dialect dialect_;
  std::vector<std::string> events_;
};

SopasDeviceOptions Options(DeviceFamily family, std::string name, double ready = -1) {
  SopasDeviceOptions o;
  o.family = family;
  o.identity = Identity(std::move(name));
  o.ready_after_run_s = ready;
  return o;
}

// A scan as the device's scans look (DIST1 at `range_mm`, RSSI1 16-bit, time block).
std::unique_ptr<cola::ScanTelegram> Scan(const ScanGeometry& g, std::uint16_t range_mm,
                                         std::int16_t layer_angle = 0) {
  auto scan = std::make_unique<cola::ScanTelegram>();
  scan->scan_frequency_raw = g.scan_frequency_raw;
  scan->time_since_startup_us = 20'000'000;
  scan->layer_angle_raw = layer_angle;
  cola::ScanChannel* dist = scan->channels16.emplace_slot();
  std::memcpy(dist->name.data(), "DIST1", 5);
  dist->start_angle_raw = g.start_angle_raw;
  dist->angle_step_raw = g.angle_step_raw;
  dist->count = g.count;
  for (std::size_t i = 0; i < g.count; ++i) dist->raw[i] = range_mm;
  cola::ScanChannel* rssi = scan->channels16.emplace_slot();
  *rssi = *dist;
  std::memcpy(rssi->name.data(), "RSSI1", 5);
  for (std::size_t i = 0; i < g.count; ++i) rssi->raw[i] = 12000;
  scan->has_time = true;
  scan->time.year = 1970;
  return scan;
}

TEST(DeviceFamilyTest, FromDeviceIdentNames) {
  EXPECT_EQ(FamilyFromDeviceName("LMS111-10100"), DeviceFamily::kLms1xx);
  EXPECT_EQ(FamilyFromDeviceName("LMS511-10100"), DeviceFamily::kLms5xx);
  EXPECT_EQ(FamilyFromDeviceName("TiM561-2050101"), DeviceFamily::kTim5xx);
  EXPECT_EQ(FamilyFromDeviceName("TiM781-2174101"), DeviceFamily::kTim7xx);
  EXPECT_EQ(FamilyFromDeviceName("TiM781S-2174104"), DeviceFamily::kTim7xxS);
  EXPECT_EQ(FamilyFromDeviceName("MRS1xxxx"), DeviceFamily::kMrs1xxx);
  EXPECT_EQ(FamilyFromDeviceName("LMS1104C-111011"), std::nullopt);  // an LMS1000
  EXPECT_EQ(FamilyFromDeviceName("NAV350"), std::nullopt);
  EXPECT_EQ(ParseDeviceFamily("tim7xxs"), DeviceFamily::kTim7xxS);
  EXPECT_EQ(ParseDeviceFamily("LMS5xx"), DeviceFamily::kLms5xx);
  EXPECT_EQ(std::string(DeviceFamilyName(DeviceFamily::kMrs1xxx)), "MRS1xxx");
}

class DialectTest : public ::testing::TestWithParam<Dialect> {};

// The start-up dialogue of SICK's driver for an MRS1104 (shared capture), plus the 3.9 driver's
// first request, answered by the model.
TEST_P(DialectTest, MrsDialogueStateMachineAndRefusals) {
  SopasDevice device(Options(DeviceFamily::kMrs1xxx, "MRS1xxxx"));
  Client c(&device, GetParam());
  const auto R = [&](CommandType t, std::string_view n, const SopasValues& v = {}) {
    return c.Expect(t, n, v);
  };
  EXPECT_EQ(c.Ask(CommandType::kRead, "SCdevicestate"),
            R(CommandType::kReadAnswer, "SCdevicestate", {S::U8(1)}));
  // Writes and measurement methods need the authorized client.
  EXPECT_EQ(c.Ask(CommandType::kMethod, "LMCstopmeas"), c.Error(1));
  EXPECT_EQ(c.Ask(CommandType::kWrite, "EIHstCola", {S::U8(1)}), c.Error(10));
  EXPECT_FALSE(c.Login(3, 0x6FD62C05));  // the safety scanner's hash is not this device's
  EXPECT_TRUE(c.Login(3, 0xF4724744));
  EXPECT_EQ(device.user_level(), 3);
  EXPECT_EQ(c.Ask(CommandType::kRead, "SCdevicestate"),
            R(CommandType::kReadAnswer, "SCdevicestate", {S::U8(0)}));
  EXPECT_EQ(c.Ask(CommandType::kWrite, "EIHstCola", {S::U8(1)}),
            c.Expect(CommandType::kWriteAnswer, "EIHstCola", {}, true));
  EXPECT_EQ(c.Ask(CommandType::kMethod, "LMCstopmeas"),
            R(CommandType::kMethodAnswer, "LMCstopmeas", {S::U8(0)}));
  EXPECT_FALSE(device.measuring());
  EXPECT_EQ(c.Ask(CommandType::kWrite, "SetActiveApplications",
                  {S::U16(1), S::Fixed("FEVL", 4), S::U8(0)}),
            R(CommandType::kWriteAnswer, "SetActiveApplications"));
  EXPECT_EQ(c.Ask(CommandType::kRead, "SetActiveApplications"),
            R(CommandType::kReadAnswer, "SetActiveApplications",
              {S::U16(2), S::Fixed("FEVL", 4), S::U8(0), S::Fixed("RANG", 4), S::U8(1)}));
  EXPECT_EQ(c.Ask(CommandType::kRead, "DeviceIdent"),
            R(CommandType::kReadAnswer, "DeviceIdent", {S::Str("MRS1xxxx"), S::Str("test")}));
  // An output range beyond the device's field of view: refused as the MRS1104 refused it.
  EXPECT_EQ(c.Ask(CommandType::kWrite, "LMPoutputRange",
                  {S::U16(1), S::U32(2500), S::I32(-1359292), S::I32(1390708)}),
            c.Error(4));
  EXPECT_EQ(c.Ask(CommandType::kRead, "LMPoutputRange"),
            R(CommandType::kReadAnswer, "LMPoutputRange",
              {S::U16(1), S::U32(2500), S::I32(-475000), S::I32(2275000)}));
  EXPECT_EQ(c.Ask(CommandType::kWrite, "LMDscandatacfg",
                  {S::U8(7), S::U8(0), S::U8(1), S::U8(0), S::U8(0), S::U8(0), S::U8(0), S::U8(0),
                   S::U8(0), S::U8(0), S::U8(1), S::U16(1)}),
            c.Expect(CommandType::kWriteAnswer, "LMDscandatacfg", {}, true));
  EXPECT_EQ(c.Ask(CommandType::kWrite, "FREchoFilter", {S::U8(2)}),
            R(CommandType::kWriteAnswer, "FREchoFilter"));
  EXPECT_EQ(c.Ask(CommandType::kWrite, "ScanLayerFilter",
                  {S::U16(4), S::U8(1), S::U8(0), S::U8(1), S::U8(1)}),
            c.Expect(CommandType::kWriteAnswer, "ScanLayerFilter", {}, true));
  EXPECT_EQ(c.Ask(CommandType::kMethod, "LMCstartmeas"),
            R(CommandType::kMethodAnswer, "LMCstartmeas", {S::U8(0)}));
  // Run at t = 1 s: busy until 15.5 s, as the MRS1104 of the capture.
  EXPECT_EQ(c.Ask(CommandType::kMethod, "Run", {}, kNsPerS),
            R(CommandType::kMethodAnswer, "Run", {S::U8(1)}));
  EXPECT_EQ(device.user_level(), 0);
  EXPECT_EQ(c.Ask(CommandType::kEvent, "LMDscandata", {S::U8(1)}, kNsPerS),
            R(CommandType::kEventAnswer, "LMDscandata", {S::U8(1)}));
  EXPECT_EQ(c.Ask(CommandType::kRead, "SCdevicestate", {}, 15400 * kNsPerMs),
            R(CommandType::kReadAnswer, "SCdevicestate", {S::U8(0)}));
  EXPECT_FALSE(device.ScanOutputEnabled(15400 * kNsPerMs));
  EXPECT_EQ(c.Ask(CommandType::kRead, "SCdevicestate", {}, 15600 * kNsPerMs),
            R(CommandType::kReadAnswer, "SCdevicestate", {S::U8(1)}));
  EXPECT_TRUE(device.ScanOutputEnabled(15600 * kNsPerMs));
  // The MRS1104 has no IMU event in this model, as the recorded one answered it.
  EXPECT_EQ(c.Ask(CommandType::kEvent, "InertialMeasurementUnit", {S::U8(1)}), c.Error(15));
  // The layer filter drops layer 2 (0°): its telegrams are not sent.
  const ScanGeometry g{-475000, 2500, 1101, 5000, 0};
  std::vector<SopasOutput> events;
  EXPECT_TRUE(device.PrepareScan(Scan(g, 5000, 250).get(), 16 * kNsPerS, &events));
  EXPECT_FALSE(device.PrepareScan(Scan(g, 5000, 0).get(), 16 * kNsPerS, &events));
  EXPECT_TRUE(device.PrepareScan(Scan(g, 5000, -500).get(), 16 * kNsPerS, &events));
  EXPECT_EQ(device.counters().scans_suppressed, 1u);
  // Stopping the measurement stops the scans.
  EXPECT_TRUE(c.Login(3, 0xF4724744, 17 * kNsPerS));
  EXPECT_EQ(c.Ask(CommandType::kMethod, "LMCstopmeas", {}, 17 * kNsPerS),
            R(CommandType::kMethodAnswer, "LMCstopmeas", {S::U8(0)}));
  c.Ask(CommandType::kMethod, "Run", {}, 17 * kNsPerS);
  EXPECT_FALSE(device.ScanOutputEnabled(60 * kNsPerS));
  EXPECT_EQ(device.counters().sfa, 4u);
  EXPECT_EQ(device.counters().logins_refused, 1u);
}

TEST_P(DialectTest, LoginLevelsHaveTheirOwnHashes) {
  for (const auto& [family, name, client_hash, other_hash] :
       {std::tuple{DeviceFamily::kTim7xxS, "TiM781S-2174104", 0x6FD62C05u, 0xF4724744u},
        std::tuple{DeviceFamily::kTim7xx, "TiM781-2174101", 0xF4724744u, 0x6FD62C05u},
        std::tuple{DeviceFamily::kLms1xx, "LMS111-10100", 0xF4724744u, 0x6FD62C05u}}) {
    SopasDevice device(Options(family, name));
    Client c(&device, GetParam());
    EXPECT_FALSE(c.Login(3, other_hash)) << name;
    EXPECT_EQ(device.user_level(), 0) << name;
    EXPECT_FALSE(c.Login(3, 0x81BE23AA)) << name << ": the service hash at the client level";
    EXPECT_FALSE(c.Login(7, client_hash)) << name << ": no such level";
    EXPECT_TRUE(c.Login(2, 0xB21ACE26)) << name << ": maintenance";
    EXPECT_EQ(c.Ask(CommandType::kMethod, "LMCstartmeas"), c.Error(1)) << name << ": below client";
    EXPECT_TRUE(c.Login(3, client_hash)) << name;
    EXPECT_TRUE(c.Login(4, 0x81BE23AA)) << name << ": service";
    EXPECT_EQ(device.user_level(), 4);
    EXPECT_EQ(c.Ask(CommandType::kMethod, "LMCstartmeas"),
              c.Expect(CommandType::kMethodAnswer, "LMCstartmeas", {S::U8(0)}));
    EXPECT_EQ(device.counters().logins_refused, 3u);
    // A new connection starts without a user level.
    device.OnDisconnect();
    EXPECT_EQ(device.user_level(), 0);
    EXPECT_EQ(c.Ask(CommandType::kMethod, "LMCstartmeas"), c.Error(1));
  }
}

TEST_P(DialectTest, LmsFieldsIoAndScanConfiguration) {
  SopasDevice device(Options(DeviceFamily::kLms5xx, "LMS511-10100"));
  Client c(&device, GetParam());
  ASSERT_TRUE(c.Login(3, 0xF4724744));
  // Thirty field slots: the first ten with the field layout, then one byte 0; field030 is unknown.
  const SopasValues* field000 = device.Value("field000");
  ASSERT_NE(field000, nullptr);
  EXPECT_EQ(c.Ask(CommandType::kRead, "field000"),
            c.Expect(CommandType::kReadAnswer, "field000", *field000));
  EXPECT_EQ(c.Ask(CommandType::kRead, "field010"),
            c.Expect(CommandType::kReadAnswer, "field010", {S::U8(0)}));
  EXPECT_EQ(c.Ask(CommandType::kRead, "field030"), c.Error(3));
  EXPECT_EQ(c.Ask(CommandType::kWrite, "field000", *field000), c.Error(10));  // read-only
  // Scan frequency and resolution are the source's: another one is refused with its status.
  EXPECT_EQ(
      c.Ask(CommandType::kMethod, "mLMPsetscancfg",
            {S::U32(2500), S::U16(1), S::U32(1667), S::I32(-50000), S::I32(1850000)}),
      c.Expect(CommandType::kMethodAnswer, "mLMPsetscancfg",
               {S::U8(0), S::U32(2500), S::U16(1), S::U32(1667), S::I32(-50000), S::I32(1850000)}));
  EXPECT_EQ(
      c.Ask(CommandType::kMethod, "mLMPsetscancfg",
            {S::U32(5000), S::U16(1), S::U32(5000), S::I32(-50000), S::I32(1850000)}),
      c.Expect(CommandType::kMethodAnswer, "mLMPsetscancfg",
               {S::U8(3), S::U32(2500), S::U16(1), S::U32(1667), S::I32(-50000), S::I32(1850000)}));
  // Output: a narrower range, no remission, every second scan, no time block.
  EXPECT_EQ(c.Ask(CommandType::kWrite, "LMPoutputRange",
                  {S::U16(1), S::U32(1667), S::I32(400000), S::I32(1400000)}),
            c.Expect(CommandType::kWriteAnswer, "LMPoutputRange", {}, true));
  const SopasValues cfg = {S::U8(1), S::U8(0), S::U8(0), S::U8(0), S::U8(0), S::U8(0),
                           S::U8(0), S::U8(0), S::U8(0), S::U8(0), S::U8(0), S::U16(2)};
  EXPECT_EQ(c.Ask(CommandType::kWrite, "LMDscandatacfg", cfg),
            c.Expect(CommandType::kWriteAnswer, "LMDscandatacfg", {}, true));
  EXPECT_EQ(c.Ask(CommandType::kRead, "LMDscandatacfg"),
            c.Expect(CommandType::kReadAnswer, "LMDscandatacfg", cfg));
  c.Ask(CommandType::kMethod, "LMCstartmeas");
  c.Ask(CommandType::kMethod, "Run");
  EXPECT_EQ(c.Ask(CommandType::kEvent, "LMDscandata", {S::U8(1)}),
            c.Expect(CommandType::kEventAnswer, "LMDscandata", {S::U8(1)}));
  EXPECT_EQ(c.Ask(CommandType::kEvent, "LFErec", {S::U8(1)}),
            c.Expect(CommandType::kEventAnswer, "LFErec", {S::U8(1)}));
  // The output state follows its subscription at once, as the LMS511 sent it.
  EXPECT_EQ(c.Ask(CommandType::kEvent, "LIDoutputstate", {S::U8(1)}),
            c.Expect(CommandType::kEventAnswer, "LIDoutputstate", {S::U8(1)}));
  ASSERT_EQ(c.events().size(), 1u);
  EXPECT_EQ(c.events()[0].substr(0, 19), "sSN LIDoutputstate ");
  EXPECT_TRUE(device.ScanOutputEnabled(0));

  const ScanGeometry g{-50000, 1667, 1141, 2500, 8};
  std::vector<SopasOutput> events;
  auto far = Scan(g, 5000);
  ASSERT_TRUE(device.PrepareScan(far.get(), kNsPerS, &events));
  EXPECT_TRUE(events.empty()) << "the first evaluation sets the state, it is no change";
  ASSERT_EQ(far->channels16.size(), 1u) << "remission off";
  EXPECT_EQ(far->channels8.size(), 0u);
  const cola::ScanChannel& dist = far->channels16[0];
  EXPECT_EQ(dist.start_angle_raw, -50000 + 270 * 1667);  // first beam at or after 40°
  EXPECT_EQ(dist.count, 601);                            // up to 140°
  EXPECT_FALSE(far->has_time);
  EXPECT_FALSE(device.PrepareScan(Scan(g, 5000).get(), kNsPerS, &events)) << "every second scan";
  // Everything at 0.8 m, in front too: inside the near field (1 m ahead) -> LFErec and
  // LIDoutputstate.
  ASSERT_TRUE(device.PrepareScan(Scan(g, 800).get(), 2 * kNsPerS, &events));
  ASSERT_EQ(events.size(), 2u);
  const std::string lferec(events[0].payload.begin(), events[0].payload.end());
  EXPECT_EQ(lferec.substr(0, 11), "sSN LFErec ");
  SopasValues values;
  ASSERT_TRUE(cola::DecodeValues(cola::SopasSchema::Compile(kLfeRecSchema), GetParam(),
                                 std::span<const std::uint8_t>(events[0].payload).subspan(11),
                                 &values)
                  .ok());
  ASSERT_GE(values.size(), 9u);
  EXPECT_EQ(values[0].AsInt(), 2);  // the two configured fields
  EXPECT_EQ(values[2].AsInt(), 1);  // field #1 ...
  EXPECT_EQ(values[8].AsInt(), 2);  // ... infringed
  EXPECT_EQ(device.counters().events_sent, 3u);
  // CoLa-A scans when subscribed in CoLa-A.
  EXPECT_EQ(device.EncodeScan(*far).dialect, GetParam());
}

TEST_P(DialectTest, HostileRequestsGetTheDevicesErrorCodes) {
  SopasDevice device(Options(DeviceFamily::kLms1xx, "LMS111-10100"));
  Client c(&device, GetParam());
  const auto text = [](std::string_view s) {
    return std::vector<std::uint8_t>(s.begin(), s.end());
  };
  EXPECT_EQ(c.Raw(text("sXY Foo")), c.Error(12));
  EXPECT_EQ(c.Raw(text("s")), c.Error(12));
  EXPECT_EQ(c.Raw(text("sRA SCdevicestate")), c.Error(12)) << "an answer sent to the device";
  EXPECT_EQ(c.Ask(CommandType::kRead, "NoSuchVariable"), c.Error(3));
  EXPECT_EQ(c.Ask(CommandType::kMethod, "NoSuchMethod"), c.Error(2));
  EXPECT_EQ(c.Ask(CommandType::kEvent, "NoSuchEvent", {S::U8(1)}), c.Error(15));
  EXPECT_EQ(c.Ask(CommandType::kRead, "SCdevicestate", {S::U8(1)}), c.Error(7));
  EXPECT_EQ(c.Ask(CommandType::kMethod, "SetAccessMode", {S::U8(3)}), c.Error(8));
  EXPECT_EQ(c.Ask(CommandType::kEvent, "LMDscandata", {S::U8(1), S::U8(1)}), c.Error(7));
  EXPECT_EQ(c.Ask(CommandType::kEvent, "LMDscandata", {S::U8(9)}), c.Error(4));
  EXPECT_EQ(c.Ask(CommandType::kRead, "LFErec"), c.Error(3)) << "an LMS1xx only sends it";
  if (GetParam() == Dialect::kColaA) {
    EXPECT_EQ(c.Raw(text("sMN SetAccessMode 3 F47247XX")), c.Error(17));
    EXPECT_EQ(c.Raw(text("sMN SetAccessMode 300 F4724744")), c.Error(16));
  }
  EXPECT_EQ(device.counters().unknown_commands, 7u);
  EXPECT_EQ(device.counters().requests, device.counters().sfa + device.counters().replies);
}

TEST_P(DialectTest, RecordedReadsReplaceDefaultsAndRebootRestoresSavedValues) {
  SopasDeviceOptions o = Options(DeviceFamily::kLms1xx, "LMS111-10100");
  // The LMS111's recorded output range (shared capture) and a location.
  o.identity.recorded_reads["LMPoutputRange"] = {0x00, 0x01, 0x00, 0x00, 0x13, 0x88, 0xff,
                                                 0xf9, 0x22, 0x33, 0x00, 0x22, 0x55, 0x0d};
  o.identity.recorded_reads["LocationName"] = {0x00, 0x03, 'l', 'a', 'b'};
  o.identity.recorded_reads["SCdevicestate"] = {0x00};  // live: never stored
  o.identity.recorded_reads["LMPoutputRangeX"] = {0x00};
  SopasDevice device(o);
  EXPECT_EQ(device.counters().recorded_reads_used, 2u);
  EXPECT_EQ(device.counters().recorded_reads_ignored, 2u);
  Client c(&device, GetParam());
  EXPECT_EQ(c.Ask(CommandType::kRead, "LMPoutputRange"),
            c.Expect(CommandType::kReadAnswer, "LMPoutputRange",
                     {S::U16(1), S::U32(5000), S::I32(-449997), S::I32(2249997)}));
  ASSERT_TRUE(c.Login(3, 0xF4724744));
  EXPECT_EQ(c.Ask(CommandType::kWrite, "LocationName", {S::Str("hall 2")}),
            c.Expect(CommandType::kWriteAnswer, "LocationName", {}, true));
  EXPECT_EQ(c.Ask(CommandType::kMethod, "mEEwriteall"),
            c.Expect(CommandType::kMethodAnswer, "mEEwriteall", {S::U8(1)}));
  EXPECT_EQ(c.Ask(CommandType::kWrite, "LocationName", {S::Str(std::string(17, 'x'))}), c.Error(4));
  EXPECT_EQ(c.Ask(CommandType::kWrite, "LocationName", {S::Str("temporary")}),
            c.Expect(CommandType::kWriteAnswer, "LocationName", {}, true));
  EXPECT_EQ(c.Ask(CommandType::kRead, "ODpwrc"),
            c.Expect(CommandType::kReadAnswer, "ODpwrc", {S::U32(42)}));
  EXPECT_EQ(c.Ask(CommandType::kMethod, "mSCreboot"),
            c.Expect(CommandType::kMethodAnswer, "mSCreboot", {}));
  EXPECT_EQ(c.Ask(CommandType::kRead, "LocationName"),
            c.Expect(CommandType::kReadAnswer, "LocationName", {S::Str("hall 2")}));
  EXPECT_EQ(c.Ask(CommandType::kRead, "ODpwrc"),
            c.Expect(CommandType::kReadAnswer, "ODpwrc", {S::U32(43)}));
  EXPECT_EQ(device.user_level(), 0);
  // Operating hours grow with the time the device runs (0.1 h units).
  EXPECT_EQ(c.Ask(CommandType::kRead, "ODoprh", {}, 3600 * kNsPerS),
            c.Expect(CommandType::kReadAnswer, "ODoprh", {S::U32(1234 + 10)}));
}

INSTANTIATE_TEST_SUITE_P(BothDialects, DialectTest,
                         ::testing::Values(Dialect::kColaB, Dialect::kColaA),
                         [](const auto& param_info) {
                           return std::string(param_info.param == Dialect::kColaA ? "ColaA"
                                                                                  : "ColaB");
                         });

TEST(SopasDeviceTest, CoLaATextIsWhatSicksListingShows) {
  SopasDevice device(Options(DeviceFamily::kLms1xx, "LMS111-10100"));
  Client c(&device, Dialect::kColaA);
  EXPECT_EQ(c.Ask(CommandType::kRead, "LMPoutputRange"),
            "sRA LMPoutputRange 1 1388 FFF92230 225510");
  EXPECT_EQ(c.Ask(CommandType::kRead, "LocationName"), "sRA LocationName B not defined");
  EXPECT_EQ(c.Raw(std::vector<std::uint8_t>{'s', 'M', 'N', ' ', 'S', 'e', 't', 'A', 'c', 'c',
                                            'e', 's', 's', 'M', 'o', 'd', 'e', ' ', '0', '3',
                                            ' ', 'F', '4', '7', '2', '4', '7', '4', '4'}),
            "sAN SetAccessMode 1");
  EXPECT_EQ(c.Ask(CommandType::kWrite, "EIHstCola", {S::U8(0)}), "sWA EIHstCola");
  EXPECT_EQ(device.host_dialect(), Dialect::kColaA);
}

TEST(SopasDeviceTest, LmsReadyShortlyAfterRunAndTimTimAtOnce) {
  SopasDevice lms(Options(DeviceFamily::kLms1xx, "LMS111-10100"));
  Client l(&lms, Dialect::kColaB);
  ASSERT_TRUE(l.Login(3, 0xF4724744));
  l.Ask(CommandType::kMethod, "Run", {}, 10 * kNsPerS);
  EXPECT_EQ(lms.DeviceState(10 * kNsPerS + 400 * kNsPerMs), 0);
  EXPECT_EQ(lms.DeviceState(10 * kNsPerS + 600 * kNsPerMs), 1);
  SopasDevice tim(Options(DeviceFamily::kTim5xx, "TiM561-2050101", 2.0));  // an explicit delay
  Client t(&tim, Dialect::kColaB);
  ASSERT_TRUE(t.Login(3, 0xF4724744));
  t.Ask(CommandType::kMethod, "Run", {}, 0);
  EXPECT_EQ(tim.DeviceState(1900 * kNsPerMs), 0);
  EXPECT_EQ(tim.DeviceState(2100 * kNsPerMs), 1);
  EXPECT_EQ(t.Ask(CommandType::kRead, "field000"), t.Error(3)) << "a TiM5xx has no fields";
}

TEST(SopasDeviceTest, RemissionWidthAndEchoChannelsFollowTheConfiguration) {
  SopasDeviceOptions o = Options(DeviceFamily::kTim5xx, "TiM561-2050101");
  o.identity.geometry = {-450000, 3333, 811, 1500, 16};
  SopasDevice device(o);
  Client c(&device, Dialect::kColaB);
  ASSERT_TRUE(c.Login(3, 0xF4724744));
  // 8-bit remission, echo 1 only, every scan, time block.
  const SopasValues cfg = {S::U8(1), S::U8(0), S::U8(1), S::U8(0), S::U8(0), S::U8(0),
                           S::U8(0), S::U8(0), S::U8(0), S::U8(0), S::U8(1), S::U16(1)};
  ASSERT_EQ(c.Ask(CommandType::kWrite, "LMDscandatacfg", cfg),
            c.Expect(CommandType::kWriteAnswer, "LMDscandatacfg", {}, true));
  auto scan = Scan(o.identity.geometry, 3000);
  cola::ScanChannel* dist2 = scan->channels16.emplace_slot();
  *dist2 = scan->channels16[0];
  std::memcpy(dist2->name.data(), "DIST2", 5);
  std::vector<SopasOutput> events;
  ASSERT_TRUE(device.PrepareScan(scan.get(), 0, &events));
  ASSERT_EQ(scan->channels16.size(), 1u) << "DIST2 is not an output channel";
  EXPECT_EQ(scan->channels16[0].name_view(), "DIST1");
  ASSERT_EQ(scan->channels8.size(), 1u);
  EXPECT_EQ(scan->channels8[0].name_view(), "RSSI1");
  EXPECT_EQ(scan->channels8[0].raw[0], 12000 / 257);
  EXPECT_EQ(scan->channels8[0].count, 811);
  std::vector<std::uint8_t> payload(cola::MaxEncodedSize(*scan));
  EXPECT_GT(cola::EncodeScanTelegram(*scan, payload), 0u);
}

}  // namespace
}  // namespace lrfnet::tools
