#include "firmware_tracker/cola/cola_test_util.h"

#include <cstring>
#include <optional>

#include "common/byte_order.h"
#include "firmware_tracker/cola/framer.h"

namespace lrfnet::cola::test {
namespace {

constexpr auto Be16 = common::LoadBe16;
constexpr auto Be32 = common::LoadBe32;
constexpr auto Le32 = common::LoadLe32;

// Ethernet frame -> TCP payload from the sensor port, with its sequence number.
struct Segment {
  std::uint32_t seq = 0;
  std::span<const std::uint8_t> payload;
};
std::optional<Segment> SensorSegment(std::span<const std::uint8_t> frame,
                                     std::uint16_t sensor_port) {
  if (frame.size() < 14 + 20 || Be16(frame.data() + 12) != 0x0800) return std::nullopt;
  const std::uint8_t* ip = frame.data() + 14;
  const std::size_t ihl = (ip[0] & 0x0F) * 4u;
  const std::size_t total = Be16(ip + 2);
  if ((ip[0] >> 4) != 4 || ip[9] != 6 || total > frame.size() - 14 || ihl + 20 > total)
    return std::nullopt;
  const std::uint8_t* tcp = ip + ihl;
  if (Be16(tcp) != sensor_port) return std::nullopt;
  const std::size_t tcp_header = (tcp[12] >> 4) * 4u;
  if (ihl + tcp_header > total) return std::nullopt;
  return Segment{Be32(tcp + 4), {tcp + tcp_header, total - ihl - tcp_header}};
}

class StreamBuilder {
 public:
  void Add(const Segment& s) {
    if (s.payload.empty()) return;
    if (have_next_) {
      // Signed modular difference: the LMS511 capture wraps its 32-bit sequence number.
      const auto behind = static_cast<std::int32_t>(next_seq_ - s.seq);
      if (behind > 0) return;
    }
    out_.insert(out_.end(), s.payload.begin(), s.payload.end());
    next_seq_ = s.seq + static_cast<std::uint32_t>(s.payload.size());
    have_next_ = true;
  }
  std::vector<std::uint8_t> Take() { return std::move(out_); }

