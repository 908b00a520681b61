#include "firmware_tracker/cola/commands.h"

#include <cstring>

#include "common/byte_order.h"

namespace lrfnet::cola {
namespace {

// Appends to a caller buffer; once anything does not fit, every later write is dropped and Size()
// is 0.
class Writer {
 public:
  explicit Writer(std::span<std::uint8_t> out) : out_(out) {}
  void Text(std::string_view s) {
    Bytes(reinterpret_cast<const std::uint8_t*>(s.data()), s.size());
  }
  void Bytes(std::span<const std::uint8_t> b) { Bytes(b.data(), b.size()); }
  void U8(std::uint8_t v) { Bytes(&v, 1); }
  void U16(std::uint16_t v) {
    std::uint8_t b[2];
    common::StoreBe16(b, v);
    Bytes(b, 2);
  }
  void U32(std::uint32_t v) {
    std::uint8_t b[4];
    common::StoreBe32(b, v);
    Bytes(b, 4);
  }
  std::size_t Size() const { return ok_ ? pos_ : 0; }

 private:
  void Bytes(const std::uint8_t* p, std::size_t n) {
    if (!ok_ || out_.size() - pos_ < n) {
      ok_ = false;
      return;
    }
    if (n > 0) std::memcpy(out_.data() + pos_, p, n);
    pos_ += n;
  }

