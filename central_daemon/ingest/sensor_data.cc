#include "central_daemon/ingest/sensor_data.h"

namespace lrfnet::daemon {

const char* ToString(TrackState state) {
  switch (state) {
    case TrackState::kTentative:
      return "tentative";
    case TrackState::kConfirmed:
      return "confirmed";
    case TrackState::kCoasting:
      return "coasting";
  }
  return "invalid";
}

const char* ToString(MeasurementKind kind) {
  switch (kind) {
    case MeasurementKind::kUnspecified:
      return "unspecified";
    case MeasurementKind::kCenterOfMass:
      return "center_of_mass";
    case MeasurementKind::kEllipse:
      return "ellipse";
    case MeasurementKind::kShapeFit:
      return "shape_fit";
  }
  return "invalid";
}

const char* ToString(ObjectShape shape) {
  switch (shape) {
    case ObjectShape::kUnspecified:
      return "unspecified";
    case ObjectShape::kTorso:
      return "torso";
    case ObjectShape::kLegs:
      return "legs";
    case ObjectShape::kCylinder:
      return "cylinder";
    case ObjectShape::kBox:
      return "box";
  }
  return "invalid";
}

const char* ToString(MountHeight mount) {
  switch (mount) {
    case MountHeight::kUnspecified:
      return "unspecified";
    case MountHeight::kTorso:
      return "torso";
    case MountHeight::kLegs:
      return "legs";
  }
  return "invalid";
}

const char* ToString(ClockSync sync) {
  switch (sync) {
    case ClockSync::kUnknown:
      return "unknown";
    case ClockSync::kSynchronized:
      return "synchronized";
    case ClockSync::kUnsynchronized:
      return "unsynchronized";
    case ClockSync::kReplay:
      return "replay";
  }
  return "invalid";
}

}  // namespace lrfnet::daemon
