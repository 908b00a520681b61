#include "tools/dump.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <utility>
#include <vector>

#include "common/capture/packet_parser.h"
#include "common/capture/pcap_reader.h"

namespace lrfnet::tools {
namespace {

// A flat JSON object whose keys are sorted on output, as json.dumps(..., sort_keys=True) prints it.
class JsonObject {
 public:
  void Add(std::string key, std::string raw_value) {
    fields_.emplace_back(std::move(key), std::move(raw_value));
  }
  std::string Str() {
    std::sort(fields_.begin(), fields_.end());
    std::string out = "{";
    for (std::size_t i = 0; i < fields_.size(); ++i) {
      if (i != 0) out += ", ";
      out += '"' + fields_[i].first + "\": " + fields_[i].second;
    }
    return out + "}";
  }

 private:
  std::vector<std::pair<std::string, std::string>> fields_;
};

template <typename Int>
std::string IntList(std::initializer_list<Int> values) {
  std::string out = "[";
  for (const Int v : values) out += (out.size() > 1 ? ", " : "") + std::to_string(v);
  return out + "]";
}

std::string Rounded4(double v) { return FormatPythonFloat(RoundDecimals(v, 4)); }

std::string CountMap(const std::map<std::string, std::uint64_t>& counts) {
  JsonObject o;
  for (const auto& [key, n] : counts) o.Add(key, std::to_string(n));
  return o.Str();
}

class DumpListener : public cola::TelegramListener {
 public:
  DumpListener(std::ostream* out, DumpSummary* summary) : out_(out), summary_(summary) {}

  void OnScan(const cola::ScanTelegram& scan, common::UtcNs receive_time_ns) override {
    ++summary_->scans;
    if (out_ != nullptr) *out_ << ScanJsonLine(scan, receive_time_ns) << '\n';
  }
  void OnTelegram(const cola::TelegramHeader& header, std::span<const std::uint8_t>,
                  common::UtcNs) override {
    ++summary_->other_by_type[cola::CommandTypeName(header.type)];
    if (header.type == cola::CommandType::kEventData)
      ++summary_->events_by_name[std::string(header.name)];
  }

