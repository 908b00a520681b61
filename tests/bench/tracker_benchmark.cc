// Per-scan cost of lrfnet-tracker's whole path (Google Benchmark): CoLa-B frame bytes -> stream
// decoder -> clock mapping -> background model, segmentation, measurements, multi-target tracker ->
// datagram encoding -> UDP send to a receiver on loopback. One benchmark iteration = one scan.
//
// Inputs: the shared LMS511 capture (1141 beams, 25 Hz; its scans looped with rewritten counters
// and ticks so time runs on) when present, and synthetic LMS5xx scans (1141 beams over 190 deg, 25
// Hz) of a 30 x 20 m hall with 0, 10 and 50 people walking. The background is learned before
// timing. Reported per case: median and p99 microseconds per scan, heap allocations in the timed
// loop, peak RSS of the process after the case, uplink bytes per second against raw CoLa-B bytes
// per second. Every input runs twice: with the previous measurement (fixed-axes ellipse, no
// static-object handling or limits: "old") and with the body-centre shape fit (the default: "new"),
// so the cost of each shows side by side in the same run. A markdown table goes to stdout and to
// --out FILE (replacing its header and table; the file's "## " sections after them are kept).
//
//   tracker_benchmark [--out FILE] [--scans N] [--people LIST] [--no-send] [--rounds R]
//                     [--no-turns] [--before-single-precision-fit] [--before-send-per-datagram]
//                     [google benchmark flags]
//
// --people 0,50 renders only those synthetic scenes and skips the capture (for profiling one case
// under callgrind, where rendering every scene costs more than the timed loop). --no-send drops the
// encoded datagrams instead of sending them (the path without the kernel's UDP send).
//
// --rounds R runs the cases in turns instead of one after the other (Google Benchmark's runner is
// then not used; --benchmark_filter=PATTERN still selects the cases): each case's scans are cut
// into R blocks and block r of every case runs before block r + 1 of any. On a shared machine the
// load changes within seconds; run one after the other, one scene may be measured in a quiet
// moment and the next in a busy one, and their ratio moves by more than most changes to the
// tracker. In turns, every round's ratio to the empty scene compares times taken within the same
// few hundred milliseconds; the table gives the median over the rounds and its spread. Without
// --rounds the cases run one after the other as before and then once more in 10 rounds, whose
// ratios the table's last column gives (--no-turns leaves that run out).
//
// Code placement: built with the compiler's default function alignment (16 bytes), the same code
// shifted by 16, 32 or 48 bytes in the binary moved the 10-people ratio in turns by up to 0.07
// (2.085 to 2.155, medians of four runs each), as much as most changes to the tracker. The per-scan
// libraries are therefore built with their functions on 64-byte boundaries
// (LRFNET_ALIGN_HOT_FUNCTIONS): two builds' ratios then compare the code, not where it landed.
// Within one binary the rounds' lowest and highest ratios show the machine's share of the spread;
// the load also moves a binary's median by up to 0.05 between sittings minutes apart, so two builds
// are compared alternated, run after run.
//
// --before-single-precision-fit fits a person's outline with every point in double precision
// (ShapeFitOptions::single_precision_points = false), the previous arithmetic, so that the same
// binary measures both.
//
// --before-send-per-datagram sends every datagram with its own send(2) (UdpUplinkOptions::
// batch_sends = false) instead of a scan's datagrams in one sendmmsg(2).
//
// For every case that sends, stderr gets its datagrams per scan and how many of them went in
// batches (sendmmsg). For every case with shape fits, stderr gets the fits' evaluations of their
// objective (each one pass over the points): fits, evaluations per fit and the fits by their count
// of evaluations (PipelineCounters::shape_fit_evaluations).

#include <benchmark/benchmark.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <fstream>
#include <iterator>
#include <memory>
#include <optional>
#include <random>
#include <regex>
#include <string>
#include <vector>

#include "common/capture/capture_stream.h"
#include "firmware_tracker/app/node_test_util.h"
#include "firmware_tracker/app/tracker_node.h"
#include "firmware_tracker/cola/framer.h"
#include "firmware_tracker/cola/stream_decoder.h"
#include "firmware_tracker/io/udp_uplink.h"
#include "tests/support/alloc_counter.h"
#include "tests/support/test_data.h"
#include "tests/support/udp_peer.h"

