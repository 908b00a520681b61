#pragma once
// The daemon's recording (DESIGN.md "Recording", lrfnet.proto): every datagram received, in order,
// with its receive time and sender, as varint-delimited RecordEntry messages; each file starts with
// a header entry {format_version 1, created_ns, writer}.
//
// - Rotation: when a file would exceed max_file_bytes, the next one is started: the first file is
//   `path`, then `path.1`, `path.2`, ... (RecordingFiles and OpenDatagramFile read them as one).
//   0 = never rotate.
// - Durability: entries are buffered and written with write(2) when the buffer is full, when
//   flush_interval_s of receive time has passed since the last write (checked on every Append
//   and on FlushIfDue, which the daemon calls from a timer), and on Flush/Close. A kill therefore
//   loses at most the last flush_interval_s. Whole entries only reach the file.
// - A write error (disk full) is counted, the buffered entries are dropped (counted) and the file
//   is cut back to its last whole entry; later entries are tried again. Never fatal.
// Not thread-safe.

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "common/time.h"

namespace lrfnet::daemon {

struct RecordingWriterOptions {
  std::string path;
  std::string writer = "lrfnetd";                  // program and version, in every header
  std::uint64_t max_file_bytes = 1ULL << 30;      // 0 = no rotation; else >= 64 KiB
  double flush_interval_s = 1.0;                   // > 0
  std::size_t buffer_bytes = 1 << 20;              // >= 64 KiB
};
std::optional<std::string> Validate(const RecordingWriterOptions& options);

struct RecordingWriterCounters {
  std::uint64_t entries = 0;          // datagram entries accepted
  std::uint64_t entries_written = 0;  // reached the file
  std::uint64_t bytes_written = 0;    // including headers
  std::uint64_t files = 0;            // files created (1 + rotations)
  std::uint64_t flushes = 0;
  std::uint64_t write_errors = 0;
  std::uint64_t dropped_entries = 0;
  int last_errno = 0;
};

class RecordingWriter {
 public:
  explicit RecordingWriter(const RecordingWriterOptions& options);
  ~RecordingWriter();  // Close()
  RecordingWriter(const RecordingWriter&) = delete;
  RecordingWriter& operator=(const RecordingWriter&) = delete;

  // Creates (truncates) `path` and writes its header; removes stale rotation parts path.1, ...
  // of an earlier recording so the set read back is this one. nullopt on success.
  std::optional<std::string> Open(common::UtcNs created_ns);
  std::optional<std::string> Close();
  bool is_open() const;

  // One received datagram (any bytes up to kMaxRecordEntryBytes - 256, valid or not).
  bool Append(std::span<const std::uint8_t> datagram, std::string_view source,
              common::UtcNs receive_ns);
  void FlushIfDue(common::UtcNs now_ns);
  bool Flush();

  const std::string& current_path() const;
  const RecordingWriterCounters& counters() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace lrfnet::daemon
