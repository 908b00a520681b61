// lrfnetd's receive path (UdpReceiver -> Daemon: record, decode, validate, sequence, store) with
// the tracker's own encoder making the datagrams. Per simulated sensor: SensorInfo first, then one
// track frame of 5 tracks per scan and a Health after every 50 frames (1 s at 50 Hz).
//
// 1. Throughput on one core over loopback: the daemon's io thread (UdpReceiver + Daemon, like
//    lrfnetd with its 250 ms tick) pinned to CPU 0, all senders in one thread pinned to CPU 1, one
//    UDP socket per sensor, round-robin as fast as possible over pre-encoded datagrams, 10 and 100
//    sensors, without and with recording.
// 2. Application-level loss at fixed offered loads: the same, with the senders paced on a steady
//    clock schedule (datagram i due at start + i / rate); loss per the daemon's sequence counters.
// 3. Memory per sensor-hour: one simulated hour of one sensor through Daemon::OnDatagram directly
//    (no sockets), recorded to a temporary file.
// Prints a markdown table and writes it to OUT. Not a test: timings depend on the machine.
//
//   daemon_benchmark [--out OUT] [--seconds S]      (OUT: results/daemon_benchmark.md; S: 3)

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sched.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <boost/asio/io_context.hpp>
#include <boost/asio/steady_timer.hpp>
#include <chrono>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <future>
#include <optional>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "central_daemon/app/daemon.h"
#include "central_daemon/io/recording_writer.h"
#include "central_daemon/io/udp_receiver.h"
#include "firmware_tracker/io/datagram_encoder.h"

namespace lrfnet::bench {
namespace {

namespace asio = boost::asio;
using Clock = std::chrono::steady_clock;
using common::DurationNs;
using common::kNsPerMs;
using common::kNsPerS;
using common::UtcNs;

constexpr std::size_t kTracks = 5;
constexpr std::uint32_t kFramesPerHealth = 50;
constexpr DurationNs kScanPeriodNs = 20 * kNsPerMs;  // 50 Hz

// ---------------------------------------------------------------------------------------------
// Machine and process facts.

UtcNs RealtimeNs() {
  timespec ts{};
  ::clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<UtcNs>(ts.tv_sec) * kNsPerS + ts.tv_nsec;
}

std::int64_t ThreadCpuNs() {
  timespec ts{};
  ::clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * kNsPerS + ts.tv_nsec;
}

bool PinToCpu(int cpu) {
  cpu_set_t set;
  CPU_ZERO(&set);
  CPU_SET(cpu, &set);
  return ::sched_setaffinity(0, sizeof(set), &set) == 0;  // 0: the calling thread
}

std::size_t RssBytes() {
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line)) {
    if (line.rfind("VmRSS:", 0) == 0) return std::stoull(line.substr(6)) * 1024;
  }
  return 0;
}

std::string CpuModel() {
  std::ifstream cpuinfo("/proc/cpuinfo");
  std::string line;
  while (std::getline(cpuinfo, line)) {
    if (line.rfind("model name", 0) == 0) {
      const auto colon = line.find(':');
      if (colon != std::string::npos) return line.substr(line.find_first_not_of(' ', colon + 1));
    }
  }
  return "unknown";
}

std::string LoadAverage() {
  std::ifstream f("/proc/loadavg");
  std::string one, five, fifteen;
  f >> one >> five >> fifteen;
  return one + " " + five + " " + fifteen;
}

double Seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

// ---------------------------------------------------------------------------------------------
// What a tracker sends.

// One sensor's stream through the tracker's encoder. Scan k starts at t0 + k * period and is sent
// 25 ms later (end of scan + processing).
class SensorStream {
 public:
  SensorStream(const std::string& sensor_id, std::uint64_t session_id, UtcNs t0_ns,
               DurationNs period_ns)
      : encoder_({sensor_id, session_id}), t0_ns_(t0_ns), period_ns_(period_ns) {}