namespace lrfnet::bench {
namespace {

using Clock = std::chrono::steady_clock;

struct Frame {
  std::vector<std::uint8_t> bytes;  // one complete CoLa-B frame
  common::UtcNs receive_ns = 0;
};

struct Input {
  std::string name;
  double rate_hz = 25.0;
  std::vector<Frame> learn;  // fed before timing (background learning)
  std::vector<Frame> timed;  // cycled through while timing
};

struct Row {
  std::string name;
  std::size_t scans = 0;
  double median_us = 0.0;
  double p99_us = 0.0;
  double cpu_median_us = 0.0;
  double cpu_p99_us = 0.0;
  std::size_t allocations = 0;
  long peak_rss_kib = 0;
  double uplink_bytes_per_s = 0.0;
  double raw_bytes_per_s = 0.0;
  std::uint64_t confirmed_tracks = 0;
};

// Per case, from the run in turns (Interleaved): the CPU / empty-scene ratio's median over the
// rounds and its lowest and highest.
struct TurnStats {
  double ratio_median = 0.0, ratio_low = 0.0, ratio_high = 0.0;
};
std::vector<std::pair<std::string, TurnStats>>& Turns() {
  static std::vector<std::pair<std::string, TurnStats>> turns;
  return turns;
}

std::vector<Row>& Rows() {
  static std::vector<Row> rows;
  return rows;
}

Frame EncodeFrame(const cola::ScanTelegram& scan, common::UtcNs receive_ns) {
  std::vector<std::uint8_t> payload(cola::MaxEncodedSize(scan) + 64);
  payload.resize(cola::EncodeScanTelegram(scan, payload));
  Frame frame;
  frame.bytes.resize(payload.size() + 16);
  frame.bytes.resize(cola::EncodeFrame(payload, frame.bytes));
  frame.receive_ns = receive_ns;
  return frame;
}

// The LMS511 capture's scans, looped `passes` times with counters and ticks continued.
std::unique_ptr<Input> CaptureInput(std::size_t timed_scans) {
  const auto path = lrfnet::testing::SharedFile("data/sick/lms511_20210301.pcap");
  if (!path) return nullptr;
  struct Collect : cola::TelegramListener {
    std::vector<std::unique_ptr<cola::ScanTelegram>> scans;
    std::vector<common::UtcNs> times;
    void OnScan(const cola::ScanTelegram& s, common::UtcNs rx) override {
      scans.push_back(std::make_unique<cola::ScanTelegram>(s));
      times.push_back(rx);
    }
  } collect;
  std::string error;
  auto capture = capture::CaptureStream::Open(*path, capture::CaptureStreamOptions{}, &error);
  if (!capture) return nullptr;
  cola::StreamDecoder decoder;
  capture::StreamChunk chunk;
  while (capture->Next(&chunk)) decoder.Feed(chunk.bytes, chunk.receive_time_ns, collect);
  if (collect.scans.size() < 2) return nullptr;

  auto input = std::make_unique<Input>();
  input->name = "LMS511 capture (looped)";
  input->rate_hz = collect.scans.front()->scan_frequency_hz();
  const std::size_t n = collect.scans.size();
  const common::DurationNs span_ns = collect.times.back() - collect.times.front() +
                                     static_cast<common::DurationNs>(1e9 / input->rate_hz);
  const std::uint32_t span_us = static_cast<std::uint32_t>(span_ns / 1000);
  const std::size_t learn = static_cast<std::size_t>(6.0 * input->rate_hz);
  for (std::size_t i = 0; i < learn + timed_scans; ++i) {
    const std::size_t pass = i / n;
    cola::ScanTelegram scan = *collect.scans[i % n];
    scan.scan_counter = static_cast<std::uint16_t>(scan.scan_counter + pass * n);
    scan.telegram_counter = static_cast<std::uint16_t>(scan.telegram_counter + pass * n);
    scan.time_since_startup_us += static_cast<std::uint32_t>(pass) * span_us;
    scan.time_of_transmission_us += static_cast<std::uint32_t>(pass) * span_us;
    const common::UtcNs rx = collect.times[i % n] + static_cast<common::DurationNs>(pass) * span_ns;
    (i < learn ? input->learn : input->timed).push_back(EncodeFrame(scan, rx));
  }
  return input;
}

// LMS5xx-like synthetic scans of a hall with `people` random walkers.
std::unique_ptr<Input> SyntheticInput(int people, std::size_t timed_scans) {
  tracking::testing::ScannerConfig config;
  config.first_angle_rad = common::DegToRad(-95.0);
  config.angle_step_rad = common::DegToRad(190.0 / 1140.0);
  config.beams = 1141;
  config.max_range_m = 40.0;
  config.rate_hz = 25.0;
  tracker::testing::SyntheticDevice device(config);
  // Sensor on the middle of the south wall of a 30 x 20 m hall, looking north (+x).
  const std::vector<tracking::testing::Wall> hall = {
      {{-0.5, -15.0}, {19.5, -15.0}}, {{19.5, -15.0}, {19.5, 15.0}},
      {{19.5, 15.0}, {-0.5, 15.0}},   {{-0.5, 15.0}, {-0.5, -15.0}},
      {{6.0, -6.0}, {7.0, -6.0}},     {{7.0, -6.0}, {7.0, -5.0}},  // a pillar
  };
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> ux(1.0, 18.0), uy(-13.0, 13.0), ua(-M_PI, M_PI);
  std::vector<tracking::testing::Body> bodies(static_cast<std::size_t>(people));
  std::vector<double> heading(bodies.size());
  for (std::size_t i = 0; i < bodies.size(); ++i) {
    bodies[i] = {{ux(rng), uy(rng)}, 0.25, 0.15, 0.0};
    heading[i] = ua(rng);
  }
  auto input = std::make_unique<Input>();
  input->name = "synthetic 1141 beams, " + std::to_string(people) + " people";
  const std::size_t learn = static_cast<std::size_t>(6.0 * config.rate_hz);
  const std::vector<tracking::testing::Body> none;
  for (std::size_t k = 0; k < learn + timed_scans; ++k) {
    const bool walking = k >= learn;
    if (walking) {
      for (std::size_t i = 0; i < bodies.size(); ++i) {
        heading[i] += 0.1 * ua(rng) / M_PI;
        Eigen::Vector2d step(std::cos(heading[i]), std::sin(heading[i]));
        bodies[i].centre_m += 0.05 * step;  // 1.25 m/s
        const Eigen::Vector2d& c = bodies[i].centre_m;
        if (c.x() < 1.0 || c.x() > 18.0 || std::abs(c.y()) > 13.0) heading[i] += M_PI;
        bodies[i].yaw_rad = heading[i] + M_PI / 2;
      }
    }
    common::UtcNs rx = 0;
    const cola::ScanTelegram& scan =
        device.Scan(static_cast<std::int64_t>(k), hall, walking ? bodies : none, &rx);
    (walking ? input->timed : input->learn).push_back(EncodeFrame(scan, rx));
  }
  return input;
}

struct Listener : cola::TelegramListener {
  tracker::TrackerNode* node = nullptr;
  void OnScan(const cola::ScanTelegram& scan, common::UtcNs rx) override {
    node->OnScan(scan, rx, rx);
    node->OnTick(rx, tracker::LinkHealth{}, clock);
  }
  io::ClockStatus clock{io::ClockSync::kReplay};
};

// CPU time of this thread: unlike wall time it does not count preemption by other processes.
double ThreadCpuUs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) * 1e6 + static_cast<double>(ts.tv_nsec) * 1e-3;
}

