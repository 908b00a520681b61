#include "tools/sim/sim_output.h"

#include <fmt/format.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <thread>

#include "firmware_tracker/cola/commands.h"
#include "firmware_tracker/cola/framer.h"
#include "tools/sim/rng.h"

namespace lrfnet::sim {

namespace {

constexpr double kPi = 3.14159265358979323846;
// Bits on a 100 Mbit/s wire per frame byte, including preamble and inter-frame gap (20 bytes per
// frame, added separately).
constexpr double kWireSecondsPerByte = 8.0 / 100e6;
constexpr std::size_t kWireOverheadBytes = 14 + 20 + 32 + 20;
// The client's stack answers a received frame with a pure ACK after this long.
constexpr double kAckDelayS = 40e-6;
// The client sends its next command this long after a reply.
constexpr double kClientThinkS = 200e-6;
constexpr double kHandshakeRttS = 250e-6;

std::vector<std::uint8_t> Frame(std::span<const std::uint8_t> payload) {
  std::vector<std::uint8_t> frame(payload.size() + cola::kFrameHeaderBytes +
                                  cola::kFrameTrailerBytes);
  frame.resize(cola::EncodeFrame(payload, frame));
  return frame;
}

void AppendFlexString(std::string_view text, std::vector<std::uint8_t>* out) {
  const auto n = static_cast<std::uint16_t>(std::min<std::size_t>(text.size(), 0xFFFF));
  out->push_back(static_cast<std::uint8_t>(n >> 8));
  out->push_back(static_cast<std::uint8_t>(n & 0xFF));
  out->insert(out->end(), text.begin(), text.begin() + n);
}

std::vector<std::uint8_t> ReplyFrame(cola::CommandType type, std::string_view name,
                                     std::span<const std::uint8_t> args) {
  std::vector<std::uint8_t> payload(name.size() + args.size() + 8);
  payload.resize(cola::EncodeReply(type, name, args, payload));
  return Frame(payload);
}

struct Exchange {
  std::vector<std::uint8_t> command;  // frame
  std::vector<std::uint8_t> reply;    // frame
  double response_s;                  // the device's time to answer
};

// The start-up dialogue of io::SickClient (default options) and the device's answers.
std::vector<Exchange> Dialogue(const SensorSetup& sensor) {
  using cola::CommandType;
  const tools::DeviceIdentity id = IdentityOf(sensor);
  std::array<std::uint8_t, 64> buf{};
  const auto command = [&](std::size_t n) { return Frame({buf.data(), n}); };
  std::vector<Exchange> out;
  std::vector<std::uint8_t> args;

  args = {1};
  out.push_back({command(cola::EncodeSetAccessMode(cola::AccessLevel::kAuthorizedClient,
                                                   cola::kAuthorizedClientPasswordHash, buf)),
                 ReplyFrame(CommandType::kMethodAnswer, "SetAccessMode", args), 1.6e-3});
  args.clear();
  AppendFlexString(id.name, &args);
  AppendFlexString(id.version, &args);
  out.push_back({command(cola::EncodeReadVariable("DeviceIdent", buf)),
                 ReplyFrame(CommandType::kReadAnswer, "DeviceIdent", args), 1.1e-3});
  args.clear();
  AppendFlexString(id.firmware_version, &args);
  out.push_back({command(cola::EncodeReadVariable("FirmwareVersion", buf)),
                 ReplyFrame(CommandType::kReadAnswer, "FirmwareVersion", args), 1.0e-3});
  args.clear();
  AppendFlexString(id.serial_number, &args);
  out.push_back({command(cola::EncodeReadVariable("SerialNumber", buf)),
                 ReplyFrame(CommandType::kReadAnswer, "SerialNumber", args), 1.0e-3});
  args = {0};
  out.push_back({command(cola::EncodeStartMeasurement(buf)),
                 ReplyFrame(CommandType::kMethodAnswer, "LMCstartmeas", args), 2.4e-3});
  args = {1};
  out.push_back(
      {command(cola::EncodeRun(buf)), ReplyFrame(CommandType::kMethodAnswer, "Run", args), 3.1e-3});
  args = {1};
  out.push_back({command(cola::EncodeScanDataEvent(true, buf)),
                 ReplyFrame(CommandType::kEventAnswer, "LMDscandata", args), 1.2e-3});
  return out;
}

std::string Num(double v) { return fmt::format("{}", v); }

std::string Quoted(const std::string& s) {
  std::string out = "\"";
  for (char c : s) {
    if (c == '"' || c == '\\') out += '\\';
    out += c;
  }
  return out + "\"";
}

std::string IpText(const TcpEndpoint& e) {
  return fmt::format("{}.{}.{}.{}", e.ip[0], e.ip[1], e.ip[2], e.ip[3]);
}

}  // namespace

tools::DeviceIdentity IdentityOf(const SensorSetup& sensor) {
  const DeviceModel& m = *sensor.device.model;
  tools::DeviceIdentity id;
  id.name = std::string(m.ident_name);
  id.version = std::string(m.ident_version);
  id.firmware_version = std::string(m.firmware);
  id.serial_number = fmt::format("{:08}", sensor.serial_number);
  return id;
}

TcpEndpoint DeviceEndpoint(const SensorSetup& sensor, std::size_t index) {
  TcpEndpoint e;
  e.mac = {0x00,
           0x06,
           0x77,
           static_cast<std::uint8_t>(sensor.serial_number >> 16),
           static_cast<std::uint8_t>(sensor.serial_number >> 8),
           static_cast<std::uint8_t>(sensor.serial_number)};
  e.ip = {192, 168, static_cast<std::uint8_t>(index / 200),
          static_cast<std::uint8_t>(11 + index % 200)};
  e.port = 2112;
  return e;
}

bool WriteCapture(const Simulator& sim, std::size_t sensor_index, const std::string& path,
                  CaptureSummary* summary, std::string* error) {
  const SensorSetup& sensor = sim.sensor(sensor_index);
  const Scenario& scenario = sim.scenario();
  std::unique_ptr<PcapWriter> pcap = PcapWriter::Create(path, error);
  if (!pcap) return false;

  Rng rng(MixSeed({scenario.seed, static_cast<std::uint64_t>(RngStream::kSession), sensor_index}));
  const auto client_isn = static_cast<std::uint32_t>(rng.NextU64());
  const auto device_isn = static_cast<std::uint32_t>(rng.NextU64());
  TcpEndpoint client;
  client.mac = {0x02, 0x00, 0x00, 0x00, 0x00, 0x64};
  client.ip = {192, 168, 0, 100};
  client.port = static_cast<std::uint16_t>(40000 + rng.Below(20000));
  const TcpEndpoint device = DeviceEndpoint(sensor, sensor_index);
  TcpSessionWriter tcp(pcap.get(), client, device, client_isn, device_isn);

  const std::int64_t gateway_ns = std::llround(sensor.gateway_offset_ms * 1e6);
  const auto utc_ns = [&](double t_s) {
    return scenario.start_utc_ns + std::llround(t_s * 1e9) + gateway_ns;
  };
  const auto client_ts = [&](double t_s) {
    return static_cast<std::uint32_t>(utc_ns(t_s) / 1000000);
  };
  const auto device_ts = [&](double t_s) {
    return static_cast<std::uint32_t>(sensor.clock.TickAt(t_s) / 1000);
  };

  const std::vector<Exchange> dialogue = Dialogue(sensor);
  double dialogue_s = kHandshakeRttS + 20e-6;
  for (const Exchange& e : dialogue) dialogue_s += kClientThinkS + e.response_s + kAckDelayS;
  const double first_tx = sensor.scan_count > 0 ? sim.Timing(sensor_index, 0).transmit_s : 0.0;
  double t = first_tx - dialogue_s - rng.Uniform(2e-3, std::max(3e-3, sensor.device.period_s));

  tcp.Handshake(utc_ns(t), utc_ns(t + kHandshakeRttS), utc_ns(t + kHandshakeRttS + 20e-6),
                client_ts(t), device_ts(t + kHandshakeRttS / 2));
  t += kHandshakeRttS + 20e-6;
  for (const Exchange& e : dialogue) {
    t += kClientThinkS;
    tcp.ClientData(utc_ns(t), e.command, client_ts(t));
    t += e.response_s;
    const std::int64_t at = utc_ns(t);
    tcp.DeviceData(e.reply, {&at, 1}, device_ts(t));
    t += kAckDelayS;
    tcp.ClientAck(utc_ns(t), client_ts(t));
  }

  auto scan = std::make_unique<cola::ScanTelegram>();
  std::vector<std::uint8_t> payload;
  std::vector<std::uint8_t> frame;
  std::vector<std::int64_t> segment_ns;
  double last_s = t;
  std::uint64_t bytes = 0;
  for (std::uint64_t k = 0; k < sensor.scan_count; ++k) {
    const ScanTiming timing = sim.Timing(sensor_index, k);
    sim.SimulateScan(sensor_index, k, scan.get());
    payload.resize(cola::MaxEncodedSize(*scan));
    payload.resize(cola::EncodeScanTelegram(*scan, payload));
    frame.resize(payload.size() + cola::kFrameHeaderBytes + cola::kFrameTrailerBytes);
    frame.resize(cola::EncodeFrame(payload, frame));

    Rng latency_rng(
        MixSeed({scenario.seed, static_cast<std::uint64_t>(RngStream::kLatency), sensor_index, k}));
    const double latency_s = (sensor.latency_ms + latency_rng.Exponential(sensor.jitter_ms)) * 1e-3;
    // TCP delivers in order: a scan delayed in the network holds back the next one.
    double arrival = std::max(timing.transmit_s + latency_s, last_s + 2e-6);
    const std::size_t n = TcpSessionWriter::SegmentCount(frame.size());
    segment_ns.resize(n);
    std::size_t remaining = frame.size();
    for (std::size_t i = 0; i < n; ++i) {
      const std::size_t seg = std::min(remaining, kMaxSegmentPayload);
      remaining -= seg;
      arrival += static_cast<double>(seg + kWireOverheadBytes) * kWireSecondsPerByte;
      segment_ns[i] = utc_ns(arrival);
    }
    tcp.DeviceData(frame, segment_ns, device_ts(timing.transmit_s));
    last_s = arrival + kAckDelayS;
    tcp.ClientAck(utc_ns(last_s), client_ts(last_s));
    bytes += frame.size();
  }
  if (summary != nullptr) {
    summary->scans = sensor.scan_count;
    summary->packets = pcap->packets();
    summary->bytes = bytes;
  }
  return pcap->Close(error);
}

std::string PoseHistoryYaml(const Scenario& s, std::int64_t start_utc_ns) {
  std::string y = "poses:\n";
  for (const SensorSpec& sensor : s.sensors) {
    for (const SensorPoseSpan& p : PoseSpans(sensor, s.duration_s)) {
      y += fmt::format(
          "  - {{id: {}, from_s: {}, to_s: {}, from_utc_ns: {}, x_m: {}, y_m: {}, yaw_deg: {}}}\n",
          Quoted(sensor.id), Num(p.from_s), Num(p.to_s),
          start_utc_ns + static_cast<std::int64_t>(std::llround(p.from_s * 1e9)), Num(p.x_m),
          Num(p.y_m), Num(p.yaw_deg));
    }
  }
  if (s.world.changes.empty()) return y;
  y += "world_changes:\n";
  for (const WorldChange& c : s.world.changes) {
    if (c.remove) {
      y += fmt::format("  - {{at_s: {}, remove: {}}}\n", Num(c.at_s), *c.remove);
    } else {
      std::string polygon;
      for (const Vec2& v : c.add) {
        polygon += fmt::format("{}[{}, {}]", polygon.empty() ? "" : ", ", Num(v.x), Num(v.y));
      }
      y += fmt::format("  - {{at_s: {}, add: [{}]}}\n", Num(c.at_s), polygon);
    }
  }
  return y;
}

std::string TruthYaml(const Simulator& sim, std::int64_t start_utc_ns, bool with_captures) {
  const Scenario& s = sim.scenario();
  std::string y;
  y += "# Ground truth written by lrfnet sim. `sensors`: poses in the world frame exactly as in "
       "the\n";
  y += "# scenario (x forward = the telegram's 90 deg beam, yaw counter-clockwise, metres, "
       "degrees);\n";
  y += "# a sensor that moves during the run is listed with its pose at the end, and `poses` "
       "gives\n";
  y += "# every pose with its time range (scenario seconds, [from_s, to_s)).\n";
  y += "scenario: " + Quoted(s.name) + "\n";
  y += "seed: " + std::to_string(s.seed) + "\n";
  y += "duration_s: " + Num(s.duration_s) + "\n";
  y += "start_utc: " + Quoted(FormatUtc(start_utc_ns)) + "\n";
  y += "start_utc_ns: " + std::to_string(start_utc_ns) + "\n";
  y += "sensors:\n";
  for (std::size_t i = 0; i < sim.sensor_count(); ++i) {
    const SensorPoseSpan last = PoseSpans(s.sensors[i], s.duration_s).back();
    y += fmt::format("  - {{id: {}, x_m: {}, y_m: {}, yaw_deg: {}}}\n", Quoted(sim.sensor(i).id),
                     Num(last.x_m), Num(last.y_m), Num(last.yaw_deg));
  }
  y += PoseHistoryYaml(s, start_utc_ns);
  y += "devices:\n";
  for (std::size_t i = 0; i < sim.sensor_count(); ++i) {
    const SensorSetup& x = sim.sensor(i);
    const DeviceConfig& d = x.device;
    y += "  - id: " + Quoted(x.id) + "\n";
    y += "    model: " + std::string(d.model->key) + "\n";
    y += std::string("    mount: ") + ToString(x.mount) + "\n";
    if (with_captures) {
      y += "    capture: " + Quoted(x.id + ".pcap") + "\n";
      y += "    ip: " + Quoted(IpText(DeviceEndpoint(x, i))) + "\n";
    }
    y += fmt::format("    serial_number: {}\n", x.serial_number);
    y += fmt::format("    range_m: {}\n    fov_deg: {}\n    resolution_deg: {}\n    rate_hz: {}\n",
                     Num(d.range_m), Num(d.fov_deg), Num(d.step_raw / 10000.0), Num(d.rate_hz));
    y += fmt::format("    beams: {}\n    noise_m: {}\n    noise_per_m: {}\n    bias_m: {}\n",
                     d.count, Num(d.noise_m), Num(d.noise_per_m), Num(x.bias_m));
    y += fmt::format("    clock: {{offset_s: {}, drift_ppm: {}}}\n", Num(x.clock_offset_s),
                     Num(x.drift_ppm));
    y += fmt::format("    network: {{latency_ms: {}, jitter_ms: {}, gateway_offset_ms: {}}}\n",
                     Num(x.latency_ms), Num(x.jitter_ms), Num(x.gateway_offset_ms));
    y += fmt::format("    scans: {}\n    first_scan_tick_us: {}\n    first_telegram_counter: {}\n",
                     x.scan_count, SensorClock::Wire(x.first_scan_tick_us),
                     x.first_telegram_counter);
  }
  y += "targets:";
  y += sim.targets().empty() ? " []\n" : "\n";
  for (std::size_t i = 0; i < sim.targets().size(); ++i) {
    const Target& t = sim.targets()[i];
    const TargetSpec& spec = s.targets[t.spec_index()];
    const Trajectory& traj = t.trajectory();
    const PersonBody& body = t.body();
    std::string shape;
    switch (t.shape()) {
      case TargetShape::kCylinder:
        shape = fmt::format("shape: cylinder, radius_m: {}", Num(spec.radius_m));
        break;
      case TargetShape::kPerson:
        shape = fmt::format(
            "shape: person, a_m: {}, b_m: {}, torso_exponent: {}, sway_m: {}, leg_radius_m: {}, "
            "hip_half_width_m: {}",
            Num(body.a_m), Num(body.b_m), Num(body.exponent), Num(body.sway_m),
            Num(body.leg_radius_m), Num(body.hip_half_width_m));
        break;
      case TargetShape::kTrolley:
        shape = fmt::format("shape: trolley, length_m: {}, width_m: {}", Num(spec.length_m),
                            Num(spec.width_m));
        break;
      case TargetShape::kChair:
        shape = fmt::format("shape: chair, size_m: {}, yaw_deg: {}", Num(spec.size_m),
                            Num(spec.yaw_deg));
        break;
      case TargetShape::kDoor:
        shape = fmt::format("shape: door, hinge: [{}, {}], width_m: {}", Num(spec.door->hinge.x),
                            Num(spec.door->hinge.y), Num(spec.door->width_m));
        break;
    }
    if (traj.knots().empty()) {
      y += fmt::format("  - {{id: {}, {}, present: false}}\n", Quoted(t.id()), shape);
    } else {
      y += fmt::format("  - {{id: {}, {}, enter_s: {}, leave_s: {}}}\n", Quoted(t.id()), shape,
                       Num(traj.start_s()), Num(traj.end_s()));
    }
  }
  return y;
}

bool WriteTruthTracks(const Simulator& sim, std::int64_t start_utc_ns, const std::string& path,
                      std::string* error) {
  std::ofstream out(path, std::ios::trunc);
  if (!out) {
    *error = path + ": cannot create";
    return false;
  }
  const Scenario& s = sim.scenario();
  out << "time_s,utc_ns,target,x_m,y_m,heading_deg,vx_mps,vy_mps,kind\n";
  std::string line;
  for (std::uint64_t n = 0;; ++n) {
    const double t = static_cast<double>(n) / s.truth_rate_hz;
    if (t >= s.duration_s) break;
    for (const TruthSample& ts : sim.TruthAt(t)) {
      const TargetState& st = ts.state;
      const Target& target = sim.targets()[ts.target];
      line = fmt::format("{},{},{},{:.6f},{:.6f},{:.3f},{:.4f},{:.4f},{}\n", Num(t),
                         start_utc_ns + std::llround(t * 1e9), target.id(), st.center.x,
                         st.center.y, st.heading_rad * 180.0 / kPi, st.velocity_mps.x,
                         st.velocity_mps.y, ToString(target.shape()));
      out << line;
    }
  }
  out.flush();
  if (!out.good()) {
    *error = path + ": write error";
    return false;
  }
  return true;
}

std::optional<std::string> Validate(const OutputOptions& options) {
  if (options.jobs < 1 || options.jobs > 256) return "jobs must be 1 ... 256";
  return std::nullopt;
}

bool WriteSimulation(const Simulator& sim, const std::string& dir, const OutputOptions& options,
                     std::vector<CaptureSummary>* summary, std::string* error) {
  if (auto e = Validate(options)) {
    *error = *e;
    return false;
  }
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) {
    *error = dir + ": cannot create the output folder: " + ec.message();
    return false;
  }
  const std::filesystem::path base(dir);
  const std::size_t n = sim.sensor_count();
  std::vector<CaptureSummary> summaries(n);
  std::vector<std::string> errors(n);
  std::vector<char> ok(n, 0);
  std::atomic<std::size_t> next{0};
  const auto worker = [&]() {
    for (std::size_t i = next++; i < n; i = next++) {
      const std::string path = (base / (sim.sensor(i).id + ".pcap")).string();
      ok[i] = WriteCapture(sim, i, path, &summaries[i], &errors[i]) ? 1 : 0;
    }
  };
  const int jobs = std::clamp(options.jobs, 1, static_cast<int>(std::max<std::size_t>(n, 1)));
  std::vector<std::thread> threads;
  for (int j = 1; j < jobs; ++j) threads.emplace_back(worker);
  worker();
  for (std::thread& th : threads) th.join();
  for (std::size_t i = 0; i < n; ++i) {
    if (!ok[i]) {
      *error = errors[i];
      return false;
    }
  }
  const std::string truth_path = (base / "truth.yaml").string();
  {
    std::ofstream truth(truth_path, std::ios::trunc);
    truth << TruthYaml(sim, sim.scenario().start_utc_ns, true);
    truth.flush();
    if (!truth.good()) {
      *error = truth_path + ": write error";
      return false;
    }
  }
  if (!WriteTruthTracks(sim, sim.scenario().start_utc_ns, (base / "truth_tracks.csv").string(),
                        error)) {
    return false;
  }
  if (summary != nullptr) *summary = std::move(summaries);
  return true;
}

}  // namespace lrfnet::sim
