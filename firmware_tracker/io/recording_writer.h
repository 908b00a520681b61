#pragma once
// Writes the tracker's own datagrams as a recording (DESIGN.md "Recording", lrfnet.proto): a stream
// of length-delimited `RecordEntry` messages (varint length + message, as protobuf's
// writeDelimitedTo), the first with `header` set {format_version 1, created_ns, writer}. Every
// further entry holds one datagram exactly as sent, receive_ns = its sent_ns (the tracker is its
// own receiver), and source = TrackerRecordSource(sensor id) = "tracker:<sensor id>" where a
// daemon's recording has "ip:port".
//
// - Entries are collected in a buffer of buffer_bytes allocated at construction and written with
//   write(2) when it cannot take the next entry, when flush_interval_s of entry time has passed
//   since the last write, on Flush() and on Close(). So data reaches the file at least every
//   flush_interval_s of stream time and the file holds only whole entries after every write.
// - A failed write (disk full, I/O error) is counted with its errno; the buffered entries are
//   dropped (counted) and the file is cut back to its last whole entry where possible, so a reader
//   never sees a torn entry; later entries are tried again. Never fatal.
// - Datagrams larger than kMaxDatagramBytes are refused (counted).
// Not thread-safe. No allocation after construction.

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "common/time.h"
#include "firmware_tracker/io/datagram_encoder.h"
#include "lrfnet.nanopb.h"

namespace lrfnet::io {

inline constexpr std::uint32_t kRecordingFormatVersion = 1;

// "tracker:<sensor id>": the source of every entry of a tracker's own recording.
std::string TrackerRecordSource(std::string_view sensor_id);

struct RecordingWriterOptions {
  std::string path;
  std::string writer = "lrfnet-tracker";  // program and version, <= 64 bytes
  std::string source;                     // <= 64 bytes, e.g. TrackerRecordSource(id)
  std::size_t buffer_bytes = 64 * 1024;   // >= 4096 (two largest entries)
  double flush_interval_s = 1.0;
};
std::optional<std::string> Validate(const RecordingWriterOptions& options);

struct RecordingCounters {
  std::uint64_t entries = 0;  // datagram entries accepted into the buffer (header not counted)
  std::uint64_t entries_written = 0;
  std::uint64_t bytes_written = 0;  // including the header entry
  std::uint64_t flushes = 0;
  std::uint64_t write_errors = 0;
  std::uint64_t dropped_entries = 0;  // lost with a failed write
  std::uint64_t oversize = 0;
  std::uint64_t not_open = 0;
  int last_errno = 0;
};

class RecordingWriter final : public DatagramSink {
 public:
  // Precondition: Validate(options) is nullopt (checked; aborts otherwise).
  explicit RecordingWriter(const RecordingWriterOptions& options);
  ~RecordingWriter() override;
  RecordingWriter(const RecordingWriter&) = delete;
  RecordingWriter& operator=(const RecordingWriter&) = delete;

  // Creates (truncates) the file and writes the header entry at once. nullopt on success.
  std::optional<std::string> Open(common::UtcNs created_ns);
  // Flushes and closes; nullopt when everything reached the file.
  std::optional<std::string> Close();
  bool is_open() const { return fd_ >= 0; }

  // DatagramSink: the tracker's own datagram, recorded with receive_ns = sent_ns.
  void Send(std::span<const std::uint8_t> datagram, common::UtcNs sent_ns) override {
    Append(datagram, sent_ns);
  }
  // False when refused (not open, oversize) or when a flush it triggered failed.
  bool Append(std::span<const std::uint8_t> datagram, common::UtcNs receive_ns);
  // Writes the buffer out; false (counted) on a write error.
  bool Flush();

  const RecordingCounters& counters() const { return counters_; }

 private:
  bool AppendEntry(common::UtcNs receive_ns);

  RecordingWriterOptions options_;
  int fd_ = -1;
  std::uint64_t file_bytes_ = 0;      // whole entries known to be in the file
  std::vector<std::uint8_t> buffer_;  // sized once
  std::size_t used_ = 0;
  std::size_t buffered_entries_ = 0;
  common::UtcNs last_flush_ns_ = 0;
  RecordingCounters counters_;
  lrfnet_proto_RecordEntry entry_{};
  std::vector<std::uint8_t> scratch_;  // one encoded entry, sized once
};

}  // namespace lrfnet::io