  // Hands exactly one datagram to `sink` and returns its sent_ns.
  UtcNs Next(io::DatagramSink& sink) {
    const UtcNs scan_ns = t0_ns_ + static_cast<DurationNs>(scan_) * period_ns_;
    const UtcNs sent_ns = scan_ns + 25 * kNsPerMs;
    if (!info_sent_) {
      info_sent_ = true;
      io::SensorInfoReport info;
      info.model = "LMS511-20100 PRO";
      info.serial = "21450123";
      info.firmware = "V3.21";
      info.first_angle_rad = -0.0873;
      info.angle_step_rad = 0.00290888;
      info.beam_count = 1141;
      info.fov_rad = 3.3161;
      info.scan_frequency_hz = 1e9 / static_cast<double>(period_ns_);
      info.max_range_m = 80.0;
      info.tracker_version = "lrfnet-tracker 0.1.0";
      encoder_.EncodeSensorInfo(info, sent_ns, sink);
      return sent_ns;
    }
    if (frames_since_health_ == kFramesPerHealth) {
      frames_since_health_ = 0;
      io::HealthReport health;
      health.scans = scan_;
      health.datagrams_sent = encoder_.next_sequence();
      health.scan_cpu_us_mean = 812.5f;
      health.scan_cpu_us_max = 1630.25f;
      health.clock_sync = io::ClockSync::kSynchronized;
      health.clock_error_estimate_s = 0.0012f;
      health.tick_offset_s = 1234.5678;
      health.tick_drift_ppm = 3.2;
      encoder_.EncodeHealth(health, sent_ns, sink);
      return sent_ns;
    }
    tracking::ScanTracks scan;
    scan.scan_start_ns = scan_ns;
    scan.scan_period_s = static_cast<double>(period_ns_) * 1e-9;
    scan.scan_counter = scan_;
    const double t_s = static_cast<double>(scan_) * scan.scan_period_s;
    for (std::size_t i = 0; i < kTracks; ++i) {
      // People walking at about 1.2 m/s on circles of a few metres.
      const double phase = t_s * 0.3 + static_cast<double>(i) * 1.2566;
      tracking::TrackReport* t = scan.tracks.emplace_slot();
      t->track_id = static_cast<std::uint32_t>(100 + i);
      t->state = tracking::TrackState::kConfirmed;
      t->kind = i % 2 == 0 ? tracking::MeasurementKind::kEllipse
                           : tracking::MeasurementKind::kCenterOfMass;
      t->x_m = 6.0 + static_cast<double>(i) + 4.0 * std::cos(phase);
      t->y_m = -3.0 + 4.0 * std::sin(phase);
      t->vx_mps = -1.2 * std::sin(phase);
      t->vy_mps = 1.2 * std::cos(phase);
      Eigen::Matrix4d p = Eigen::Matrix4d::Zero();
      p.diagonal() << 0.0104, 0.0121, 0.0513, 0.0607;
      p(0, 1) = p(1, 0) = 0.0021;
      p(0, 2) = p(2, 0) = 0.0102;
      p(1, 3) = p(3, 1) = 0.0113;
      p(2, 3) = p(3, 2) = 0.0031;
      t->covariance = p * (1.0 + 0.1 * std::sin(phase));
      t->age_scans = scan_ + static_cast<std::uint32_t>(i);
      t->points = 17 + static_cast<std::uint32_t>(i);
      t->ellipse_yaw_rad = phase;
    }
    encoder_.EncodeTracks(scan, sent_ns, sink);
    ++scan_;
    ++frames_since_health_;
    return sent_ns;
  }

 private:
  io::DatagramEncoder encoder_;
  UtcNs t0_ns_;
  DurationNs period_ns_;
  std::uint32_t scan_ = 0;
  std::uint32_t frames_since_health_ = 0;
  bool info_sent_ = false;
};

// One sensor's datagrams, encoded in advance, back to back.
struct Encoded final : io::DatagramSink {
  std::vector<std::uint8_t> bytes;
  std::vector<std::uint32_t> ends;
  std::vector<UtcNs> sent_ns;
  void Send(std::span<const std::uint8_t> d, UtcNs sent) override {
    bytes.insert(bytes.end(), d.begin(), d.end());
    ends.push_back(static_cast<std::uint32_t>(bytes.size()));
    sent_ns.push_back(sent);
  }
  void Clear() {
    bytes.clear();
    ends.clear();
    sent_ns.clear();
  }
  std::size_t size() const { return ends.size(); }
  std::span<const std::uint8_t> At(std::size_t i) const {
    const std::uint32_t begin = i == 0 ? 0 : ends[i - 1];
    return {bytes.data() + begin, ends[i] - begin};
  }
};

std::string SensorId(std::size_t s) {
  char id[32];
  std::snprintf(id, sizeof(id), "site-%03zu", s);
  return id;
}

std::vector<Encoded> Encode(std::size_t sensors, std::size_t per_sensor, UtcNs t0_ns,
                            DurationNs period_ns) {
  std::vector<Encoded> out(sensors);
  auto encode = [&](std::size_t first, std::size_t step) {
    for (std::size_t s = first; s < sensors; s += step) {
      SensorStream stream(SensorId(s), 7000 + s, t0_ns, period_ns);
      out[s].bytes.reserve(per_sensor * 500);
      out[s].ends.reserve(per_sensor);
      out[s].sent_ns.reserve(per_sensor);
      for (std::size_t i = 0; i < per_sensor; ++i) stream.Next(out[s]);
    }
  };
  // Both cores: encoding is set-up, not measured.
  std::thread helper(encode, 1, 2);
  encode(0, 2);
  helper.join();
  return out;
}

// ---------------------------------------------------------------------------------------------
// The daemon side: lrfnetd's io thread.

class FileRecorder final : public daemon::RecordSink {
 public:
  explicit FileRecorder(const daemon::RecordingWriterOptions& options) : writer_(options) {}
  daemon::RecordingWriter& writer() { return writer_; }
  void Record(std::span<const std::uint8_t> datagram, std::string_view source,
              UtcNs receive_ns) override {
    writer_.Append(datagram, source, receive_ns);
  }
  void FlushIfDue(UtcNs now_ns) override { writer_.FlushIfDue(now_ns); }

