#pragma once
// CoLa-B telegram header: "<type> <name>[ <binary arguments>]", e.g. "sSN LMDscandata <binary>",
// "sRN FirmwareVersion" (no arguments, no trailing space) and "sFA<uint16 error code>" (no name).
// Parsing never allocates: names and arguments are views into the payload.

#include <cstdint>
#include <span>
#include <string_view>

namespace lrfnet::cola {

enum class CommandType : std::uint8_t {
  kUnknown,
  // client -> device
  kRead,         // sRN
  kWrite,        // sWN
  kMethod,       // sMN
  kEvent,        // sEN
  // device -> client
  kReadAnswer,   // sRA
  kWriteAnswer,  // sWA
  kMethodAnswer, // sAN
  kEventAnswer,  // sEA
  kEventData,    // sSN (event telegram, e.g. LMDscandata)
  kError,        // sFA
};

const char* CommandTypeName(CommandType t);  // "sRN", ... or "?"

struct TelegramHeader {
  CommandType type = CommandType::kUnknown;
  std::string_view name;                  // empty for sFA
  std::span<const std::uint8_t> args;     // bytes after "<type> <name> "; empty if none
  std::uint16_t error_code = 0;           // sFA only
};

enum class HeaderStatus { kOk, kTooShort, kUnknownType, kBadName };

// Splits a frame payload into type, name and arguments. A name is printable ASCII up to the first space
// or the end of the payload.
HeaderStatus ParseTelegramHeader(std::span<const std::uint8_t> payload, TelegramHeader* out);
const char* HeaderStatusName(HeaderStatus s);

// True when the payload is an `sSN LMDscandata ` telegram (exact name; LMDscandatamon is another one).
bool IsScanTelegram(std::span<const std::uint8_t> payload);

// Human-readable meaning of an sFA error code (SICK telegram listing) with SICK's identifier, e.g.
// 3 -> "unknown variable (Sopas_Error_VARIABLE_UNKNOWNINDEX)"; codes above 26 -> "unknown SOPAS error code".
const char* SopasErrorName(std::uint16_t code);

}  // namespace lrfnet::cola