  std::span<std::uint8_t> out_;
  std::size_t pos_ = 0;
  bool ok_ = true;
};

bool IsValidName(std::string_view name) {
  if (name.empty()) return false;
  for (const char c : name) {
    if (c <= 0x20 || c >= 0x7F) return false;
  }
  return true;
}

std::size_t EncodeCommand(std::string_view text, std::span<std::uint8_t> out) {
  Writer w(out);
  w.Text(text);
  return w.Size();
}

}  // namespace

std::size_t EncodeSetAccessMode(AccessLevel level, std::uint32_t password_hash,
                                std::span<std::uint8_t> out) {
  // sMN SetAccessMode: user level uint8, password hash uint32 big-endian (real LMS111 login:
  // `sMN SetAccessMode 03 F4 72 47 44`).
  Writer w(out);
  w.Text("sMN SetAccessMode ");
  w.U8(static_cast<std::uint8_t>(level));
  w.U32(password_hash);
  return w.Size();
}

std::size_t EncodeReadVariable(std::string_view name, std::span<std::uint8_t> out) {
  if (!IsValidName(name)) return 0;
  Writer w(out);
  w.Text("sRN ");
  w.Text(name);
  return w.Size();
}

std::size_t EncodeStartMeasurement(std::span<std::uint8_t> out) {
  return EncodeCommand("sMN LMCstartmeas", out);
}

std::size_t EncodeStopMeasurement(std::span<std::uint8_t> out) {
  return EncodeCommand("sMN LMCstopmeas", out);
}

std::size_t EncodeRun(std::span<std::uint8_t> out) { return EncodeCommand("sMN Run", out); }

std::size_t EncodeScanDataEvent(bool enable, std::span<std::uint8_t> out) {
  Writer w(out);
  w.Text("sEN LMDscandata ");
  w.U8(enable ? 1 : 0);
  return w.Size();
}

std::size_t EncodeScanDataConfig(const ScanDataConfig& config, std::span<std::uint8_t> out) {
  // sWN LMDscandatacfg, 13 argument bytes (LMS1xx/LMS5xx telegram listing; the CoLa-A form is
  // "sWN LMDscandatacfg 01 00 1 1 0 00 00 0 0 0 1 +1"):
  //   output channel u8 (echo bit mask) | 00 | remission u8 | resolution u8 (0 = 8-bit, 1 = 16-bit
  //   RSSI) | unit u8 (0 = digits) | encoder u8 (0 = none, 1 = channel 1) | 00 | position u8 |
  //   device name u8 | comment u8 | time u8 | output interval u16 (every n-th scan)
  // Real captures: LMS111 (DIST1 only) `01 00 00 00 00 00 00 00 00 00 01 00 01`, LMS511 (8-bit
  // RSSI1) `01 00 01 00 00 00 00 00 00 00 01 00 01`, MRS1104 (three echoes) `07 00 00 00 ... 01 00
  // 01`.
  Writer w(out);
  w.Text("sWN LMDscandatacfg ");
  w.U8(config.output_channel);
  w.U8(0);
  w.U8(config.remission ? 1 : 0);
  w.U8(config.resolution);
  w.U8(0);
  w.U8(config.encoder ? 1 : 0);
  w.U8(0);
  w.U8(config.position ? 1 : 0);
  w.U8(config.device_name ? 1 : 0);
  w.U8(config.comment ? 1 : 0);
  w.U8(config.time ? 1 : 0);
  w.U16(config.output_interval);
  return w.Size();
}

bool DecodeScanDataConfig(std::span<const std::uint8_t> args, ScanDataConfig* out) {
  // Byte order as in EncodeScanDataConfig; bytes 1, 4 and 6 are not kept.
  if (args.size() != 13) return false;
  ScanDataConfig c;
  c.output_channel = args[0];
  c.remission = args[2] != 0;
  c.resolution = args[3];
  c.encoder = args[5] != 0;
  c.position = args[7] != 0;
  c.device_name = args[8] != 0;
  c.comment = args[9] != 0;
  c.time = args[10] != 0;
  c.output_interval = common::LoadBe16(args.data() + 11);
  *out = c;
  return true;
}

bool DecodeOutputRange(std::span<const std::uint8_t> args, OutputRange* out) {
  if (args.size() < 2) return false;
  const std::uint16_t sectors = common::LoadBe16(args.data());
  if (sectors == 0 || args.size() != 2 + std::size_t{sectors} * 12) return false;
  out->sectors = sectors;
  out->step_raw = common::LoadBe32(args.data() + 2);
  out->start_raw = static_cast<std::int32_t>(common::LoadBe32(args.data() + 6));
  out->stop_raw = static_cast<std::int32_t>(common::LoadBe32(args.data() + 10));
  return true;
}

std::size_t EncodeReply(CommandType type, std::string_view name, std::span<const std::uint8_t> args,
                        std::span<std::uint8_t> out) {
  return EncodeReply(type, name, args, EmptyArgsSpace::kOmit, out);
}

std::size_t EncodeReply(CommandType type, std::string_view name, std::span<const std::uint8_t> args,
                        EmptyArgsSpace empty_args_space, std::span<std::uint8_t> out) {
  if (type == CommandType::kUnknown || type == CommandType::kError || !IsValidName(name)) return 0;
  Writer w(out);
  w.Text(CommandTypeName(type));
  w.Text(" ");
  w.Text(name);
  if (!args.empty() || empty_args_space == EmptyArgsSpace::kWrite) w.Text(" ");
  w.Bytes(args);
  return w.Size();
}

std::size_t EncodeErrorReply(std::uint16_t sopas_error_code, std::span<std::uint8_t> out) {
  Writer w(out);
  w.Text("sFA");
  w.U16(sopas_error_code);
  return w.Size();
}

bool DecodeFlexString(std::span<const std::uint8_t> args, FlexString* out) {
  if (args.size() < 2) return false;
  const std::size_t length = common::LoadBe16(args.data());
  if (args.size() - 2 < length) return false;
  out->text = std::string_view(reinterpret_cast<const char*>(args.data()) + 2, length);
  out->consumed = 2 + length;
  return true;
}

bool DecodeDeviceIdent(std::span<const std::uint8_t> args, DeviceIdent* out) {
  FlexString name;
  FlexString version;
  if (!DecodeFlexString(args, &name)) return false;
  if (!DecodeFlexString(args.subspan(name.consumed), &version)) return false;
  out->name = name.text;
  out->version = version.text;
  return true;
}

bool DecodeFirstByte(std::span<const std::uint8_t> args, std::uint8_t* out) {
  if (args.empty()) return false;
  *out = args[0];
  return true;
}

}  // namespace lrfnet::cola