double Quantile(std::vector<double> values, double q) {
  std::sort(values.begin(), values.end());
  const auto i = static_cast<std::size_t>(q * static_cast<double>(values.size() - 1) + 0.5);
  return values[std::min(i, values.size() - 1)];
}

// --before-single-precision-fit.
bool g_before_single_precision_fit = false;
// --before-send-per-datagram.
bool g_before_send_per_datagram = false;

struct Case {
  const Input* input = nullptr;
  bool old_measurement = false;
  bool send = true;  // false: datagrams are encoded and dropped (no system call)
  std::string name;
};

// Takes the encoder's datagrams and drops them: the path without the kernel's UDP send.
class DroppingSink final : public io::DatagramSink {
 public:
  void Send(std::span<const std::uint8_t> datagram, common::UtcNs) override {
    bytes += datagram.size();
  }
  std::size_t bytes = 0;
};

// One case's tracker with its learned background, fed the case's timed scans one at a time.
class CaseRunner {
 public:
  explicit CaseRunner(const Case* c) : case_(c) {}

  // Opens the uplink and learns the background; an error message when the uplink cannot open.
  std::optional<std::string> SetUp() {
    io::UdpUplinkOptions udp_options;
    udp_options.host = "127.0.0.1";
    udp_options.port = receiver_.port();
    udp_options.sensor_id = "bench";
    udp_options.batch_sends = !g_before_send_per_datagram;
    udp_ = std::make_unique<io::UdpUplink>(udp_options);
    if (auto e = udp_->Open()) return e;
    tracker::TrackerConfig config;
    config.sensor_id = "bench";
    config.tracking.background.max_range_m = 40.0;
    if (g_before_single_precision_fit) config.tracking.shape.fit.single_precision_points = false;
    if (case_->old_measurement) {
      config.tracking.method = tracking::MeasurementMethod::kEllipse;
      config.tracking.tracking.static_objects = false;
      config.tracking.tracking.report_coasting_s = config.tracking.tracking.coast_timeout_s;
      config.tracking.tracking.max_speed_mps = 1000.0;
    }
    node_ = case_->send ? std::make_unique<tracker::TrackerNode>(config, 1, *udp_)
                        : std::make_unique<tracker::TrackerNode>(config, 1, dropping_);
    listener_.node = node_.get();
    for (const Frame& f : case_->input->learn) decoder_.Feed(f.bytes, f.receive_ns, listener_);
    receiver_.Drain();
    bytes_before_ = node_->encoder().counters().bytes;
    sent_before_ = udp_->counters();
    return std::nullopt;
  }

