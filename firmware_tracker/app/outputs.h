#pragma once

// Where lrfnet-tracker's datagrams go: UDP to lrfnetd (--uplink), a recording (--out), both, or
// only counted; sealed with the sensor's key first when auth.key is set.

#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "common/time.h"
#include "firmware_tracker/app/config.h"
#include "firmware_tracker/app/tracker_node.h"
#include "firmware_tracker/io/datagram_encoder.h"
#include "firmware_tracker/io/recording_writer.h"
#include "firmware_tracker/io/sealing_sink.h"
#include "firmware_tracker/io/udp_uplink.h"

namespace lrfnet::tracker {

// Where the datagrams go: UDP, a recording, both, or only counted.
class Outputs {
 public:
  // Opens what the config and record_path ask for; the error names the flag.
  std::optional<std::string> Open(const TrackerConfig& config, const std::string& record_path,
                                  common::UtcNs created_ns);

  // The sink the node writes its datagrams to.
  io::DatagramSink& sink();

  // Reads the daemon's Request datagrams (non-blocking) and hands them to the node.
  void ServeRequests(TrackerNode& node);

  // UDP send errors and recording write errors, so far.
  std::uint64_t send_errors() const;

  // Closes the recording; false (message printed) when the last write failed.
  bool Close();

  // The outputs' counters for the summary line (" udp_sent=N ..."; empty without outputs).
  std::string Summary() const;

 private:
  io::DatagramFanout fanout_;
  std::unique_ptr<io::SealingSink> sealing_;
  std::unique_ptr<io::UdpUplink> udp_;
  std::unique_ptr<io::RecordingWriter> recording_;
};

}  // namespace lrfnet::tracker
