#pragma once
// The live state as Foxglove channels (pure; JSON encoding, schemas as JSON Schema):
//   /tf                        foxglove.FrameTransforms  world -> <sensor id> of placed sensors
//   /lrfnet/fused              foxglove.SceneUpdate      fused tracks (world): a cylinder of a
//                                                        person's size, a velocity arrow, the id
//   /lrfnet/tracks/<sensor>    foxglove.SceneUpdate      the sensor's raw tracks (world when
//                                                        placed, else the sensor's frame)
//   /lrfnet/background/<sensor> foxglove.LaserScan       the static background, sensor frame
//   /lrfnet/zones              foxglove.SceneUpdate      zones (world) with their counts
//   /lrfnet/calibration        lrfnet.Calibration        state, progress, poses
// Frame ids: "world" (the calibration's world, the reference sensor at its origin) and the sensor
// ids, as `lrfnet export --format ros2-static-tf` names them by default. Every SceneUpdate
// replaces the channel's previous entities (a deletion of all first).

#include <vector>

#include "central_daemon/app/live_state.h"
#include "central_daemon/io/live_view_server.h"

namespace lrfnet::daemon {

std::vector<FoxgloveChannelMessage> FoxgloveMessagesOf(const LiveState& state);

}  // namespace lrfnet::daemon