 private:
  std::ostream* out_;
  DumpSummary* summary_;
};

}  // namespace

std::string FormatPythonFloat(double v) {
  if (std::isnan(v)) return "NaN";
  if (std::isinf(v)) return v > 0 ? "Infinity" : "-Infinity";
  if (v == 0.0) return std::signbit(v) ? "-0.0" : "0.0";
  // Shortest round-trip digits (what Python's repr picks), then Python's layout rules.
  char buf[64];
  const auto result =
      std::to_chars(buf, buf + sizeof buf, std::fabs(v), std::chars_format::scientific);
  const std::string_view sci(buf, static_cast<std::size_t>(result.ptr - buf));  // d[.ddd]e±XX
  const std::size_t e_pos = sci.find('e');
  std::string digits;
  for (const char c : sci.substr(0, e_pos)) {
    if (c != '.') digits += c;
  }
  const int exponent = std::atoi(std::string(sci.substr(e_pos + 1)).c_str());
  std::string out = std::signbit(v) ? "-" : "";
  if (exponent >= -4 && exponent < 16) {
    const int int_digits = exponent + 1;
    if (int_digits <= 0) {
      out += "0." + std::string(static_cast<std::size_t>(-int_digits), '0') + digits;
    } else if (static_cast<std::size_t>(int_digits) >= digits.size()) {
      out += digits + std::string(static_cast<std::size_t>(int_digits) - digits.size(), '0') + ".0";
    } else {
      out += digits.substr(0, static_cast<std::size_t>(int_digits)) + "." +
             digits.substr(static_cast<std::size_t>(int_digits));
    }
  } else {
    out += digits.substr(0, 1);
    if (digits.size() > 1) out += "." + digits.substr(1);
    char exp_buf[16];
    std::snprintf(exp_buf, sizeof exp_buf, "e%c%02d", exponent < 0 ? '-' : '+', std::abs(exponent));
    out += exp_buf;
  }
  return out;
}

double RoundDecimals(double v, int decimals) {
  if (!std::isfinite(v)) return v;
  // glibc prints the exact binary value rounded half-to-even, which is what Python's round()
  // computes.
  char buf[512];
  std::snprintf(buf, sizeof buf, "%.*f", decimals, v);
  return std::strtod(buf, nullptr);
}

std::string ScanJsonLine(const cola::ScanTelegram& scan, common::UtcNs receive_time_ns) {
  JsonObject o;
  o.Add("telegram_counter", std::to_string(scan.telegram_counter));
  o.Add("scan_counter", std::to_string(scan.scan_counter));
  o.Add("time_since_startup_us", std::to_string(scan.time_since_startup_us));
  o.Add("time_of_transmission_us", std::to_string(scan.time_of_transmission_us));
  o.Add("scan_frequency_hz", Rounded4(scan.scan_frequency_raw / 100.0));

  const cola::ScanChannel* dist = scan.FindChannel("DIST1");
  if (dist != nullptr) {
    o.Add("start_angle_deg", Rounded4(dist->start_angle_deg()));
    o.Add("angle_step_deg", Rounded4(dist->angle_step_deg()));
    o.Add("n_points", std::to_string(dist->count));
    std::uint64_t sum = 0;
    for (std::size_t i = 0; i < dist->count; ++i) sum += dist->raw[i];
    o.Add("dist1_raw_sum", std::to_string(sum));
    o.Add("dist1_scale", Rounded4(dist->scale_factor));
    std::string first3 = "[";
    for (std::size_t i = 0; i < std::min<std::size_t>(3, dist->count); ++i) {
      first3 += (i != 0 ? ", " : "") + Rounded4(dist->RangeM(i));
    }
    o.Add("dist1_first3_m", first3 + "]");
  } else {
    for (const char* key : {"start_angle_deg", "angle_step_deg", "dist1_scale"}) o.Add(key, "null");
    o.Add("n_points", "0");
    o.Add("dist1_raw_sum", "0");
    o.Add("dist1_first3_m", "[]");
  }

  const cola::ScanChannel* rssi = scan.FindChannel("RSSI1");
  std::uint64_t rssi_sum = 0;
  if (rssi != nullptr) {
    for (std::size_t i = 0; i < rssi->count; ++i) rssi_sum += rssi->raw[i];
  }
  o.Add("rssi_n", std::to_string(rssi != nullptr ? rssi->count : 0));
  o.Add("rssi_raw_sum", std::to_string(rssi_sum));
  o.Add("rssi_bits", std::to_string(rssi != nullptr ? rssi->bits : 0));

  if (scan.has_time) {
    const cola::ScanTimeBlock& t = scan.time;
    o.Add("time_block", IntList<std::uint32_t>(
                            {t.year, t.month, t.day, t.hour, t.minute, t.second, t.microsecond}));
  } else {
    o.Add("time_block", "null");
  }

  o.Add("device_status", IntList<unsigned>({scan.device_status[0], scan.device_status[1]}));
  o.Add("layer_angle_deg", Rounded4(scan.layer_angle_raw / 100.0));
  o.Add("receive_time_ns", std::to_string(receive_time_ns));
  o.Add("serial_number", std::to_string(scan.serial_number));
  return o.Str();
}

std::string SummaryJson(const DumpSummary& s) {
  JsonObject o;
  o.Add("frames", std::to_string(s.stream.framer.frames));
  o.Add("bad_checksums", std::to_string(s.stream.framer.bad_checksum));
  o.Add("oversize_lengths", std::to_string(s.stream.framer.oversize_length));
  o.Add("garbage_bytes", std::to_string(s.stream.framer.garbage_bytes));
  o.Add("stream_bytes", std::to_string(s.stream.framer.bytes_in));
  o.Add("scans", std::to_string(s.scans));
  o.Add("scan_decode_errors", std::to_string(s.stream.scan_decode_errors));
  o.Add("bad_headers", std::to_string(s.stream.bad_headers));
  std::uint64_t others = 0;
  for (const auto& [type, n] : s.other_by_type) others += n;
  o.Add("other_telegrams", std::to_string(others));
  o.Add("other_by_type", CountMap(s.other_by_type));
  o.Add("events_by_name", CountMap(s.events_by_name));
  o.Add("packets", std::to_string(s.capture.packets));
  o.Add("stream_packets", std::to_string(s.capture.stream_packets));
  o.Add("malformed_packets", std::to_string(s.capture.malformed_packets));
  o.Add("retransmitted_bytes", std::to_string(s.capture.retransmitted_bytes));
  o.Add("out_of_order_segments", std::to_string(s.capture.out_of_order_segments));
  o.Add("gaps", std::to_string(s.capture.gaps));
  o.Add("gap_bytes", std::to_string(s.capture.gap_bytes));
  o.Add("connections", std::to_string(s.capture.connections));
  o.Add("discontinuities", std::to_string(s.discontinuities));
  return o.Str();
}

bool DumpCapture(const std::string& path, const DumpOptions& options, std::ostream* out,
                 DumpSummary* summary, std::string* error) {
  DumpSummary local;
  DumpSummary* sum = summary != nullptr ? summary : &local;
  std::unique_ptr<capture::CaptureStream> capture =
      capture::CaptureStream::Open(path, options.capture, error);
  if (!capture) return false;
  auto decoder = std::make_unique<cola::StreamDecoder>();  // holds a ~100 kB scan: not on the stack
  DumpListener listener(out, sum);
  capture::StreamChunk chunk;
  while (capture->Next(&chunk)) {
    if (chunk.discontinuity) {
      ++sum->discontinuities;
      decoder->Reset();
    }
    decoder->Feed(chunk.bytes, chunk.receive_time_ns, listener);
  }
  sum->stream = decoder->counters();
  sum->capture = capture->counters();
  if (!capture->error().empty()) {
    *error = capture->error();
    return false;
  }
  return true;
}

CaptureContent InspectCapture(const std::string& path, std::uint16_t tcp_port,
                              std::uint16_t udp_port) {
  CaptureContent content;
  std::string error;
  const std::unique_ptr<capture::PcapReader> reader = capture::PcapReader::Open(path, &error);
  if (!reader) return content;
  content.is_capture = true;
  capture::RawPacket raw;
  // A read error at the end is the scan or datagram path's to report: the packets before it count.
  while (reader->Next(&raw) == capture::ReadStatus::kPacket) {
    const capture::ParseResult parsed = capture::ParsePacket(raw.link_type, raw.bytes);
    if (parsed.status != capture::ParseStatus::kOk) continue;
    const capture::ParsedPacket& p = parsed.packet;
    if (p.protocol == capture::TransportProtocol::kTcp &&
        (p.src_port == tcp_port || p.dst_port == tcp_port)) {
      ++content.scanner_tcp_packets;
      break;  // decided: scans
    }
    if (p.protocol == capture::TransportProtocol::kUdp && (udp_port == 0 || p.dst_port == udp_port))
      ++content.udp_packets;
  }
  return content;
}

DumpInput ChooseDumpInput(const CaptureContent& content) {
  if (!content.is_capture) return DumpInput::kDatagrams;
  if (content.scanner_tcp_packets > 0) return DumpInput::kScans;
  return content.udp_packets > 0 ? DumpInput::kDatagrams : DumpInput::kScans;
}

}  // namespace lrfnet::tools