 private:
  daemon::RecordingWriter writer_;
};

class Replies final : public daemon::RequestSink {
 public:
  explicit Replies(daemon::UdpReceiver& receiver) : receiver_(receiver) {}
  bool SendTo(std::string_view source, std::span<const std::uint8_t> datagram) override {
    return receiver_.SendTo(source, datagram);
  }

 private:
  daemon::UdpReceiver& receiver_;
};

void RemoveRecording(const std::string& path) {
  std::error_code ec;
  std::filesystem::remove(path, ec);
  for (int i = 1; i < 1000; ++i) {
    if (!std::filesystem::remove(path + "." + std::to_string(i), ec)) break;
  }
}

std::string TempPath(const char* name) {
  return (std::filesystem::temp_directory_path() /
          (std::string("daemon_benchmark_") + std::to_string(::getpid()) + "_" + name))
      .string();
}

struct SensorResult {
  std::uint64_t received = 0;  // SequenceCounters::received
  std::uint64_t lost = 0;
};

struct ReceiverResult {
  bool ok = false;
  std::string error;
  int granted_buffer_bytes = 0;
  daemon::UdpReceiverCounters udp;
  daemon::IngestCounters ingest;
  std::uint64_t frames_added = 0;
  std::uint64_t recorded_bytes = 0;
  std::uint64_t recorded_entries = 0;
  std::int64_t cpu_ns = 0;
  Clock::time_point last_handled;
  std::vector<SensorResult> sensors;  // by sensor index
};

// Runs the daemon's io loop on CPU 0 until `senders_done` and every offered datagram was received
// or dropped by the kernel (or nothing arrived for 300 ms).
class ReceiverThread {
 public:
  ReceiverThread(std::size_t sensors, bool record, daemon::DaemonOptions options)
      : sensors_(sensors), record_(record), options_(std::move(options)) {
    thread_ = std::thread([this] { Run(); });
  }
  // The bound port (0 when Open failed).
  std::uint16_t WaitForPort() { return port_.get_future().get(); }
  void SendersDone(std::uint64_t offered) {
    offered_.store(offered);
    senders_done_.store(true);
  }
  ReceiverResult Join() {
    thread_.join();
    return std::move(result_);
  }

 private:
  void Run() {
    if (!PinToCpu(0)) result_.error = "sched_setaffinity(CPU 0) failed; ";
    asio::io_context io;
    std::optional<FileRecorder> recorder;
    const std::string path = TempPath("throughput.rec");
    if (record_) {
      daemon::RecordingWriterOptions w;
      w.path = path;
      w.writer = "daemon_benchmark";
      recorder.emplace(w);
      if (auto e = recorder->writer().Open(RealtimeNs())) {
        result_.error += *e;
        port_.set_value(0);
        return;
      }
    }
    daemon::Daemon* core = nullptr;
    std::uint64_t handled = 0;
    daemon::UdpReceiverOptions ro;
    ro.address = "127.0.0.1";
    ro.port = 0;
    daemon::UdpReceiver receiver(
        io, ro, [&](std::span<const std::uint8_t> bytes, const std::string& source, UtcNs t) {
          core->OnDatagram(bytes, source, t);
          // A clock read per 256 datagrams (and at the last one) keeps its cost out of the
          // measurement.
          if ((++handled & 255) == 0 || handled >= offered_.load(std::memory_order_relaxed))
            result_.last_handled = Clock::now();
        });
    Replies replies(receiver);
    daemon::Daemon daemon(options_, recorder ? &*recorder : nullptr, &replies, 99);
    core = &daemon;
    if (auto e = receiver.Open()) {
      result_.error += *e;
      port_.set_value(0);
      return;
    }
    result_.granted_buffer_bytes = receiver.receive_buffer_bytes();

    // lrfnetd's tick (silence, eviction, recording flush, requests) every 250 ms.
    asio::steady_timer tick(io);
    std::function<void()> schedule_tick = [&] {
      tick.expires_after(std::chrono::milliseconds(250));
      tick.async_wait([&](const boost::system::error_code& ec) {
        if (ec) return;
        daemon.OnTick(RealtimeNs());
        schedule_tick();
      });
    };
    schedule_tick();
    // The end of the run (not part of lrfnetd).
    asio::steady_timer poll(io);
    std::uint64_t last_seen = 0;
    int idle_polls = 0;
    std::function<void()> schedule_poll = [&] {
      poll.expires_after(std::chrono::milliseconds(10));
      poll.async_wait([&](const boost::system::error_code& ec) {
        if (ec) return;
        const daemon::UdpReceiverCounters& c = receiver.counters();
        if (senders_done_.load()) {
          idle_polls = c.datagrams == last_seen ? idle_polls + 1 : 0;
          if (c.datagrams + c.kernel_drops >= offered_.load() || idle_polls >= 30) {
            io.stop();
            return;
          }
        }
        last_seen = c.datagrams;
        schedule_poll();
      });
    };
    schedule_poll();

    port_.set_value(receiver.local_port());
    const std::int64_t cpu0 = ThreadCpuNs();
    io.run();
    result_.cpu_ns = ThreadCpuNs() - cpu0;

    daemon.OnTick(RealtimeNs());
    result_.udp = receiver.counters();
    result_.ingest = daemon.ingest().counters();
    result_.frames_added = daemon.store().counters().frames_added;
    result_.sensors.resize(sensors_);
    for (std::size_t s = 0; s < sensors_; ++s) {
      if (auto status = daemon.ingest().Sensor(SensorId(s))) {
        result_.sensors[s] = {status->counters.sequence.received, status->counters.sequence.lost};
      }
    }
    receiver.Close();
    if (recorder) {
      if (auto e = recorder->writer().Close()) result_.error += *e;
      result_.recorded_bytes = recorder->writer().counters().bytes_written;
      result_.recorded_entries = recorder->writer().counters().entries_written;
      RemoveRecording(path);
    }
    result_.ok = true;
  }

