#pragma once

// The recording of everything received, as the core's RecordSink.

#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>

#include "central_daemon/app/daemon.h"
#include "central_daemon/io/recording_writer.h"
#include "common/time.h"

namespace lrfnet::daemon {

// RecordSink over the recording writer; logs write errors once per burst.
class Recorder final : public RecordSink {
 public:
  explicit Recorder(const RecordingWriterOptions& options) : writer_(options) {}
  std::optional<std::string> Open(common::UtcNs now_ns) { return writer_.Open(now_ns); }
  std::optional<std::string> Close() { return writer_.Close(); }
  void Record(std::span<const std::uint8_t> datagram, std::string_view source,
              common::UtcNs receive_ns) override {
    writer_.Append(datagram, source, receive_ns);
    CheckErrors();
  }
  void FlushIfDue(common::UtcNs now_ns) override {
    writer_.FlushIfDue(now_ns);
    CheckErrors();
  }
  const RecordingWriter& writer() const { return writer_; }

 private:
  void CheckErrors();
  RecordingWriter writer_;
  std::uint64_t reported_errors_ = 0;
};

}  // namespace lrfnet::daemon
