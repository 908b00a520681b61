// The cost of authenticated datagrams per datagram: the tracker's encoder alone (unsealed), with
// sealing (ChaCha20-Poly1305 tag over the datagram) and with encryption, for a typical track frame
// (5 tracks) and the largest datagram (a background part of 398 beams); and, where the daemon is
// built, its verification (envelope checks, window, tag, decryption). Thread CPU time, median of
// 7 runs of N datagrams each. Writes a Markdown table (--out FILE, --append to add a platform's
// section, --platform NAME for its title). Under qemu-user absolute times mean little: the ratio to
// the unsealed path is the figure to read there.
//
//   auth_benchmark --out results/auth_benchmark.md --platform "x86-64"
//   qemu-aarch64 -L /usr/aarch64-linux-gnu auth_benchmark --append --platform "aarch64 (qemu)"

#include <time.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <functional>
#include <string>
#include <vector>

#include "common/datagram_auth.h"
#include "firmware_tracker/io/datagram_encoder.h"
#include "firmware_tracker/io/sealing_sink.h"
#if defined(LRFNET_BENCH_DAEMON)
#include "central_daemon/ingest/datagram_verifier.h"
#endif

namespace {

using namespace lrfnet;

struct NullSink final : io::DatagramSink {
  std::size_t bytes = 0;
  void Send(std::span<const std::uint8_t> d, common::UtcNs) override { bytes += d.size(); }
};

struct Collect final : io::DatagramSink {
  std::vector<std::vector<std::uint8_t>> got;
  void Send(std::span<const std::uint8_t> d, common::UtcNs) override {
    got.emplace_back(d.begin(), d.end());
  }
};

constexpr char kId[] = "hall-north.lms511";

auth::SensorKeys Keys() {
  auth::Key site{};
  site.fill(9);
  return auth::DeriveSensorKeys(auth::DeriveSensorKey(site, kId), 1);
}

auth::SealerOptions Sealing(bool encrypt) {
  auth::SealerOptions o;
  o.sensor_id = kId;
  o.keys = Keys();
  o.encrypt = encrypt;
  o.salt = 5;
  o.first_counter = 1'700'000'000'000'000'000ULL;
  return o;
}

// This thread's CPU time in ns: a loaded machine (other processes on the same cores) stretches
// the wall clock, not the CPU time a datagram needs.
double ThreadCpuNs() {
  timespec ts{};
  ::clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) * 1e9 + static_cast<double>(ts.tv_nsec);
}

// CPU ns per call of `f` (which handles one datagram): median of 7 runs of n calls.
double NsPerDatagram(std::size_t n, const std::function<void()>& f) {
  std::vector<double> runs;
  for (int r = 0; r < 7; ++r) {
    const double start = ThreadCpuNs();
    for (std::size_t i = 0; i < n; ++i) f();
    runs.push_back((ThreadCpuNs() - start) / static_cast<double>(n));
  }
  std::sort(runs.begin(), runs.end());
  return runs[runs.size() / 2];
}

tracking::ScanTracks Frame(std::size_t tracks) {
  tracking::ScanTracks scan;
  scan.scan_start_ns = 1'700'000'000'000'000'000;
  scan.scan_period_s = 0.04;
  for (std::uint32_t i = 0; i < tracks; ++i) {
    tracking::TrackReport* t = scan.tracks.emplace_slot();
    t->track_id = i;
    t->state = tracking::TrackState::kConfirmed;
    t->x_m = 3.0 + i;
    t->y_m = -1.0 + 0.5 * i;
    t->vx_mps = 0.8;
    t->covariance = Eigen::Matrix4d::Identity() * 0.01;
    t->points = 12;
  }
  return scan;
}

struct Row {
  std::string what;
  std::size_t bytes = 0;
  double unsealed_ns = 0, signed_ns = 0, encrypted_ns = 0;
  double verify_signed_ns = -1, verify_encrypted_ns = -1;
};

std::string Fixed(double v, int digits) {
  char b[32];
  std::snprintf(b, sizeof b, "%.*f", digits, v);
  return b;
}

}  // namespace

