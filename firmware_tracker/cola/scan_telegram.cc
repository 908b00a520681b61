#include "firmware_tracker/cola/scan_telegram.h"

#include <algorithm>
#include <bit>
#include <cstring>
#include <initializer_list>

#include "common/byte_order.h"
#include "common/geometry.h"
#include "firmware_tracker/cola/telegram.h"

// Wire layout after "sSN LMDscandata " (SICK telegram listing for LMS1xx/LMS5xx/TiM; all
// big-endian):
//
//   offset 16  version u16, device number u16, serial number u32, device status u8 u8,
//              telegram counter u16, scan counter u16, time since startup u32 µs,
//              time of transmission u32 µs, digital inputs u16, digital outputs u16,
//              layer angle i16 (MRS: 1/100°, "reserved" on single-layer devices),
//              scan frequency u32 (1/100 Hz), measurement frequency u32         (36 bytes)
//   offset 52  encoder count u16, per encoder: position u32, speed i16
//              16-bit channel count u16, per channel:
//                content 5 chars, scale factor f32, scale offset f32, start angle i32 (1/10000°),
//                angular step u16 (1/10000°), count u16, count × u16             (21 + 2n bytes)
//              8-bit channel count u16, per channel: the same with count × u8    (21 + n bytes)
//              position flag u16; if 1: x, y, z, x rotation, y rotation, z rotation f32 ("Real"),
//                rotation type enum8, "transmits name of device" enum8            (26 bytes)
//              name flag u16; if 1: length u8 + that many chars
//              comment flag u16; if 1: length u8 + that many chars
//              time flag u16; if 1: year u16, month, day, hour, minute, second u8, microseconds u32
//              event flag u16; if 1: type 4 chars ("FDIN"), encoder position u32,
//                time of event u32 µs, angle of event i32 (1/10000°)                (16 bytes)
//
// Nothing follows the event flag. Every real telegram of the shared captures (TiM781S, LMS111,
// LMS511, MRS1104) has encoder count, position, name, comment and event flags 0 and the time
// flag 1. Flags other than 0 and 1 are rejected: they have no defined meaning and could not be
// re-encoded to the same bytes.

namespace lrfnet::cola {
namespace {

constexpr char kPrefix[] = "sSN LMDscandata ";
constexpr std::size_t kPrefixBytes = sizeof(kPrefix) - 1;
constexpr std::size_t kFixedHeaderBytes = 36;
constexpr std::size_t kEncoderBytes = 6;
constexpr std::size_t kChannelHeaderBytes = 21;
constexpr std::size_t kPositionBlockBytes = 26;
constexpr std::size_t kTimeBlockBytes = 11;
constexpr std::size_t kEventBlockBytes = 16;

constexpr auto U16 = common::LoadBe16;
constexpr auto U32 = common::LoadBe32;
std::int16_t I16(const std::uint8_t* p) { return static_cast<std::int16_t>(U16(p)); }
std::int32_t I32(const std::uint8_t* p) { return static_cast<std::int32_t>(U32(p)); }
float F32(const std::uint8_t* p) { return std::bit_cast<float>(U32(p)); }

std::uint8_t* PutU16(std::uint8_t* p, std::uint16_t v) {
  common::StoreBe16(p, v);
  return p + 2;
}
std::uint8_t* PutU32(std::uint8_t* p, std::uint32_t v) {
  common::StoreBe32(p, v);
  return p + 4;
}
std::uint8_t* PutI16(std::uint8_t* p, std::int16_t v) {
  return PutU16(p, static_cast<std::uint16_t>(v));
}
std::uint8_t* PutI32(std::uint8_t* p, std::int32_t v) {
  return PutU32(p, static_cast<std::uint32_t>(v));
}
std::uint8_t* PutF32(std::uint8_t* p, float v) {
  return PutU32(p, std::bit_cast<std::uint32_t>(v));
}
std::uint8_t* PutBytes(std::uint8_t* p, const void* src, std::size_t n) {
  if (n > 0) std::memcpy(p, src, n);
  return p + n;
}

// Bounds-checked cursor over the payload. A failed Need() records why and where decoding stopped.
class Cursor {
 public:
  explicit Cursor(std::span<const std::uint8_t> payload)
      : data_(payload.data()), size_(payload.size()) {}

