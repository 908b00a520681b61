#include "central_daemon/ingest/datagram_verifier.h"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>

namespace lrfnet::daemon {

struct DatagramVerifier::Sensor {
  std::vector<auth::SensorKeys> keys;  // one per epoch
  auth::ReplayWindow window;
  std::uint32_t epoch = 0;    // newest epoch accepted (0: none yet)
  bool has_state = false;     // a datagram was accepted, or a state restored
  std::uint64_t counter = 0;  // highest counter accepted or restored

  const auth::SensorKeys* KeysOf(std::uint32_t e) const {
    for (const auth::SensorKeys& k : keys) {
      if (k.epoch == e) return &k;
    }
    return nullptr;
  }
};

const char* ToString(AuthFailure failure) {
  switch (failure) {
    case AuthFailure::kNone:
      return "ok";
    case AuthFailure::kUnsigned:
      return "unsigned";
    case AuthFailure::kHeader:
      return "auth_header";
    case AuthFailure::kUnknownSensor:
      return "unknown_sensor";
    case AuthFailure::kWrongEpoch:
      return "wrong_epoch";
    case AuthFailure::kWrongKey:
      return "wrong_key";
    case AuthFailure::kAhead:
      return "timestamp";
    case AuthFailure::kReplayed:
      return "replayed";
    case AuthFailure::kStale:
      return "stale";
    case AuthFailure::kBadTag:
      return "bad_tag";
    case AuthFailure::kEncrypted:
      return "encrypted";
  }
  return "invalid";
}

std::optional<std::string> Validate(const AuthOptions& o) {
  for (std::size_t i = 0; i < o.keys.size(); ++i) {
    const auth::KeyFile& k = o.keys[i];
    if (k.kind != auth::KeyFile::Kind::kSensor || !auth::IsValidSensorId(k.sensor_id))
      return "keys: not a sensor key";
    for (std::size_t j = 0; j < i; ++j) {
      if (o.keys[j].sensor_id == k.sensor_id && o.keys[j].epoch == k.epoch)
        return "keys: two keys of sensor '" + k.sensor_id + "' for epoch " +
               std::to_string(k.epoch);
    }
  }
  if (!(std::isfinite(o.max_counter_ahead_s) && o.max_counter_ahead_s >= 0.0 &&
        o.max_counter_ahead_s <= 1e9))
    return "max_counter_ahead_s must be in [0, 1e9]";
  return std::nullopt;
}

std::string FormatAuthState(const std::vector<StoredAuthState>& state) {
  std::string text =
      "# lrfnetd: per sensor the newest key epoch and the highest counter accepted; datagrams "
      "at or\n# below it are refused after a restart.\n";
  for (const StoredAuthState& s : state) {
    text += s.sensor_id + " " + std::to_string(s.epoch) + " " + std::to_string(s.counter) + "\n";
  }
  return text;
}

std::optional<std::string> ParseAuthState(std::string_view text,
                                          std::vector<StoredAuthState>* out) {
  std::vector<StoredAuthState> state;
  std::size_t line_number = 0;
  while (!text.empty()) {
    const std::size_t end = text.find('\n');
    const std::string_view line = text.substr(0, end);
    text = end == std::string_view::npos ? std::string_view() : text.substr(end + 1);
    ++line_number;
    if (line.empty() || line.front() == '#') continue;
    const std::string where = "line " + std::to_string(line_number);
    const std::size_t a = line.find(' ');
    const std::size_t b = a == std::string_view::npos ? a : line.find(' ', a + 1);
    if (b == std::string_view::npos) return where + ": expected 'sensor_id epoch counter'";
    StoredAuthState s;
    s.sensor_id.assign(line.substr(0, a));
    if (!auth::IsValidSensorId(s.sensor_id)) return where + ": bad sensor id";
    const std::string_view epoch = line.substr(a + 1, b - a - 1);
    const std::string_view counter = line.substr(b + 1);
    const auto e = std::from_chars(epoch.data(), epoch.data() + epoch.size(), s.epoch);
    const auto c = std::from_chars(counter.data(), counter.data() + counter.size(), s.counter);
    if (e.ec != std::errc() || e.ptr != epoch.data() + epoch.size() || c.ec != std::errc() ||
        c.ptr != counter.data() + counter.size())
      return where + ": epoch and counter must be numbers";
    state.push_back(std::move(s));
  }
  *out = std::move(state);
  return std::nullopt;
}

DatagramVerifier::DatagramVerifier(const AuthOptions& options)
    : options_(options), request_counter_(options.request_first_counter) {
  if (const auto error = Validate(options)) {
    std::fprintf(stderr, "DatagramVerifier: invalid options: %s\n", error->c_str());
    std::abort();
  }
  if (!auth::Init() && !options.keys.empty()) {
    std::fprintf(stderr, "DatagramVerifier: libsodium cannot be initialised\n");
    std::abort();
  }
  for (const auth::KeyFile& k : options_.keys) {
    auto it = sensors_.find(k.sensor_id);
    if (it == sensors_.end()) it = sensors_.emplace(k.sensor_id, std::make_unique<Sensor>()).first;
    it->second->keys.push_back(auth::DeriveSensorKeys(k.key, k.epoch));
  }
}

DatagramVerifier::~DatagramVerifier() = default;

AuthResult DatagramVerifier::Verify(std::span<const std::uint8_t> bytes, common::UtcNs receive_ns) {
  AuthResult r;
  const auto fail = [&](AuthFailure failure, std::string detail) {
    r.failure = failure;
    r.payload = {};
    r.detail = std::move(detail);
    return r;
  };
  if (!auth::LooksSealed(bytes)) {
    if (enabled()) return fail(AuthFailure::kUnsigned, "not sealed, and keys are configured");
    r.payload = bytes;
    return r;
  }
  r.sealed = true;
  auth::Envelope e;
  if (const auth::HeaderError error = auth::ParseEnvelope(bytes, &e);
      error != auth::HeaderError::kNone) {
    return fail(AuthFailure::kHeader, std::string("envelope: ") + auth::ToString(error));
  }
  r.sensor_id = e.sensor_id;
  r.epoch = e.epoch;
  r.counter = e.counter;
  if (e.direction != auth::Direction::kToDaemon)
    return fail(AuthFailure::kHeader, "envelope sealed for a tracker, not for the daemon");
  if (e.payload.size() > plain_.size()) return fail(AuthFailure::kHeader, "envelope too large");
  if (!enabled()) {
    if (e.encrypted) return fail(AuthFailure::kEncrypted, "encrypted, and no keys are configured");
    r.payload = e.payload;  // read, not verified
    return r;
  }
  const auto it = sensors_.find(e.sensor_id);
  if (it == sensors_.end()) return fail(AuthFailure::kUnknownSensor, "no key for this sensor");
  const Sensor& sensor = *it->second;
  const auth::SensorKeys* keys = sensor.KeysOf(e.epoch);
  if (keys == nullptr)
    return fail(AuthFailure::kWrongEpoch, "no key of epoch " + std::to_string(e.epoch));
  if (sensor.has_state && e.epoch < sensor.epoch) {
    return fail(AuthFailure::kWrongEpoch, "epoch " + std::to_string(e.epoch) +
                                              " is older than the epoch in use (" +
                                              std::to_string(sensor.epoch) + ")");
  }
  if (e.key_id != keys->key_id)
    return fail(AuthFailure::kWrongKey, "sealed with another key than this sensor's");
  if (options_.max_counter_ahead_s > 0.0 && receive_ns > 0) {
    const auto limit = static_cast<long double>(receive_ns) +
                       static_cast<long double>(options_.max_counter_ahead_s) * 1e9L;
    if (static_cast<long double>(e.counter) > limit)
      return fail(AuthFailure::kAhead, "counter (the sender's start time) is in the future");
  }
  switch (sensor.window.Check(e.counter)) {
    case auth::ReplayWindow::Verdict::kReplayed:
      return fail(AuthFailure::kReplayed, "counter " + std::to_string(e.counter) + " seen before");
    case auth::ReplayWindow::Verdict::kTooOld:
      return fail(AuthFailure::kStale, "counter " + std::to_string(e.counter) +
                                           " older than the window or the stored state");
    case auth::ReplayWindow::Verdict::kFresh:
      break;
  }
  std::span<const std::uint8_t> payload;
  if (!auth::OpenEnvelope(e, *keys, plain_, &payload))
    return fail(AuthFailure::kBadTag, "tag does not verify");
  r.verified = true;
  r.payload = payload;
  return r;
}

void DatagramVerifier::Commit(const AuthResult& result) {
  if (!result.ok() || !result.verified) return;
  const auto it = sensors_.find(result.sensor_id);
  if (it == sensors_.end()) return;
  Sensor& s = *it->second;
  s.window.Commit(result.counter);
  if (!s.has_state || result.epoch > s.epoch) s.epoch = result.epoch;
  if (!s.has_state || result.counter > s.counter) s.counter = result.counter;
  s.has_state = true;
  ++changes_;
}

std::size_t DatagramVerifier::SealRequest(std::string_view sensor_id,
                                          std::span<const std::uint8_t> payload,
                                          std::span<std::uint8_t> out) {
  const auto it = sensors_.find(sensor_id);
  if (it == sensors_.end() || !it->second->has_state) return 0;
  const auth::SensorKeys* keys = it->second->KeysOf(it->second->epoch);
  if (keys == nullptr) return 0;
  auth::SealerOptions o;
  o.sensor_id = std::string(sensor_id);
  o.keys = *keys;
  o.direction = auth::Direction::kToTracker;
  o.salt = options_.request_salt;
  o.first_counter = request_counter_;
  auth::Sealer sealer(o);
  const std::size_t n = sealer.Seal(payload, out);
  if (n > 0) ++request_counter_;  // one counter for all sensors: unique per key as well
  return n;
}

std::vector<StoredAuthState> DatagramVerifier::State() const {
  std::vector<StoredAuthState> out;
  for (const auto& [id, s] : sensors_) {
    if (!s->has_state) continue;
    out.push_back({id, s->epoch, s->counter});
  }
  return out;
}

void DatagramVerifier::Restore(const std::vector<StoredAuthState>& state) {
  for (const StoredAuthState& stored : state) {
    const auto it = sensors_.find(stored.sensor_id);
    if (it == sensors_.end()) continue;
    Sensor& s = *it->second;
    s.window.SetFloor(stored.counter);
    if (!s.has_state || stored.epoch > s.epoch) s.epoch = stored.epoch;
    if (!s.has_state || stored.counter > s.counter) s.counter = stored.counter;
    s.has_state = true;
  }
}

}  // namespace lrfnet::daemon