int main(int argc, char** argv) {
  std::string out_path, platform = "this machine";
  bool append = false;
  std::size_t n = 20000;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--out" && i + 1 < argc) {
      out_path = argv[++i];
    } else if (a == "--platform" && i + 1 < argc) {
      platform = argv[++i];
    } else if (a == "--append") {
      append = true;
    } else if (a == "--datagrams" && i + 1 < argc) {
      n = static_cast<std::size_t>(std::stoul(argv[++i]));
    } else {
      std::fprintf(
          stderr,
          "usage: auth_benchmark [--out FILE] [--append] [--platform NAME] [--datagrams N]\n");
      return 2;
    }
  }
  if (!auth::Init()) return 1;

  std::vector<Row> rows;
  const std::vector<float> ranges(io::kBeamsPerPart, 7.5f);
  const tracking::ScanTracks frame = Frame(5);
  for (const bool background : {false, true}) {
    Row row;
    row.what = background ? "background part, 398 beams" : "track frame, 5 tracks";
    const auto encode = [&](io::DatagramEncoder& encoder, io::DatagramSink& sink) {
      if (background) {
        encoder.EncodeBackground({1, -1.0, 0.001, ranges}, 2, sink);
      } else {
        encoder.EncodeTracks(frame, 2, sink);
      }
    };
    {
      NullSink sink;
      io::DatagramEncoder encoder({kId, 1});
      row.unsealed_ns = NsPerDatagram(n, [&] { encode(encoder, sink); });
      Collect one;
      encode(encoder, one);
      row.bytes = one.got.at(0).size();
    }
    for (const bool encrypt : {false, true}) {
      NullSink sink;
      io::SealingSink sealing(Sealing(encrypt), sink);
      io::DatagramEncoder encoder({kId, 1});
      const double ns = NsPerDatagram(n, [&] { encode(encoder, sealing); });
      (encrypt ? row.encrypted_ns : row.signed_ns) = ns;
    }
#if defined(LRFNET_BENCH_DAEMON)
    for (const bool encrypt : {false, true}) {
      // n + 1 distinct sealed datagrams per run (a repeated one would be refused as replayed).
      Collect sealed_out;
      io::SealingSink sealing(Sealing(encrypt), sealed_out);
      io::DatagramEncoder encoder({kId, 1});
      for (std::size_t i = 0; i < 7 * n; ++i) encode(encoder, sealing);
      daemon::AuthOptions options;
      auth::KeyFile key;
      key.kind = auth::KeyFile::Kind::kSensor;
      key.sensor_id = kId;
      key.epoch = 1;
      auth::Key site{};
      site.fill(9);
      key.key = auth::DeriveSensorKey(site, kId);
      options.keys = {key};
      daemon::DatagramVerifier verifier(options);
      std::size_t next = 0, accepted = 0;
      const double ns = NsPerDatagram(n, [&] {
        const daemon::AuthResult r = verifier.Verify(sealed_out.got[next++], 0);
        if (r.ok()) {
          verifier.Commit(r);
          ++accepted;
        }
      });
      if (accepted != 7 * n) {
        std::fprintf(stderr, "auth_benchmark: %zu of %zu verified\n", accepted, 7 * n);
        return 1;
      }
      (encrypt ? row.verify_encrypted_ns : row.verify_signed_ns) = ns;
    }
#endif
    rows.push_back(row);
  }

  std::string table = "\n## " + platform + "\n\n";
  table +=
      "| datagram | bytes (unsealed) | encode, unsealed [ns] | encode + seal [ns] | ratio | "
      "encode + seal + encrypt [ns] | ratio | daemon: verify [ns] | verify + decrypt [ns] |\n"
      "|---|---:|---:|---:|---:|---:|---:|---:|---:|\n";
  for (const Row& r : rows) {
    table += "| " + r.what + " | " + std::to_string(r.bytes) + " (+" +
             std::to_string(auth::kFixedHeaderBytes + std::strlen(kId) + auth::kTagBytes) +
             " sealed) | " + Fixed(r.unsealed_ns, 0) + " | " + Fixed(r.signed_ns, 0) + " | " +
             Fixed(r.signed_ns / r.unsealed_ns, 2) + " | " + Fixed(r.encrypted_ns, 0) + " | " +
             Fixed(r.encrypted_ns / r.unsealed_ns, 2) + " | " +
             (r.verify_signed_ns >= 0 ? Fixed(r.verify_signed_ns, 0) : "–") + " | " +
             (r.verify_encrypted_ns >= 0 ? Fixed(r.verify_encrypted_ns, 0) : "–") + " |\n";
  }
  std::printf("%s", table.c_str());
  if (!out_path.empty()) {
    std::ofstream out(out_path, append ? std::ios::app : std::ios::trunc);
    if (!append) {
      out << "# Authenticated datagrams: cost per datagram\n\n"
             "`scripts/bench.sh` (tests/bench/auth_benchmark.cc): the tracker's encoder alone, "
             "with "
             "the envelope's tag (SealingSink: ChaCha20-Poly1305 over the whole datagram) and with "
             "the payload encrypted; the daemon's verification (DatagramVerifier: envelope checks, "
             "replay window, tag, decryption). Sensor id of 17 characters. Thread CPU time per "
             "datagram, "
             "median of 7 runs of "
          << n
          << " datagrams, one core. The aarch64 section runs under qemu-user on the same "
             "machine: read its ratios, not its times.\n";
    }
    out << table;
  }
  return 0;
}
