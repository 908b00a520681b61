#pragma once
// `lrfnet dump`: the scans of a capture as JSON lines, and a summary of what the stream held.
//
// One JSON object per `sSN LMDscandata` telegram of the sensor -> client stream (CaptureStream,
// then cola::StreamDecoder: the path the tracker's replay uses), keys sorted, formatted as Python's
// json.dumps would print them (", " and ": " separators, floats in Python's shortest repr,
// e.g. 15.0 not 15). The golden keys (shared data README) and their formatting:
//   angle_step_deg, dist1_first3_m, dist1_raw_sum, dist1_scale, n_points, rssi_bits, rssi_n,
//   rssi_raw_sum, scan_counter, scan_frequency_hz, start_angle_deg, telegram_counter, time_block
//   (null or 7 ints), time_of_transmission_us, time_since_startup_us
// Floats are rounded to 4 decimals as Python's round() does. Extra keys:
//   device_status [u8, u8], layer_angle_deg (MRS layer, 1/100° field / 100), receive_time_ns
//   (capture time of the packet that completed the telegram), serial_number (the telegram's u32
//   serial field).

#include <cstdint>
#include <map>
#include <optional>
#include <ostream>
#include <string>

#include "common/capture/capture_stream.h"
#include "common/time.h"
#include "firmware_tracker/cola/scan_telegram.h"
#include "firmware_tracker/cola/stream_decoder.h"

namespace lrfnet::tools {

// Python's repr() of a double: shortest round-trip digits, fixed notation for 1e-4 <= |v| < 1e16
// (always with a fractional part: "15.0"), else "1.5e-05" / "1e+16"; "NaN", "Infinity", "-Infinity"
// as json.dumps.
std::string FormatPythonFloat(double v);
// Python's round(v, decimals): the double nearest to the correctly rounded decimal value.
double RoundDecimals(double v, int decimals);

// One JSON object (no trailing newline) for a decoded scan.
std::string ScanJsonLine(const cola::ScanTelegram& scan, common::UtcNs receive_time_ns);

struct DumpOptions {
  capture::CaptureStreamOptions capture;  // sensor_port selects the scanner's TCP port
};

struct DumpSummary {
  cola::StreamCounters stream;
  capture::CaptureCounters capture;
  // Telegrams other than LMDscandata scans, by type ("sRA", "sFA", ...) and, for sSN events, by
  // name.
  std::map<std::string, std::uint64_t> other_by_type;
  std::map<std::string, std::uint64_t> events_by_name;
  std::uint64_t scans = 0;
  std::uint64_t discontinuities = 0;
};
// The summary as one JSON object (keys sorted, no trailing newline).
std::string SummaryJson(const DumpSummary& summary);

// Reads the capture at `path` and writes one scan line per LMDscandata telegram to `out` (nullptr:
// none). Returns false with *error (one line) when the file cannot be opened or ends in a read
// error; lines for the scans before a read error are still written.
bool DumpCapture(const std::string& path, const DumpOptions& options, std::ostream* out,
                 DumpSummary* summary, std::string* error);

// What a pcap/pcapng file holds, from one pass over its packets, so that `lrfnet dump` can choose
// between scans (the scanner's TCP stream) and datagram lines (a capture of the UDP uplink).
struct CaptureContent {
  bool is_capture = false;                // libpcap opened the file (pcap or pcapng)
  std::uint64_t scanner_tcp_packets = 0;  // TCP from or to tcp_port; the pass stops at the first
  std::uint64_t udp_packets = 0;          // UDP to udp_port (0: any)
};
CaptureContent InspectCapture(const std::string& path, std::uint16_t tcp_port,
                              std::uint16_t udp_port);

enum class DumpInput : std::uint8_t {
  kScans,      // the scanner's TCP stream (DumpCapture), or a capture holding neither
  kDatagrams,  // UDP datagrams, or not a capture (a recording: OpenDatagramFile decides)
};
// Scans when the capture holds any TCP packet of the scanner's port, else datagrams when it holds
// UDP, else scans (no output, as before there were datagram files). Not a capture: datagrams.
DumpInput ChooseDumpInput(const CaptureContent& content);

}  // namespace lrfnet::tools
