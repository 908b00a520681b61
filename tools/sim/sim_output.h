#pragma once
// What `lrfnet sim SCENARIO --out DIR` writes:
//
// DIR/<sensor id>.pcap: the sensor's CoLa-B TCP session as captured on its gateway. SYN, SYN-ACK,
//   ACK; the commands the live client sends (io::SickClient: sMN SetAccessMode, sRN DeviceIdent,
//   FirmwareVersion, SerialNumber, sMN LMCstartmeas, sMN Run, sEN LMDscandata 1), each answered
//   by the device; then one sSN LMDscandata per scan, split into TCP segments, with a pure ACK
//   from the client after each. Packet times are the gateway's receive clock: UTC (start_utc +
//   scenario time) + the gateway's offset. A scan arrives at its time of transmission + network
//   latency (latency_ms + an exponential delay of mean jitter_ms, never overtaking the previous
//   scan) + its segments' time on a 100 Mbit/s wire. The dialogue ends just before the first scan.
// DIR/truth.yaml: sensor poses exactly as in the scenario (DESIGN.md "Poses": a `sensors` list of
//   {id, x_m, y_m, yaw_deg}; a sensor with `moves` at its pose at the end of the run), `poses`
//   (every sensor's poses with their time ranges: {id, from_s, to_s, from_utc_ns, x_m, y_m,
//   yaw_deg}), `world_changes` (when the scenario has any), then `devices` (model, resolved
//   parameters, clock, network, capture file) and `targets` (shape, presence).
// DIR/truth_tracks.csv: time_s,utc_ns,target,x_m,y_m,heading_deg,vx_mps,vy_mps,kind for every
//   target present at time_s = n / truth_rate_hz < duration_s (body centre including sway, facing
//   direction, velocity of the path point; a door: the leaf's centre and direction, its velocity);
//   utc_ns = start_utc + time_s; kind: person, cylinder, trolley, chair or door (a trolley's pusher
//   is a person, "<id>.pusher"). Columns are only ever added at the end.

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "tools/scan_source.h"
#include "tools/sim/pcap_writer.h"
#include "tools/sim/simulator.h"

namespace lrfnet::sim {

// The identity a sensor reports in the start-up dialogue (DeviceIdent name and version from the
// model, FirmwareVersion padded as the device pads it, SerialNumber as 8 digits).
tools::DeviceIdentity IdentityOf(const SensorSetup& sensor);

// Addresses of sensor i's session: device 192.168.0.(11 + i) (MAC 00:06:77 + serial, SICK's OUI),
// port 2112; client 192.168.0.100.
TcpEndpoint DeviceEndpoint(const SensorSetup& sensor, std::size_t index);

struct CaptureSummary {
  std::uint64_t scans = 0;
  std::uint64_t packets = 0;
  std::uint64_t bytes = 0;
};

// Writes sensor `sensor`'s session to `path`. False with *error (one line) on an I/O error.
bool WriteCapture(const Simulator& sim, std::size_t sensor, const std::string& path,
                  CaptureSummary* summary, std::string* error);

// truth.yaml text. `start_utc_ns` is the UTC of scenario time 0 (the scenario's start_utc when
// writing captures; the wall clock at start when serving); `with_captures` adds each device's
// capture file name.
std::string TruthYaml(const Simulator& sim, std::int64_t start_utc_ns, bool with_captures);
// The `poses` (and `world_changes`) sections of truth.yaml.
std::string PoseHistoryYaml(const Scenario& scenario, std::int64_t start_utc_ns);
bool WriteTruthTracks(const Simulator& sim, std::int64_t start_utc_ns, const std::string& path,
                      std::string* error);

struct OutputOptions {
  int jobs = 1;  // sensors simulated in parallel, 1 ... 256
};
std::optional<std::string> Validate(const OutputOptions& options);

// Everything above into `dir` (created if needed). `summary` gets one entry per sensor.
bool WriteSimulation(const Simulator& sim, const std::string& dir, const OutputOptions& options,
                     std::vector<CaptureSummary>* summary, std::string* error);

}  // namespace lrfnet::sim
