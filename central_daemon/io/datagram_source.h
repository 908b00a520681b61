#pragma once
// Files of received datagrams, read alike: daemon (or tracker) recordings (DESIGN.md "Recording":
// varint-delimited RecordEntry, the first carrying the header; a rotated recording REC, REC.1,
// REC.2, ... is read as one) and pcap/pcapng captures of the UDP stream (every UDP payload to the
// selected port, with the packet's capture time as receive time and "ip:port" of its sender as
// source). The kind is detected from the file's content, not its name.
//
// Damaged input is never fatal: a recording that ends in a torn entry, a length prefix above
// kMaxRecordEntryBytes or an entry that does not parse ends the stream with ReadStatus::kError and
// a one-line error() (entries before it were delivered); malformed packets of a capture are
// skipped and counted.
//
// Not thread-safe: one source per thread.

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "common/time.h"

namespace lrfnet::daemon {

inline constexpr std::size_t kMaxRecordEntryBytes = 64 * 1024;

struct ReceivedDatagram {
  common::UtcNs receive_ns = 0;
  std::string source;  // "ip:port", "[ipv6]:port", or "tracker:<id>" in a tracker's recording
  std::vector<std::uint8_t> bytes;
};

enum class DatagramFileKind : std::uint8_t { kRecording, kCapture };

struct DatagramSourceOptions {
  // Captures: UDP datagrams to this destination port; 0 = every UDP datagram.
  std::uint16_t udp_port = 0;
};

struct DatagramSourceCounters {
  std::uint64_t datagrams = 0;
  std::uint64_t files = 0;           // recording files opened (rotation parts)
  // Captures:
  std::uint64_t packets = 0;
  std::uint64_t malformed_packets = 0;
  std::uint64_t other_packets = 0;   // not UDP, or another port
};

enum class SourceStatus : std::uint8_t { kDatagram, kEnd, kError };

class DatagramSource {
 public:
  virtual ~DatagramSource() = default;
  // The next datagram in file order. After kEnd or kError every further call returns the same.
  virtual SourceStatus Next(ReceivedDatagram* datagram) = 0;
  virtual DatagramFileKind kind() const = 0;
  virtual const DatagramSourceCounters& counters() const = 0;
  // One line naming the file and what is wrong (after kError), else empty.
  virtual const std::string& error() const = 0;
  // Recordings: the header of the first file (format_version, created_ns, writer); 0/empty for
  // captures.
  virtual std::uint32_t format_version() const { return 0; }
  virtual common::UtcNs created_ns() const { return 0; }
  virtual const std::string& writer() const = 0;
};

// Opens `path` as a recording (with its rotation parts) or a pcap/pcapng capture. nullptr and a
// one-line *error when the file cannot be read or is neither.
std::unique_ptr<DatagramSource> OpenDatagramFile(const std::string& path,
                                                 const DatagramSourceOptions& options,
                                                 std::string* error);

// The files of a recording that was rotated: path, path.1, path.2, ... as long as they exist.
std::vector<std::string> RecordingFiles(const std::string& path);

// Several sources read as one stream in receive order, as a daemon received them (the per-sensor
// recordings or captures of one session): the source whose next datagram was received first goes
// first, ties to the earlier source. A source ending in kError is reported once and the others go
// on.
class MergedDatagramSource {
 public:
  explicit MergedDatagramSource(std::vector<std::unique_ptr<DatagramSource>> sources);
  // kDatagram: the next datagram, *index its source. kError: source *index ended with an error
  // (once per source; its error() says what). kEnd: every source has ended.
  SourceStatus Next(ReceivedDatagram* datagram, std::size_t* index);
  std::size_t size() const { return heads_.size(); }
  const DatagramSource& source(std::size_t i) const { return *heads_[i].source; }

 private:
  struct Head {
    std::unique_ptr<DatagramSource> source;
    ReceivedDatagram next;
    SourceStatus status = SourceStatus::kDatagram;
    bool loaded = false;    // `next` and `status` are read ahead
    bool reported = false;  // its end was returned (kError)
  };
  std::vector<Head> heads_;
};

}  // namespace lrfnet::daemon
