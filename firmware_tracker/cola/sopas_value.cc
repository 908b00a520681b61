#include "firmware_tracker/cola/sopas_value.h"

#include <bit>
#include <cctype>
#include <cstdlib>
#include <cstring>

#include "common/byte_order.h"
#include "firmware_tracker/cola/scan_telegram.h"

namespace lrfnet::cola {
namespace {

constexpr int kMaxSchemaDepth = 8;
constexpr std::uint8_t kMaxFixedWidth = 64;

std::uint32_t WidthMask(SopasType t) {
  switch (t) {
    case SopasType::kU8:
    case SopasType::kI8:
      return 0xFFu;
    case SopasType::kU16:
    case SopasType::kI16:
      return 0xFFFFu;
    default:
      return 0xFFFFFFFFu;
  }
}

std::size_t BinaryWidth(SopasType t) {
  switch (t) {
    case SopasType::kU8:
    case SopasType::kI8:
      return 1;
    case SopasType::kU16:
    case SopasType::kI16:
      return 2;
    default:
      return 4;
  }
}

bool IsSigned(SopasType t) {
  return t == SopasType::kI8 || t == SopasType::kI16 || t == SopasType::kI32;
}
bool IsUnsigned(SopasType t) {
  return t == SopasType::kU8 || t == SopasType::kU16 || t == SopasType::kU32;
}

// ---- schema parsing

struct SchemaLexer {
  std::string_view text;
  std::size_t pos = 0;

  // Next token: a run of [a-z0-9], or one of "[]?*"; empty at the end.
  std::string_view Next() {
    while (pos < text.size() && std::isspace(static_cast<unsigned char>(text[pos]))) ++pos;
    if (pos >= text.size()) return {};
    const std::size_t start = pos;
    const char c = text[pos];
    if (c == '[' || c == ']' || c == '?' || c == '*') {
      ++pos;
      return text.substr(start, 1);
    }
    while (pos < text.size() && (std::islower(static_cast<unsigned char>(text[pos])) ||
                                 std::isdigit(static_cast<unsigned char>(text[pos])))) {
      ++pos;
    }
    if (pos == start) ++pos;  // an unexpected character: a token of its own, rejected later
    return text.substr(start, pos - start);
  }
  std::string_view Peek() {
    const std::size_t saved = pos;
    const std::string_view t = Next();
    pos = saved;
    return t;
  }
};

bool ParseScalarName(std::string_view t, SopasType* type, std::uint8_t* width) {
  static constexpr struct {
    const char* name;
    SopasType type;
  } kNames[] = {{"u8", SopasType::kU8},   {"u16", SopasType::kU16}, {"u32", SopasType::kU32},
                {"i8", SopasType::kI8},   {"i16", SopasType::kI16}, {"i32", SopasType::kI32},
                {"f32", SopasType::kF32}, {"str", SopasType::kStr}, {"sstr", SopasType::kShortStr}};
  for (const auto& n : kNames) {
    if (t == n.name) {
      *type = n.type;
      *width = 0;
      return true;
    }
  }
  if (t.size() >= 2 && t[0] == 'c') {
    unsigned n = 0;
    for (const char c : t.substr(1)) {
      if (!std::isdigit(static_cast<unsigned char>(c)) || n > kMaxFixedWidth) return false;
      n = n * 10 + static_cast<unsigned>(c - '0');
    }
    if (n < 1 || n > kMaxFixedWidth) return false;
    *type = SopasType::kFixed;
    *width = static_cast<std::uint8_t>(n);
    return true;
  }
  return false;
}

bool ParseGroup(SchemaLexer* lex, int depth, bool nested, std::vector<SopasSchema::Node>* out,
                std::string* error) {
  using Node = SopasSchema::Node;
  if (depth > kMaxSchemaDepth) {
    *error = "groups nested too deeply";
    return false;
  }
  while (true) {
    const std::string_view t = lex->Next();
    if (t.empty()) {
      if (nested) {
        *error = "missing ']'";
        return false;
      }
      return true;
    }
    if (t == "]") {
      if (!nested) {
        *error = "unexpected ']'";
        return false;
      }
      if (out->empty()) {
        *error = "empty group";
        return false;
      }
      return true;
    }
    Node node;
    if (std::isdigit(static_cast<unsigned char>(t[0]))) {
      std::uint32_t n = 0;
      for (const char c : t) {
        if (!std::isdigit(static_cast<unsigned char>(c)) || n > 100000) {
          *error = "bad repeat count '" + std::string(t) + "'";
          return false;
        }
        n = n * 10 + static_cast<std::uint32_t>(c - '0');
      }
      if (lex->Next() != "*" || lex->Next() != "[" || n == 0) {
        *error = "a number must start a group 'N*[...]' with N > 0";
        return false;
      }
      node.kind = Node::Kind::kRepeat;
      node.repeat = n;
      if (!ParseGroup(lex, depth + 1, true, &node.children, error)) return false;
      out->push_back(std::move(node));
      continue;
    }
    if (!ParseScalarName(t, &node.type, &node.width)) {
      *error = "unknown type '" + std::string(t) + "'";
      return false;
    }
    const std::string_view next = lex->Peek();
    if (next == "[" || next == "?") {
      if (!IsUnsigned(node.type)) {
        *error = "a count or flag must be u8, u16 or u32";
        return false;
      }
      lex->Next();
      node.kind = Node::Kind::kCounted;
      if (next == "?") {
        if (lex->Next() != "[") {
          *error = "'?' must be followed by '['";
          return false;
        }
        node.kind = Node::Kind::kOptional;
      }
      if (!ParseGroup(lex, depth + 1, true, &node.children, error)) return false;
    }
    out->push_back(std::move(node));
  }
}

// ---- decoding

class Decoder {
 public:
  Decoder(Dialect dialect, std::span<const std::uint8_t> input, SopasValues* out)
      : dialect_(dialect), input_(input), out_(out) {}

