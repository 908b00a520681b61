#include "firmware_tracker/cola/telegram.h"

#include <array>
#include <cstring>

#include "common/byte_order.h"

namespace lrfnet::cola {
namespace {

struct TypeEntry {
  char text[4];
  CommandType type;
};

constexpr std::array<TypeEntry, 10> kTypes = {{
    {"sRN", CommandType::kRead},
    {"sWN", CommandType::kWrite},
    {"sMN", CommandType::kMethod},
    {"sEN", CommandType::kEvent},
    {"sRA", CommandType::kReadAnswer},
    {"sWA", CommandType::kWriteAnswer},
    {"sAN", CommandType::kMethodAnswer},
    {"sEA", CommandType::kEventAnswer},
    {"sSN", CommandType::kEventData},
    {"sFA", CommandType::kError},
}};

constexpr char kScanPrefix[] = "sSN LMDscandata ";
constexpr std::size_t kScanPrefixBytes = sizeof(kScanPrefix) - 1;

bool IsNameChar(std::uint8_t c) { return c > 0x20 && c < 0x7F; }

}  // namespace

const char* CommandTypeName(CommandType t) {
  for (const auto& e : kTypes) {
    if (e.type == t) return e.text;
  }
  return "?";
}

HeaderStatus ParseTelegramHeader(std::span<const std::uint8_t> payload, TelegramHeader* out) {
  *out = TelegramHeader{};
  if (payload.size() < 3) return HeaderStatus::kTooShort;
  CommandType type = CommandType::kUnknown;
  for (const auto& e : kTypes) {
    if (std::memcmp(payload.data(), e.text, 3) == 0) {
      type = e.type;
      break;
    }
  }
  if (type == CommandType::kUnknown) return HeaderStatus::kUnknownType;

  if (type == CommandType::kError) {
    // "sFA" + uint16 big-endian SOPAS error code, no space and no name (LMS511: `sFA 00 03`).
    if (payload.size() < 5) return HeaderStatus::kTooShort;
    out->type = type;
    out->error_code = common::LoadBe16(payload.data() + 3);
    out->args = payload.subspan(5);
    return HeaderStatus::kOk;
  }

  if (payload.size() < 5) return HeaderStatus::kTooShort;  // "<type> " and at least one name char
  if (payload[3] != ' ') return HeaderStatus::kBadName;
  std::size_t end = 4;
  while (end < payload.size() && payload[end] != ' ') {
    if (!IsNameChar(payload[end])) return HeaderStatus::kBadName;
    ++end;
  }
  if (end == 4) return HeaderStatus::kBadName;
  out->type = type;
  out->name = std::string_view(reinterpret_cast<const char*>(payload.data()) + 4, end - 4);
  // Devices send both "sWA LMDscandatacfg " (trailing space, no arguments) and "sWA FREchoFilter":
  // either way the arguments are empty.
  if (end < payload.size()) out->args = payload.subspan(end + 1);
  return HeaderStatus::kOk;
}

const char* HeaderStatusName(HeaderStatus s) {
  switch (s) {
    case HeaderStatus::kOk:
      return "ok";
    case HeaderStatus::kTooShort:
      return "telegram too short for its header";
    case HeaderStatus::kUnknownType:
      return "unknown telegram type (not sRN/sWN/sMN/sEN/sRA/sWA/sAN/sEA/sSN/sFA)";
    case HeaderStatus::kBadName:
      return "telegram name missing or not printable ASCII";
  }
  return "?";
}

bool IsScanTelegram(std::span<const std::uint8_t> payload) {
  return payload.size() >= kScanPrefixBytes &&
         std::memcmp(payload.data(), kScanPrefix, kScanPrefixBytes) == 0;
}

const char* SopasErrorName(std::uint16_t code) {
  // SOPAS error codes of sFA replies, in code order (SICK telegram listing; sick_scan_xd names them
  // Sopas_Ok, Sopas_Error_METHODIN_ACCESSDENIED, ...).
  static constexpr std::array<const char*, 27> kNames = {
      "ok (Sopas_Ok)",
      "access denied (Sopas_Error_METHODIN_ACCESSDENIED)",
      "unknown method (Sopas_Error_METHODIN_UNKNOWNINDEX)",
      "unknown variable (Sopas_Error_VARIABLE_UNKNOWNINDEX)",
      "local condition failed (Sopas_Error_LOCALCONDITIONFAILED)",
      "invalid data (Sopas_Error_INVALID_DATA)",
      "unknown error (Sopas_Error_UNKNOWN_ERROR)",
      "buffer overflow (Sopas_Error_BUFFER_OVERFLOW)",
      "buffer underflow (Sopas_Error_BUFFER_UNDERFLOW)",
      "unknown type (Sopas_Error_ERROR_UNKNOWN_TYPE)",
      "variable write access denied (Sopas_Error_VARIABLE_WRITE_ACCESSDENIED)",
      "unknown command for name server (Sopas_Error_UNKNOWN_CMD_FOR_NAMESERVER)",
      "unknown CoLa command (Sopas_Error_UNKNOWN_COLA_COMMAND)",
      "method server busy (Sopas_Error_METHODIN_SERVER_BUSY)",
      "flex array or string out of bounds (Sopas_Error_FLEX_OUT_OF_BOUNDS)",
      "unknown event (Sopas_Error_EVENTREG_UNKNOWNINDEX)",
      "CoLa-A value overflow (Sopas_Error_COLA_A_VALUE_OVERFLOW)",
      "CoLa-A invalid character (Sopas_Error_COLA_A_INVALID_CHARACTER)",
      "no OSAI message (Sopas_Error_OSAI_NO_MESSAGE)",
      "no OSAI answer message (Sopas_Error_OSAI_NO_ANSWER_MESSAGE)",
      "internal error (Sopas_Error_INTERNAL)",
      "hub address corrupted (Sopas_Error_HubAddressCorrupted)",
      "hub address decoding error (Sopas_Error_HubAddressDecoding)",
      "hub address exceeded (Sopas_Error_HubAddressAddressExceeded)",
      "hub address: blank expected (Sopas_Error_HubAddressBlankExpected)",
      "asynchronous methods are suppressed (Sopas_Error_AsyncMethodsAreSuppressed)",
      "complex arrays not supported (Sopas_Error_ComplexArraysNotSupported)",
  };
  if (code < kNames.size()) return kNames[code];
  return "unknown SOPAS error code";
}

}  // namespace lrfnet::cola
