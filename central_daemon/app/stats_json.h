#pragma once
// The daemon's counters as JSON (lrfnetd --stats-out, tests, benchmarks): totals, rejections by
// reason (RejectReason names), authentication (authenticated: keys configured; verified /
// unverified: accepted sealed datagrams read with / without keys), and per sensor its datagrams by
// kind, rejections, sequence state, silence, clock state, description and store size.

#include <nlohmann/json.hpp>

#include "central_daemon/ingest/ingest.h"
#include "central_daemon/io/recording_writer.h"
#include "central_daemon/io/udp_receiver.h"
#include "central_daemon/store/track_store.h"

namespace lrfnet::daemon {

nlohmann::json StatsJson(const Ingest& ingest, const TrackStore& store);
nlohmann::json ReceiverJson(const UdpReceiverCounters& counters);
nlohmann::json RecordingJson(const RecordingWriterCounters& counters);

}  // namespace lrfnet::daemon