  std::size_t sensors_;
  bool record_;
  daemon::DaemonOptions options_;
  std::promise<std::uint16_t> port_;
  std::atomic<bool> senders_done_{false};
  std::atomic<std::uint64_t> offered_{~std::uint64_t{0}};  // known when the senders are done
  ReceiverResult result_;
  std::thread thread_;
};

// One UDP socket per sensor, connected to the daemon (as a tracker's uplink is).
class Senders {
 public:
  Senders(std::size_t sensors, std::uint16_t port) {
    sockaddr_in to{};
    to.sin_family = AF_INET;
    to.sin_port = htons(port);
    to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    for (std::size_t s = 0; s < sensors; ++s) {
      const int fd = ::socket(AF_INET, SOCK_DGRAM, 0);
      if (fd < 0 || ::connect(fd, reinterpret_cast<const sockaddr*>(&to), sizeof(to)) != 0) {
        if (fd >= 0) ::close(fd);
        break;
      }
      fds_.push_back(fd);
    }
  }
  ~Senders() {
    for (int fd : fds_) ::close(fd);
  }
  Senders(const Senders&) = delete;
  Senders& operator=(const Senders&) = delete;
  bool ok(std::size_t sensors) const { return fds_.size() == sensors; }
  bool Send(std::size_t s, std::span<const std::uint8_t> d) {
    return ::send(fds_[s], d.data(), d.size(), 0) == static_cast<ssize_t>(d.size());
  }

 private:
  std::vector<int> fds_;
};

struct SendResult {
  std::uint64_t offered = 0;
  std::uint64_t send_errors = 0;
  std::vector<std::uint64_t> per_sensor;
  double seconds = 0.0;
  Clock::time_point start;
  bool pinned = true;
};

// rate_per_s == 0: as fast as possible for `seconds`; else datagram i (round-robin over the
// sensors) is due at start + i / rate, for `seconds`.
SendResult RunSenders(const std::vector<Encoded>& data, std::uint16_t port, double seconds,
                      double rate_per_s) {
  SendResult r;
  r.pinned = PinToCpu(1);
  const std::size_t n = data.size();
  Senders senders(n, port);
  r.per_sensor.assign(n, 0);
  if (!senders.ok(n)) return r;
  ::prctl(PR_SET_TIMERSLACK, 1UL, 0UL, 0UL, 0UL);  // paced: wake up on time, not 50 µs late
  std::size_t available = data[0].size();
  for (const Encoded& e : data) available = std::min(available, e.size());
  auto send_one = [&](std::uint64_t i) {
    const std::size_t s = static_cast<std::size_t>(i % n);
    const std::size_t k = static_cast<std::size_t>(i / n);
    if (senders.Send(s, data[s].At(k))) {
      ++r.per_sensor[s];
      ++r.offered;
    } else {
      ++r.send_errors;
    }
  };
  const std::uint64_t total_available = static_cast<std::uint64_t>(available) * n;
  r.start = Clock::now();
  const auto end =
      r.start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(seconds));
  std::uint64_t i = 0;
  if (rate_per_s <= 0.0) {
    while (i < total_available && Clock::now() < end) {
      for (std::size_t s = 0; s < n && i < total_available; ++s) send_one(i++);
    }
  } else {
    const auto total = std::min<std::uint64_t>(
        total_available, static_cast<std::uint64_t>(std::llround(rate_per_s * seconds)));
    const double ns_per_datagram = 1e9 / rate_per_s;
    // Due times from the start and the index: no drift, late sends catch up at once.
    auto due = [&](std::uint64_t k) {
      return r.start + std::chrono::nanoseconds(
                           static_cast<std::int64_t>(static_cast<double>(k) * ns_per_datagram));
    };
    while (i < total) {
      const auto now = Clock::now();
      while (i < total && due(i) <= now) send_one(i++);
      if (i < total) std::this_thread::sleep_until(due(i));
    }
  }
  r.seconds = Seconds(Clock::now() - r.start);
  return r;
}

