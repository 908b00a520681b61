#pragma once
// `sSN LMDscandata` — the scan telegram of SICK LMS1xx / LMS5xx / TiM5xx / TiM7xx / MRS1xxx devices,
// every field of the CoLa-B binary layout (all multi-byte values big-endian):
//
//   version u16, device number u16, serial u32, device status 2×u8, telegram counter u16,
//   scan counter u16, time since startup u32 µs, time of transmission u32 µs, digital inputs u16,
//   digital outputs u16, layer angle i16 (1/100°, MRS; reserved elsewhere), scan frequency u32 (1/100 Hz),
//   measurement frequency u32 (100 Hz units), encoder count u16 (+ per encoder position u32, speed i16),
//   16-bit channel count u16 + channels, 8-bit channel count u16 + channels, each channel:
//     name 5 chars (DIST1..5, RSSI1..5, ANGL1...), scale factor float32, scale offset float32,
//     start angle i32 (1/10000°), angular step u16 (1/10000°), count u16, count × data (u16 or u8);
//   position flag u16 (+ block), name flag u16 (+ block), comment flag u16 (+ block),
//   time flag u16 (+ year u16, month, day, hour, minute, second u8, microseconds u32),
//   event flag u16 (+ block).
//
// Angles in the telegram use SICK's raw convention (start −45° for a 270° device). The polar scan uses
// the sensor frame of DESIGN.md: x forward = the telegram's 90° beam, counter-clockwise.
//
// Storage is fixed-capacity: decoding into an existing ScanTelegram never allocates.

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string_view>

#include "common/fixed_capacity.h"

namespace lrfnet::cola {

// Largest devices: LMS5xx 1141 points per channel at 0.1667°; 2880 leaves room for 0.125° over 360°.
inline constexpr std::size_t kMaxPointsPerChannel = 2880;
inline constexpr std::size_t kMaxChannelsPerWidth = 10;  // DIST1..5 + RSSI1..5 (+ others)
inline constexpr std::size_t kMaxEncoders = 4;
inline constexpr std::size_t kMaxBlockTextBytes = 64;  // device name / comment blocks

struct ScanChannel {
  std::array<char, 6> name{};  // 5 chars + NUL, e.g. "DIST1"
  std::uint8_t bits = 16;      // 16 or 8 (which channel block it came from)
  float scale_factor = 1.0f;
  float scale_offset = 0.0f;
  std::int32_t start_angle_raw = 0;  // 1/10000 °, SICK convention
  std::uint16_t angle_step_raw = 0;  // 1/10000 °
  std::uint16_t count = 0;
  std::array<std::uint16_t, kMaxPointsPerChannel> raw{};  // 8-bit data widened

  std::string_view name_view() const { return {name.data(), 5}; }
  double start_angle_deg() const { return start_angle_raw / 10000.0; }
  double angle_step_deg() const { return angle_step_raw / 10000.0; }
  bool is_distance() const { return name_view().substr(0, 4) == "DIST"; }
  // raw × scale + offset, in the channel's unit (mm for DIST channels per SICK; see RangeM).
  double Scaled(std::size_t i) const { return raw[i] * static_cast<double>(scale_factor) + scale_offset; }
  // Distance channels: raw × scale / 1000 + offset, metres (0 = no echo).
  double RangeM(std::size_t i) const {
    return raw[i] * static_cast<double>(scale_factor) / 1000.0 + scale_offset;
  }
};

struct ScanEncoder {
  std::uint32_t position = 0;  // ticks
  std::int16_t speed = 0;      // ticks/mm
};

struct ScanPositionBlock {  // present when position flag == 1
  float x = 0, y = 0, z = 0;
  float x_rotation = 0, y_rotation = 0, z_rotation = 0;
  std::uint8_t rotation_type = 0;
  std::uint8_t transmits_name = 0;  // enum8 as sent
};

struct ScanTimeBlock {  // present when time flag == 1 (device clock, often unset: 1970)
  std::uint16_t year = 0;
  std::uint8_t month = 0, day = 0, hour = 0, minute = 0, second = 0;
  std::uint32_t microsecond = 0;
};

struct ScanEventBlock {  // present when event flag == 1
  std::array<char, 5> type{};  // 4 chars + NUL, e.g. "FDIN"
  std::uint32_t encoder_position = 0;
  std::uint32_t event_time_us = 0;
  std::int32_t angle_raw = 0;  // 1/10000 °
};

struct ScanText {  // device name or comment block: u8 length + chars (as sent)
  std::uint8_t length = 0;
  std::array<char, kMaxBlockTextBytes> text{};
  std::string_view view() const { return {text.data(), length}; }
};

struct ScanTelegram {
  std::uint16_t version = 0;
  std::uint16_t device_number = 0;
  std::uint32_t serial_number = 0;
  std::array<std::uint8_t, 2> device_status{};
  std::uint16_t telegram_counter = 0;
  std::uint16_t scan_counter = 0;
  std::uint32_t time_since_startup_us = 0;
  std::uint32_t time_of_transmission_us = 0;
  std::uint16_t digital_inputs = 0;
  std::uint16_t digital_outputs = 0;
  std::int16_t layer_angle_raw = 0;          // 1/100 °, MRS layer; 0 on single-layer devices
  std::uint32_t scan_frequency_raw = 0;      // 1/100 Hz
  std::uint32_t measurement_frequency_raw = 0;  // 100 Hz units
  common::FixedVector<ScanEncoder, kMaxEncoders> encoders;
  common::FixedVector<ScanChannel, kMaxChannelsPerWidth> channels16;
  common::FixedVector<ScanChannel, kMaxChannelsPerWidth> channels8;
  bool has_position = false;
  ScanPositionBlock position;
  bool has_name = false;
  ScanText name;
  bool has_comment = false;
  ScanText comment;
  bool has_time = false;
  ScanTimeBlock time;
  bool has_event = false;
  ScanEventBlock event;

