#pragma once
// SOPAS telegram arguments as typed values, in both dialects.
//
// A telegram's arguments are a sequence of scalars whose layout a schema describes. CoLa-B sends
// them as big-endian binary; CoLa-A as text tokens separated by one space: unsigned and signed
// integers in upper-case hexadecimal without leading zeros (signed ones as the two's complement of
// their width: −45° = FFF92230), floats as the 8 hex digits of their IEEE bits, strings as
// "<hex length> <chars>" (`sRA LocationName B not defined`), fixed-width names as their chars
// (`DIST1`, `FEVL`). A CoLa-A number may also be written in decimal with a sign (`+1`, `-450000`),
// as SICK's telegram listings show for requests.
//
// Schema language (whitespace separates items):
//   u8 u16 u32 i8 i16 i32 f32   integers and float32
//   str                          string with a u16 length (flex string)
//   sstr                         string with a u8 length (scan telegram name / comment blocks)
//   cN                           N fixed characters, 1 <= N <= 64 (c4 = "FEVL", c5 = "DIST1")
//   T[ ... ]                     T (u8/u16/u32) counts how often the group follows
//   T?[ ... ]                    T is a flag: the group follows once when it is non-zero
//   N*[ ... ]                    the group exactly N times
// e.g. LMPoutputRange is "u16[u32 i32 i32]", a scan channel "c5 f32 f32 i32 u16 u16[u16]".
// Counts and flags are values themselves (decoding keeps them, encoding writes them as given).
//
// Decoding checks bounds: a count larger than the remaining input can hold is an error, and so is
// anything left over. No exceptions; allocation only for the output values.

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "firmware_tracker/cola/sopas_framer.h"
#include "firmware_tracker/cola/telegram.h"

namespace lrfnet::cola {

enum class SopasType : std::uint8_t {
  kU8,
  kU16,
  kU32,
  kI8,
  kI16,
  kI32,
  kF32,
  kStr,
  kShortStr,
  kFixed
};

struct SopasScalar {
  SopasType type = SopasType::kU8;
  std::uint32_t bits = 0;  // integers: the value in 32 bits (two's complement); f32: IEEE bits
  std::string text;        // kStr, kShortStr, kFixed
  std::uint8_t width = 0;  // kFixed: number of characters

  static SopasScalar U8(std::uint32_t v) { return {SopasType::kU8, v & 0xFFu, {}, 0}; }
  static SopasScalar U16(std::uint32_t v) { return {SopasType::kU16, v & 0xFFFFu, {}, 0}; }
  static SopasScalar U32(std::uint32_t v) { return {SopasType::kU32, v, {}, 0}; }
  static SopasScalar I8(std::int32_t v);
  static SopasScalar I16(std::int32_t v);
  static SopasScalar I32(std::int32_t v) {
    return {SopasType::kI32, static_cast<std::uint32_t>(v), {}, 0};
  }
  static SopasScalar F32(float v);
  static SopasScalar Str(std::string_view s) { return {SopasType::kStr, 0, std::string(s), 0}; }
  static SopasScalar ShortStr(std::string_view s) {
    return {SopasType::kShortStr, 0, std::string(s), 0};
  }
  // Exactly `width` characters: longer text is cut, shorter padded with spaces.
  static SopasScalar Fixed(std::string_view s, std::uint8_t width);

  // Integers sign-extended by type (unsigned as is); f32 and strings give 0.
  std::int64_t AsInt() const;
  float AsFloat() const;

  friend bool operator==(const SopasScalar&, const SopasScalar&) = default;
};
using SopasValues = std::vector<SopasScalar>;

// A compiled schema.
class SopasSchema {
 public:
  // Returns nullopt and sets *error (one line) on a malformed schema.
  static std::optional<SopasSchema> Parse(std::string_view text, std::string* error);
  // For schemas written in code: aborts on a malformed one (a programming error).
  static SopasSchema Compile(std::string_view text);

  struct Node {
    enum class Kind : std::uint8_t { kScalar, kCounted, kOptional, kRepeat };
    Kind kind = Kind::kScalar;
    SopasType type = SopasType::kU8;  // the scalar, or the count / flag
    std::uint8_t width = 0;           // kFixed
    std::uint32_t repeat = 0;         // kRepeat
    std::vector<Node> children;
  };
  const std::vector<Node>& nodes() const { return nodes_; }
  bool empty() const { return nodes_.empty(); }

 private:
  std::vector<Node> nodes_;
};

// Why decoding failed, each with the SOPAS error code a device answers it with (SopasErrorName).
enum class ValueStatus : std::uint8_t {
  kOk,
  kTruncated,     // input ended inside the layout (Sopas_Error_BUFFER_UNDERFLOW, 8)
  kTrailing,      // input left after the layout (Sopas_Error_BUFFER_OVERFLOW, 7)
  kBadCharacter,  // CoLa-A: not a number / wrong separator (Sopas_Error_COLA_A_INVALID_CHARACTER,
                  // 17)
  kOverflow,      // CoLa-A: number too large for its type (Sopas_Error_COLA_A_VALUE_OVERFLOW, 16)
  kTooMany,       // a count beyond what the input can hold (Sopas_Error_FLEX_OUT_OF_BOUNDS, 14)
};
const char* ValueStatusName(ValueStatus s);
std::uint16_t SopasErrorCodeOf(ValueStatus s);

struct ValueResult {
  ValueStatus status = ValueStatus::kOk;
  std::size_t offset = 0;  // input offset where decoding stopped
  bool ok() const { return status == ValueStatus::kOk; }
};

// Decodes all of `args` (CoLa-B bytes, or CoLa-A text) by `schema` into *out (replaced).
ValueResult DecodeValues(const SopasSchema& schema, Dialect dialect,
                         std::span<const std::uint8_t> args, SopasValues* out);
// Appends the encoding of `values`. False (and `out` unspecified) when a value cannot be sent:
// a string longer than its length field allows, or in CoLa-A a character that is not printable.
bool AppendValues(const SopasValues& values, Dialect dialect, std::vector<std::uint8_t>* out);

// ---- telegrams in either dialect

// The header of a telegram: for CoLa-B exactly ParseTelegramHeader; CoLa-A has the same text
// header, except that its error reply is "sFA <hex code>".
HeaderStatus ParseSopasTelegram(Dialect dialect, std::span<const std::uint8_t> payload,
                                TelegramHeader* out);

// "<type> <name>[ <values>]". `space_when_empty`: a CoLa-B reply without values that ends in a
// space (LMS devices answer "sWA LMDscandatacfg ", the MRS1104 "sWA FREchoFilter"); CoLa-A never
// ends in a space. Empty vector when a value cannot be encoded or the name is not printable.
std::vector<std::uint8_t> EncodeSopasTelegram(Dialect dialect, CommandType type,
                                              std::string_view name, const SopasValues& values,
                                              bool space_when_empty = false);
// "sFA" + u16 code (CoLa-B) or "sFA <hex code>" (CoLa-A).
std::vector<std::uint8_t> EncodeSopasError(Dialect dialect, std::uint16_t code);

// ---- the arguments of `sSN LMDscandata` (scan_telegram.h) as values
struct ScanTelegram;
// Decodes either dialect; its CoLa-B encoding is byte for byte EncodeScanTelegram's.
const SopasSchema& ScanTelegramSchema();
// Replaces *out with the scan's values (for the CoLa-A telegram; allocates).
void ScanTelegramToValues(const ScanTelegram& scan, SopasValues* out);

}  // namespace lrfnet::cola
