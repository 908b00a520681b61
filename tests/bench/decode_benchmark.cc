// Decode throughput of the SICK link on the gateway path: capture -> reassembled stream (libpcap + TCP
// reassembly), stream -> telegrams (framing + LMDscandata decode), and the telegram decoder alone.
// Input: the LMS511 capture of the shared data (1141 points, 8-bit RSSI) when present, else a synthetic
// LMS511-like stream from the telegram encoder. Prints a markdown table and writes it to --out.
//
//   decode_benchmark [--capture FILE] [--out FILE] [--seconds S]

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "common/capture/capture_stream.h"
#include "firmware_tracker/cola/framer.h"
#include "firmware_tracker/cola/stream_decoder.h"
#include "tests/support/test_data.h"

namespace {

using Clock = std::chrono::steady_clock;

struct CountingListener : lrfnet::cola::TelegramListener {
  std::uint64_t scans = 0;
  std::uint64_t points = 0;
  void OnScan(const lrfnet::cola::ScanTelegram& scan, lrfnet::common::UtcNs) override {
    ++scans;
    points += scan.channels16.empty() ? 0 : scan.channels16[0].count;
  }
};

// Runs `fn` repeatedly for about `seconds`; returns the median seconds per call over the repetitions.
template <typename Fn>
double MedianSeconds(double seconds, Fn&& fn) {
  std::vector<double> t;
  const auto end = Clock::now() + std::chrono::duration<double>(seconds);
  do {
    const auto a = Clock::now();
    fn();
    t.push_back(std::chrono::duration<double>(Clock::now() - a).count());
  } while (Clock::now() < end || t.size() < 5);
  std::sort(t.begin(), t.end());
  return t[t.size() / 2];
}

std::vector<std::uint8_t> SyntheticStream(std::size_t telegrams) {
  lrfnet::cola::ScanTelegram scan;
  scan.version = 1;
  scan.serial_number = 12345678;
  scan.scan_frequency_raw = 2500;
  scan.measurement_frequency_raw = 300;
  auto* dist = scan.channels16.emplace_slot();
  std::memcpy(dist->name.data(), "DIST1", 5);
  dist->start_angle_raw = -50000;
  dist->angle_step_raw = 1667;
  dist->count = 1141;
  auto* rssi = scan.channels8.emplace_slot();
  std::memcpy(rssi->name.data(), "RSSI1", 5);
  rssi->bits = 8;
  rssi->start_angle_raw = -50000;
  rssi->angle_step_raw = 1667;
  rssi->count = 1141;
  scan.has_time = true;
  scan.time.year = 1970;
  std::vector<std::uint8_t> stream, payload(lrfnet::cola::MaxEncodedSize(scan)), frame(payload.size() + 16);
  for (std::size_t k = 0; k < telegrams; ++k) {
    scan.telegram_counter = static_cast<std::uint16_t>(k);
    scan.scan_counter = static_cast<std::uint16_t>(k);
    scan.time_since_startup_us = static_cast<std::uint32_t>(40000 * k);
    for (std::size_t i = 0; i < 1141; ++i) {
      dist->raw[i] = static_cast<std::uint16_t>(2000 + (i * 7 + k) % 5000);
      rssi->raw[i] = static_cast<std::uint16_t>((i + k) % 255);
    }
    const std::size_t n = lrfnet::cola::EncodeScanTelegram(scan, payload);
    const std::size_t f = lrfnet::cola::EncodeFrame({payload.data(), n}, frame);
    stream.insert(stream.end(), frame.begin(), frame.begin() + static_cast<std::ptrdiff_t>(f));
  }
  return stream;
}

}  // namespace