  ValueStatus Group(const std::vector<SopasSchema::Node>& nodes) {
    using Kind = SopasSchema::Node::Kind;
    for (const auto& node : nodes) {
      if (node.kind == Kind::kRepeat) {
        for (std::uint32_t k = 0; k < node.repeat; ++k) {
          if (const ValueStatus s = Group(node.children); s != ValueStatus::kOk) return s;
        }
        continue;
      }
      SopasScalar scalar;
      if (const ValueStatus s = Scalar(node.type, node.width, &scalar); s != ValueStatus::kOk) {
        return s;
      }
      const std::uint32_t value = scalar.bits;
      out_->push_back(std::move(scalar));
      if (node.kind == Kind::kOptional && value != 0) {
        if (const ValueStatus s = Group(node.children); s != ValueStatus::kOk) return s;
      } else if (node.kind == Kind::kCounted) {
        // Every element takes at least one byte (binary) or one character (text).
        if (value > input_.size() - pos_) return ValueStatus::kTooMany;
        for (std::uint32_t k = 0; k < value; ++k) {
          if (const ValueStatus s = Group(node.children); s != ValueStatus::kOk) return s;
        }
      }
    }
    return ValueStatus::kOk;
  }

  ValueStatus Finish() {
    if (dialect_ == Dialect::kColaA) {
      // Trailing spaces are tolerated; anything else is left over.
      while (pos_ < input_.size() && input_[pos_] == ' ') ++pos_;
    }
    return pos_ == input_.size() ? ValueStatus::kOk : ValueStatus::kTrailing;
  }

  std::size_t pos() const { return pos_; }

 private:
  ValueStatus Scalar(SopasType type, std::uint8_t width, SopasScalar* out) {
    out->type = type;
    out->width = width;
    return dialect_ == Dialect::kColaB ? BinaryScalar(type, width, out)
                                       : AsciiScalar(type, width, out);
  }

