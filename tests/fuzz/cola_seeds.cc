#include "tests/fuzz/cola_seeds.h"

#include <algorithm>
#include <array>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <span>
#include <string>
#include <string_view>

#include "firmware_tracker/cola/commands.h"
#include "firmware_tracker/cola/framer.h"
#include "firmware_tracker/cola/scan_telegram.h"

namespace lrfnet::fuzz {
namespace {

using Bytes = std::vector<std::uint8_t>;
using cola::ScanChannel;
using cola::ScanTelegram;

void WriteFile(const std::filesystem::path& path, std::span<const std::uint8_t> bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(bytes.data()),
            static_cast<std::streamsize>(bytes.size()));
}

Bytes Payload(const ScanTelegram& scan) {
  Bytes out(cola::MaxEncodedSize(scan));
  out.resize(cola::EncodeScanTelegram(scan, out));
  return out;
}

Bytes Frame(std::span<const std::uint8_t> payload) {
  Bytes out(payload.size() + cola::kFrameHeaderBytes + cola::kFrameTrailerBytes);
  out.resize(cola::EncodeFrame(payload, out));
  return out;
}
Bytes Frame(std::string_view payload) {
  return Frame(std::span(reinterpret_cast<const std::uint8_t*>(payload.data()), payload.size()));
}

void Append(Bytes& a, const Bytes& b) { a.insert(a.end(), b.begin(), b.end()); }

ScanChannel Channel(const char* name, std::uint16_t count, std::int32_t start_raw,
                    std::uint16_t step_raw, std::uint16_t max_value) {
  ScanChannel ch;
  std::memcpy(ch.name.data(), name, 5);
  ch.start_angle_raw = start_raw;
  ch.angle_step_raw = step_raw;
  ch.count = count;
  for (std::size_t i = 0; i < count; ++i) {
    ch.raw[i] = static_cast<std::uint16_t>((i * 131u + 7u) % (max_value + 1u));
  }
  return ch;
}

std::unique_ptr<ScanTelegram> BaseScan(std::uint16_t counter) {
  auto s = std::make_unique<ScanTelegram>();
  s->version = 1;
  s->device_number = 1;
  s->serial_number = 18090362;
  s->telegram_counter = counter;
  s->scan_counter = counter;
  s->time_since_startup_us = 1948810585u + counter;
  s->time_of_transmission_us = 1948813715u + counter;
  s->scan_frequency_raw = 5000;
  s->measurement_frequency_raw = 2700;
  s->has_time = true;
  s->time = {1970, 1, 1, 2, 55, 34, 889000};
  return s;
}

// TiM781S shape: DIST1 + RSSI1, both 16-bit.
std::unique_ptr<ScanTelegram> Tim(std::uint16_t points) {
  auto s = BaseScan(44977);
  (void)s->channels16.push_back(Channel("DIST1", points, -450000, 3333, 20000));
  (void)s->channels16.push_back(Channel("RSSI1", points, -450000, 3333, 65535));
  return s;
}

// LMS511 shape: DIST1 16-bit, RSSI1 8-bit, version 0.
std::unique_ptr<ScanTelegram> Lms511(std::uint16_t points) {
  auto s = BaseScan(10203);
  s->version = 0;
  (void)s->channels16.push_back(Channel("DIST1", points, -50000, 1667, 20000));
  ScanChannel rssi = Channel("RSSI1", points, -50000, 1667, 254);
  rssi.bits = 8;
  (void)s->channels8.push_back(rssi);
  return s;
}

// MRS1104 shape: DIST1 only, layer angle.
std::unique_ptr<ScanTelegram> Mrs(std::int16_t layer_angle_raw) {
  auto s = BaseScan(21835);
  s->layer_angle_raw = layer_angle_raw;
  s->measurement_frequency_raw = 180;
  (void)s->channels16.push_back(Channel("DIST1", 64, -475000, 2500, 64000));
  return s;
}

// Multi-echo with encoders and every optional block.
std::unique_ptr<ScanTelegram> Everything(std::uint16_t points) {
  auto s = BaseScan(7);
  s->device_status = {1, 0};
  (void)s->encoders.push_back({123456u, -3});
  (void)s->encoders.push_back({0xFFFFFFFFu, 300});
  const char* kDist[] = {"DIST1", "DIST2", "DIST3", "DIST4", "DIST5"};
  const char* kRssi[] = {"RSSI1", "RSSI2", "RSSI3", "RSSI4", "RSSI5"};
  for (int e = 0; e < 5; ++e) {
    ScanChannel d = Channel(kDist[e], points, -450000, 5000, 65535);
    d.scale_factor = 2.0f;
    (void)s->channels16.push_back(d);
    ScanChannel r = Channel(kRssi[e], points, -450000, 5000, 255);
    r.bits = 8;
    (void)s->channels8.push_back(r);
  }
  s->has_position = true;
  s->position = {1.0f, 2.0f, 3.0f, 0.5f, -0.5f, 1.5f, 1, 0};
  s->has_name = true;
  s->name.length = 6;
  std::memcpy(s->name.text.data(), "LMS511", 6);
  s->has_comment = true;
  s->comment.length = 12;
  std::memcpy(s->comment.text.data(), "door, 2.1 m ", 12);
  s->has_event = true;
  s->event = {{'F', 'D', 'I', 'N', '\0'}, 42u, 1000u, 900000};
  return s;
}

}  // namespace