// CPU time of the whole machine (all CPUs, not idle) and of this process, seconds.
struct CpuUse {
  double machine_s = 0.0;
  double process_s = 0.0;
};
CpuUse ReadCpuUse() {
  CpuUse u;
  std::ifstream stat("/proc/stat");
  std::string cpu;
  // user nice system idle iowait irq softirq steal
  std::uint64_t v[8] = {};
  stat >> cpu;
  for (auto& x : v) stat >> x;
  const double hz = static_cast<double>(::sysconf(_SC_CLK_TCK));
  u.machine_s = static_cast<double>(v[0] + v[1] + v[2] + v[5] + v[6] + v[7]) / hz;
  rusage r{};
  ::getrusage(RUSAGE_SELF, &r);
  auto tv = [](const timeval& t) {
    return static_cast<double>(t.tv_sec) + static_cast<double>(t.tv_usec) * 1e-6;
  };
  u.process_s = tv(r.ru_utime) + tv(r.ru_stime);
  return u;
}

struct LoopbackRow {
  std::size_t sensors = 0;
  bool record = false;
  double rate_per_s = 0.0;  // 0: as fast as possible
  SendResult sent;
  ReceiverResult received;
  double wall_s = 0.0;  // first send to last datagram handled
  // CPU time used by everything but this process while the row ran (other programs, the kernel's
  // own threads), as a share of one CPU.
  double others_cpu = 0.0;
};

LoopbackRow RunLoopback(const std::vector<Encoded>& data, bool record, double seconds,
                        double rate_per_s) {
  LoopbackRow row;
  row.sensors = data.size();
  row.record = record;
  row.rate_per_s = rate_per_s;
  daemon::DaemonOptions options;  // lrfnetd's defaults
  const CpuUse before = ReadCpuUse();
  const auto t_begin = Clock::now();
  ReceiverThread receiver(data.size(), record, options);
  const std::uint16_t port = receiver.WaitForPort();
  if (port != 0) {
    std::thread sender([&] { row.sent = RunSenders(data, port, seconds, rate_per_s); });
    sender.join();
  }
  receiver.SendersDone(row.sent.offered);
  row.received = receiver.Join();
  row.wall_s = Seconds(row.received.last_handled - row.sent.start);
  const CpuUse after = ReadCpuUse();
  const double others_s =
      (after.machine_s - before.machine_s) - (after.process_s - before.process_s);
  row.others_cpu = std::max(0.0, others_s) / Seconds(Clock::now() - t_begin);
  return row;
}

// ---------------------------------------------------------------------------------------------
// 3. Memory per sensor-hour: Daemon::OnDatagram directly.

struct MemoryResult {
  std::uint64_t datagrams = 0;
  std::uint64_t accepted = 0;
  std::size_t frames = 0;
  std::size_t store_bytes = 0;
  std::size_t rss_growth = 0;
  std::uint64_t recording_bytes = 0;
  double cpu_s = 0.0;
  std::string error;
};

MemoryResult RunMemory(double hours) {
  MemoryResult m;
  daemon::DaemonOptions options;
  options.store.max_age_s = 2.0 * hours * 3600.0 + 3600.0;
  options.store.max_bytes = std::size_t{1} << 40;  // keep everything: the memory of the full hour
  const std::string path = TempPath("memory.rec");
  daemon::RecordingWriterOptions w;
  w.path = path;
  w.writer = "daemon_benchmark";
  w.max_file_bytes = 0;
  FileRecorder recorder(w);
  const UtcNs t0 = 1'700'000'000LL * kNsPerS;
  if (auto e = recorder.writer().Open(t0)) {
    m.error = *e;
    return m;
  }
  // Encoded a simulated minute at a time, outside the CPU time; the chunk's memory is in use before
  // the RSS is first read and reused after.
  SensorStream stream("site-000", 4242, t0, kScanPeriodNs);
  const auto scans = static_cast<std::uint64_t>(hours * 3600.0 * 50.0);
  // Datagrams until `scans` frames: one SensorInfo, and one Health per 50 frames.
  const std::uint64_t datagrams = 1 + scans + scans / kFramesPerHealth;
  constexpr std::uint64_t kChunk = 60 * 51;
  Encoded chunk;
  chunk.bytes.reserve(kChunk * io::kMaxDatagramBytes);
  chunk.ends.reserve(kChunk);
  chunk.sent_ns.reserve(kChunk);
  std::uint64_t encoded = 0;
  auto encode_chunk = [&] {
    chunk.Clear();
    for (; chunk.size() < kChunk && encoded < datagrams; ++encoded) stream.Next(chunk);
  };
  encode_chunk();
  const std::size_t rss_before = RssBytes();
  {
    daemon::Daemon core(options, &recorder, nullptr, 99);
    UtcNs last_tick_ns = 0;
    std::int64_t cpu_ns = 0;
    while (chunk.size() > 0) {
      const std::int64_t cpu0 = ThreadCpuNs();
      for (std::size_t i = 0; i < chunk.size(); ++i) {
        const UtcNs receive_ns = chunk.sent_ns[i] + 2 * kNsPerMs;
        core.OnDatagram(chunk.At(i), "10.20.0.17:40123", receive_ns);
        if (receive_ns - last_tick_ns >= 250 * kNsPerMs) {
          core.OnTick(receive_ns);
          last_tick_ns = receive_ns;
        }
      }
      cpu_ns += ThreadCpuNs() - cpu0;
      encode_chunk();
    }
    m.cpu_s = static_cast<double>(cpu_ns) * 1e-9;
    const std::size_t rss_after = RssBytes();
    m.rss_growth = rss_after - std::min(rss_after, rss_before);
    m.datagrams = core.ingest().counters().datagrams;
    m.accepted = core.ingest().counters().accepted;
    m.frames = core.store().frames();
    m.store_bytes = core.store().bytes_used();
  }
  if (auto e = recorder.writer().Close()) m.error = *e;
  std::error_code ec;
  m.recording_bytes = std::filesystem::file_size(path, ec);
  if (ec) m.error += " cannot stat the recording: " + ec.message();
  RemoveRecording(path);
  return m;
}