  bool Exhausted() const { return next_ == case_->input->timed.size(); }

  // Feeds the next timed scan; its wall and thread CPU time in µs.
  void Feed(double* wall_us, double* cpu_us) {
    const Frame& f = case_->input->timed[next_++];
    const double cpu_started = ThreadCpuUs();
    const auto started = Clock::now();
    decoder_.Feed(f.bytes, f.receive_ns, listener_);
    *wall_us = std::chrono::duration<double, std::micro>(Clock::now() - started).count();
    *cpu_us = ThreadCpuUs() - cpu_started;
    raw_bytes_ += f.bytes.size();
    if ((next_ & 255) == 0) receiver_.Drain();
  }

  std::size_t fed() const { return next_; }
  double uplink_bytes() const {
    return static_cast<double>(node_->encoder().counters().bytes - bytes_before_);
  }
  double raw_bytes() const { return static_cast<double>(raw_bytes_); }
  std::uint64_t confirmed_tracks() const {
    return node_->pipeline().tracker().counters().confirmed;
  }
  // The datagrams per timed scan (where sent), and the shape fits' evaluations of their objective
  // so far, to stderr: fits, evaluations per fit and the fits by their count of evaluations (the
  // last bin: that many or more).
  void PrintCaseCounters() const {
    if (case_->send && fed() > 0) {
      const io::UdpUplinkCounters& c = udp_->counters();
      const auto per_scan = [&](std::uint64_t now, std::uint64_t before) {
        return static_cast<double>(now - before) / static_cast<double>(fed());
      };
      std::fprintf(stderr,
                   "sends: %s: %.3f datagrams per scan, %.3f of them in batches, %.3f sendmmsg "
                   "calls per scan\n",
                   case_->name.c_str(), per_scan(c.datagrams_sent, sent_before_.datagrams_sent),
                   per_scan(c.batched, sent_before_.batched),
                   per_scan(c.batches, sent_before_.batches));
    }
    const auto& histogram = node_->pipeline().counters().shape_fit_evaluations;
    std::uint64_t fits = 0, evaluations = 0;
    std::string bins;
    for (std::size_t e = 0; e < histogram.size(); ++e) {
      fits += histogram[e];
      evaluations += e * histogram[e];
      bins += " " + std::to_string(e) + (e + 1 == histogram.size() ? "+:" : ":") +
              std::to_string(histogram[e]);
    }
    if (fits == 0) return;
    std::fprintf(stderr, "fit evaluations: %s: %llu fits, %.4f per fit;%s\n", case_->name.c_str(),
                 static_cast<unsigned long long>(fits),
                 static_cast<double>(evaluations) / static_cast<double>(fits), bins.c_str());
  }