void WriteColaSeeds(const std::vector<std::vector<std::uint8_t>>& sensor_streams,
                    const std::string& out_dir) {
  const std::filesystem::path dir(out_dir);
  std::filesystem::create_directories(dir);

  // Windows of the real streams: evenly spread, sizes between 4 and 16 KB.
  constexpr std::size_t kWindows = 8;
  for (std::size_t k = 0; k < sensor_streams.size(); ++k) {
    const Bytes& stream = sensor_streams[k];
    if (stream.empty()) continue;
    for (std::size_t w = 0; w < kWindows; ++w) {
      const std::size_t size = std::min(stream.size(), 4096 + (w * 1733) % (12 * 1024 + 1));
      const std::size_t start = (stream.size() - size) * w / (kWindows - 1);
      WriteFile(dir / ("stream" + std::to_string(k) + "_window" + std::to_string(w) + ".bin"),
                std::span(stream).subspan(start, size));
      if (size == stream.size()) break;  // a short stream: one window holds all of it
    }
  }

  // Synthetic scans, framed and bare.
  struct Named {
    const char* name;
    std::unique_ptr<ScanTelegram> scan;
  };
  Named scans[] = {
      {"tim_16bit_rssi", Tim(40)},
      {"lms511_8bit_rssi", Lms511(40)},
      {"mrs_layer_250", Mrs(250)},
      {"mrs_layer_-500", Mrs(-500)},
      {"multi_echo_all_blocks", Everything(12)},
      {"empty_channels", BaseScan(1)},
  };
  Bytes all_frames;
  for (const Named& n : scans) {
    const Bytes payload = Payload(*n.scan);
    WriteFile(dir / (std::string("payload_") + n.name + ".bin"), payload);
    const Bytes frame = Frame(payload);
    WriteFile(dir / (std::string("frame_") + n.name + ".bin"), frame);
    Append(all_frames, frame);
  }
  WriteFile(dir / "frames_all_synthetic.bin", all_frames);

  // A reply dialogue as the LMS111 answers the driver, with the start sequence inside
  // LIDinputstate.
  Bytes dialogue;
  std::array<std::uint8_t, 64> buf{};
  const std::uint8_t one = 1;
  Append(dialogue, Frame(std::span<const std::uint8_t>(
                       buf.data(), cola::EncodeReply(cola::CommandType::kMethodAnswer,
                                                     "SetAccessMode", std::span(&one, 1), buf))));
  Append(dialogue, Frame(std::string_view("sRA FirmwareVersion \x00\x09V1.80.2  ", 31)));
  Append(dialogue, Frame(std::string_view("sRA DeviceIdent \x00\x08MRS1xxxx\x00\x08"
                                          "1.0.0.0R",
                                          36)));
  Append(dialogue, Frame(std::string_view(
                       "sRA LIDinputstate \x00\x01\x00\x00\x00\x00\x02\x02\x02\x02\x00\x00", 30)));
  Append(dialogue,
         Frame(std::span<const std::uint8_t>(buf.data(), cola::EncodeErrorReply(3, buf))));
  Append(dialogue, Frame("sWA LMDscandatacfg "));
  Append(dialogue, Frame(std::string_view("sEA LMDscandata \x01", 17)));
  Append(dialogue, Frame(std::string_view("sSN LMDscandatamon \x01", 20)));
  WriteFile(dir / "dialogue.bin", dialogue);

  // Framing faults around a good frame: bad checksum, impossible and zero lengths, garbage, a cut
  // frame.
  const Bytes good = Frame(Payload(*Tim(8)));
  Bytes faults = {'x', 'y', 2, 2, 2};
  Bytes bad = good;
  bad.back() ^= 0x5A;
  Append(faults, bad);
  Append(faults, Bytes{2, 2, 2, 2, 0xFF, 0xFF, 0xFF, 0xFF});
  Append(faults, Bytes{2, 2, 2, 2, 0, 0, 0, 0});
  Append(faults, good);
  faults.insert(faults.end(), good.begin(),
                good.begin() + static_cast<std::ptrdiff_t>(good.size() / 2));
  WriteFile(dir / "framing_faults.bin", faults);
}

}  // namespace lrfnet::fuzz
