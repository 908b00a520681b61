#pragma once
// The one place where the daemon turns wire messages (lrfnet.proto, libprotobuf-lite) into its
// value types (sensor_data.h). Inputs are validated datagrams (DatagramDecoder): enum values are
// known, counts within their bounds.

#include "central_daemon/ingest/background_assembler.h"
#include "central_daemon/ingest/sensor_data.h"
#include "common/time.h"
#include "lrfnet.pb.h"

namespace lrfnet::daemon {

// Precondition: d holds a validated track frame. Reuses the capacity of out->tracks (no allocation
// once it has grown to the largest frame).
void ToTrackFrame(const proto::Datagram& d, common::UtcNs receive_ns, TrackFrameData* out);
// Precondition: d holds a validated background part. The part's ranges are a view into d.
BackgroundPart ToBackgroundPart(const proto::Datagram& d);
// Precondition: d holds a validated Health.
SensorHealth ToSensorHealth(const proto::Datagram& d, common::UtcNs receive_ns);
// Precondition: info is validated.
SensorDescription ToSensorDescription(const proto::SensorInfo& info);

TrackState ToTrackState(proto::TrackState state);
MeasurementKind ToMeasurementKind(proto::MeasurementKind kind);
ObjectShape ToObjectShape(proto::ObjectShape shape);
MountHeight ToMountHeight(proto::MountHeight mount);
ClockSync ToClockSync(proto::ClockSyncState sync);

}  // namespace lrfnet::daemon