 private:
  const Case* case_;
  lrfnet::testing::LoopbackUdpPeer receiver_;
  std::unique_ptr<io::UdpUplink> udp_;
  DroppingSink dropping_;
  std::unique_ptr<tracker::TrackerNode> node_;
  cola::StreamDecoder decoder_;
  Listener listener_;
  std::uint64_t bytes_before_ = 0;
  io::UdpUplinkCounters sent_before_;
  std::uint64_t raw_bytes_ = 0;
  std::size_t next_ = 0;
};

void RunCase(benchmark::State& state, const Case* c) {
  const Input* input = c->input;
  CaseRunner runner(c);
  if (auto e = runner.SetUp()) {
    state.SkipWithError(e->c_str());
    return;
  }
  std::vector<double> durations_us;
  std::vector<double> cpu_us;
  durations_us.reserve(input->timed.size());
  cpu_us.reserve(input->timed.size());
  lrfnet::testing::StartCountingAllocations();
  for (auto _ : state) {
    if (runner.Exhausted()) {
      // Out of pre-rendered scans: stop (the learning above must not be repeated in the loop).
      state.SkipWithError("input exhausted; pass a smaller --benchmark_min_time or more --scans");
      break;
    }
    double wall = 0.0, cpu = 0.0;
    runner.Feed(&wall, &cpu);
    durations_us.push_back(wall);
    cpu_us.push_back(cpu);
  }
  const std::size_t allocations = lrfnet::testing::StopCountingAllocations();
  if (durations_us.empty()) return;

  Row row;
  row.name = c->name;
  row.scans = durations_us.size();
  row.median_us = Quantile(durations_us, 0.5);
  row.p99_us = Quantile(durations_us, 0.99);
  row.cpu_median_us = Quantile(cpu_us, 0.5);
  row.cpu_p99_us = Quantile(cpu_us, 0.99);
  // Allocations that are not the benchmark harness's own (the duration vector is reserved).
  row.allocations = allocations;
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  row.peak_rss_kib = usage.ru_maxrss;
  const double seconds = static_cast<double>(row.scans) / input->rate_hz;
  row.uplink_bytes_per_s = runner.uplink_bytes() / seconds;
  row.raw_bytes_per_s = runner.raw_bytes() / seconds;
  row.confirmed_tracks = runner.confirmed_tracks();
  runner.PrintCaseCounters();
  state.counters["median_us"] = row.median_us;
  state.counters["p99_us"] = row.p99_us;
  state.counters["allocs"] = static_cast<double>(row.allocations);
  // The framework calls a case several times while it sizes the run; the last run is reported.
  auto& rows = Rows();
  auto it =
      std::find_if(rows.begin(), rows.end(), [&](const Row& r) { return r.name == row.name; });
  if (it != rows.end()) {
    *it = row;
  } else {
    rows.push_back(row);
  }
}

// The empty scene's case of the same measurement as `c` (the same name after the last comma).
std::size_t EmptySceneOf(const std::vector<const Case*>& cases, std::size_t c) {
  const std::string& name = cases[c]->name;
  const std::size_t comma = name.rfind(',');
  if (comma == std::string::npos) return cases.size();
  const std::string suffix = name.substr(comma);
  for (std::size_t e = 0; e < cases.size(); ++e) {
    const std::string& n = cases[e]->name;
    const std::size_t n_comma = n.rfind(',');
    if (n.find(" 0 people") != std::string::npos && n_comma != std::string::npos &&
        n.substr(n_comma) == suffix) {
      return e;
    }
  }
  return cases.size();
}

