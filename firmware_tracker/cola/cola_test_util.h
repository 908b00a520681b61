#pragma once
// Test helpers for the CoLa-B codec tests (not part of the library): crude capture reading that
// does not depend on the capture library, frame extraction independent of Framer, and synthetic
// scan telegrams.

#include <cstdint>
#include <memory>
#include <span>
#include <string_view>
#include <vector>

#include "firmware_tracker/cola/scan_telegram.h"

namespace lrfnet::cola::test {

using Bytes = std::vector<std::uint8_t>;

// The bytes of a text.
Bytes B(std::string_view s);

// A whole CoLa-B frame (header, length, payload, checksum) around `payload`.
Bytes Frame(const Bytes& payload);
Bytes Frame(std::string_view payload);

// a += b.
void Append(Bytes& a, const Bytes& b);

// The sensor -> client TCP payload of a classic pcap or pcapng file (Ethernet, IPv4, TCP from
// `sensor_port`), concatenated in capture order; a segment whose sequence number lies before the
// next expected one (a retransmission) is dropped. Enough for the shared SICK captures, not a
// general reader.
std::vector<std::uint8_t> SensorStreamFromCapture(std::span<const std::uint8_t> file_bytes,
                                                  std::uint16_t sensor_port = 2112);

// Payloads of all checksum-valid CoLa-B frames in `stream` that start with `prefix`, found by
// scanning for `02 02 02 02` with a plausible length (a valid frame is skipped whole).
std::vector<std::vector<std::uint8_t>> ExtractFrames(std::span<const std::uint8_t> stream,
                                                     std::string_view prefix);

// A scan with `points` beams in DIST1 (16-bit) and RSSI1 (16-bit), time block present, nothing
// else: the TiM781S shape.
std::unique_ptr<ScanTelegram> MakeSimpleScan(std::uint16_t points, std::uint16_t telegram_counter);

// Everything at once: two encoders, DIST1..DIST5 and RSSI1..RSSI5 (RSSI in the 8-bit block),
// position, name, comment, time and event blocks.
std::unique_ptr<ScanTelegram> MakeFullScan(std::uint16_t points);

// Field-by-field equality of two scans (raw values compared up to each channel's count).
bool SameScan(const ScanTelegram& a, const ScanTelegram& b);

// Whole frame (header + payload + checksum) of an encoded scan.
std::vector<std::uint8_t> EncodeScanFrame(const ScanTelegram& scan);

}  // namespace lrfnet::cola::test
