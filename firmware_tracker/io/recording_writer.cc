#include "firmware_tracker/io/recording_writer.h"

#include <fcntl.h>
#include <pb_encode.h>
#include <unistd.h>

#include "common/file_append.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>

namespace lrfnet::io {
namespace {

constexpr std::size_t kMaxVarint32Bytes = 5;
constexpr std::size_t kMinBufferBytes = 4096;

std::size_t PutVarint(std::uint64_t v, std::uint8_t* out) {
  std::size_t n = 0;
  while (v >= 0x80) {
    out[n++] = static_cast<std::uint8_t>(v | 0x80);
    v >>= 7;
  }
  out[n++] = static_cast<std::uint8_t>(v);
  return n;
}

void CopyField(const std::string& text, char* out, std::size_t capacity) {
  const std::size_t n = std::min(text.size(), capacity - 1);
  std::memcpy(out, text.data(), n);
  out[n] = '\0';
}

}  // namespace

std::string TrackerRecordSource(std::string_view sensor_id) {
  return "tracker:" + std::string(sensor_id);
}

std::optional<std::string> Validate(const RecordingWriterOptions& o) {
  if (o.path.empty()) return "recording: empty path";
  if (o.writer.size() >= sizeof(lrfnet_proto_RecordHeader::writer))
    return "recording: writer longer than 64 bytes";
  if (o.source.size() >= sizeof(lrfnet_proto_RecordEntry::source))
    return "recording: source longer than 64 bytes";
  if (o.buffer_bytes < kMinBufferBytes) return "recording: buffer_bytes must be >= 4096";
  if (!std::isfinite(o.flush_interval_s) || o.flush_interval_s <= 0.0)
    return "recording: flush_interval_s must be positive";
  return std::nullopt;
}

RecordingWriter::RecordingWriter(const RecordingWriterOptions& options)
    : options_(options), buffer_(options.buffer_bytes), scratch_(lrfnet_proto_RecordEntry_size) {
  if (const auto error = Validate(options)) {
    std::fprintf(stderr, "RecordingWriter: invalid options: %s\n", error->c_str());
    std::abort();
  }
}

RecordingWriter::~RecordingWriter() { Close(); }

std::optional<std::string> RecordingWriter::Open(common::UtcNs created_ns) {
  Close();
  counters_ = {};
  const int fd = ::open(options_.path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) return "recording: cannot create '" + options_.path + "': " + std::strerror(errno);
  fd_ = fd;
  file_bytes_ = 0;
  used_ = 0;
  buffered_entries_ = 0;
  last_flush_ns_ = created_ns;

  entry_ = lrfnet_proto_RecordEntry{};
  entry_.receive_ns = created_ns;
  CopyField(options_.source, entry_.source, sizeof(entry_.source));
  entry_.has_header = true;
  entry_.header.format_version = kRecordingFormatVersion;
  entry_.header.created_ns = created_ns;
  CopyField(options_.writer, entry_.header.writer, sizeof(entry_.header.writer));
  const bool appended = AppendEntry(created_ns);
  buffered_entries_ = 0;  // the header is not a datagram entry
  entry_.has_header = false;
  entry_.header = lrfnet_proto_RecordHeader{};
  if (!appended || !Flush()) {
    const int error = counters_.last_errno;
    ::close(fd_);
    fd_ = -1;
    return "recording: cannot write the header of '" + options_.path + "': " + std::strerror(error);
  }
  return std::nullopt;
}

std::optional<std::string> RecordingWriter::Close() {
  if (fd_ < 0) return std::nullopt;
  Flush();
  const int rc = ::close(fd_);
  const int close_errno = errno;
  fd_ = -1;
  if (counters_.write_errors > 0) {
    return "recording: " + std::to_string(counters_.write_errors) + " write error(s) on '" +
           options_.path + "', " + std::to_string(counters_.dropped_entries) +
           " entries lost; last: " + std::strerror(counters_.last_errno);
  }
  if (rc != 0) return "recording: closing '" + options_.path + "': " + std::strerror(close_errno);
  return std::nullopt;
}

bool RecordingWriter::AppendEntry(common::UtcNs receive_ns) {
  entry_.receive_ns = receive_ns;
  pb_ostream_t stream = pb_ostream_from_buffer(scratch_.data(), scratch_.size());
  if (!pb_encode(&stream, lrfnet_proto_RecordEntry_fields, &entry_)) {
    // Cannot happen within the static bounds (scratch holds RecordEntry_size); counted as a write
    // error.
    ++counters_.write_errors;
    return false;
  }
  const std::size_t size = stream.bytes_written;
  if (used_ + kMaxVarint32Bytes + size > buffer_.size() && !Flush()) return false;
  used_ += PutVarint(size, buffer_.data() + used_);
  std::memcpy(buffer_.data() + used_, scratch_.data(), size);
  used_ += size;
  ++buffered_entries_;
  return true;
}

bool RecordingWriter::Append(std::span<const std::uint8_t> datagram, common::UtcNs receive_ns) {
  if (fd_ < 0) {
    ++counters_.not_open;
    return false;
  }
  if (datagram.size() > sizeof(entry_.datagram.bytes)) {
    ++counters_.oversize;
    return false;
  }
  if (!datagram.empty()) std::memcpy(entry_.datagram.bytes, datagram.data(), datagram.size());
  entry_.datagram.size = static_cast<pb_size_t>(datagram.size());
  if (!AppendEntry(receive_ns)) return false;
  ++counters_.entries;
  const auto interval_ns = static_cast<common::DurationNs>(options_.flush_interval_s * 1e9);
  // A time step backwards (replay of a capture with a clock jump) restarts the interval.
  if (receive_ns - last_flush_ns_ >= interval_ns || receive_ns < last_flush_ns_) {
    last_flush_ns_ = receive_ns;
    return Flush();
  }
  return true;
}

bool RecordingWriter::Flush() {
  if (fd_ < 0 || used_ == 0) return fd_ >= 0;
  if (const int error = common::AppendWhole(fd_, buffer_.data(), used_, file_bytes_)) {
    // The partial write was cut off again, so the file ends with a whole entry.
    ++counters_.write_errors;
    counters_.last_errno = error;
    counters_.dropped_entries += buffered_entries_;
    used_ = 0;
    buffered_entries_ = 0;
    return false;
  }
  file_bytes_ += used_;
  counters_.bytes_written += used_;
  counters_.entries_written += buffered_entries_;
  ++counters_.flushes;
  used_ = 0;
  buffered_entries_ = 0;
  return true;
}

}  // namespace lrfnet::io
