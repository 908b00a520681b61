#include "firmware_tracker/cola/telegram.h"

#include <gtest/gtest.h>

#include <string>
#include <string_view>
#include <vector>

#include "firmware_tracker/cola/cola_test_util.h"

namespace lrfnet::cola {
namespace {

using Bytes = std::vector<std::uint8_t>;

using test::B;
std::string Str(std::span<const std::uint8_t> s) { return std::string(s.begin(), s.end()); }

// Payloads as the real devices sent them (shared captures).
TEST(TelegramHeaderTest, MethodAnswerWithArgument) {
  const Bytes p = B(std::string_view("sAN SetAccessMode \x01", 19));
  TelegramHeader h;
  ASSERT_EQ(ParseTelegramHeader(p, &h), HeaderStatus::kOk);
  EXPECT_EQ(h.type, CommandType::kMethodAnswer);
  EXPECT_EQ(h.name, "SetAccessMode");
  EXPECT_EQ(Str(h.args), std::string("\x01"));
}

TEST(TelegramHeaderTest, ReadWithoutArgumentsHasNoTrailingSpace) {
  const Bytes p = B("sRN FirmwareVersion");
  TelegramHeader h;
  ASSERT_EQ(ParseTelegramHeader(p, &h), HeaderStatus::kOk);
  EXPECT_EQ(h.type, CommandType::kRead);
  EXPECT_EQ(h.name, "FirmwareVersion");
  EXPECT_TRUE(h.args.empty());
}

TEST(TelegramHeaderTest, WriteAnswersWithAndWithoutTrailingSpace) {
  TelegramHeader h;
  const Bytes lms = B("sWA LMDscandatacfg ");  // LMS111 / LMS511
  ASSERT_EQ(ParseTelegramHeader(lms, &h), HeaderStatus::kOk);
  EXPECT_EQ(h.type, CommandType::kWriteAnswer);
  EXPECT_EQ(h.name, "LMDscandatacfg");
  EXPECT_TRUE(h.args.empty());
  const Bytes mrs = B("sWA FREchoFilter");  // MRS1104
  ASSERT_EQ(ParseTelegramHeader(mrs, &h), HeaderStatus::kOk);
  EXPECT_EQ(h.name, "FREchoFilter");
  EXPECT_TRUE(h.args.empty());
}

TEST(TelegramHeaderTest, ErrorReplyHasCodeAndNoName) {
  const Bytes p = B(std::string_view("sFA\x00\x03", 5));  // LMS511 answer to sRN field030
  TelegramHeader h;
  ASSERT_EQ(ParseTelegramHeader(p, &h), HeaderStatus::kOk);
  EXPECT_EQ(h.type, CommandType::kError);
  EXPECT_TRUE(h.name.empty());
  EXPECT_EQ(h.error_code, 3);
  EXPECT_TRUE(h.args.empty());
  EXPECT_STREQ(SopasErrorName(h.error_code),
               "unknown variable (Sopas_Error_VARIABLE_UNKNOWNINDEX)");

  const Bytes big = B(std::string_view("sFA\x01\x0f", 5));
  ASSERT_EQ(ParseTelegramHeader(big, &h), HeaderStatus::kOk);
  EXPECT_EQ(h.error_code, 0x010f);
  EXPECT_EQ(ParseTelegramHeader(B(std::string_view("sFA\x00", 4)), &h), HeaderStatus::kTooShort);
}

TEST(TelegramHeaderTest, ScanAndEventTelegrams) {
  TelegramHeader h;
  const Bytes scan = B(std::string_view("sSN LMDscandata \x00\x01\x00\x01", 20));
  ASSERT_EQ(ParseTelegramHeader(scan, &h), HeaderStatus::kOk);
  EXPECT_EQ(h.type, CommandType::kEventData);
  EXPECT_EQ(h.name, "LMDscandata");
  EXPECT_EQ(h.args.size(), 4u);
  EXPECT_EQ(h.args.data(), scan.data() + 16);  // a view, not a copy
  const Bytes ea = B(std::string_view("sEA LMDscandata \x01", 17));
  ASSERT_EQ(ParseTelegramHeader(ea, &h), HeaderStatus::kOk);
  EXPECT_EQ(h.type, CommandType::kEventAnswer);
  EXPECT_EQ(Str(h.args), "\x01");
}

TEST(TelegramHeaderTest, EveryTypeIsRecognisedAndNamed) {
  const std::vector<std::pair<std::string, CommandType>> kAll = {
      {"sRN", CommandType::kRead},         {"sWN", CommandType::kWrite},
      {"sMN", CommandType::kMethod},       {"sEN", CommandType::kEvent},
      {"sRA", CommandType::kReadAnswer},   {"sWA", CommandType::kWriteAnswer},
      {"sAN", CommandType::kMethodAnswer}, {"sEA", CommandType::kEventAnswer},
      {"sSN", CommandType::kEventData}};
  for (const auto& [text, type] : kAll) {
    TelegramHeader h;
    ASSERT_EQ(ParseTelegramHeader(B(text + " X"), &h), HeaderStatus::kOk) << text;
    EXPECT_EQ(h.type, type);
    EXPECT_EQ(CommandTypeName(type), text);
  }
  EXPECT_STREQ(CommandTypeName(CommandType::kError), "sFA");
  EXPECT_STREQ(CommandTypeName(CommandType::kUnknown), "?");
}

TEST(TelegramHeaderTest, MalformedHeadersAreRejectedWithAStatus) {
  TelegramHeader h;
  EXPECT_EQ(ParseTelegramHeader(B(""), &h), HeaderStatus::kTooShort);
  EXPECT_EQ(ParseTelegramHeader(B("sR"), &h), HeaderStatus::kTooShort);
  EXPECT_EQ(ParseTelegramHeader(B("sRN"), &h), HeaderStatus::kTooShort);
  EXPECT_EQ(ParseTelegramHeader(B("sRN "), &h), HeaderStatus::kTooShort);
  EXPECT_EQ(ParseTelegramHeader(B("sXN Name"), &h), HeaderStatus::kUnknownType);
  EXPECT_EQ(ParseTelegramHeader(B("SRN Name"), &h), HeaderStatus::kUnknownType);
  EXPECT_EQ(ParseTelegramHeader(B("sRNName"), &h), HeaderStatus::kBadName);
  EXPECT_EQ(ParseTelegramHeader(B("sRN  Name"), &h), HeaderStatus::kBadName);
  EXPECT_EQ(ParseTelegramHeader(B(std::string_view("sRN Na\x01me", 10)), &h),
            HeaderStatus::kBadName);
  EXPECT_EQ(h.type, CommandType::kUnknown);  // nothing half-filled on failure
  EXPECT_STRNE(HeaderStatusName(HeaderStatus::kBadName), HeaderStatusName(HeaderStatus::kTooShort));
}

TEST(IsScanTelegramTest, ExactNameFollowedBySpace) {
  EXPECT_TRUE(IsScanTelegram(B(std::string_view("sSN LMDscandata \x00\x01", 18))));
  EXPECT_FALSE(IsScanTelegram(B("sSN LMDscandatamon \x01")));
  EXPECT_FALSE(IsScanTelegram(B("sSN LMDscandata")));
  EXPECT_FALSE(IsScanTelegram(B("sRA LMDscandata \x01")));
  EXPECT_FALSE(IsScanTelegram(B("sSN LIDoutputstate \x00")));
}

TEST(SopasErrorNameTest, CoversTheSopasCodes) {
  EXPECT_STREQ(SopasErrorName(0), "ok (Sopas_Ok)");
  EXPECT_STREQ(SopasErrorName(1), "access denied (Sopas_Error_METHODIN_ACCESSDENIED)");
  EXPECT_STREQ(SopasErrorName(4), "local condition failed (Sopas_Error_LOCALCONDITIONFAILED)");
  EXPECT_STREQ(SopasErrorName(15), "unknown event (Sopas_Error_EVENTREG_UNKNOWNINDEX)");
  EXPECT_STREQ(SopasErrorName(26),
               "complex arrays not supported (Sopas_Error_ComplexArraysNotSupported)");
  EXPECT_STREQ(SopasErrorName(27), "unknown SOPAS error code");
  EXPECT_STREQ(SopasErrorName(0xFFFF), "unknown SOPAS error code");
}

}  // namespace
}  // namespace lrfnet::cola
