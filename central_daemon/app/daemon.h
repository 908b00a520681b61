#pragma once
// The daemon's core, shared by the live daemon (UDP), the offline mode (recordings and UDP
// captures as input) and tests: every datagram is first recorded (as received, valid or not), then
// ingested; accepted track frames and backgrounds go to the track store. OnTick drives silence
// detection, store retention, recording flushes and the Requests to trackers. No socket, no clock,
// no logging: time is passed in, output goes through the two sink interfaces, and what should be
// logged is returned (TakeEvents, StatusLine).
// Not thread-safe: the daemon's io thread owns it.

#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "central_daemon/ingest/ingest.h"
#include "central_daemon/store/track_store.h"
#include "common/time.h"

namespace lrfnet::daemon {

// Where received datagrams are recorded (the RecordingWriter in the daemon).
class RecordSink {
 public:
  virtual ~RecordSink() = default;
  virtual void Record(std::span<const std::uint8_t> datagram, std::string_view source,
                      common::UtcNs receive_ns) = 0;
  virtual void FlushIfDue(common::UtcNs now_ns) = 0;
};

// Sends a datagram to a tracker at `source` ("ip:port" as received). False when dropped.
class RequestSink {
 public:
  virtual ~RequestSink() = default;
  virtual bool SendTo(std::string_view source, std::span<const std::uint8_t> datagram) = 0;
};

// Receives every accepted track frame (or part of one) as it arrives, after the store has it, and
// every accepted sensor info (the fusion in lrfnetd).
class FrameListener {
 public:
  virtual ~FrameListener() = default;
  virtual void OnFrame(const std::string& sensor_id, const TrackFrameData& frame) = 0;
  virtual void OnSensorInfo(const std::string& /*sensor_id*/, const SensorDescription& /*info*/) {}
};

struct DaemonOptions {
  IngestOptions ingest;
  TrackStoreOptions store;
  bool send_requests = true;
};
std::optional<std::string> Validate(const DaemonOptions& options);

// Encodes the daemon's Request to `sensor_id` as a Datagram (version 1, the daemon's own
// sequence and session id; lrfnet.proto Request).
std::vector<std::uint8_t> EncodeRequestDatagram(const PendingRequest& request,
                                                std::uint64_t sequence, common::UtcNs sent_ns,
                                                std::uint64_t session_id);

class Daemon final : public IngestListener {
 public:
  // `recorder` and `requests` may be null (no recording; offline: no replies). Both must outlive
  // the daemon. Precondition: Validate(options).
  Daemon(const DaemonOptions& options, RecordSink* recorder, RequestSink* requests,
         std::uint64_t session_id);

  void OnDatagram(std::span<const std::uint8_t> datagram, std::string_view source,
                  common::UtcNs receive_ns);
  void OnTick(common::UtcNs now_ns);
  // Applies what may change at run time (validation, silence, requests, retention).
  void Reconfigure(const DaemonOptions& options);
  // The authentication state of an earlier run (lrfnetd's state directory).
  void RestoreAuthState(const std::vector<StoredAuthState>& state) {
    ingest_.RestoreAuthState(state);
  }

  // One line: sensors (active/silent), datagram rate and accepted/invalid since the last status
  // line, loss, store size, and per sensor (the worst few when there are many): rate, loss and
  // clock state. Starts a new rate interval.
  std::string StatusLine(common::UtcNs now_ns);
  // Sensor events (new, restart, silent, back, sequence reset) since the last call, oldest first
  // (at most 1000 kept).
  std::vector<SensorEvent> TakeEvents();

  // May be null (none). Must outlive the daemon or be reset first.
  void set_frame_listener(FrameListener* listener) { frame_listener_ = listener; }

  const Ingest& ingest() const { return ingest_; }
  const TrackStore& store() const { return store_; }
  std::uint64_t requests_sent() const { return requests_sent_; }
  std::uint64_t requests_dropped() const { return requests_dropped_; }

  // IngestListener
  void OnTrackFrame(const std::string& sensor_id, const TrackFrameData& frame) override;
  void OnBackground(const std::string& sensor_id, const BackgroundScan& background) override;
  void OnSensorInfo(const std::string& sensor_id, const SensorDescription& info) override;
  void OnSensorEvent(const SensorEvent& event) override;

 private:
  DaemonOptions options_;
  RecordSink* recorder_;
  RequestSink* requests_;
  FrameListener* frame_listener_ = nullptr;
  std::uint64_t session_id_;
  TrackStore store_;
  Ingest ingest_;
  std::deque<SensorEvent> events_;
  std::uint64_t request_sequence_ = 0;
  std::uint64_t requests_sent_ = 0;
  std::uint64_t requests_dropped_ = 0;
  // Status interval.
  common::UtcNs status_since_ns_ = 0;
  IngestCounters status_counters_;
  struct SensorMark {
    std::uint64_t datagrams = 0;
    std::uint64_t received = 0;
    std::uint64_t lost = 0;
  };
  std::map<std::string, SensorMark, std::less<>> status_marks_;
};

}  // namespace lrfnet::daemon
