#include "central_daemon/io/recording_writer.h"

#include "common/file_append.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>

#include "central_daemon/io/datagram_source.h"
#include "central_daemon/io/recording_decoder.h"
#include "lrfnet.pb.h"

namespace lrfnet::daemon {
namespace {

constexpr std::uint64_t kMinFileBytes = 64 * 1024;
constexpr std::size_t kMinBufferBytes = 64 * 1024;
constexpr std::size_t kMaxWriterBytes = 256;
constexpr std::size_t kMaxVarint32Bytes = 5;

std::size_t PutVarint(std::uint64_t v, std::uint8_t* out) {
  std::size_t n = 0;
  while (v >= 0x80) {
    out[n++] = static_cast<std::uint8_t>(v | 0x80);
    v >>= 7;
  }
  out[n++] = static_cast<std::uint8_t>(v);
  return n;
}

std::size_t VarintBytes(std::uint64_t v) {
  std::size_t n = 1;
  while (v >= 0x80) {
    v >>= 7;
    ++n;
  }
  return n;
}

std::string PartPath(const std::string& path, std::uint64_t part) {
  return part == 0 ? path : path + "." + std::to_string(part);
}

}  // namespace

std::optional<std::string> Validate(const RecordingWriterOptions& o) {
  if (o.path.empty()) return "recording: empty path";
  if (o.writer.size() > kMaxWriterBytes) return "recording: writer longer than 256 bytes";
  if (o.max_file_bytes != 0 && o.max_file_bytes < kMinFileBytes)
    return "recording: max_file_bytes must be 0 (no rotation) or >= 65536";
  if (!std::isfinite(o.flush_interval_s) || o.flush_interval_s <= 0.0)
    return "recording: flush_interval_s must be positive";
  if (o.buffer_bytes < kMinBufferBytes) return "recording: buffer_bytes must be >= 65536";
  return std::nullopt;
}

struct RecordingWriter::Impl {
  RecordingWriterOptions options;
  RecordingWriterCounters counters;
  bool open = false;       // between a successful Open() and Close()
  int fd = -1;             // -1 while open when starting a rotation part failed
  std::uint64_t part = 0;  // 0 = `path`, N = `path.N`
  std::string current_path;
  std::uint64_t file_bytes = 0;      // whole entries known to be in the current file
  std::uint64_t file_datagrams = 0;  // datagram entries given to the current file
  std::vector<std::uint8_t> buffer;  // sized at Open()
  std::size_t used = 0;
  std::uint64_t buffered_entries = 0;  // datagram entries in the buffer (not the header)
  common::UtcNs last_write_ns = 0;
  common::DurationNs interval_ns = 0;
  proto::RecordEntry entry;  // reused: its strings keep their capacity
  proto::RecordEntry header_entry;

  // Serializes `message` behind its prefix into the buffer, writing the buffer out first when it
  // cannot take it. The message is buffered either way (a failed write empties the buffer: its
  // entries are dropped, this one is tried with the next write); false when that write failed.
  bool Buffer(const proto::RecordEntry& message, std::size_t message_size, common::UtcNs now_ns) {
    bool ok = true;
    if (used + VarintBytes(message_size) + message_size > buffer.size()) {
      ok = Write();
      last_write_ns = now_ns;
    }
    used += PutVarint(message_size, buffer.data() + used);
    message.SerializeWithCachedSizesToArray(buffer.data() + used);
    used += message_size;
    return ok;
  }

  bool Write() {
    if (fd < 0 || used == 0) return fd >= 0;
    if (const int error = common::AppendWhole(fd, buffer.data(), used, file_bytes)) {
      // A reader stops at a torn entry: AppendWhole cut the partial write off, so the entries
      // that follow a recovered disk are still readable.
      ++counters.write_errors;
      counters.last_errno = error;
      counters.dropped_entries += buffered_entries;
      used = 0;
      buffered_entries = 0;
      return false;
    }
    file_bytes += used;
    counters.bytes_written += used;
    counters.entries_written += buffered_entries;
    ++counters.flushes;
    used = 0;
    buffered_entries = 0;
    return true;
  }

