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
// stream: only datagrams to udp_port, 0 = all) in order. False with a one-line *error naming the
// file when one cannot be opened or is corrupt; invalid datagrams are only counted. With keys
// (auth.keys), every datagram is verified as lrfnetd does (fresh windows: forged and repeated ones
// in the files are dropped); without, sealed plain datagrams are read unverified and encrypted
// ones dropped (datagram_verifier.h).
bool LoadCalibrationInput(const std::vector<std::string>& paths, std::uint16_t udp_port,
                          calib::CalibrationInput* input, LoadCounters* counters,
                          std::string* error, const AuthOptions& auth = {});

}  // namespace lrfnet::daemon