// ---------------------------------------------------------------------------------------------

double AverageBytes(const std::vector<Encoded>& data) {
  std::uint64_t bytes = 0, n = 0;
  for (const Encoded& e : data) {
    bytes += e.bytes.size();
    n += e.size();
  }
  return n > 0 ? static_cast<double>(bytes) / static_cast<double>(n) : 0.0;
}

double BatchSize(const daemon::UdpReceiverCounters& c) {
  return c.batches > 0 ? static_cast<double>(c.datagrams) / static_cast<double>(c.batches) : 0.0;
}

std::string Number(double v) {
  char text[64];
  std::snprintf(text, sizeof(text), "%.0f", std::abs(v));
  const std::string digits = text;
  std::string s = v < 0 ? "-" : "";
  for (std::size_t i = 0; i < digits.size(); ++i) {
    if (i > 0 && (digits.size() - i) % 3 == 0) s += ',';
    s += digits[i];
  }
  return s;
}
std::string Number(std::uint64_t v) { return Number(static_cast<double>(v)); }

std::string Format(const char* format, ...) __attribute__((format(printf, 1, 2)));
std::string Format(const char* format, ...) {
  char text[2048];
  va_list args;
  va_start(args, format);
  std::vsnprintf(text, sizeof(text), format, args);
  va_end(args);
  return text;
}

}  // namespace
}  // namespace lrfnet::bench