  ValueStatus BinaryScalar(SopasType type, std::uint8_t width, SopasScalar* out) {
    const std::uint8_t* p = input_.data() + pos_;
    const std::size_t left = input_.size() - pos_;
    switch (type) {
      case SopasType::kStr:
      case SopasType::kShortStr: {
        const std::size_t prefix = type == SopasType::kStr ? 2 : 1;
        if (left < prefix) return ValueStatus::kTruncated;
        const std::size_t n = prefix == 2 ? common::LoadBe16(p) : p[0];
        if (left - prefix < n) return ValueStatus::kTruncated;
        out->text.assign(reinterpret_cast<const char*>(p + prefix), n);
        pos_ += prefix + n;
        return ValueStatus::kOk;
      }
      case SopasType::kFixed:
        if (left < width) return ValueStatus::kTruncated;
        out->text.assign(reinterpret_cast<const char*>(p), width);
        pos_ += width;
        return ValueStatus::kOk;
      default: {
        const std::size_t n = BinaryWidth(type);
        if (left < n) return ValueStatus::kTruncated;
        out->bits = n == 1 ? p[0] : n == 2 ? common::LoadBe16(p) : common::LoadBe32(p);
        pos_ += n;
        return ValueStatus::kOk;
      }
    }
  }

  // One token: skips the separator before it (one or more spaces; none before the first).
  ValueStatus AsciiToken(std::string_view* token) {
    if (started_) {
      if (pos_ >= input_.size()) return ValueStatus::kTruncated;
      if (input_[pos_] != ' ') return ValueStatus::kBadCharacter;
    }
    while (pos_ < input_.size() && input_[pos_] == ' ') ++pos_;
    started_ = true;
    const std::size_t start = pos_;
    while (pos_ < input_.size() && input_[pos_] != ' ') ++pos_;
    if (pos_ == start) return ValueStatus::kTruncated;
    *token = std::string_view(reinterpret_cast<const char*>(input_.data()) + start, pos_ - start);
    return ValueStatus::kOk;
  }

  static ValueStatus ParseHex(std::string_view t, std::uint32_t* value) {
    std::uint64_t v = 0;
    for (const char c : t) {
      int d;
      if (c >= '0' && c <= '9') {
        d = c - '0';
      } else if (c >= 'A' && c <= 'F') {
        d = c - 'A' + 10;
      } else if (c >= 'a' && c <= 'f') {
        d = c - 'a' + 10;
      } else {
        return ValueStatus::kBadCharacter;
      }
      v = (v << 4) | static_cast<std::uint64_t>(d);
      if (v > 0xFFFFFFFFull) return ValueStatus::kOverflow;
    }
    *value = static_cast<std::uint32_t>(v);
    return ValueStatus::kOk;
  }

  static ValueStatus ParseInteger(std::string_view t, SopasType type, std::uint32_t* bits) {
    const std::uint32_t mask = WidthMask(type);
    if (t[0] == '+' || t[0] == '-') {
      if (t.size() < 2 || t.size() > 12) {
        return t.size() < 2 ? ValueStatus::kBadCharacter : ValueStatus::kOverflow;
      }
      std::int64_t v = 0;
      for (const char c : t.substr(1)) {
        if (c < '0' || c > '9') return ValueStatus::kBadCharacter;
        v = v * 10 + (c - '0');
      }
      if (t[0] == '-') v = -v;
      std::int64_t lo = 0;
      std::int64_t hi = mask;
      if (IsSigned(type)) {
        hi = mask >> 1;
        lo = -hi - 1;
      }
      if (v < lo || v > hi) return ValueStatus::kOverflow;
      *bits = static_cast<std::uint32_t>(v) & mask;
      return ValueStatus::kOk;
    }
    std::uint32_t v = 0;
    if (const ValueStatus s = ParseHex(t, &v); s != ValueStatus::kOk) return s;
    if (v > mask) return ValueStatus::kOverflow;
    *bits = v;
    return ValueStatus::kOk;
  }