// The cases run in turns: every case's timed scans are cut into `rounds` consecutive blocks, and
// block r of every case runs before block r + 1 of any (the order of the cases rotated from round
// to round), so that a change in the machine's load during the run falls on every scene alike. Per
// case: the median over the rounds of each round's median CPU time per scan, with the fastest and
// slowest round's, and the ratio to the empty scene of the same measurement taken round by round
// (each round's median against the empty scene's in the same round), its median over the rounds
// with the smallest and largest.
std::string Interleaved(const std::vector<const Case*>& cases, std::size_t rounds) {
  std::vector<std::unique_ptr<CaseRunner>> runners;
  for (const Case* c : cases) {
    runners.push_back(std::make_unique<CaseRunner>(c));
    if (auto e = runners.back()->SetUp()) {
      std::fprintf(stderr, "tracker_benchmark: %s: %s\n", c->name.c_str(), e->c_str());
      std::exit(1);
    }
  }
  const std::size_t n = cases.size();
  // round_median[c][r]
  std::vector<std::vector<double>> round_median(n, std::vector<double>(rounds, 0.0));
  std::vector<std::size_t> allocations(n, 0);
  std::vector<double> cpu_us, wall_us;
  for (std::size_t r = 0; r < rounds; ++r) {
    for (std::size_t k = 0; k < n; ++k) {
      const std::size_t c = (k + r) % n;
      const std::size_t total = cases[c]->input->timed.size();
      const std::size_t end = total * (r + 1) / rounds;
      cpu_us.clear();
      wall_us.clear();
      cpu_us.reserve(total);
      wall_us.reserve(total);
      lrfnet::testing::StartCountingAllocations();
      while (runners[c]->fed() < end) {
        double wall = 0.0, cpu = 0.0;
        runners[c]->Feed(&wall, &cpu);
        wall_us.push_back(wall);
        cpu_us.push_back(cpu);
      }
      allocations[c] += lrfnet::testing::StopCountingAllocations();
      round_median[c][r] = cpu_us.empty() ? 0.0 : Quantile(cpu_us, 0.5);
    }
  }
  std::string out =
      "| input | scans | rounds | CPU median µs (median of the rounds) | fastest round | slowest "
      "round | CPU / empty scene (median of the rounds) | lowest | highest | allocations | "
      "uplink B/s | confirmed tracks |\n"
      "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";
  char line[512];
  for (std::size_t c = 0; c < n; ++c) {
    runners[c]->PrintCaseCounters();
    const std::vector<double>& m = round_median[c];
    const std::size_t e = EmptySceneOf(cases, c);
    std::vector<double> ratio;
    if (e < n) {
      for (std::size_t r = 0; r < rounds; ++r) {
        if (round_median[e][r] > 0.0) ratio.push_back(m[r] / round_median[e][r]);
      }
    }
    const auto [lo, hi] = std::minmax_element(m.begin(), m.end());
    if (!ratio.empty()) {
      Turns().emplace_back(
          cases[c]->name,
          TurnStats{Quantile(ratio, 0.5), *std::min_element(ratio.begin(), ratio.end()),
                    *std::max_element(ratio.begin(), ratio.end())});
    }
    const double seconds = static_cast<double>(runners[c]->fed()) / cases[c]->input->rate_hz;
    std::snprintf(line, sizeof line,
                  "| %s | %zu | %zu | %.1f | %.1f | %.1f | %.2f | %.2f | %.2f | %zu | %.0f | %llu "
                  "|\n",
                  cases[c]->name.c_str(), runners[c]->fed(), rounds, Quantile(m, 0.5), *lo, *hi,
                  ratio.empty() ? 0.0 : Quantile(ratio, 0.5),
                  ratio.empty() ? 0.0 : *std::min_element(ratio.begin(), ratio.end()),
                  ratio.empty() ? 0.0 : *std::max_element(ratio.begin(), ratio.end()),
                  allocations[c], runners[c]->uplink_bytes() / seconds,
                  static_cast<unsigned long long>(runners[c]->confirmed_tracks()));
    out += line;
  }
  return out;
}

