#pragma once
// CoLa-B commands a client sends and the replies a device returns, as frame payloads (use
// EncodeFrame to wrap them). Everything writes into caller-provided fixed buffers: no allocation.

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string_view>

#include "firmware_tracker/cola/telegram.h"

namespace lrfnet::cola {

// SOPAS user levels for SetAccessMode, with the devices' published default password hashes.
enum class AccessLevel : std::uint8_t {
  kOperator = 1,
  kMaintenance = 2,
  kAuthorizedClient = 3,
  kService = 4
};
inline constexpr std::uint32_t kAuthorizedClientPasswordHash = 0xF4724744;  // "client"
inline constexpr std::uint32_t kServicePasswordHash = 0x81BE23AA;           // "servicelevel"

// ---- client -> device (payload bytes written to `out`; return value is the size, 0 if out is too
// small or a name is empty or not printable ASCII without spaces)
std::size_t EncodeSetAccessMode(AccessLevel level, std::uint32_t password_hash,
                                std::span<std::uint8_t> out);
std::size_t EncodeReadVariable(std::string_view name, std::span<std::uint8_t> out);  // sRN <name>
std::size_t EncodeStartMeasurement(std::span<std::uint8_t> out);            // sMN LMCstartmeas
std::size_t EncodeStopMeasurement(std::span<std::uint8_t> out);             // sMN LMCstopmeas
std::size_t EncodeRun(std::span<std::uint8_t> out);                         // sMN Run
std::size_t EncodeScanDataEvent(bool enable, std::span<std::uint8_t> out);  // sEN LMDscandata 1|0

// sWN LMDscandatacfg: which channels and blocks the device puts into LMDscandata (LMS1xx/5xx
// layout). Wire layout (13 argument bytes): output_channel u8, 00, remission u8, resolution u8,
// unit u8 (always 0), encoder u8, 00, position u8, device_name u8, comment u8, time u8,
// output_interval u16 big-endian. The LMS111 capture's config is {output_channel 1, remission
// false, resolution 0, time true, interval 1}, the LMS511's the same with remission true (8-bit
// RSSI1).
struct ScanDataConfig {
  std::uint8_t output_channel = 1;  // bit mask of echo channels (1 = first echo)
  bool remission = true;            // RSSI channel on
  std::uint8_t resolution = 1;      // 0 = 8-bit RSSI, 1 = 16-bit RSSI
  bool encoder = false;
  bool position = false;
  bool device_name = false;
  bool comment = false;
  bool time = true;                   // time block
  std::uint16_t output_interval = 1;  // every n-th scan

  friend bool operator==(const ScanDataConfig&, const ScanDataConfig&) = default;
};
std::size_t EncodeScanDataConfig(const ScanDataConfig& config, std::span<std::uint8_t> out);
// The arguments of `sRA LMDscandatacfg` (the same 13 bytes). False unless exactly 13 bytes.
bool DecodeScanDataConfig(std::span<const std::uint8_t> args, ScanDataConfig* out);

// The first sector of `sRA LMPoutputRange`: sector count u16, then per sector angular step u32,
// start and stop angle i32 (1/10000 °, SICK convention). The LMS111 of the shared capture:
// 1 sector, 0.5°, −45° .. 224.9997°.
struct OutputRange {
  std::uint16_t sectors = 0;
  std::uint32_t step_raw = 0;
  std::int32_t start_raw = 0;
  std::int32_t stop_raw = 0;
};
bool DecodeOutputRange(std::span<const std::uint8_t> args, OutputRange* out);

// ---- device -> client (used by the emulator and by tests)
// "<type> <name>[ <args>]"; a type of kError must use EncodeErrorReply instead.
std::size_t EncodeReply(CommandType type, std::string_view name, std::span<const std::uint8_t> args,
                        std::span<std::uint8_t> out);
std::size_t EncodeErrorReply(std::uint16_t sopas_error_code, std::span<std::uint8_t> out);  // sFA
// Whether a reply without arguments ends in a space: LMS devices answer "sWA LMDscandatacfg "
// (space), the MRS1104 answers "sWA FREchoFilter" (none). The four-argument EncodeReply omits it.
enum class EmptyArgsSpace : std::uint8_t { kOmit, kWrite };
std::size_t EncodeReply(CommandType type, std::string_view name, std::span<const std::uint8_t> args,
                        EmptyArgsSpace empty_args_space, std::span<std::uint8_t> out);

// ---- decoding of reply arguments (views into the payload; all bounds-checked)
// A length-prefixed string (uint16 big-endian length + chars), e.g. FirmwareVersion, SerialNumber.
struct FlexString {
  std::string_view text;
  std::size_t consumed = 0;  // bytes used from the input
};
bool DecodeFlexString(std::span<const std::uint8_t> args, FlexString* out);

// DeviceIdent: two flex strings, device name and version.
struct DeviceIdent {
  std::string_view name;
  std::string_view version;
};
bool DecodeDeviceIdent(std::span<const std::uint8_t> args, DeviceIdent* out);

// The first argument byte of a method/event answer (SetAccessMode: 1 = success; LMCstartmeas: 0 =
// success; Run: 1 = success; sEA LMDscandata: 1 = enabled). Returns false when there is no argument
// byte.
bool DecodeFirstByte(std::span<const std::uint8_t> args, std::uint8_t* out);

}  // namespace lrfnet::cola