  // Creates the current part and writes its header at once, so every file on disk starts with
  // one. On failure the part stays closed (fd -1) and *error says why.
  bool StartFile(common::UtcNs created_ns, std::string* error) {
    current_path = PartPath(options.path, part);
    const int new_fd = ::open(current_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (new_fd < 0) {
      ++counters.write_errors;
      counters.last_errno = errno;
      *error =
          "recording: cannot create '" + current_path + "': " + std::strerror(counters.last_errno);
      return false;
    }
    fd = new_fd;
    ++counters.files;
    file_bytes = 0;
    file_datagrams = 0;
    used = 0;
    buffered_entries = 0;
    header_entry.set_receive_ns(created_ns);
    proto::RecordHeader* header = header_entry.mutable_header();
    header->set_format_version(kRecordingFormatVersion);
    header->set_created_ns(created_ns);
    header->set_writer(options.writer);
    const std::size_t size = header_entry.ByteSizeLong();
    const bool written = Buffer(header_entry, size, created_ns) && Write();
    last_write_ns = created_ns;
    if (!written) {
      *error = "recording: cannot write the header of '" + current_path +
               "': " + std::strerror(counters.last_errno);
      ::close(fd);
      fd = -1;
      return false;
    }
    return true;
  }

  // False when a write was due and failed.
  bool FlushIfDue(common::UtcNs now_ns) {
    if (used == 0) return true;
    // A clock stepped backwards restarts the interval (and writes now) rather than holding data
    // back until the clock catches up.
    if (now_ns - last_write_ns < interval_ns && now_ns >= last_write_ns) return true;
    last_write_ns = now_ns;
    return Write();
  }

  void CloseFile() {
    if (fd < 0) return;
    Write();
    if (::close(fd) != 0) {
      ++counters.write_errors;
      counters.last_errno = errno;
    }
    fd = -1;
  }
};

RecordingWriter::RecordingWriter(const RecordingWriterOptions& options)
    : impl_(std::make_unique<Impl>()) {
  impl_->options = options;
  impl_->current_path = options.path;
}

RecordingWriter::~RecordingWriter() { Close(); }

std::optional<std::string> RecordingWriter::Open(common::UtcNs created_ns) {
  Close();
  Impl& m = *impl_;
  if (auto error = Validate(m.options)) return error;
  m.counters = {};
  // Parts of an earlier, longer recording under the same name would be read back as a
  // continuation of this one.
  for (std::uint64_t n = 1;; ++n) {
    const std::string stale = PartPath(m.options.path, n);
    if (::unlink(stale.c_str()) != 0) {
      const int unlink_errno = errno;
      if (unlink_errno == ENOENT) break;
      return "recording: cannot remove the stale part '" + stale +
             "': " + std::strerror(unlink_errno);
    }
  }
  // Room for the largest entry, so Buffer() never has to bypass the buffer.
  m.buffer.assign(std::max(m.options.buffer_bytes, kMaxRecordEntryBytes + kMaxVarint32Bytes), 0);
  m.interval_ns = common::SecondsToNs(m.options.flush_interval_s);
  m.part = 0;
  std::string error;
  if (!m.StartFile(created_ns, &error)) return error;
  m.open = true;
  return std::nullopt;
}

std::optional<std::string> RecordingWriter::Close() {
  Impl& m = *impl_;
  if (!m.open) return std::nullopt;
  m.CloseFile();
  m.open = false;
  m.buffer.clear();
  m.buffer.shrink_to_fit();
  if (m.counters.write_errors > 0) {
    return "recording: " + std::to_string(m.counters.write_errors) + " write error(s) on '" +
           m.options.path + "', " + std::to_string(m.counters.dropped_entries) +
           " entries lost; last: " + std::strerror(m.counters.last_errno);
  }
  return std::nullopt;
}

bool RecordingWriter::is_open() const { return impl_->open; }

bool RecordingWriter::Append(std::span<const std::uint8_t> datagram, std::string_view source,
                             common::UtcNs receive_ns) {
  Impl& m = *impl_;
  if (!m.open) {
    ++m.counters.dropped_entries;
    return false;
  }
  m.entry.set_receive_ns(receive_ns);
  m.entry.mutable_source()->assign(source.data(), source.size());
  m.entry.mutable_datagram()->assign(reinterpret_cast<const char*>(datagram.data()),
                                     datagram.size());
  const std::size_t size = m.entry.ByteSizeLong();
  if (size > kMaxRecordEntryBytes) {  // readers reject it; the caller broke the size contract
    ++m.counters.dropped_entries;
    return false;
  }
  const std::uint64_t entry_bytes = VarintBytes(size) + size;
  if (m.fd >= 0 && m.options.max_file_bytes > 0 && m.file_datagrams > 0 &&
      m.file_bytes + m.used + entry_bytes > m.options.max_file_bytes) {
    m.CloseFile();
    ++m.part;
  }
  if (m.fd < 0) {
    // A new part, or one whose creation failed before (tried again with every entry).
    std::string error;
    if (!m.StartFile(receive_ns, &error)) {
      ++m.counters.dropped_entries;
      return false;
    }
  }
  const bool buffered_cleanly = m.Buffer(m.entry, size, receive_ns);
  ++m.buffered_entries;
  ++m.file_datagrams;
  ++m.counters.entries;
  return m.FlushIfDue(receive_ns) && buffered_cleanly;
}

void RecordingWriter::FlushIfDue(common::UtcNs now_ns) {
  if (impl_->open) impl_->FlushIfDue(now_ns);
}

bool RecordingWriter::Flush() {
  Impl& m = *impl_;
  if (!m.open) return false;
  return m.Write();
}

const std::string& RecordingWriter::current_path() const { return impl_->current_path; }

const RecordingWriterCounters& RecordingWriter::counters() const { return impl_->counters; }

}  // namespace lrfnet::daemon