std::string TurnsCell(const std::string& name) {
  for (const auto& [n, t] : Turns()) {
    if (n != name) continue;
    char cell[64];
    std::snprintf(cell, sizeof cell, "%.2f [%.2f - %.2f]", t.ratio_median, t.ratio_low,
                  t.ratio_high);
    return cell;
  }
  return "-";
}

std::string Table() {
  std::string out =
      "| input | scans | median µs/scan | p99 µs/scan | CPU median µs | CPU p99 µs | CPU median / "
      "empty scene | allocations | peak RSS MiB | uplink B/s | raw CoLa-B B/s | uplink/raw | "
      "confirmed tracks | CPU / empty scene, in turns: median [lowest - highest round] |\n"
      "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";
  char line[512];
  // The empty scene of the same measurement in this run.
  auto empty_cpu = [](const Row& r) {
    const std::string suffix = r.name.substr(r.name.rfind(','));
    for (const Row& e : Rows()) {
      if (e.name.find("0 people") != std::string::npos &&
          e.name.substr(e.name.rfind(',')) == suffix) {
        return e.cpu_median_us;
      }
    }
    return 0.0;
  };
  for (const Row& r : Rows()) {
    const double empty = empty_cpu(r);
    std::snprintf(
        line, sizeof line,
        "| %s | %zu | %.1f | %.1f | %.1f | %.1f | %.2f | %zu | %.1f | %.0f | %.0f | %.3f | "
        "%llu | %s |\n",
        r.name.c_str(), r.scans, r.median_us, r.p99_us, r.cpu_median_us, r.cpu_p99_us,
        empty > 0 ? r.cpu_median_us / empty : 0.0, r.allocations,
        static_cast<double>(r.peak_rss_kib) / 1024.0, r.uplink_bytes_per_s, r.raw_bytes_per_s,
        r.uplink_bytes_per_s / r.raw_bytes_per_s,
        static_cast<unsigned long long>(r.confirmed_tracks), TurnsCell(r.name).c_str());
    out += line;
  }
  return out;
}

}  // namespace
}  // namespace lrfnet::bench