  ValueStatus AsciiScalar(SopasType type, std::uint8_t width, SopasScalar* out) {
    std::string_view t;
    switch (type) {
      case SopasType::kStr:
      case SopasType::kShortStr: {
        if (const ValueStatus s = AsciiToken(&t); s != ValueStatus::kOk) return s;
        std::uint32_t n = 0;
        if (const ValueStatus s =
                ParseInteger(t, type == SopasType::kStr ? SopasType::kU16 : SopasType::kU8, &n);
            s != ValueStatus::kOk) {
          return s;
        }
        if (n == 0) {
          out->text.clear();
          return ValueStatus::kOk;
        }
        // One space, then exactly n characters (which may themselves hold spaces).
        if (pos_ >= input_.size()) return ValueStatus::kTruncated;
        if (input_[pos_] != ' ') return ValueStatus::kBadCharacter;
        ++pos_;
        if (input_.size() - pos_ < n) return ValueStatus::kTruncated;
        out->text.assign(reinterpret_cast<const char*>(input_.data()) + pos_, n);
        pos_ += n;
        return ValueStatus::kOk;
      }
      case SopasType::kFixed:
        if (const ValueStatus s = AsciiToken(&t); s != ValueStatus::kOk) return s;
        if (t.size() != width) return ValueStatus::kBadCharacter;
        out->text.assign(t);
        return ValueStatus::kOk;
      case SopasType::kF32: {
        if (const ValueStatus s = AsciiToken(&t); s != ValueStatus::kOk) return s;
        if (t[0] == '+' || t[0] == '-') {
          // A decimal float as a courtesy to hand-typed requests.
          if (t.size() > 32) return ValueStatus::kOverflow;
          const std::string copy(t);
          char* end = nullptr;
          const float f = std::strtof(copy.c_str(), &end);
          if (end != copy.c_str() + copy.size()) return ValueStatus::kBadCharacter;
          out->bits = std::bit_cast<std::uint32_t>(f);
          return ValueStatus::kOk;
        }
        return ParseHex(t, &out->bits);
      }
      default:
        if (const ValueStatus s = AsciiToken(&t); s != ValueStatus::kOk) return s;
        return ParseInteger(t, type, &out->bits);
    }
  }

