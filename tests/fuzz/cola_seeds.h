#pragma once
// Seed corpus of the cola_fuzz target.

#include <cstdint>
#include <string>
#include <vector>

namespace lrfnet::fuzz {

// Writes seed files into `out_dir` (created if absent): up to 8 windows of 4-16 KB of every sensor
// stream (the reassembled sensor -> client bytes of a capture), and synthetic inputs made with the
// encoder that exist on any machine: framed scan telegrams (16-bit and 8-bit RSSI, multi-echo,
// encoders, every optional block, MRS layer angles), bare scan payloads (for the direct
// DecodeScanTelegram path), a reply dialogue with a start sequence inside a payload, and framing
// faults. File names are stable, so re-running overwrites instead of adding.
void WriteColaSeeds(const std::vector<std::vector<std::uint8_t>>& sensor_streams,
                    const std::string& out_dir);

}  // namespace lrfnet::fuzz
