#pragma once
// The keys of auth_fuzz (shared with the seeds make_fuzz_corpus writes): sensor "gate-3", epochs 1
// and 2 of a fixed site key.

#include "central_daemon/ingest/datagram_verifier.h"
#include "common/datagram_auth.h"

namespace lrfnet::fuzz {

inline constexpr char kAuthFuzzSensor[] = "gate-3";

inline auth::Key AuthFuzzSensorKey(std::uint32_t epoch) {
  auth::Key site{};
  site.fill(static_cast<std::uint8_t>(0x40 + epoch));
  return auth::DeriveSensorKey(site, kAuthFuzzSensor);
}

inline auth::SensorKeys AuthFuzzKeys(std::uint32_t epoch) {
  return auth::DeriveSensorKeys(AuthFuzzSensorKey(epoch), epoch);
}

inline daemon::AuthOptions AuthFuzzOptions() {
  daemon::AuthOptions o;
  for (std::uint32_t epoch : {1u, 2u}) {
    auth::KeyFile k;
    k.kind = auth::KeyFile::Kind::kSensor;
    k.sensor_id = kAuthFuzzSensor;
    k.epoch = epoch;
    k.key = AuthFuzzSensorKey(epoch);
    o.keys.push_back(k);
  }
  return o;
}

}  // namespace lrfnet::fuzz
