// recording_fuzz seeds: small recordings written by the daemon's and the tracker's writers, whole
// and damaged (cut in the header, in a length prefix and in an entry, an oversize length, a header
// missing or repeated, an unknown format version), and small UDP captures (pcap, pcapng, torn).

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "central_daemon/io/recording_decoder.h"
#include "central_daemon/io/recording_writer.h"
#include "central_daemon/io/udp_capture_test_util.h"
#include "firmware_tracker/io/recording_writer.h"
#include "tests/fuzz/daemon_seeds.h"

namespace lrfnet::fuzz {
namespace {

using Bytes = std::vector<std::uint8_t>;

constexpr common::UtcNs kT0 = 1'700'000'000'000'000'000;

Bytes ReadAll(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), {}};
}

void Write(const std::filesystem::path& path, const Bytes& bytes) {
  std::ofstream(path, std::ios::binary | std::ios::trunc)
      .write(reinterpret_cast<const char*>(bytes.data()),
             static_cast<std::streamsize>(bytes.size()));
}

Bytes Datagram(std::size_t size, std::uint8_t seed) {
  Bytes d(size);
  for (std::size_t i = 0; i < size; ++i) d[i] = static_cast<std::uint8_t>(seed + i * 13);
  return d;
}

// Entry end offsets of a recording (header first).
std::vector<std::size_t> EntryEnds(const Bytes& bytes) {
  std::vector<std::size_t> ends;
  daemon::RecordingDecoder decoder;
  std::span<const std::uint8_t> rest(bytes);
  std::size_t consumed = 0;
  while (decoder.Feed(rest, &consumed) == daemon::RecordingDecodeStatus::kEntry) {
    rest = rest.subspan(consumed);
    ends.push_back(static_cast<std::size_t>(decoder.offset()));
  }
  return ends;
}

Bytes Cut(const Bytes& bytes, std::size_t n) {
  return Bytes(bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(n));
}

}  // namespace

void WriteRecordingSeeds(const std::string& dir_name) {
  const std::filesystem::path dir = dir_name;
  std::filesystem::create_directories(dir);

  const std::filesystem::path whole_path = dir / "daemon_whole.rec";
  {
    daemon::RecordingWriterOptions options;
    options.path = whole_path.string();
    options.writer = "lrfnetd seeds";
    daemon::RecordingWriter writer(options);
    if (writer.Open(kT0)) return;
    const char* const sources[] = {"192.168.1.10:40000", "[fe80::1]:40001", "tracker:gate-3"};
    const std::size_t sizes[] = {0, 1, 60, 300, 1400};
    for (std::size_t i = 0; i < 5; ++i) {
      writer.Append(Datagram(sizes[i], static_cast<std::uint8_t>(i)), sources[i % 3],
                    kT0 + static_cast<common::UtcNs>(i) * 40'000'000);
    }
    writer.Close();
  }
  const Bytes whole = ReadAll(whole_path);
  const std::vector<std::size_t> ends = EntryEnds(whole);
  if (ends.size() != 6) return;

  {
    daemon::RecordingWriterOptions options;
    options.path = (dir / "daemon_header_only.rec").string();
    daemon::RecordingWriter writer(options);
    writer.Open(kT0);
  }
  {
    io::RecordingWriterOptions options;
    options.path = (dir / "tracker.rec").string();
    options.source = io::TrackerRecordSource("gate-3");
    io::RecordingWriter writer(options);
    if (!writer.Open(kT0)) {
      for (std::uint8_t i = 0; i < 3; ++i) writer.Append(Datagram(100u * i, i), kT0 + i);
    }
  }

  Write(dir / "cut_in_header.rec", Cut(whole, ends[0] / 2));
  Write(dir / "cut_in_prefix.rec", Cut(whole, ends[4] + 1));  // the last entry needs 2 bytes
  Write(dir / "cut_in_entry.rec", Cut(whole, ends[4] + 100));
  Bytes oversize = Cut(whole, ends[2]);
  for (const int b : {0x81, 0x80, 0x04}) oversize.push_back(static_cast<std::uint8_t>(b));  // 65537
  oversize.insert(oversize.end(), whole.begin() + static_cast<std::ptrdiff_t>(ends[2]) + 1,
                  whole.end());
  Write(dir / "oversize_length.rec", oversize);
  Bytes twice = whole;
  twice.insert(twice.end(), whole.begin(), whole.end());
  Write(dir / "second_header.rec", twice);
  Write(dir / "no_header.rec",
        Bytes(whole.begin() + static_cast<std::ptrdiff_t>(ends[0]), whole.end()));
  Write(dir / "format_version_2.rec", {0x04, 0x22, 0x02, 0x08, 0x02});
  Bytes flipped = whole;
  flipped[ends[0] + 1] ^= 0x07;  // the first datagram entry's first tag: wire type 7
  Write(dir / "flipped_tag.rec", flipped);

  using namespace daemon::test_util;
  const std::array<std::uint8_t, 4> a = {192, 168, 1, 10};
  const std::array<std::uint8_t, 4> b = {192, 168, 1, 2};
  const std::array<std::uint8_t, 16> c = {0xfe, 0x80, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1};
  const std::array<std::uint8_t, 16> d = {0xfe, 0x80, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 2};
  const Bytes payload = Datagram(40, 7);
  PcapFile pcap(capture::kLinkTypeEthernet);
  pcap.Add(kT0, Ethernet(Ipv4Udp(a, 40000, b, 2222, payload)))
      .Add(kT0 + 1000, Ethernet(Ipv6Udp(c, 40001, d, 2222, payload)))
      .Add(kT0 + 2000, Ethernet(Ipv4Udp(a, 40000, b, 3333, {})));
  Write(dir / "udp_ethernet.pcap", pcap.bytes());
  Write(dir / "udp_torn.pcap", Cut(pcap.bytes(), pcap.bytes().size() - 5));
  PcapFile raw(capture::kLinkTypeRaw, /*nanosecond=*/true);
  raw.Add(kT0 + 1, Ipv4Udp(a, 1, b, 2222, payload)).Add(kT0 + 2, Ipv6Udp(c, 2, d, 2222, payload));
  Write(dir / "udp_raw_ns.pcap", raw.bytes());
  PcapngFile pcapng(capture::kLinkTypeEthernet);
  pcapng.Add(kT0 + 3, Ethernet(Ipv4Udp(a, 40000, b, 2222, payload)));
  Write(dir / "udp.pcapng", pcapng.bytes());
}

}  // namespace lrfnet::fuzz