 private:
  std::vector<std::uint8_t> out_;
  std::uint32_t next_seq_ = 0;
  bool have_next_ = false;
};

ScanChannel MakeChannel(const char* name, std::uint16_t count, std::int32_t start_raw,
                        std::uint16_t step_raw, std::uint16_t seed, std::uint16_t max_value) {
  ScanChannel ch;
  std::memcpy(ch.name.data(), name, 5);
  ch.scale_factor = 1.0f;
  ch.start_angle_raw = start_raw;
  ch.angle_step_raw = step_raw;
  ch.count = count;
  for (std::size_t i = 0; i < count; ++i) {
    ch.raw[i] = static_cast<std::uint16_t>((seed + i * 37u + (i * i) % 101u) % (max_value + 1u));
  }
  return ch;
}

bool SameChannel(const ScanChannel& a, const ScanChannel& b) {
  if (a.name != b.name || a.bits != b.bits || a.count != b.count ||
      a.start_angle_raw != b.start_angle_raw || a.angle_step_raw != b.angle_step_raw ||
      std::memcmp(&a.scale_factor, &b.scale_factor, sizeof(float)) != 0 ||
      std::memcmp(&a.scale_offset, &b.scale_offset, sizeof(float)) != 0) {
    return false;
  }
  return std::equal(a.raw.begin(), a.raw.begin() + a.count, b.raw.begin());
}

}  // namespace

std::vector<std::uint8_t> SensorStreamFromCapture(std::span<const std::uint8_t> file,
                                                  std::uint16_t sensor_port) {
  StreamBuilder stream;
  if (file.size() >= 24 && Le32(file.data()) == 0xA1B2C3D4u) {  // classic pcap, little-endian
    std::size_t pos = 24;
    while (pos + 16 <= file.size()) {
      const std::size_t caplen = Le32(file.data() + pos + 8);
      pos += 16;
      if (caplen > file.size() - pos) break;
      if (auto s = SensorSegment(file.subspan(pos, caplen), sensor_port)) stream.Add(*s);
      pos += caplen;
    }
  } else if (file.size() >= 12 && Le32(file.data()) == 0x0A0D0D0Au) {  // pcapng, little-endian
    std::size_t pos = 0;
    while (pos + 12 <= file.size()) {
      const std::uint32_t type = Le32(file.data() + pos);
      const std::size_t length = Le32(file.data() + pos + 4);
      if (length < 12 || length > file.size() - pos) break;
      if (type == 6 && length >= 32) {  // enhanced packet block
        const std::size_t caplen = Le32(file.data() + pos + 20);
        if (caplen <= length - 32) {
          if (auto s = SensorSegment(file.subspan(pos + 28, caplen), sensor_port)) stream.Add(*s);
        }
      }
      pos += length;
    }
  }
  return stream.Take();
}

std::vector<std::vector<std::uint8_t>> ExtractFrames(std::span<const std::uint8_t> stream,
                                                     std::string_view prefix) {
  std::vector<std::vector<std::uint8_t>> frames;
  std::size_t i = 0;
  while (i + 9 <= stream.size()) {
    const std::uint8_t* p = stream.data() + i;
    if (p[0] == 2 && p[1] == 2 && p[2] == 2 && p[3] == 2) {
      const std::size_t length = Be32(p + 4);
      if (length > 0 && length <= 1 << 20 && length + 9 <= stream.size() - i) {
        const auto payload = stream.subspan(i + 8, length);
        if (Checksum(payload) == p[8 + length]) {
          if (payload.size() >= prefix.size() &&
              std::memcmp(payload.data(), prefix.data(), prefix.size()) == 0) {
            frames.emplace_back(payload.begin(), payload.end());
          }
          i += length + 9;
          continue;
        }
      }
    }
    ++i;
  }
  return frames;
}

std::unique_ptr<ScanTelegram> MakeSimpleScan(std::uint16_t points, std::uint16_t telegram_counter) {
  auto s = std::make_unique<ScanTelegram>();
  s->version = 1;
  s->device_number = 1;
  s->serial_number = 18480390;
  s->telegram_counter = telegram_counter;
  s->scan_counter = static_cast<std::uint16_t>(telegram_counter + 7);
  s->time_since_startup_us = 1000000u + telegram_counter * 66667u;
  s->time_of_transmission_us = s->time_since_startup_us + 3000;
  s->scan_frequency_raw = 1500;
  s->measurement_frequency_raw = 1217;
  (void)s->channels16.push_back(
      MakeChannel("DIST1", points, -450000, 3333, telegram_counter, 20000));
  (void)s->channels16.push_back(MakeChannel("RSSI1", points, -450000, 3333, 11, 65535));
  s->has_time = true;
  s->time = {1970, 1, 1, 0, 2, 3, 456789};
  return s;
}

std::unique_ptr<ScanTelegram> MakeFullScan(std::uint16_t points) {
  auto s = MakeSimpleScan(points, 4242);
  s->channels16.clear();
  s->device_status = {1, 0};
  s->digital_inputs = 0x0102;
  s->digital_outputs = 0x0304;
  s->layer_angle_raw = -250;
  (void)s->encoders.push_back({123456789u, -42});
  (void)s->encoders.push_back({0xFFFFFFF0u, 17});
  const char* kDist[] = {"DIST1", "DIST2", "DIST3", "DIST4", "DIST5"};
  const char* kRssi[] = {"RSSI1", "RSSI2", "RSSI3", "RSSI4", "RSSI5"};
  for (std::uint16_t e = 0; e < 5; ++e) {
    ScanChannel d =
        MakeChannel(kDist[e], points, -50000, 1667, static_cast<std::uint16_t>(e * 1000), 65535);
    d.scale_factor = 2.0f;
    d.scale_offset = 0.25f;
    (void)s->channels16.push_back(d);
    ScanChannel r =
        MakeChannel(kRssi[e], points, -50000, 1667, static_cast<std::uint16_t>(e * 3), 255);
    r.bits = 8;
    (void)s->channels8.push_back(r);
  }
  s->has_position = true;
  s->position = {1.5f, -2.25f, 0.75f, 0.0f, 0.1f, -3.0f, 2, 1};
  s->has_name = true;
  s->name.length = 9;
  std::memcpy(s->name.text.data(), "gateway-7", 9);
  s->has_comment = true;
  s->comment.length = 21;
  std::memcpy(s->comment.text.data(), "mounted at the door\x01\xff", 21);
  s->has_event = true;
  s->event = {{'F', 'D', 'I', 'N', '\0'}, 987654u, 55555u, -123456};
  return s;
}

bool SameScan(const ScanTelegram& a, const ScanTelegram& b) {
  if (a.version != b.version || a.device_number != b.device_number ||
      a.serial_number != b.serial_number || a.device_status != b.device_status ||
      a.telegram_counter != b.telegram_counter || a.scan_counter != b.scan_counter ||
      a.time_since_startup_us != b.time_since_startup_us ||
      a.time_of_transmission_us != b.time_of_transmission_us ||
      a.digital_inputs != b.digital_inputs || a.digital_outputs != b.digital_outputs ||
      a.layer_angle_raw != b.layer_angle_raw || a.scan_frequency_raw != b.scan_frequency_raw ||
      a.measurement_frequency_raw != b.measurement_frequency_raw) {
    return false;
  }
  if (a.encoders.size() != b.encoders.size() || a.channels16.size() != b.channels16.size() ||
      a.channels8.size() != b.channels8.size()) {
    return false;
  }
  for (std::size_t i = 0; i < a.encoders.size(); ++i) {
    if (a.encoders[i].position != b.encoders[i].position ||
        a.encoders[i].speed != b.encoders[i].speed) {
      return false;
    }
  }
  for (std::size_t i = 0; i < a.channels16.size(); ++i) {
    if (!SameChannel(a.channels16[i], b.channels16[i])) return false;
  }
  for (std::size_t i = 0; i < a.channels8.size(); ++i) {
    if (!SameChannel(a.channels8[i], b.channels8[i])) return false;
  }
  if (a.has_position != b.has_position || a.has_name != b.has_name ||
      a.has_comment != b.has_comment || a.has_time != b.has_time || a.has_event != b.has_event) {
    return false;
  }
  if (a.has_position) {
    const auto& p = a.position;
    const auto& q = b.position;
    if (p.x != q.x || p.y != q.y || p.z != q.z || p.x_rotation != q.x_rotation ||
        p.y_rotation != q.y_rotation || p.z_rotation != q.z_rotation ||
        p.rotation_type != q.rotation_type || p.transmits_name != q.transmits_name) {
      return false;
    }
  }
  if (a.has_name && a.name.view() != b.name.view()) return false;
  if (a.has_comment && a.comment.view() != b.comment.view()) return false;
  if (a.has_time) {
    const auto& t = a.time;
    const auto& u = b.time;
    if (t.year != u.year || t.month != u.month || t.day != u.day || t.hour != u.hour ||
        t.minute != u.minute || t.second != u.second || t.microsecond != u.microsecond) {
      return false;
    }
  }
  if (a.has_event) {
    const auto& e = a.event;
    const auto& f = b.event;
    if (std::memcmp(e.type.data(), f.type.data(), 4) != 0 ||
        e.encoder_position != f.encoder_position || e.event_time_us != f.event_time_us ||
        e.angle_raw != f.angle_raw) {
      return false;
    }
  }
  return true;
}

std::vector<std::uint8_t> EncodeScanFrame(const ScanTelegram& scan) {
  std::vector<std::uint8_t> payload(MaxEncodedSize(scan));
  payload.resize(EncodeScanTelegram(scan, payload));
  std::vector<std::uint8_t> frame(payload.size() + kFrameHeaderBytes + kFrameTrailerBytes);
  frame.resize(EncodeFrame(payload, frame));
  return frame;
}

Bytes B(std::string_view s) { return Bytes(s.begin(), s.end()); }

Bytes Frame(const Bytes& payload) {
  Bytes out(payload.size() + kFrameHeaderBytes + kFrameTrailerBytes);
  out.resize(EncodeFrame(payload, out));
  return out;
}

Bytes Frame(std::string_view payload) { return Frame(B(payload)); }

void Append(Bytes& a, const Bytes& b) { a.insert(a.end(), b.begin(), b.end()); }

}  // namespace lrfnet::cola::test
