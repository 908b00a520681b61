#include "firmware_tracker/cola/sopas_value.h"

#include <gtest/gtest.h>

#include <string>
#include <string_view>
#include <vector>

#include "firmware_tracker/cola/cola_test_util.h"
#include "firmware_tracker/cola/scan_telegram.h"
#include "tests/support/test_data.h"

namespace lrfnet::cola {
namespace {

using Bytes = std::vector<std::uint8_t>;
using S = SopasScalar;

using test::B;
std::string Text(const Bytes& b) { return std::string(b.begin(), b.end()); }

Bytes Encode(const SopasValues& v, Dialect d) {
  Bytes out;
  EXPECT_TRUE(AppendValues(v, d, &out));
  return out;
}

SopasValues Decode(std::string_view schema, Dialect d, const Bytes& args,
                   ValueStatus expect = ValueStatus::kOk) {
  SopasValues v;
  const ValueResult r = DecodeValues(SopasSchema::Compile(schema), d, args, &v);
  EXPECT_EQ(r.status, expect) << ValueStatusName(r.status) << " at " << r.offset << " in '"
                              << Text(args) << "'";
  return v;
}

TEST(SopasSchemaTest, ParsesTheLanguageAndRejectsNonsense) {
  std::string error;
  for (const char* good :
       {"", "u8", "u16[u32 i32 i32]", "u16?[u16 u8 u8 u8 u8 u8 u32]", "11*[u8 u32] u16",
        "c5 f32 f32 i32 u16 u16[u16]", "u16[c4 u8]", "str str sstr", "u8[u8[u8]]"}) {
    EXPECT_TRUE(SopasSchema::Parse(good, &error).has_value()) << good << ": " << error;
  }
  for (const char* bad : {"u7", "i16[u8]", "u16[", "u16[]", "]", "u16?u8", "0*[u8]", "3[u8]", "c0",
                          "c65", "f32?[u8]", "u8 $", "u8[u8[u8[u8[u8[u8[u8[u8[u8[u8]]]]]]]]]"}) {
    EXPECT_FALSE(SopasSchema::Parse(bad, &error).has_value()) << bad;
    EXPECT_FALSE(error.empty());
  }
}

// LMPoutputRange as the LMS111 sent it (CoLa-B, shared capture: −44.9997° .. 224.9997° at 0.5°)
// and in CoLa-A.
TEST(SopasValueTest, OutputRangeInBothDialects) {
  const Bytes binary = {0x00, 0x01, 0x00, 0x00, 0x13, 0x88, 0xff,
                        0xf9, 0x22, 0x33, 0x00, 0x22, 0x55, 0x0d};
  const SopasValues v = Decode("u16[u32 i32 i32]", Dialect::kColaB, binary);
  ASSERT_EQ(v.size(), 4u);
  EXPECT_EQ(v[0].AsInt(), 1);
  EXPECT_EQ(v[1].AsInt(), 5000);
  EXPECT_EQ(v[2].AsInt(), -449997);
  EXPECT_EQ(v[3].AsInt(), 2249997);
  EXPECT_EQ(Encode(v, Dialect::kColaB), binary);
  EXPECT_EQ(Text(Encode(v, Dialect::kColaA)), "1 1388 FFF92233 22550D");
  EXPECT_EQ(Decode("u16[u32 i32 i32]", Dialect::kColaA, B("1 1388 FFF92233 22550D")), v);
  // Decimal with a sign, as hand-written requests use it; leading zeros and extra spaces too.
  EXPECT_EQ(Decode("u16[u32 i32 i32]", Dialect::kColaA, B("+1 +5000 -449997  +2249997 ")), v);
  EXPECT_EQ(Decode("u16[u32 i32 i32]", Dialect::kColaA, B("0001 00001388 FFF92233 22550D")), v);
}

TEST(SopasValueTest, StringsCarryTheirLengthAndMayHoldSpaces) {
  const SopasValues v = {S::Str("not defined")};
  EXPECT_EQ(Text(Encode(v, Dialect::kColaA)), "B not defined");
  EXPECT_EQ(Encode(v, Dialect::kColaB), B(std::string_view("\x00\x0bnot defined", 13)));
  EXPECT_EQ(Decode("str", Dialect::kColaA, B("B not defined")), v);
  EXPECT_EQ(Decode("str str", Dialect::kColaA, B("8 MRS1xxxx 8 1.0.0.0R")),
            (SopasValues{S::Str("MRS1xxxx"), S::Str("1.0.0.0R")}));
  EXPECT_EQ(Text(Encode({S::Str("")}, Dialect::kColaA)), "0");
  EXPECT_EQ(Decode("str u8", Dialect::kColaA, B("0 1")), (SopasValues{S::Str(""), S::U8(1)}));
  EXPECT_EQ(Text(Encode({S::U16(1), S::Fixed("FEVL", 4), S::U8(0)}, Dialect::kColaA)), "1 FEVL 0");
  EXPECT_EQ(Encode({S::U16(1), S::Fixed("FEVL", 4), S::U8(0)}, Dialect::kColaB),
            (Bytes{0, 1, 'F', 'E', 'V', 'L', 0}));
}

TEST(SopasValueTest, FloatsAndSignedValuesInCoLaA) {
  EXPECT_EQ(Text(Encode({S::F32(1.0f), S::F32(0.0f), S::I16(-500), S::I8(-1), S::I32(250)},
                        Dialect::kColaA)),
            "3F800000 00000000 FE0C FF FA");
  const SopasValues v = Decode("f32 i16 i8", Dialect::kColaA, B("+2.5 FE0C -1"));
  EXPECT_EQ(v[0].AsFloat(), 2.5f);
  EXPECT_EQ(v[1].AsInt(), -500);
  EXPECT_EQ(v[2].AsInt(), -1);
}

TEST(SopasValueTest, HostileArgumentsGiveTheirErrorNotACrash) {
  const auto status = [](std::string_view schema, Dialect d, const Bytes& args) {
    SopasValues v;
    return DecodeValues(SopasSchema::Compile(schema), d, args, &v).status;
  };
  EXPECT_EQ(status("u32", Dialect::kColaB, {1, 2, 3}), ValueStatus::kTruncated);
  EXPECT_EQ(status("u8", Dialect::kColaB, {1, 2}), ValueStatus::kTrailing);
  EXPECT_EQ(status("u16[u8]", Dialect::kColaB, {0xFF, 0xFF, 1}), ValueStatus::kTooMany);
  EXPECT_EQ(status("str", Dialect::kColaB, {0x00, 0x05, 'a'}), ValueStatus::kTruncated);
  EXPECT_EQ(status("u8", Dialect::kColaA, B("1G")), ValueStatus::kBadCharacter);
  EXPECT_EQ(status("u8", Dialect::kColaA, B("100")), ValueStatus::kOverflow);
  EXPECT_EQ(status("u8", Dialect::kColaA, B("-1")), ValueStatus::kOverflow);
  EXPECT_EQ(status("i8", Dialect::kColaA, B("+128")), ValueStatus::kOverflow);
  EXPECT_EQ(status("u32", Dialect::kColaA, B("123456789")), ValueStatus::kOverflow);
  EXPECT_EQ(status("u32", Dialect::kColaA, B("+99999999999999")), ValueStatus::kOverflow);
  EXPECT_EQ(status("u8 u8", Dialect::kColaA, B("1")), ValueStatus::kTruncated);
  EXPECT_EQ(status("u8", Dialect::kColaA, B("1 2")), ValueStatus::kTrailing);
  EXPECT_EQ(status("str", Dialect::kColaA, B("FF abc")), ValueStatus::kTruncated);
  EXPECT_EQ(status("c4", Dialect::kColaA, B("FEV")), ValueStatus::kBadCharacter);
  EXPECT_EQ(status("u16[u8]", Dialect::kColaA, B("FFFF 1")), ValueStatus::kTooMany);
  EXPECT_EQ(SopasErrorCodeOf(ValueStatus::kTruncated), 8);
  EXPECT_EQ(SopasErrorCodeOf(ValueStatus::kBadCharacter), 17);
  // What CoLa-A cannot carry is refused instead of breaking the frame.
  Bytes out;
  EXPECT_FALSE(AppendValues({S::Str("a\x03")}, Dialect::kColaA, &out));
  out.clear();
  EXPECT_FALSE(AppendValues({S::Str(std::string(70000, 'x'))}, Dialect::kColaB, &out));
}

TEST(SopasTelegramTest, HeadersAndErrorsInBothDialects) {
  TelegramHeader h;
  const Bytes login = B("sMN SetAccessMode 3 F4724744");
  ASSERT_EQ(ParseSopasTelegram(Dialect::kColaA, login, &h), HeaderStatus::kOk);
  EXPECT_EQ(h.type, CommandType::kMethod);
  EXPECT_EQ(h.name, "SetAccessMode");
  EXPECT_EQ(Text(Bytes(h.args.begin(), h.args.end())), "3 F4724744");
  ASSERT_EQ(ParseSopasTelegram(Dialect::kColaA, B("sFA F"), &h), HeaderStatus::kOk);
  EXPECT_EQ(h.type, CommandType::kError);
  EXPECT_EQ(h.error_code, 15);
  ASSERT_EQ(ParseSopasTelegram(Dialect::kColaB, Bytes{'s', 'F', 'A', 0, 3}, &h), HeaderStatus::kOk);
  EXPECT_EQ(h.error_code, 3);
  EXPECT_NE(ParseSopasTelegram(Dialect::kColaA, B("sFA XYZ"), &h), HeaderStatus::kOk);
  EXPECT_NE(ParseSopasTelegram(Dialect::kColaA, B("sXY Foo"), &h), HeaderStatus::kOk);

  EXPECT_EQ(EncodeSopasError(Dialect::kColaB, 3), (Bytes{'s', 'F', 'A', 0, 3}));
  EXPECT_EQ(Text(EncodeSopasError(Dialect::kColaA, 15)), "sFA F");
  EXPECT_EQ(Text(EncodeSopasTelegram(Dialect::kColaA, CommandType::kReadAnswer, "SCdevicestate",
                                     {S::U8(1)})),
            "sRA SCdevicestate 1");
  EXPECT_EQ(Text(EncodeSopasTelegram(Dialect::kColaB, CommandType::kWriteAnswer, "LMDscandatacfg",
                                     {}, true)),
            "sWA LMDscandatacfg ");
  EXPECT_EQ(Text(EncodeSopasTelegram(Dialect::kColaA, CommandType::kWriteAnswer, "LMDscandatacfg",
                                     {}, true)),
            "sWA LMDscandatacfg");
  EXPECT_TRUE(
      EncodeSopasTelegram(Dialect::kColaB, CommandType::kReadAnswer, "bad name", {}).empty());
}

// Every scan telegram of the shared captures: the schema decodes it, re-encodes it byte for byte,
// and its CoLa-A form (as the driver's ASCII parser reads it) carries the same values.
class CaptureScanValuesTest : public ::testing::TestWithParam<std::string> {};

TEST_P(CaptureScanValuesTest, SchemaRoundTripsEveryScanThroughCoLaA) {
  LRFNET_REQUIRE_SHARED_FILE(path, "data/sick/" + GetParam());
  const std::vector<std::uint8_t> file = testing::ReadFileBytes(path);
  const auto frames = test::ExtractFrames(test::SensorStreamFromCapture(file), "sSN LMDscandata ");
  ASSERT_FALSE(frames.empty());
  constexpr std::size_t kPrefix = 16;  // "sSN LMDscandata "
  auto scan = std::make_unique<ScanTelegram>();
  for (std::size_t i = 0; i < frames.size(); ++i) {
    const std::span<const std::uint8_t> args(frames[i].data() + kPrefix,
                                             frames[i].size() - kPrefix);
    SopasValues values;
    const ValueResult r = DecodeValues(ScanTelegramSchema(), Dialect::kColaB, args, &values);
    ASSERT_TRUE(r.ok()) << "scan " << i << ": " << ValueStatusName(r.status) << " at " << r.offset;
    ASSERT_EQ(Encode(values, Dialect::kColaB), Bytes(args.begin(), args.end())) << "scan " << i;
    ASSERT_TRUE(DecodeScanTelegram(frames[i], scan.get()).ok);
    SopasValues from_scan;
    ScanTelegramToValues(*scan, &from_scan);
    ASSERT_EQ(from_scan, values) << "scan " << i;
    const Bytes ascii = Encode(values, Dialect::kColaA);
    SopasValues again;
    ASSERT_TRUE(DecodeValues(ScanTelegramSchema(), Dialect::kColaA, ascii, &again).ok());
    ASSERT_EQ(again, values) << "scan " << i;
    if (i == 0) {
      // The tokens SICK's ASCII parser indexes: [18] = "DIST1" counting from "sSN LMDscandata".
      std::vector<std::string> tokens;
      std::string t;
      for (const std::uint8_t c : ascii) {
        if (c == ' ') {
          tokens.push_back(t);
          t.clear();
        } else {
          t.push_back(static_cast<char>(c));
        }
      }
      ASSERT_GT(tokens.size(), 30u);
      EXPECT_EQ(tokens[18], "DIST1");
      EXPECT_EQ(tokens[13], "0") << "reserved / layer angle of a single-layer device";
    }
  }
}

INSTANTIATE_TEST_SUITE_P(SharedCaptures, CaptureScanValuesTest,
                         ::testing::Values("test.pcapng", "lms111_20210302.pcap",
                                           "lms511_20210301.pcap"));

TEST(SopasScanValuesTest, EveryOptionalBlockRoundTrips) {
  const auto scan = test::MakeFullScan(100);
  SopasValues values;
  ScanTelegramToValues(*scan, &values);
  const Bytes binary = Encode(values, Dialect::kColaB);
  std::vector<std::uint8_t> payload(MaxEncodedSize(*scan));
  payload.resize(EncodeScanTelegram(*scan, payload));
  ASSERT_EQ(Bytes(payload.begin() + 16, payload.end()), binary);
  // Its comment ends in bytes 01 FF, which CoLa-A cannot carry: refused, not sent broken.
  Bytes ascii;
  EXPECT_FALSE(AppendValues(values, Dialect::kColaA, &ascii));
  scan->comment.length = 19;  // "mounted at the door"
  ScanTelegramToValues(*scan, &values);
  SopasValues again;
  ASSERT_TRUE(
      DecodeValues(ScanTelegramSchema(), Dialect::kColaA, Encode(values, Dialect::kColaA), &again)
          .ok());
  EXPECT_EQ(again, values);
}

}  // namespace
}  // namespace lrfnet::cola