  Dialect dialect_;
  std::span<const std::uint8_t> input_;
  SopasValues* out_;
  std::size_t pos_ = 0;
  bool started_ = false;
};

// ---- encoding

void AppendHex(std::uint32_t v, bool pad8, std::vector<std::uint8_t>* out) {
  static constexpr char kDigits[] = "0123456789ABCDEF";
  char buf[8];
  int n = 0;
  do {
    buf[n++] = kDigits[v & 0xF];
    v >>= 4;
  } while (v != 0 || (pad8 && n < 8));
  while (n > 0) out->push_back(static_cast<std::uint8_t>(buf[--n]));
}

bool Printable(std::string_view s) {
  for (const char c : s) {
    if (static_cast<unsigned char>(c) < 0x20 || static_cast<unsigned char>(c) > 0x7E) return false;
  }
  return true;
}

bool IsValidName(std::string_view name) {
  if (name.empty()) return false;
  for (const char c : name) {
    if (c <= 0x20 || c >= 0x7F) return false;
  }
  return true;
}

void AppendText(std::string_view s, std::vector<std::uint8_t>* out) {
  out->insert(out->end(), s.begin(), s.end());
}

}  // namespace

// ---- SopasScalar

SopasScalar SopasScalar::I8(std::int32_t v) {
  return {SopasType::kI8, static_cast<std::uint32_t>(v) & 0xFFu, {}, 0};
}
SopasScalar SopasScalar::I16(std::int32_t v) {
  return {SopasType::kI16, static_cast<std::uint32_t>(v) & 0xFFFFu, {}, 0};
}
SopasScalar SopasScalar::F32(float v) {
  return {SopasType::kF32, std::bit_cast<std::uint32_t>(v), {}, 0};
}
SopasScalar SopasScalar::Fixed(std::string_view s, std::uint8_t width) {
  std::string text(s.substr(0, width));
  text.resize(width, ' ');
  return {SopasType::kFixed, 0, std::move(text), width};
}

std::int64_t SopasScalar::AsInt() const {
  switch (type) {
    case SopasType::kU8:
    case SopasType::kU16:
    case SopasType::kU32:
      return bits;
    case SopasType::kI8:
      return static_cast<std::int8_t>(bits & 0xFFu);
    case SopasType::kI16:
      return static_cast<std::int16_t>(bits & 0xFFFFu);
    case SopasType::kI32:
      return static_cast<std::int32_t>(bits);
    default:
      return 0;
  }
}

float SopasScalar::AsFloat() const {
  return type == SopasType::kF32 ? std::bit_cast<float>(bits) : 0.0f;
}

// ---- SopasSchema

std::optional<SopasSchema> SopasSchema::Parse(std::string_view text, std::string* error) {
  SopasSchema schema;
  SchemaLexer lex{text};
  if (!ParseGroup(&lex, 0, false, &schema.nodes_, error)) return std::nullopt;
  return schema;
}

SopasSchema SopasSchema::Compile(std::string_view text) {
  std::string error;
  auto schema = Parse(text, &error);
  if (!schema) std::abort();  // schemas in code are checked by the tests
  return std::move(*schema);
}

// ---- values

const char* ValueStatusName(ValueStatus s) {
  switch (s) {
    case ValueStatus::kOk:
      return "ok";
    case ValueStatus::kTruncated:
      return "arguments end early";
    case ValueStatus::kTrailing:
      return "bytes left after the arguments";
    case ValueStatus::kBadCharacter:
      return "invalid character in a CoLa-A argument";
    case ValueStatus::kOverflow:
      return "CoLa-A number too large for its type";
    case ValueStatus::kTooMany:
      return "array count beyond the telegram";
  }
  return "?";
}

std::uint16_t SopasErrorCodeOf(ValueStatus s) {
  switch (s) {
    case ValueStatus::kOk:
      return 0;
    case ValueStatus::kTruncated:
      return 8;  // Sopas_Error_BUFFER_UNDERFLOW
    case ValueStatus::kTrailing:
      return 7;  // Sopas_Error_BUFFER_OVERFLOW
    case ValueStatus::kBadCharacter:
      return 17;  // Sopas_Error_COLA_A_INVALID_CHARACTER
    case ValueStatus::kOverflow:
      return 16;  // Sopas_Error_COLA_A_VALUE_OVERFLOW
    case ValueStatus::kTooMany:
      return 14;  // Sopas_Error_FLEX_OUT_OF_BOUNDS
  }
  return 6;  // Sopas_Error_UNKNOWN_ERROR
}

ValueResult DecodeValues(const SopasSchema& schema, Dialect dialect,
                         std::span<const std::uint8_t> args, SopasValues* out) {
  out->clear();
  Decoder decoder(dialect, args, out);
  ValueResult result;
  result.status = decoder.Group(schema.nodes());
  if (result.status == ValueStatus::kOk) result.status = decoder.Finish();
  result.offset = decoder.pos();
  return result;
}

bool AppendValues(const SopasValues& values, Dialect dialect, std::vector<std::uint8_t>* out) {
  bool first = true;
  for (const SopasScalar& v : values) {
    if (dialect == Dialect::kColaB) {
      std::uint8_t b[4];
      switch (v.type) {
        case SopasType::kStr:
          if (v.text.size() > 0xFFFF) return false;
          common::StoreBe16(b, static_cast<std::uint16_t>(v.text.size()));
          out->insert(out->end(), b, b + 2);
          AppendText(v.text, out);
          break;
        case SopasType::kShortStr:
          if (v.text.size() > 0xFF) return false;
          out->push_back(static_cast<std::uint8_t>(v.text.size()));
          AppendText(v.text, out);
          break;
        case SopasType::kFixed:
          if (v.text.size() != v.width) return false;
          AppendText(v.text, out);
          break;
        default: {
          const std::size_t n = BinaryWidth(v.type);
          if (n == 1) {
            b[0] = static_cast<std::uint8_t>(v.bits);
          } else if (n == 2) {
            common::StoreBe16(b, static_cast<std::uint16_t>(v.bits));
          } else {
            common::StoreBe32(b, v.bits);
          }
          out->insert(out->end(), b, b + n);
          break;
        }
      }
      continue;
    }
    if (!first) out->push_back(' ');
    first = false;
    switch (v.type) {
      case SopasType::kStr:
      case SopasType::kShortStr:
        if (v.text.size() > (v.type == SopasType::kStr ? 0xFFFFu : 0xFFu) || !Printable(v.text)) {
          return false;
        }
        AppendHex(static_cast<std::uint32_t>(v.text.size()), false, out);
        if (!v.text.empty()) {
          out->push_back(' ');
          AppendText(v.text, out);
        }
        break;
      case SopasType::kFixed:
        if (v.text.size() != v.width || !Printable(v.text) ||
            v.text.find(' ') != std::string::npos) {
          return false;
        }
        AppendText(v.text, out);
        break;
      case SopasType::kF32:
        AppendHex(v.bits, true, out);
        break;
      default:
        AppendHex(v.bits & WidthMask(v.type), false, out);
        break;
    }
  }
  return true;
}

HeaderStatus ParseSopasTelegram(Dialect dialect, std::span<const std::uint8_t> payload,
                                TelegramHeader* out) {
  if (dialect == Dialect::kColaB || payload.size() < 3 ||
      std::memcmp(payload.data(), "sFA", 3) != 0) {
    return ParseTelegramHeader(payload, out);
  }
  // CoLa-A error: "sFA <hex code>".
  *out = TelegramHeader{};
  if (payload.size() < 5 || payload[3] != ' ') return HeaderStatus::kTooShort;
  std::size_t end = 4;
  std::uint32_t code = 0;
  while (end < payload.size() && payload[end] != ' ') {
    const char c = static_cast<char>(payload[end]);
    const int d = std::isdigit(static_cast<unsigned char>(c)) ? c - '0'
                  : (c >= 'A' && c <= 'F')                    ? c - 'A' + 10
                  : (c >= 'a' && c <= 'f')                    ? c - 'a' + 10
                                                              : -1;
    if (d < 0 || end - 4 >= 4) return HeaderStatus::kBadName;
    code = code * 16 + static_cast<std::uint32_t>(d);
    ++end;
  }
  out->type = CommandType::kError;
  out->error_code = static_cast<std::uint16_t>(code);
  if (end < payload.size()) out->args = payload.subspan(end + 1);
  return HeaderStatus::kOk;
}

std::vector<std::uint8_t> EncodeSopasTelegram(Dialect dialect, CommandType type,
                                              std::string_view name, const SopasValues& values,
                                              bool space_when_empty) {
  std::vector<std::uint8_t> out;
  if (type == CommandType::kUnknown || type == CommandType::kError || !IsValidName(name)) {
    return out;
  }
  AppendText(CommandTypeName(type), &out);
  out.push_back(' ');
  AppendText(name, &out);
  if (!values.empty()) {
    out.push_back(' ');
    if (!AppendValues(values, dialect, &out)) out.clear();
  } else if (space_when_empty && dialect == Dialect::kColaB) {
    out.push_back(' ');
  }
  return out;
}

std::vector<std::uint8_t> EncodeSopasError(Dialect dialect, std::uint16_t code) {
  std::vector<std::uint8_t> out = {'s', 'F', 'A'};
  if (dialect == Dialect::kColaB) {
    out.push_back(static_cast<std::uint8_t>(code >> 8));
    out.push_back(static_cast<std::uint8_t>(code));
  } else {
    out.push_back(' ');
    AppendHex(code, false, &out);
  }
  return out;
}

// ---- LMDscandata

const SopasSchema& ScanTelegramSchema() {
  // The layout of scan_telegram.h. Digital inputs and outputs are two u8 each: the same two bytes
  // in CoLa-B, and the two tokens SICK's CoLa-A telegram (and its driver's parser) put there.
  static const SopasSchema kSchema = SopasSchema::Compile(
      "u16 u16 u32 u8 u8 u16 u16 u32 u32 u8 u8 u8 u8 i16 u32 u32 u16[u32 i16]"
      " u16[c5 f32 f32 i32 u16 u16[u16]] u16[c5 f32 f32 i32 u16 u16[u8]]"
      " u16?[f32 f32 f32 f32 f32 f32 u8 u8] u16?[sstr] u16?[sstr]"
      " u16?[u16 u8 u8 u8 u8 u8 u32] u16?[c4 u32 u32 i32]");
  return kSchema;
}

void ScanTelegramToValues(const ScanTelegram& scan, SopasValues* out) {
  using S = SopasScalar;
  out->clear();
  std::size_t points = 0;
  for (const auto& ch : scan.channels16) points += ch.count;
  for (const auto& ch : scan.channels8) points += ch.count;
  out->reserve(64 + points);
  out->push_back(S::U16(scan.version));
  out->push_back(S::U16(scan.device_number));
  out->push_back(S::U32(scan.serial_number));
  out->push_back(S::U8(scan.device_status[0]));
  out->push_back(S::U8(scan.device_status[1]));
  out->push_back(S::U16(scan.telegram_counter));
  out->push_back(S::U16(scan.scan_counter));
  out->push_back(S::U32(scan.time_since_startup_us));
  out->push_back(S::U32(scan.time_of_transmission_us));
  out->push_back(S::U8(scan.digital_inputs >> 8));
  out->push_back(S::U8(scan.digital_inputs & 0xFF));
  out->push_back(S::U8(scan.digital_outputs >> 8));
  out->push_back(S::U8(scan.digital_outputs & 0xFF));
  out->push_back(S::I16(scan.layer_angle_raw));
  out->push_back(S::U32(scan.scan_frequency_raw));
  out->push_back(S::U32(scan.measurement_frequency_raw));
  out->push_back(S::U16(static_cast<std::uint32_t>(scan.encoders.size())));
  for (const auto& e : scan.encoders) {
    out->push_back(S::U32(e.position));
    out->push_back(S::I16(e.speed));
  }
  for (const auto* block : {&scan.channels16, &scan.channels8}) {
    out->push_back(S::U16(static_cast<std::uint32_t>(block->size())));
    for (const auto& ch : *block) {
      out->push_back(S::Fixed(ch.name_view(), 5));
      out->push_back(S::F32(ch.scale_factor));
      out->push_back(S::F32(ch.scale_offset));
      out->push_back(S::I32(ch.start_angle_raw));
      out->push_back(S::U16(ch.angle_step_raw));
      out->push_back(S::U16(ch.count));
      for (std::size_t i = 0; i < ch.count; ++i) {
        out->push_back(block == &scan.channels16 ? S::U16(ch.raw[i]) : S::U8(ch.raw[i]));
      }
    }
  }
  out->push_back(S::U16(scan.has_position ? 1 : 0));
  if (scan.has_position) {
    const ScanPositionBlock& p = scan.position;
    for (const float f : {p.x, p.y, p.z, p.x_rotation, p.y_rotation, p.z_rotation}) {
      out->push_back(S::F32(f));
    }
    out->push_back(S::U8(p.rotation_type));
    out->push_back(S::U8(p.transmits_name));
  }
  out->push_back(S::U16(scan.has_name ? 1 : 0));
  if (scan.has_name) out->push_back(S::ShortStr(scan.name.view()));
  out->push_back(S::U16(scan.has_comment ? 1 : 0));
  if (scan.has_comment) out->push_back(S::ShortStr(scan.comment.view()));
  out->push_back(S::U16(scan.has_time ? 1 : 0));
  if (scan.has_time) {
    const ScanTimeBlock& t = scan.time;
    out->push_back(S::U16(t.year));
    for (const std::uint8_t b : {t.month, t.day, t.hour, t.minute, t.second}) {
      out->push_back(S::U8(b));
    }
    out->push_back(S::U32(t.microsecond));
  }
  out->push_back(S::U16(scan.has_event ? 1 : 0));
  if (scan.has_event) {
    out->push_back(S::Fixed(std::string_view(scan.event.type.data(), 4), 4));
    out->push_back(S::U32(scan.event.encoder_position));
    out->push_back(S::U32(scan.event.event_time_us));
    out->push_back(S::I32(scan.event.angle_raw));
  }
}

}  // namespace lrfnet::cola
