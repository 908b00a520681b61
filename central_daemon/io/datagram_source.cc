#include "central_daemon/io/datagram_source.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <cstring>
#include <utility>

#include "central_daemon/io/recording_file_source.h"
#include "central_daemon/io/udp_capture_source.h"

namespace lrfnet::daemon {
namespace {

// Classic pcap (micro- and nanosecond, either byte order) and the pcapng section header block.
// A recording never starts with one of them: its header entry is shorter than 16 KiB, so its
// length takes one or two bytes, followed by the tag of receive_ns, source or header (0x08, 0x12,
// 0x22); every magic has either a third length byte or another byte there.
bool IsCaptureMagic(const std::array<std::uint8_t, 4>& m) {
  static constexpr std::array<std::array<std::uint8_t, 4>, 5> kMagics = {{
      {0xd4, 0xc3, 0xb2, 0xa1},
      {0xa1, 0xb2, 0xc3, 0xd4},
      {0x4d, 0x3c, 0xb2, 0xa1},
      {0xa1, 0xb2, 0x3c, 0x4d},
      {0x0a, 0x0d, 0x0d, 0x0a},
  }};
  for (const auto& magic : kMagics) {
    if (m == magic) return true;
  }
  return false;
}

}  // namespace

std::unique_ptr<DatagramSource> OpenDatagramFile(const std::string& path,
                                                 const DatagramSourceOptions& options,
                                                 std::string* error) {
  std::string ignored;
  std::string& reason = error != nullptr ? *error : ignored;
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    reason = "cannot open '" + path + "': " + std::strerror(errno);
    return nullptr;
  }
  struct stat st {};
  if (::fstat(fd, &st) == 0 && S_ISDIR(st.st_mode)) {
    ::close(fd);
    reason = "'" + path + "' is a directory, not a recording or capture";
    return nullptr;
  }
  std::array<std::uint8_t, 4> magic{};
  std::size_t have = 0;
  while (have < magic.size()) {
    const ssize_t n = ::read(fd, magic.data() + have, magic.size() - have);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) {
      const int read_errno = errno;
      ::close(fd);
      reason = "cannot read '" + path + "': " + std::strerror(read_errno);
      return nullptr;
    }
    if (n == 0) break;
    have += static_cast<std::size_t>(n);
  }
  ::close(fd);
  if (have == magic.size() && IsCaptureMagic(magic)) {
    return UdpCaptureSource::Open(path, options, &reason);
  }
  return RecordingFileSource::Open(path, &reason);
}

std::vector<std::string> RecordingFiles(const std::string& path) {
  std::vector<std::string> files;
  struct stat st {};
  for (std::uint64_t part = 0;; ++part) {
    std::string file = part == 0 ? path : path + "." + std::to_string(part);
    if (::stat(file.c_str(), &st) != 0) break;
    files.push_back(std::move(file));
  }
  return files;
}

MergedDatagramSource::MergedDatagramSource(std::vector<std::unique_ptr<DatagramSource>> sources) {
  heads_.reserve(sources.size());
  for (auto& source : sources) heads_.push_back({std::move(source), {}, SourceStatus::kDatagram});
}

SourceStatus MergedDatagramSource::Next(ReceivedDatagram* datagram, std::size_t* index) {
  std::size_t first = heads_.size();
  for (std::size_t i = 0; i < heads_.size(); ++i) {
    Head& h = heads_[i];
    if (!h.loaded) {
      h.status = h.source->Next(&h.next);
      h.loaded = true;
    }
    if (h.status == SourceStatus::kError && !h.reported) {
      h.reported = true;
      *index = i;
      return SourceStatus::kError;
    }
    if (h.status != SourceStatus::kDatagram) continue;
    if (first == heads_.size() || h.next.receive_ns < heads_[first].next.receive_ns) first = i;
  }
  if (first == heads_.size()) return SourceStatus::kEnd;
  Head& h = heads_[first];
  std::swap(*datagram, h.next);
  h.loaded = false;
  *index = first;
  return SourceStatus::kDatagram;
}

}  // namespace lrfnet::daemon
