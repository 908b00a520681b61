#pragma once
// A recording on disk as a DatagramSource: `path`, then its rotation parts path.1, path.2, ... as
// one stream (each part's header is checked and consumed, never delivered). Files are read with
// read(2) into a 256 KiB buffer and decoded by RecordingDecoder, so memory stays bounded whatever
// the file holds. A part is looked up when the one before it ends, so a recording that is still
// being written reads as far as it has reached the disk.
//
// Errors name the file and the byte offset of the damaged entry, e.g.
//   recording 'run.rec.1': torn entry: the input ends 20 bytes into a 300-byte entry at byte 4096
//
// Not thread-safe.

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "central_daemon/io/datagram_source.h"
#include "central_daemon/io/recording_decoder.h"

namespace lrfnet::daemon {

class RecordingFileSource final : public DatagramSource {
 public:
  // Opens `path` and reads its header. nullptr and a one-line *error when the file cannot be read
  // or does not start with a recording header ("... not a recording or capture ...").
  static std::unique_ptr<RecordingFileSource> Open(const std::string& path, std::string* error);
  ~RecordingFileSource() override;

  SourceStatus Next(ReceivedDatagram* datagram) override;
  DatagramFileKind kind() const override { return DatagramFileKind::kRecording; }
  const DatagramSourceCounters& counters() const override { return counters_; }
  const std::string& error() const override { return error_; }
  std::uint32_t format_version() const override { return header_.format_version; }
  common::UtcNs created_ns() const override { return header_.created_ns; }
  const std::string& writer() const override { return header_.writer; }

  // The file being read (path or path.N).
  const std::string& current_file() const { return file_path_; }

 private:
  explicit RecordingFileSource(std::string path);
  // Opens part `part_` and consumes its header; false with error_ set.
  bool OpenPart();
  // The next entry of the current file: kDatagram (entry in decoder_), kEnd (clean end), kError.
  SourceStatus NextEntry();
  SourceStatus Fail(std::string reason);
  void CloseFile();

  std::string path_;
  std::uint64_t part_ = 0;
  std::string file_path_;
  int fd_ = -1;
  std::unique_ptr<RecordingDecoder> decoder_;
  std::unique_ptr<std::uint8_t[]> buffer_;  // kReadBufferBytes, left uninitialized
  std::size_t begin_ = 0;
  std::size_t end_ = 0;
  bool eof_ = false;
  RecordingHeader header_;
  DatagramSourceCounters counters_;
  SourceStatus final_ = SourceStatus::kDatagram;  // kEnd / kError once reached
  std::string error_;
};

}  // namespace lrfnet::daemon