int main(int argc, char** argv) {
  using namespace lrfnet::bench;
  std::string out_path;
  std::size_t scans = 3000;
  std::vector<int> people_counts = {0, 10, 50};
  bool capture_input = true;
  bool send = true;
  std::size_t rounds = 0;
  bool turns = true;
  std::string filter;
  std::vector<char*> args;
  for (int i = 0; i < argc; ++i) {
    if (std::strcmp(argv[i], "--out") == 0 && i + 1 < argc) {
      out_path = argv[++i];
    } else if (std::strcmp(argv[i], "--scans") == 0 && i + 1 < argc) {
      scans = static_cast<std::size_t>(std::stoul(argv[++i]));
    } else if (std::strcmp(argv[i], "--rounds") == 0 && i + 1 < argc) {
      rounds = static_cast<std::size_t>(std::stoul(argv[++i]));
    } else if (std::strcmp(argv[i], "--no-turns") == 0) {
      turns = false;
    } else if (std::strcmp(argv[i], "--before-single-precision-fit") == 0) {
      g_before_single_precision_fit = true;
    } else if (std::strcmp(argv[i], "--before-send-per-datagram") == 0) {
      g_before_send_per_datagram = true;
    } else if (std::strcmp(argv[i], "--no-send") == 0) {
      send = false;
    } else if (std::strcmp(argv[i], "--people") == 0 && i + 1 < argc) {
      people_counts.clear();
      const std::string list = argv[++i];
      for (std::size_t at = 0; at < list.size();) {
        const std::size_t comma = std::min(list.find(',', at), list.size());
        people_counts.push_back(std::stoi(list.substr(at, comma - at)));
        at = comma + 1;
      }
      capture_input = false;
    } else {
      if (std::strncmp(argv[i], "--benchmark_filter=", 19) == 0) filter = argv[i] + 19;
      args.push_back(argv[i]);
    }
  }
  int bench_argc = static_cast<int>(args.size());
  benchmark::Initialize(&bench_argc, args.data());

  std::vector<std::unique_ptr<Input>> inputs;
  if (!capture_input) {
    // --people: synthetic scenes only.
  } else if (auto capture = CaptureInput(scans)) {
    inputs.push_back(std::move(capture));
  } else {
    std::fprintf(stderr, "tracker_benchmark: LMS511 capture not found; synthetic inputs only\n");
  }
  for (int people : people_counts) inputs.push_back(SyntheticInput(people, scans));
  std::vector<std::unique_ptr<Case>> cases;
  for (const auto& input : inputs) {
    for (const bool old : {true, false}) {
      auto c = std::make_unique<Case>();
      c->input = input.get();
      c->old_measurement = old;
      c->send = send;
      c->name = input->name + (old ? ", old (ellipse" : ", new (shape fit") +
                (send ? ")" : "; not sent)");
      // Exactly `scans` iterations: every timed scan once, in order.
      benchmark::RegisterBenchmark(c->name.c_str(), RunCase, c.get())
          ->Iterations(static_cast<benchmark::IterationCount>(input->timed.size()))
          ->Unit(benchmark::kMicrosecond);
      cases.push_back(std::move(c));
    }
  }
  // The cases whose name --benchmark_filter's pattern finds (for the runs in turns).
  std::vector<const Case*> selected;
  const std::regex pattern(filter.empty() ? std::string(".") : filter);
  for (const auto& c : cases) {
    if (std::regex_search(c->name, pattern)) selected.push_back(c.get());
  }
  if (selected.empty()) {
    std::fprintf(stderr, "tracker_benchmark: no case matches --benchmark_filter\n");
    return 1;
  }
  if (rounds > scans) {
    std::fprintf(stderr, "tracker_benchmark: --rounds %zu is more than --scans %zu\n", rounds,
                 scans);
    return 2;
  }
  std::string table;
  if (rounds > 0) {
    table = Interleaved(selected, rounds);
  } else {
    benchmark::RunSpecifiedBenchmarks();
    // The ratios once more with the cases in turns (10 rounds), beside the table's ratios of cases
    // measured one after the other (--no-turns: without).
    if (turns) Interleaved(selected, 10);
    table = Table();
  }
  benchmark::Shutdown();

  std::printf("\n%s", table.c_str());
  if (!out_path.empty()) {
    // The file's sections after the generated table ("## ...": measurements side by side, analyses)
    // are kept: only the header and the table are this run's.
    std::string kept;
    {
      std::ifstream in(out_path);
      const std::string old((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
      const std::size_t section = old.find("\n## ");
      if (section != std::string::npos) kept = old.substr(section);
    }
    std::ofstream out(out_path);
    out << "# lrfnet-tracker per-scan path\n\n"
        << "decode -> clock mapping -> tracking -> encode -> UDP send on loopback, one scan per "
           "iteration; allocations counted in the timed loop; peak RSS is the process's after "
           "the case (inputs for all cases are held in memory). old: the previous measurement "
           "(fixed-axes ellipse), new: the body-centre shape fit (the default); CPU median / empty "
           "scene: against the 0-people scene of the same measurement in this run.";
    if (rounds == 0 && turns) {
      out << " Last column: the cases run once more in turns, 10 rounds of consecutive scans each "
             "(the order rotated from round to round), each round's median against the empty "
             "scene's in the same round; the median over the rounds with the lowest and highest "
             "(a change of the machine's load during the run falls on every scene alike).";
    }
    if (rounds > 0) {
      out << " The cases ran in turns, " << rounds
          << " rounds of consecutive scans each (the order rotated from round to round): CPU "
             "times are the median over the rounds of each round's median, the ratios to the "
             "empty scene are taken round by round and their median given with the lowest and "
             "highest.";
    }
    out << "\n\n" << table << kept;
  }
  return 0;
}
