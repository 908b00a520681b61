#pragma once
// The calibration's input from what the daemon holds, and from datagram files (recordings, UDP
// captures) read through the same daemon core as `lrfnetd --input`.

#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "central_daemon/calibration/types.h"
#include "central_daemon/ingest/ingest.h"
#include "central_daemon/store/track_store.h"
#include "common/time.h"

namespace lrfnet::daemon {

// Which datagrams and frames make a calibration's input. A live calibration takes what the store
// holds when it starts: every datagram received up to then (received_until_ns, the daemon's
// receive clock, which its recording keeps) and of those the frames with scan time from
// scan_from_ns on (its window). Both are written into calibration.yaml (`input_window`), so the
// daemon's recording gives the same input, and with it the same calibration, again
// (LoadCalibrationInput, `lrfnet calibrate --received-until-ns --scan-from-ns`).
struct InputWindow {
  common::UtcNs received_until_ns = std::numeric_limits<common::UtcNs>::max();
  common::UtcNs scan_from_ns = 0;
};

// Every sensor the store has frames or a background of, sorted by id, with its frames whose scan
// time is in [from_ns, to_ns), its newest background, its SensorInfo and clock state (from the
// ingest, when received). A copy: the calibration may run on another thread.
calib::CalibrationInput CalibrationInputFrom(
    const Ingest& ingest, const TrackStore& store, common::UtcNs from_ns = 0,
    common::UtcNs to_ns = std::numeric_limits<common::UtcNs>::max());

struct LoadCounters {
  std::uint64_t files = 0;
  std::uint64_t datagrams = 0;
  std::uint64_t invalid = 0;     // rejected by the ingest (validation, and the keys when given)
  std::uint64_t verified = 0;    // sealed and verified with the keys
  std::uint64_t unverified = 0;  // sealed, read without keys
};

// Reads every file (recordings, with their rotation parts, or pcap/pcapng captures of the UDP
// stream: only datagrams to udp_port, 0 = all) in order, the datagrams received after
// window.received_until_ns left out and the frames before window.scan_from_ns too. False with a
// one-line *error naming the file when one cannot be opened or is corrupt; invalid datagrams are
// only counted. With keys (auth.keys), every datagram is verified as lrfnetd does (fresh windows:
// forged and repeated ones in the files are dropped); without, sealed plain datagrams are read
// unverified and encrypted ones dropped (datagram_verifier.h).
bool LoadCalibrationInput(const std::vector<std::string>& paths, std::uint16_t udp_port,
                          calib::CalibrationInput* input, LoadCounters* counters,
                          std::string* error, const AuthOptions& auth = {},
                          const InputWindow& window = {});

}  // namespace lrfnet::daemon