int main(int argc, char** argv) {
  std::string capture, out = "results/decode_benchmark.md";
  double seconds = 2.0;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--capture" && i + 1 < argc) capture = argv[++i];
    else if (a == "--out" && i + 1 < argc) out = argv[++i];
    else if (a == "--seconds" && i + 1 < argc) seconds = std::stod(argv[++i]);
    else {
      std::fprintf(stderr, "usage: decode_benchmark [--capture FILE] [--out FILE] [--seconds S]\n");
      return 2;
    }
  }
  if (capture.empty()) {
    if (auto p = lrfnet::testing::SharedFile("data/sick/lms511_20210301.pcap")) capture = *p;
  }

  std::vector<std::uint8_t> stream;
  std::string source;
  double capture_s = 0;
  std::uint64_t capture_file_bytes = 0;
  if (!capture.empty()) {
    source = "LMS511 capture (" + capture.substr(capture.find_last_of('/') + 1) + ")";
    capture_file_bytes = static_cast<std::uint64_t>(std::ifstream(capture, std::ios::ate | std::ios::binary).tellg());
    capture_s = MedianSeconds(seconds, [&] {
      std::string error;
      auto cs = lrfnet::capture::CaptureStream::Open(capture, {}, &error);
      if (!cs) {
        std::fprintf(stderr, "decode_benchmark: %s\n", error.c_str());
        std::exit(1);
      }
      stream.clear();
      lrfnet::capture::StreamChunk chunk;
      while (cs->Next(&chunk)) stream.insert(stream.end(), chunk.bytes.begin(), chunk.bytes.end());
    });
  } else {
    source = "synthetic LMS511-like stream (1141 points, 8-bit RSSI)";
    stream = SyntheticStream(500);
  }

  // Framing + header + LMDscandata decode, the gateway's per-byte path.
  std::uint64_t scans = 0;
  lrfnet::cola::StreamDecoder decoder;
  const double stream_s = MedianSeconds(seconds, [&] {
    CountingListener l;
    decoder.Reset();
    decoder.Feed(stream, 0, l);
    scans = l.scans;
  });

  // The telegram decoder alone on the stream's scan payloads.
  std::vector<std::vector<std::uint8_t>> payloads;
  {
    lrfnet::cola::Framer framer;
    framer.FeedAll(stream, [&](std::span<const std::uint8_t> p) {
      if (lrfnet::cola::IsScanTelegram(p)) payloads.emplace_back(p.begin(), p.end());
    }, [](const char*) {});
  }
  std::uint64_t payload_bytes = 0;
  for (const auto& p : payloads) payload_bytes += p.size();
  auto scan = std::make_unique<lrfnet::cola::ScanTelegram>();
  const double decode_s = MedianSeconds(seconds, [&] {
    for (const auto& p : payloads) {
      if (!lrfnet::cola::DecodeScanTelegram(p, scan.get()).ok) std::abort();
    }
  });

  char table[2048];
  const double mb = 1e6;
  int n = std::snprintf(table, sizeof(table),
      "# Decode throughput (one core)\n\nInput: %s, %zu stream bytes, %llu scan telegrams.\n\n"
      "| stage | MB/s | telegrams/s | µs per telegram |\n|---|---|---|---|\n"
      "| framing + header + LMDscandata decode (StreamDecoder) | %.1f | %.0f | %.2f |\n"
      "| LMDscandata decode alone | %.1f | %.0f | %.2f |\n",
      source.c_str(), stream.size(), static_cast<unsigned long long>(scans),
      static_cast<double>(stream.size()) / stream_s / mb, static_cast<double>(scans) / stream_s,
      stream_s / static_cast<double>(scans) * 1e6,
      static_cast<double>(payload_bytes) / decode_s / mb, static_cast<double>(payloads.size()) / decode_s,
      decode_s / static_cast<double>(payloads.size()) * 1e6);
  if (capture_s > 0) {
    std::snprintf(table + n, sizeof(table) - static_cast<std::size_t>(n),
        "| pcap read + TCP reassembly (CaptureStream), file bytes | %.1f | %.0f | %.2f |\n",
        static_cast<double>(capture_file_bytes) / capture_s / mb, static_cast<double>(scans) / capture_s,
        capture_s / static_cast<double>(scans) * 1e6);
  }
  std::fputs(table, stdout);
  const auto parent = std::filesystem::path(out).parent_path();
  if (!parent.empty()) std::filesystem::create_directories(parent);
  std::ofstream(out) << table;
  std::printf("\nwritten to %s\n", out.c_str());
  return 0;
}