  double scan_frequency_hz() const { return scan_frequency_raw / 100.0; }
  // First channel with that name in the 16-bit block, then the 8-bit block; nullptr if absent.
  const ScanChannel* FindChannel(std::string_view name5) const;
};

struct DecodeResult {
  bool ok = false;
  const char* reason = "";  // static string, e.g. "truncated in channel data"
  std::size_t offset = 0;   // byte offset in the payload where decoding stopped
};

// Decodes a complete frame payload that starts with "sSN LMDscandata ". Never reads out of bounds; content
// that does not fit the fixed capacities (too many points or channels) is an error, not a truncation.
// Trailing bytes after the event flag are an error ("trailing bytes"), and so are block flags other than
// 0 and 1. On error `*out` is partly overwritten and must not be used. Absent optional blocks are zeroed.
// The exact layout of the optional blocks is written down in scan_telegram.cc.
DecodeResult DecodeScanTelegram(std::span<const std::uint8_t> payload, ScanTelegram* out);

// Writes the payload ("sSN LMDscandata " + binary) of `scan`. Returns its size, 0 if `out` is too small
// or `scan` cannot be sent (a channel count above kMaxPointsPerChannel, an 8-bit channel value above 255,
// a name or comment longer than kMaxBlockTextBytes). The block a channel sits in (channels16 or channels8)
// decides its width on the wire; ScanChannel::bits is not consulted.
// DecodeScanTelegram(EncodeScanTelegram(x)) == x, and re-encoding a decoded real telegram gives its bytes.
std::size_t EncodeScanTelegram(const ScanTelegram& scan, std::span<std::uint8_t> out);
// Upper bound of the encoded size of `scan` (for sizing buffers); the exact size when it can be encoded.
std::size_t MaxEncodedSize(const ScanTelegram& scan);

// A scan in the sensor frame (DESIGN.md): beam i at angle first_angle_rad + i × angle_step_rad, where 0 rad
// is the telegram's 90° beam (x forward) and angles grow counter-clockwise.
struct PolarScan {
  std::uint16_t telegram_counter = 0;
  std::uint16_t scan_counter = 0;
  std::uint32_t time_since_startup_us = 0;    // device tick at scan start
  std::uint32_t time_of_transmission_us = 0;  // device tick at transmission
  double scan_frequency_hz = 0;
  double layer_angle_deg = 0;
  double first_angle_rad = 0;
  double angle_step_rad = 0;
  std::uint16_t count = 0;
  std::array<float, kMaxPointsPerChannel> range_m{};    // DIST1; 0 = no echo
  bool has_intensity = false;
  std::array<float, kMaxPointsPerChannel> intensity{};  // RSSI1 scaled, if present
};

// Fills `out` from DIST1 (and RSSI1 when present). Returns false if the telegram has no DIST1 channel or the
// RSSI1 count differs (then intensity is dropped and has_intensity is false, still returning true).
bool ToPolarScan(const ScanTelegram& scan, PolarScan* out);

}  // namespace lrfnet::cola