int main(int argc, char** argv) {
  using namespace lrfnet::bench;
  std::string out = "results/daemon_benchmark.md";
  double seconds = 3.0;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--out" && i + 1 < argc) {
      out = argv[++i];
    } else if (a == "--seconds" && i + 1 < argc) {
      seconds = std::atof(argv[++i]);
    } else {
      std::fprintf(stderr, "usage: daemon_benchmark [--out FILE] [--seconds S]\n");
      return 2;
    }
  }
  if (!(seconds > 0.0 && seconds <= 60.0)) {
    std::fprintf(stderr, "daemon_benchmark: --seconds must be in (0, 60]\n");
    return 2;
  }
  const long cpus = ::sysconf(_SC_NPROCESSORS_ONLN);
  const std::string load_at_start = LoadAverage();
  const auto t_begin = Clock::now();

  // 3 first: the memory measure needs a heap that earlier runs have not grown.
  std::fprintf(stderr, "memory per sensor-hour...\n");
  const MemoryResult memory = RunMemory(1.0);
  if (!memory.error.empty()) std::fprintf(stderr, "memory: %s\n", memory.error.c_str());

  // 1. Throughput. Stamps lie in the past (like a replay of a capture) so that no datagram is
  // ahead of the daemon's clock by more than the validation allows, however many are sent.
  std::vector<LoopbackRow> throughput;
  double bytes_per_datagram = 0.0;
  for (const std::size_t sensors : {std::size_t{10}, std::size_t{100}}) {
    // Enough for 400,000 datagrams/s for the whole run (twice what this path reached on the
    // 2-core machine of the results file); a faster sender stops earlier (noted in the report).
    const auto per_sensor =
        static_cast<std::size_t>(400'000.0 * seconds / static_cast<double>(sensors)) + 1;
    const UtcNs t0 = RealtimeNs() - static_cast<DurationNs>(per_sensor + 100) * kScanPeriodNs;
    std::fprintf(stderr, "encoding %zu x %zu datagrams...", sensors, per_sensor);
    const auto t_encode = Clock::now();
    const std::vector<Encoded> data = Encode(sensors, per_sensor, t0, kScanPeriodNs);
    std::fprintf(stderr, " %.1f s\n", Seconds(Clock::now() - t_encode));
    bytes_per_datagram = AverageBytes(data);
    for (const bool record : {false, true}) {
      std::fprintf(stderr, "throughput: %zu sensors%s...\n", sensors, record ? ", recording" : "");
      throughput.push_back(RunLoopback(data, record, seconds, 0.0));
    }
  }

  // 2. Fixed offered loads: 100 sensors, stamps on the send schedule (a live site).
  std::vector<LoopbackRow> paced;
  const double paced_s = seconds + 1.0;
  for (const double rate : {5'000.0, 20'000.0, 50'000.0, 100'000.0}) {
    const std::size_t sensors = 100;
    const auto per_sensor =
        static_cast<std::size_t>(rate * paced_s / static_cast<double>(sensors)) + 2;
    const auto period_ns = static_cast<DurationNs>(1e9 * static_cast<double>(sensors) / rate);
    const std::vector<Encoded> data =
        Encode(sensors, per_sensor, RealtimeNs() + 50 * kNsPerMs, period_ns);
    std::fprintf(stderr, "offered load %.0f/s...\n", rate);
    paced.push_back(RunLoopback(data, false, paced_s, rate));
  }
  const double total_s = Seconds(Clock::now() - t_begin);
  const std::string load_at_end = LoadAverage();

  // ---- report
  std::string md;
  md += "# lrfnetd: datagrams received, decoded and stored (daemon_benchmark)\n\n";
  md += Format(
      "Machine: %ld CPUs (%s); load average (1, 5, 15 min) %s at the start, %s at the "
      "end; receive buffer granted %d KiB. Whole run %.0f s.\n\n",
      cpus, CpuModel().c_str(), load_at_start.c_str(), load_at_end.c_str(),
      throughput.empty() ? 0 : throughput[0].received.granted_buffer_bytes / 1024, total_s);
  md += Format(
      "Datagrams from the tracker's encoder (nanopb): per sensor a SensorInfo, then one track "
      "frame of %zu tracks per scan (%.0f bytes on average with the health) and a Health after "
      "every %u frames. The daemon side is lrfnetd's io loop: UdpReceiver (recvmmsg batches of 64, "
      "16 MiB buffer) -> Daemon::OnDatagram (record, decode, validate, sequence, store) with "
      "lrfnetd's default options and its 250 ms tick, in one thread pinned to CPU 0. The senders "
      "run in one thread pinned to CPU 1, one connected UDP socket per sensor, round-robin. "
      "Receiver CPU is CLOCK_THREAD_CPUTIME_ID of the daemon thread over the run.\n\n",
      kTracks, bytes_per_datagram, kFramesPerHealth);

  md += Format(
      "## 1. Throughput on one core over loopback\n\n"
      "Senders as fast as they can for %.0f s over pre-encoded datagrams (consecutive sequence "
      "numbers; stamps in the past, as in a replay). On loopback the kernel's UDP delivery (the "
      "receive side's softirq work) runs on the sender's core, so with both threads saturated on "
      "2 cores this is the ceiling of the machine, not of the daemon alone. *Receiver busy* is "
      "the receiver thread's CPU time over the wall time: below 100 %% the senders' core was the "
      "limit, the receiver often waited and took small batches (*datagrams per recvmmsg*), so its "
      "cost per datagram includes wakeups that a saturated receiver does not pay. *Datagrams per "
      "CPU-second* is accepted datagrams per second of receiver CPU time (recvmmsg + the "
      "daemon).\n\n",
      seconds);
  md +=
      "| sensors | recording | offered | received | accepted | stored frames | kernel drops | "
      "accepted/s (wall) | receiver busy | datagrams per recvmmsg | receiver CPU per datagram | "
      "datagrams per CPU-second |\n"
      "|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";
  for (const LoopbackRow& r : throughput) {
    const ReceiverResult& x = r.received;
    const double cpu_s = static_cast<double>(x.cpu_ns) * 1e-9;
    const auto accepted = static_cast<double>(x.ingest.accepted);
    md += Format(
        "| %zu | %s | %s | %s | %s | %s | %s | %s | %.0f %% | %.1f | %.2f µs | %s |\n", r.sensors,
        r.record ? Format("yes (%.0f MB)", static_cast<double>(x.recorded_bytes) / 1e6).c_str()
                 : "no",
        Number(r.sent.offered).c_str(), Number(x.udp.datagrams).c_str(),
        Number(x.ingest.accepted).c_str(), Number(x.frames_added).c_str(),
        Number(x.udp.kernel_drops).c_str(),
        Number(r.wall_s > 0 ? accepted / r.wall_s : 0.0).c_str(),
        r.wall_s > 0 ? 100.0 * cpu_s / r.wall_s : 0.0, BatchSize(x.udp),
        accepted > 0 ? cpu_s * 1e6 / accepted : 0.0,
        Number(cpu_s > 0 ? accepted / cpu_s : 0.0).c_str());
  }

  md += Format(
      "\n## 2. Application-level loss at fixed offered loads\n\n"
      "100 sensors, senders paced on a steady-clock schedule (datagram i due at start + i / rate, "
      "no drift) for %.0f s; stamps follow the schedule. *Lost* is the sum of the daemon's "
      "SequenceCounters.lost over the sensors plus the datagrams never seen at the end (sent minus "
      "received minus lost, per sensor: the last ones of a stream are not yet declared lost).\n\n",
      paced_s);
  md +=
      "| offered load | per sensor | offered | accepted | lost (sequence) | never seen | loss | "
      "kernel drops | receiver busy | datagrams per recvmmsg | receiver CPU per datagram |\n"
      "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";
  for (const LoopbackRow& r : paced) {
    const ReceiverResult& x = r.received;
    std::uint64_t lost = 0, unseen = 0;
    for (std::size_t s = 0; s < r.sensors && s < x.sensors.size(); ++s) {
      const SensorResult& q = x.sensors[s];
      lost += q.lost;
      const std::uint64_t seen = q.received + q.lost;
      unseen += r.sent.per_sensor[s] > seen ? r.sent.per_sensor[s] - seen : 0;
    }
    const double offered = static_cast<double>(r.sent.offered);
    const double cpu_s = static_cast<double>(x.cpu_ns) * 1e-9;
    md += Format(
        "| %s/s (%s/s achieved) | %.0f Hz | %s | %s | %s | %s | %.3f %% | %s | %.0f %% | "
        "%.1f | %.2f µs |\n",
        Number(r.rate_per_s).c_str(),
        Number(r.sent.seconds > 0 ? offered / r.sent.seconds : 0.0).c_str(),
        r.rate_per_s / static_cast<double>(r.sensors), Number(r.sent.offered).c_str(),
        Number(x.ingest.accepted).c_str(), Number(lost).c_str(), Number(unseen).c_str(),
        offered > 0 ? 100.0 * static_cast<double>(lost + unseen) / offered : 0.0,
        Number(x.udp.kernel_drops).c_str(), r.wall_s > 0 ? 100.0 * cpu_s / r.wall_s : 0.0,
        BatchSize(x.udp),
        x.ingest.accepted > 0 ? cpu_s * 1e6 / static_cast<double>(x.ingest.accepted) : 0.0);
  }

  const double mb = 1e6;
  md += Format(
      "\n## 3. Memory per sensor-hour\n\n"
      "One sensor, one simulated hour at 50 Hz (%s datagrams: frames of %zu tracks, a Health per "
      "second, a SensorInfo) through Daemon::OnDatagram directly (no sockets, receive times 2 ms "
      "after the stamps, OnTick every 250 ms), store limits raised so nothing is evicted, recorded "
      "with RecordingWriter to a temporary file (deleted after).\n\n"
      "| measure | value |\n|---|---:|\n"
      "| datagrams accepted / frames stored | %s / %s |\n"
      "| track store, bytes_used() | %.1f MB |\n"
      "| process RSS growth (store + ingest state + 1 MiB recording buffer) | %.1f MB |\n"
      "| recording | %.1f MB |\n"
      "| Daemon::OnDatagram with recording, no sockets | %s datagrams per CPU-second |\n",
      Number(memory.datagrams).c_str(), kTracks, Number(memory.accepted).c_str(),
      Number(static_cast<std::uint64_t>(memory.frames)).c_str(),
      static_cast<double>(memory.store_bytes) / mb, static_cast<double>(memory.rss_growth) / mb,
      static_cast<double>(memory.recording_bytes) / mb,
      Number(memory.cpu_s > 0 ? static_cast<double>(memory.datagrams) / memory.cpu_s : 0.0)
          .c_str());

  std::string notes;
  for (const auto* rows : {&throughput, &paced}) {
    for (const LoopbackRow& r : *rows) {
      if (!r.received.ok || !r.received.error.empty())
        notes += "- a run reported: " + r.received.error + "\n";
      if (!r.sent.pinned) notes += "- the senders could not be pinned to CPU 1\n";
      if (r.rate_per_s <= 0.0 && r.sent.seconds < 0.95 * seconds)
        notes += Format(
            "- %zu sensors%s: the senders used up the pre-encoded datagrams after "
            "%.2f s\n",
            r.sensors, r.record ? " with recording" : "", r.sent.seconds);
      if (r.others_cpu > 0.05)
        notes +=
            Format("- %zu sensors, %s: other programs used %.0f %% of a CPU meanwhile\n", r.sensors,
                   r.rate_per_s > 0.0 ? Format("%.0f/s", r.rate_per_s).c_str()
                   : r.record         ? "as fast as possible, recording"
                                      : "as fast as possible",
                   100.0 * r.others_cpu);
      if (r.sent.send_errors > 0)
        notes += "- " + Number(r.sent.send_errors) + " send errors in one run\n";
    }
  }
  if (!memory.error.empty()) notes += "- memory run: " + memory.error + "\n";
  if (!notes.empty()) md += "\n## Notes\n\n" + notes;

  std::fputs(md.c_str(), stdout);
  const auto parent = std::filesystem::path(out).parent_path();
  if (!parent.empty()) std::filesystem::create_directories(parent);
  std::ofstream(out) << md;
  std::printf("\nwritten to %s\n", out.c_str());
  return 0;
}
