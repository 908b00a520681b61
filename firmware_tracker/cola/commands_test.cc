#include "firmware_tracker/cola/commands.h"

#include <gtest/gtest.h>

#include <array>
#include <string>
#include <string_view>
#include <vector>

#include "firmware_tracker/cola/cola_test_util.h"

namespace lrfnet::cola {
namespace {

using Bytes = std::vector<std::uint8_t>;

using test::B;

template <typename Encode>
Bytes Encoded(Encode encode) {
  std::array<std::uint8_t, 256> buf{};
  const std::size_t n = encode(std::span<std::uint8_t>(buf));
  return Bytes(buf.begin(), buf.begin() + n);
}

// Client commands, compared with the bytes the sick_scan_xd driver sent in the shared captures.
TEST(CommandsTest, SetAccessModeMatchesTheRealLogin) {
  const Bytes real = B(std::string_view("sMN SetAccessMode \x03\xf4\x72\x47\x44", 23));
  EXPECT_EQ(Encoded([](auto out) {
              return EncodeSetAccessMode(AccessLevel::kAuthorizedClient,
                                         kAuthorizedClientPasswordHash, out);
            }),
            real);
}

TEST(CommandsTest, FixedCommandsMatchTheCaptures) {
  EXPECT_EQ(Encoded([](auto out) { return EncodeReadVariable("FirmwareVersion", out); }),
            B("sRN FirmwareVersion"));
  EXPECT_EQ(Encoded([](auto out) { return EncodeStartMeasurement(out); }), B("sMN LMCstartmeas"));
  EXPECT_EQ(Encoded([](auto out) { return EncodeStopMeasurement(out); }), B("sMN LMCstopmeas"));
  EXPECT_EQ(Encoded([](auto out) { return EncodeRun(out); }), B("sMN Run"));
  EXPECT_EQ(Encoded([](auto out) { return EncodeScanDataEvent(true, out); }),
            B(std::string_view("sEN LMDscandata \x01", 17)));
  EXPECT_EQ(Encoded([](auto out) { return EncodeScanDataEvent(false, out); }),
            B(std::string_view("sEN LMDscandata \x00", 17)));
}

TEST(CommandsTest, ReadVariableRejectsNamesThatWouldBreakTheHeader) {
  EXPECT_TRUE(Encoded([](auto out) { return EncodeReadVariable("", out); }).empty());
  EXPECT_TRUE(Encoded([](auto out) { return EncodeReadVariable("two words", out); }).empty());
  EXPECT_TRUE(Encoded([](auto out) {
                return EncodeReadVariable(std::string_view("a\x02", 2), out);
              }).empty());
}

TEST(CommandsTest, ScanDataConfigMatchesTheLms111Capture) {
  ScanDataConfig c;
  c.output_channel = 1;
  c.remission = false;
  c.resolution = 0;
  c.time = true;
  c.output_interval = 1;
  EXPECT_EQ(Encoded([&](auto out) { return EncodeScanDataConfig(c, out); }),
            B(std::string_view(
                "sWN LMDscandatacfg \x01\x00\x00\x00\x00\x00\x00\x00\x00\x00\x01\x00\x01", 32)));
}

TEST(CommandsTest, ScanDataConfigMatchesTheLms511CaptureWith8BitRssi) {
  ScanDataConfig c;
  c.remission = true;
  c.resolution = 0;
  EXPECT_EQ(Encoded([&](auto out) { return EncodeScanDataConfig(c, out); }),
            B(std::string_view(
                "sWN LMDscandatacfg \x01\x00\x01\x00\x00\x00\x00\x00\x00\x00\x01\x00\x01", 32)));
}

TEST(CommandsTest, ScanDataConfigFieldPositions) {
  ScanDataConfig c;
  c.output_channel = 7;  // the MRS1104 capture's three echoes
  c.remission = true;
  c.resolution = 1;
  c.encoder = true;
  c.position = true;
  c.device_name = true;
  c.comment = true;
  c.time = false;
  c.output_interval = 0x0203;
  EXPECT_EQ(Encoded([&](auto out) { return EncodeScanDataConfig(c, out); }),
            B(std::string_view(
                "sWN LMDscandatacfg \x07\x00\x01\x01\x00\x01\x00\x01\x01\x01\x00\x02\x03", 32)));
}

TEST(CommandsTest, EncodersReturnZeroWhenTheBufferIsTooSmall) {
  std::array<std::uint8_t, 22> small{};  // one byte short of SetAccessMode
  EXPECT_EQ(EncodeSetAccessMode(AccessLevel::kService, kServicePasswordHash, small), 0u);
  std::array<std::uint8_t, 31> cfg{};
  EXPECT_EQ(EncodeScanDataConfig({}, cfg), 0u);
  std::array<std::uint8_t, 6> run{};
  EXPECT_EQ(EncodeRun(run), 0u);
  std::array<std::uint8_t, 7> run_exact{};
  EXPECT_EQ(EncodeRun(run_exact), 7u);
  std::array<std::uint8_t, 4> fa{};
  EXPECT_EQ(EncodeErrorReply(3, fa), 0u);
}

// Device replies (for the emulator), compared with real replies.
TEST(CommandsTest, RepliesMatchTheCaptures) {
  const Bytes one{1};
  EXPECT_EQ(Encoded([&](auto out) {
              return EncodeReply(CommandType::kMethodAnswer, "SetAccessMode", one, out);
            }),
            B(std::string_view("sAN SetAccessMode \x01", 19)));
  EXPECT_EQ(Encoded([&](auto out) {
              return EncodeReply(CommandType::kWriteAnswer, "FREchoFilter", {}, out);
            }),
            B("sWA FREchoFilter"));
  EXPECT_EQ(Encoded([&](auto out) {
              return EncodeReply(CommandType::kWriteAnswer, "LMDscandatacfg", {},
                                 EmptyArgsSpace::kWrite, out);
            }),
            B("sWA LMDscandatacfg "));
  EXPECT_EQ(Encoded([](auto out) { return EncodeErrorReply(3, out); }),
            B(std::string_view("sFA\x00\x03", 5)));
  // sFA has its own encoder; an unknown type has no text.
  EXPECT_TRUE(
      Encoded([&](auto out) { return EncodeReply(CommandType::kError, "X", one, out); }).empty());
  EXPECT_TRUE(
      Encoded([&](auto out) { return EncodeReply(CommandType::kUnknown, "X", one, out); }).empty());
}

TEST(CommandsTest, RepliesParseBackToTheSameHeader) {
  const Bytes args{0x00, 0x09, 'V', '1', '.', '8', '0', '.', '2', ' ', ' '};
  const Bytes p = Encoded([&](auto out) {
    return EncodeReply(CommandType::kReadAnswer, "FirmwareVersion", args, out);
  });
  TelegramHeader h;
  ASSERT_EQ(ParseTelegramHeader(p, &h), HeaderStatus::kOk);
  EXPECT_EQ(h.type, CommandType::kReadAnswer);
  EXPECT_EQ(h.name, "FirmwareVersion");
  EXPECT_EQ(Bytes(h.args.begin(), h.args.end()), args);
}

TEST(DecodeTest, FlexStringOfTheLms111FirmwareVersion) {
  const Bytes args = B(std::string_view("\x00\x09V1.80.2  ", 11));
  FlexString s;
  ASSERT_TRUE(DecodeFlexString(args, &s));
  EXPECT_EQ(s.text, "V1.80.2  ");
  EXPECT_EQ(s.consumed, 11u);
  FlexString t;
  EXPECT_FALSE(DecodeFlexString(Bytes(args.begin(), args.end() - 1), &t));  // one char missing
  EXPECT_FALSE(DecodeFlexString(Bytes{0x00}, &t));
  EXPECT_FALSE(DecodeFlexString(Bytes{0xFF, 0xFF, 'a'}, &t));
  ASSERT_TRUE(DecodeFlexString(Bytes{0x00, 0x00}, &t));
  EXPECT_EQ(t.text, "");
}

TEST(DecodeTest, DeviceIdentOfTheMrs1104) {
  const Bytes args =
      B(std::string_view("\x00\x08MRS1xxxx\x00\x08"
                         "1.0.0.0R",
                         20));
  DeviceIdent id;
  ASSERT_TRUE(DecodeDeviceIdent(args, &id));
  EXPECT_EQ(id.name, "MRS1xxxx");
  EXPECT_EQ(id.version, "1.0.0.0R");
  for (std::size_t cut = 0; cut < args.size(); ++cut) {
    EXPECT_FALSE(DecodeDeviceIdent(std::span<const std::uint8_t>(args).first(cut), &id)) << cut;
  }
}

TEST(DecodeTest, FirstByte) {
  std::uint8_t v = 9;
  EXPECT_FALSE(DecodeFirstByte({}, &v));
  EXPECT_EQ(v, 9);
  const Bytes one{1, 2};
  ASSERT_TRUE(DecodeFirstByte(one, &v));
  EXPECT_EQ(v, 1);
}

}  // namespace
}  // namespace lrfnet::cola