  bool Need(std::size_t n, const char* reason) {
    if (size_ - pos_ >= n) return true;
    return Fail(reason);
  }
  bool Fail(const char* reason) {
    result_.ok = false;
    result_.reason = reason;
    result_.offset = pos_;
    return false;
  }
  // Reads a 0/1 presence flag (u16).
  bool Flag(const char* truncated_reason, const char* bad_value_reason, bool* present) {
    if (!Need(2, truncated_reason)) return false;
    const std::uint16_t v = U16(data_ + pos_);
    if (v > 1) return Fail(bad_value_reason);
    pos_ += 2;
    *present = v == 1;
    return true;
  }
  const std::uint8_t* Here() const { return data_ + pos_; }  // caller has checked Need(n > 0)
  const std::uint8_t* Take(std::size_t n) {                  // caller has checked Need(n)
    const std::uint8_t* p = data_ + pos_;
    pos_ += n;
    return p;
  }
  std::size_t pos() const { return pos_; }
  std::size_t size() const { return size_; }
  DecodeResult result() const { return result_; }

 private:
  const std::uint8_t* data_;
  std::size_t size_;
  std::size_t pos_ = 0;
  DecodeResult result_;
};

bool DecodeChannels(Cursor& c, bool eight_bit,
                    common::FixedVector<ScanChannel, kMaxChannelsPerWidth>* out) {
  if (!c.Need(2, eight_bit ? "truncated at 8-bit channel count"
                           : "truncated at 16-bit channel count")) {
    return false;
  }
  const std::uint16_t channels = U16(c.Here());
  if (channels > kMaxChannelsPerWidth) {
    return c.Fail(eight_bit ? "too many 8-bit channels for the fixed capacity"
                            : "too many 16-bit channels for the fixed capacity");
  }
  c.Take(2);
  // resize() only default-initialises slots beyond the previous size: with the same channel layout
  // as the previous scan (the steady state) no 5.8 KB channel is cleared; every field read below is
  // overwritten, and raw values beyond `count` are not part of the value.
  if (!out->resize(channels)) return c.Fail("too many channels for the fixed capacity");
  const std::size_t value_bytes = eight_bit ? 1 : 2;
  for (std::size_t k = 0; k < channels; ++k) {
    if (!c.Need(kChannelHeaderBytes, "truncated in channel header")) return false;
    const std::uint16_t count = U16(c.Here() + 19);
    if (count > kMaxPointsPerChannel) {
      return c.Fail("too many points in channel for the fixed capacity");
    }
    const std::uint8_t* h = c.Take(kChannelHeaderBytes);
    ScanChannel* ch = &(*out)[k];
    std::memcpy(ch->name.data(), h, 5);
    ch->name[5] = '\0';
    ch->bits = eight_bit ? 8 : 16;
    ch->scale_factor = F32(h + 5);
    ch->scale_offset = F32(h + 9);
    ch->start_angle_raw = I32(h + 13);
    ch->angle_step_raw = U16(h + 17);
    ch->count = count;
    if (!c.Need(count * value_bytes, "truncated in channel data")) return false;
    const std::uint8_t* d = c.Take(count * value_bytes);
    std::uint16_t* raw = ch->raw.data();
    if (eight_bit) {
      for (std::size_t i = 0; i < count; ++i) raw[i] = d[i];
    } else {
      for (std::size_t i = 0; i < count; ++i) raw[i] = U16(d + 2 * i);
    }
  }
  return true;
}

bool DecodeText(Cursor& c, const char* truncated_reason, const char* too_long_reason,
                ScanText* out) {
  if (!c.Need(1, truncated_reason)) return false;
  const std::uint8_t length = *c.Here();
  if (length > kMaxBlockTextBytes) return c.Fail(too_long_reason);
  c.Take(1);
  if (!c.Need(length, truncated_reason)) return false;
  out->length = length;
  std::memcpy(out->text.data(), c.Take(length), length);
  return true;
}

bool Encodable(const ScanTelegram& scan) {
  for (const auto* block : {&scan.channels16, &scan.channels8}) {
    for (const ScanChannel& ch : *block) {
      if (ch.count > kMaxPointsPerChannel) return false;
    }
  }
  for (const ScanChannel& ch : scan.channels8) {
    for (std::size_t i = 0; i < ch.count; ++i) {
      if (ch.raw[i] > 0xFF) return false;
    }
  }
  if (scan.has_name && scan.name.length > kMaxBlockTextBytes) return false;
  if (scan.has_comment && scan.comment.length > kMaxBlockTextBytes) return false;
  return true;
}

std::uint8_t* EncodeChannels(std::uint8_t* p,
                             const common::FixedVector<ScanChannel, kMaxChannelsPerWidth>& block,
                             bool eight_bit) {
  p = PutU16(p, static_cast<std::uint16_t>(block.size()));
  for (const ScanChannel& ch : block) {
    p = PutBytes(p, ch.name.data(), 5);
    p = PutF32(p, ch.scale_factor);
    p = PutF32(p, ch.scale_offset);
    p = PutI32(p, ch.start_angle_raw);
    p = PutU16(p, ch.angle_step_raw);
    p = PutU16(p, ch.count);
    if (eight_bit) {
      for (std::size_t i = 0; i < ch.count; ++i) *p++ = static_cast<std::uint8_t>(ch.raw[i]);
    } else {
      for (std::size_t i = 0; i < ch.count; ++i) p = PutU16(p, ch.raw[i]);
    }
  }
  return p;
}

// Name or comment block: presence flag, then length u8 + chars.
std::uint8_t* PutText(std::uint8_t* p, bool present, const ScanText& text) {
  p = PutU16(p, present ? 1 : 0);
  if (present) {
    *p++ = text.length;
    p = PutBytes(p, text.text.data(), text.length);
  }
  return p;
}

}  // namespace

const ScanChannel* ScanTelegram::FindChannel(std::string_view name5) const {
  for (const ScanChannel& ch : channels16) {
    if (ch.name_view() == name5) return &ch;
  }
  for (const ScanChannel& ch : channels8) {
    if (ch.name_view() == name5) return &ch;
  }
  return nullptr;
}

DecodeResult DecodeScanTelegram(std::span<const std::uint8_t> payload, ScanTelegram* out) {
  if (!IsScanTelegram(payload)) return {false, "not an sSN LMDscandata telegram", 0};
  Cursor c(payload);
  c.Take(kPrefixBytes);

  if (!c.Need(kFixedHeaderBytes, "truncated in the fixed scan header")) return c.result();
  const std::uint8_t* h = c.Take(kFixedHeaderBytes);
  out->version = U16(h + 0);
  out->device_number = U16(h + 2);
  out->serial_number = U32(h + 4);
  out->device_status = {h[8], h[9]};
  out->telegram_counter = U16(h + 10);
  out->scan_counter = U16(h + 12);
  out->time_since_startup_us = U32(h + 14);
  out->time_of_transmission_us = U32(h + 18);
  out->digital_inputs = U16(h + 22);
  out->digital_outputs = U16(h + 24);
  out->layer_angle_raw = I16(h + 26);
  out->scan_frequency_raw = U32(h + 28);
  out->measurement_frequency_raw = U32(h + 32);

  out->encoders.clear();
  if (!c.Need(2, "truncated at encoder count")) return c.result();
  const std::uint16_t encoders = U16(c.Here());
  if (encoders > kMaxEncoders) {
    c.Fail("too many encoders for the fixed capacity");
    return c.result();
  }
  c.Take(2);
  if (!c.Need(encoders * kEncoderBytes, "truncated in encoder block")) return c.result();
  for (std::size_t k = 0; k < encoders; ++k) {
    const std::uint8_t* e = c.Take(kEncoderBytes);
    ScanEncoder* enc = out->encoders.emplace_slot();
    enc->position = U32(e);
    enc->speed = I16(e + 4);
  }

  if (!DecodeChannels(c, false, &out->channels16)) return c.result();
  if (!DecodeChannels(c, true, &out->channels8)) return c.result();

  if (!c.Flag("truncated at position flag", "position flag is neither 0 nor 1",
              &out->has_position)) {
    return c.result();
  }
  out->position = {};
  if (out->has_position) {
    if (!c.Need(kPositionBlockBytes, "truncated in position block")) return c.result();
    const std::uint8_t* p = c.Take(kPositionBlockBytes);
    out->position.x = F32(p);
    out->position.y = F32(p + 4);
    out->position.z = F32(p + 8);
    out->position.x_rotation = F32(p + 12);
    out->position.y_rotation = F32(p + 16);
    out->position.z_rotation = F32(p + 20);
    out->position.rotation_type = p[24];
    out->position.transmits_name = p[25];
  }

  if (!c.Flag("truncated at name flag", "name flag is neither 0 nor 1", &out->has_name)) {
    return c.result();
  }
  out->name = {};
  if (out->has_name && !DecodeText(c, "truncated in device name block",
                                   "device name longer than the fixed capacity", &out->name)) {
    return c.result();
  }

  if (!c.Flag("truncated at comment flag", "comment flag is neither 0 nor 1", &out->has_comment)) {
    return c.result();
  }
  out->comment = {};
  if (out->has_comment && !DecodeText(c, "truncated in comment block",
                                      "comment longer than the fixed capacity", &out->comment)) {
    return c.result();
  }

  if (!c.Flag("truncated at time flag", "time flag is neither 0 nor 1", &out->has_time)) {
    return c.result();
  }
  out->time = {};
  if (out->has_time) {
    if (!c.Need(kTimeBlockBytes, "truncated in time block")) return c.result();
    const std::uint8_t* t = c.Take(kTimeBlockBytes);
    out->time.year = U16(t);
    out->time.month = t[2];
    out->time.day = t[3];
    out->time.hour = t[4];
    out->time.minute = t[5];
    out->time.second = t[6];
    out->time.microsecond = U32(t + 7);
  }

  if (!c.Flag("truncated at event flag", "event flag is neither 0 nor 1", &out->has_event)) {
    return c.result();
  }
  out->event = {};
  if (out->has_event) {
    if (!c.Need(kEventBlockBytes, "truncated in event block")) return c.result();
    const std::uint8_t* e = c.Take(kEventBlockBytes);
    std::memcpy(out->event.type.data(), e, 4);
    out->event.type[4] = '\0';
    out->event.encoder_position = U32(e + 4);
    out->event.event_time_us = U32(e + 8);
    out->event.angle_raw = I32(e + 12);
  }

  if (c.pos() != c.size()) {
    c.Fail("trailing bytes after the event flag");
    return c.result();
  }
  return {true, "", c.pos()};
}

std::size_t MaxEncodedSize(const ScanTelegram& scan) {
  std::size_t size = kPrefixBytes + kFixedHeaderBytes + 2 + kEncoderBytes * scan.encoders.size();
  size += 2;
  for (const ScanChannel& ch : scan.channels16)
    size += kChannelHeaderBytes + 2 * std::size_t{ch.count};
  size += 2;
  for (const ScanChannel& ch : scan.channels8) size += kChannelHeaderBytes + std::size_t{ch.count};
  size += 2 + (scan.has_position ? kPositionBlockBytes : 0);
  size += 2 + (scan.has_name ? 1 + std::size_t{scan.name.length} : 0);
  size += 2 + (scan.has_comment ? 1 + std::size_t{scan.comment.length} : 0);
  size += 2 + (scan.has_time ? kTimeBlockBytes : 0);
  size += 2 + (scan.has_event ? kEventBlockBytes : 0);
  return size;
}

std::size_t EncodeScanTelegram(const ScanTelegram& scan, std::span<std::uint8_t> out) {
  const std::size_t size = MaxEncodedSize(scan);
  if (out.size() < size || !Encodable(scan)) return 0;
  std::uint8_t* p = out.data();
  p = PutBytes(p, kPrefix, kPrefixBytes);
  p = PutU16(p, scan.version);
  p = PutU16(p, scan.device_number);
  p = PutU32(p, scan.serial_number);
  *p++ = scan.device_status[0];
  *p++ = scan.device_status[1];
  p = PutU16(p, scan.telegram_counter);
  p = PutU16(p, scan.scan_counter);
  p = PutU32(p, scan.time_since_startup_us);
  p = PutU32(p, scan.time_of_transmission_us);
  p = PutU16(p, scan.digital_inputs);
  p = PutU16(p, scan.digital_outputs);
  p = PutI16(p, scan.layer_angle_raw);
  p = PutU32(p, scan.scan_frequency_raw);
  p = PutU32(p, scan.measurement_frequency_raw);
  p = PutU16(p, static_cast<std::uint16_t>(scan.encoders.size()));
  for (const ScanEncoder& e : scan.encoders) {
    p = PutU32(p, e.position);
    p = PutI16(p, e.speed);
  }
  p = EncodeChannels(p, scan.channels16, false);
  p = EncodeChannels(p, scan.channels8, true);
  p = PutU16(p, scan.has_position ? 1 : 0);
  if (scan.has_position) {
    const ScanPositionBlock& b = scan.position;
    for (const float v : {b.x, b.y, b.z, b.x_rotation, b.y_rotation, b.z_rotation}) {
      p = PutF32(p, v);
    }
    *p++ = b.rotation_type;
    *p++ = b.transmits_name;
  }
  p = PutText(p, scan.has_name, scan.name);
  p = PutText(p, scan.has_comment, scan.comment);
  p = PutU16(p, scan.has_time ? 1 : 0);
  if (scan.has_time) {
    const ScanTimeBlock& t = scan.time;
    p = PutU16(p, t.year);
    for (const std::uint8_t v : {t.month, t.day, t.hour, t.minute, t.second}) *p++ = v;
    p = PutU32(p, t.microsecond);
  }
  p = PutU16(p, scan.has_event ? 1 : 0);
  if (scan.has_event) {
    p = PutBytes(p, scan.event.type.data(), 4);
    p = PutU32(p, scan.event.encoder_position);
    p = PutU32(p, scan.event.event_time_us);
    p = PutI32(p, scan.event.angle_raw);
  }
  return static_cast<std::size_t>(p - out.data());
}

bool ToPolarScan(const ScanTelegram& scan, PolarScan* out) {
  const ScanChannel* dist = scan.FindChannel("DIST1");
  if (dist == nullptr || dist->count > kMaxPointsPerChannel) return false;
  out->telegram_counter = scan.telegram_counter;
  out->scan_counter = scan.scan_counter;
  out->time_since_startup_us = scan.time_since_startup_us;
  out->time_of_transmission_us = scan.time_of_transmission_us;
  out->scan_frequency_hz = scan.scan_frequency_hz();
  out->layer_angle_deg = scan.layer_angle_raw / 100.0;
  // SICK counts angles from the sensor's right (−45° is the first beam of a 270° device); the
  // sensor frame puts 0 rad on the telegram's 90° beam.
  out->first_angle_rad = common::DegToRad(dist->start_angle_deg() - 90.0);
  out->angle_step_rad = common::DegToRad(dist->angle_step_deg());
  out->count = dist->count;
  for (std::size_t i = 0; i < dist->count; ++i)
    out->range_m[i] = static_cast<float>(dist->RangeM(i));
  const ScanChannel* rssi = scan.FindChannel("RSSI1");
  out->has_intensity = rssi != nullptr && rssi->count == dist->count;
  if (out->has_intensity) {
    for (std::size_t i = 0; i < rssi->count; ++i)
      out->intensity[i] = static_cast<float>(rssi->Scaled(i));
  }
  return true;
}

}  // namespace lrfnet::cola
