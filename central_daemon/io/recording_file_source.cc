#include "central_daemon/io/recording_file_source.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <utility>

namespace lrfnet::daemon {
namespace {

// Large enough that a read brings in many entries (one syscall per ~200 track datagrams), small
// enough to be irrelevant next to the decoder's bound.
constexpr std::size_t kReadBufferBytes = 256 * 1024;

std::string PartPath(const std::string& path, std::uint64_t part) {
  return part == 0 ? path : path + "." + std::to_string(part);
}

}  // namespace

RecordingFileSource::RecordingFileSource(std::string path)
    : path_(std::move(path)), buffer_(new std::uint8_t[kReadBufferBytes]) {}

RecordingFileSource::~RecordingFileSource() { CloseFile(); }

std::unique_ptr<RecordingFileSource> RecordingFileSource::Open(const std::string& path,
                                                               std::string* error) {
  std::unique_ptr<RecordingFileSource> source(new RecordingFileSource(path));
  if (!source->OpenPart()) {
    if (error != nullptr) *error = source->error_;
    return nullptr;
  }
  return source;
}

void RecordingFileSource::CloseFile() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

SourceStatus RecordingFileSource::Fail(std::string reason) {
  error_ = std::move(reason);
  final_ = SourceStatus::kError;
  CloseFile();
  return SourceStatus::kError;
}

bool RecordingFileSource::OpenPart() {
  file_path_ = PartPath(path_, part_);
  fd_ = ::open(file_path_.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd_ < 0) {
    const int open_errno = errno;
    Fail("recording '" + file_path_ + "': cannot open: " + std::strerror(open_errno));
    return false;
  }
  ++counters_.files;
  decoder_ = std::make_unique<RecordingDecoder>();
  begin_ = 0;
  end_ = 0;
  eof_ = false;
  const SourceStatus status = NextEntry();
  if (status == SourceStatus::kDatagram) {
    // The decoder accepts a first entry only when it is a header of a known version.
    if (part_ == 0) header_ = decoder_->entry().header;
    return true;
  }
  if (status == SourceStatus::kEnd) {
    Fail("'" + file_path_ + "' is empty: not a recording or capture");
    return false;
  }
  if (part_ == 0 && decoder_->defect() != RecordingDefect::kNone &&
      decoder_->defect() != RecordingDefect::kUnsupportedVersion) {
    // The content decides the kind; a file that is neither gets one plain answer.
    Fail("'" + file_path_ + "' is not a recording or capture (" + decoder_->error() + ")");
  }
  return false;
}

SourceStatus RecordingFileSource::NextEntry() {
  for (;;) {
    if (begin_ < end_) {
      std::size_t consumed = 0;
      const RecordingDecodeStatus status = decoder_->Feed(
          std::span<const std::uint8_t>(buffer_.get() + begin_, end_ - begin_), &consumed);
      begin_ += consumed;
      if (status == RecordingDecodeStatus::kEntry) return SourceStatus::kDatagram;
      if (status == RecordingDecodeStatus::kBad) break;
    }
    if (eof_) {
      if (decoder_->Finish() == RecordingDecodeStatus::kEnd) return SourceStatus::kEnd;
      break;
    }
    const ssize_t n = ::read(fd_, buffer_.get(), kReadBufferBytes);
    if (n < 0) {
      const int read_errno = errno;
      if (read_errno == EINTR) continue;
      return Fail("recording '" + file_path_ + "': read error after byte " +
                  std::to_string(decoder_->offset()) + ": " + std::strerror(read_errno));
    }
    begin_ = 0;
    end_ = static_cast<std::size_t>(n);
    eof_ = n == 0;
  }
  return Fail("recording '" + file_path_ + "': " + decoder_->error() + " at byte " +
              std::to_string(decoder_->error_offset()));
}

SourceStatus RecordingFileSource::Next(ReceivedDatagram* datagram) {
  if (final_ != SourceStatus::kDatagram) return final_;
  for (;;) {
    const SourceStatus status = NextEntry();
    if (status == SourceStatus::kDatagram) {
      ReceivedDatagram& entry = decoder_->entry().datagram;
      datagram->receive_ns = entry.receive_ns;
      // Swapped, not copied: the decoder refills the caller's old buffers.
      datagram->source.swap(entry.source);
      datagram->bytes.swap(entry.bytes);
      ++counters_.datagrams;
      return SourceStatus::kDatagram;
    }
    if (status == SourceStatus::kError) return status;
    CloseFile();
    ++part_;
    struct stat st {};
    if (::stat(PartPath(path_, part_).c_str(), &st) != 0 && errno == ENOENT) {
      final_ = SourceStatus::kEnd;
      return final_;
    }
    if (!OpenPart()) return SourceStatus::kError;
  }
}

}  // namespace lrfnet::daemon
