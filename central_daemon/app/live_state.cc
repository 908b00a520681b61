#include "central_daemon/app/live_state.h"

#include <charconv>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string_view>

namespace lrfnet::daemon {
namespace {

// A small streaming writer instead of a JSON DOM: the message is built a few times a second with
// thousands of background points, and writing straight into one string keeps that cheap.
class Writer {
 public:
  explicit Writer(std::string& out) : out_(out) {}

  void Raw(std::string_view s) { out_.append(s); }
  void Key(std::string_view key) {
    Comma();
    Quoted(key);
    out_.push_back(':');
    first_ = true;  // the value that follows needs no comma
  }
  void BeginObject() { Open('{'); }
  void EndObject() { Close('}'); }
  void BeginArray() { Open('['); }
  void EndArray() { Close(']'); }

  // Coordinates: rounded to the millimetre, which also keeps the text short.
  void Metres(double v) { Fixed(v, 3); }
  // Angles: micro-radians are far below anything the page can show.
  void Radians(double v) { Fixed(v, 6); }
  // Rates, fractions, covariances: six significant digits.
  void Real(double v) {
    Comma();
    if (!std::isfinite(v)) {
      out_.append("null");
      return;
    }
    char buf[32];
    const auto r = std::to_chars(buf, buf + sizeof(buf), v, std::chars_format::general, 6);
    out_.append(buf, r.ptr);
  }
  void Int(std::int64_t v) { Integer(v); }
  void UInt(std::uint64_t v) { Integer(v); }
  void Bool(bool v) {
    Comma();
    out_.append(v ? "true" : "false");
  }
  void Null() {
    Comma();
    out_.append("null");
  }
  void String(std::string_view s) {
    Comma();
    Quoted(s);
  }

 private:
  void Quoted(std::string_view s) {
    out_.push_back('"');
    AppendEscaped(s);
    out_.push_back('"');
  }
  void Open(char c) {
    Comma();
    out_.push_back(c);
    first_ = true;
  }
  void Close(char c) {
    out_.push_back(c);
    first_ = false;
  }
  void Comma() {
    if (!first_) out_.push_back(',');
    first_ = false;
  }
  // `decimals` places, trailing zeros dropped ("1.5", "-0.25", "12"). Formatted as an integer
  // count of 10^-decimals: several times faster than a shortest-form double conversion, which
  // matters with thousands of background points per message.
  void Fixed(double v, int decimals) {
    Comma();
    if (!std::isfinite(v)) {
      out_.append("null");
      return;
    }
    std::int64_t unit = 1;
    for (int i = 0; i < decimals; ++i) unit *= 10;
    const double scaled = std::round(v * static_cast<double>(unit));
    char buf[32];
    if (!(std::fabs(scaled) < 9e15)) {  // beyond exact integers: no place for a fixed point
      const auto r = std::to_chars(buf, buf + sizeof(buf), v);
      out_.append(buf, r.ptr);
      return;
    }
    std::int64_t n = static_cast<std::int64_t>(scaled);
    if (n < 0) {
      out_.push_back('-');
      n = -n;
    }
    auto r = std::to_chars(buf, buf + sizeof(buf), n / unit);
    out_.append(buf, r.ptr);
    std::int64_t fraction = n % unit;
    if (fraction == 0) return;
    int places = decimals;
    while (fraction % 10 == 0) {
      fraction /= 10;
      --places;
    }
    out_.push_back('.');
    r = std::to_chars(buf, buf + sizeof(buf), fraction);
    out_.append(static_cast<std::size_t>(places - (r.ptr - buf)), '0');
    out_.append(buf, r.ptr);
  }
  template <typename T>
  void Integer(T v) {
    Comma();
    char buf[24];
    const auto r = std::to_chars(buf, buf + sizeof(buf), v);
    out_.append(buf, r.ptr);
  }

  // Length of the well-formed UTF-8 sequence at s[i], or 0 when it is not one (overlong forms,
  // surrogates and code points above U+10FFFF included): browsers fail a WebSocket whose text frame
  // is not valid UTF-8, so a hostile sensor id must not get through as raw bytes.
  static std::size_t Utf8Length(std::string_view s, std::size_t i) {
    const auto byte = [&](std::size_t k) { return static_cast<unsigned char>(s[k]); };
    const unsigned char c = byte(i);
    std::size_t n = 0;
    unsigned char lo = 0x80, hi = 0xBF;  // allowed range of the second byte
    if (c >= 0xC2 && c <= 0xDF) {
      n = 2;
    } else if (c >= 0xE0 && c <= 0xEF) {
      n = 3;
      if (c == 0xE0) lo = 0xA0;
      if (c == 0xED) hi = 0x9F;
    } else if (c >= 0xF0 && c <= 0xF4) {
      n = 4;
      if (c == 0xF0) lo = 0x90;
      if (c == 0xF4) hi = 0x8F;
    } else {
      return 0;
    }
    if (i + n > s.size()) return 0;
    if (byte(i + 1) < lo || byte(i + 1) > hi) return 0;
    for (std::size_t k = 2; k < n; ++k) {
      if (byte(i + k) < 0x80 || byte(i + k) > 0xBF) return 0;
    }
    return n;
  }

  void AppendEscaped(std::string_view s) {
    static constexpr char kHex[] = "0123456789abcdef";
    for (std::size_t i = 0; i < s.size();) {
      const unsigned char c = static_cast<unsigned char>(s[i]);
      if (c == '"' || c == '\\') {
        out_.push_back('\\');
        out_.push_back(static_cast<char>(c));
        ++i;
      } else if (c < 0x20 || c == 0x7F) {
        out_.append("\\u00");
        out_.push_back(kHex[c >> 4]);
        out_.push_back(kHex[c & 0xF]);
        ++i;
      } else if (c < 0x80) {
        out_.push_back(static_cast<char>(c));
        ++i;
      } else if (const std::size_t n = Utf8Length(s, i); n > 0) {
        out_.append(s.substr(i, n));
        i += n;
      } else {
        out_.append("\xEF\xBF\xBD");  // U+FFFD for each byte that is not part of valid UTF-8
        ++i;
      }
    }
  }

  std::string& out_;
  bool first_ = true;
};

void WriteCalibration(Writer& w, const LiveCalibration& c) {
  w.BeginObject();
  w.Key("state");
  w.String(c.state);
  w.Key("progress");
  w.Real(c.progress);
  w.Key("message");
  w.String(c.message);
  w.Key("reference");
  w.String(c.reference);
  w.Key("track_residual_rms_m");
  w.Real(c.track_residual_rms_m);
  w.EndObject();
}

// The monitoring state of a sensor: {"state","detail"}, or null when it is not watched.
void WriteMonitor(Writer& w, const LiveSensor& s) {
  w.Key("monitor");
  if (s.monitor_state.empty()) {
    w.Null();
    return;
  }
  w.BeginObject();
  w.Key("state");
  w.String(s.monitor_state);
  w.Key("detail");
  w.String(s.monitor_detail);
  w.EndObject();
}

// What the calibration says of a sensor, or null when there is none that names it.
void WriteSensorCalibration(Writer& w, const LiveSensor& s) {
  const LiveSensor::Calibration& c = s.calibration;
  w.Key("calibration");
  if (!c.calibrated) {
    w.Null();
    return;
  }
  w.BeginObject();
  w.Key("sigma_x_m");
  w.Real(c.sigma_x_m);
  w.Key("sigma_y_m");
  w.Real(c.sigma_y_m);
  w.Key("sigma_yaw_deg");
  w.Real(common::RadToDeg(c.sigma_yaw_rad));
  w.Key("radial_bias");
  if (c.has_radial_bias) {
    w.BeginObject();
    w.Key("m");
    w.Real(c.radial_bias_m);
    w.Key("sigma_m");
    w.Real(c.sigma_radial_bias_m);
    w.Key("estimated");
    w.Bool(c.radial_bias_estimated);
    w.EndObject();
  } else {
    w.Null();
  }
  w.Key("mount_looks_like_legs");
  w.Bool(c.mount_looks_like_legs);
  w.Key("flag");
  w.String(c.flag);
  w.EndObject();
}

void WriteSensor(Writer& w, const LiveSensor& s) {
  w.BeginObject();
  w.Key("id");
  w.String(s.id);
  w.Key("model");
  w.String(s.model);
  w.Key("placed");
  w.Bool(s.placed);
  w.Key("x_m");
  w.Metres(s.world_from_sensor.x_m);
  w.Key("y_m");
  w.Metres(s.world_from_sensor.y_m);
  w.Key("yaw_rad");
  w.Radians(s.world_from_sensor.yaw_rad);
  w.Key("first_angle_rad");
  w.Radians(s.first_angle_rad);
  w.Key("fov_rad");
  w.Radians(s.fov_rad);
  w.Key("max_range_m");
  w.Metres(s.max_range_m);
  w.Key("status");
  w.String(s.status);
  w.Key("datagram_rate_hz");
  w.Real(s.datagram_rate_hz);
  w.Key("loss");
  w.Real(s.loss);
  w.Key("clock_sync");
  w.String(s.clock_sync);
  w.Key("track_frames");
  w.UInt(s.track_frames);
  w.Key("background");
  w.BeginArray();
  for (const auto& p : s.background_xy) {
    w.BeginArray();
    w.Metres(p[0]);
    w.Metres(p[1]);
    w.EndArray();
  }
  w.EndArray();
  WriteMonitor(w, s);
  WriteSensorCalibration(w, s);
  w.EndObject();
}

// Position and velocity of a track (metres, metres per second; millimetre precision).
void WriteMotion(Writer& w, double x_m, double y_m, double vx_mps, double vy_mps) {
  w.Key("x_m");
  w.Metres(x_m);
  w.Key("y_m");
  w.Metres(y_m);
  w.Key("vx_mps");
  w.Metres(vx_mps);
  w.Key("vy_mps");
  w.Metres(vy_mps);
}

void WriteTrack(Writer& w, const LiveTrack& t) {
  w.BeginObject();
  w.Key("sensor");
  w.String(t.sensor_id);
  w.Key("id");
  w.UInt(t.track_id);
  w.Key("state");
  w.String(t.state);
  WriteMotion(w, t.x_m, t.y_m, t.vx_mps, t.vy_mps);
  w.Key("fused");
  if (t.fused_id) {
    w.UInt(*t.fused_id);
  } else {
    w.Null();
  }
  w.EndObject();
}

void WriteFused(Writer& w, const LiveFusedTrack& f) {
  w.BeginObject();
  w.Key("id");
  w.UInt(f.id);
  w.Key("state");
  w.String(f.state);
  WriteMotion(w, f.x_m, f.y_m, f.vx_mps, f.vy_mps);
  w.Key("cov_xx");
  w.Real(f.cov_xx);
  w.Key("cov_xy");
  w.Real(f.cov_xy);
  w.Key("cov_yy");
  w.Real(f.cov_yy);
  w.Key("sensors");
  w.BeginArray();
  for (const auto& id : f.sensors) w.String(id);
  w.EndArray();
  w.EndObject();
}

}  // namespace

std::string LiveStateJson(const LiveState& state) {
  std::size_t points = 0;
  for (const auto& s : state.sensors) points += s.background_xy.size();
  std::string out;
  // About 16 bytes per point and 200 per sensor or track: one allocation for typical messages.
  out.reserve(512 + 16 * points +
              256 * (state.sensors.size() + state.tracks.size() + state.fused.size()));
  Writer w(out);
  w.BeginObject();
  w.Key("type");
  w.String("state");
  w.Key("stamp_ns");
  w.Int(state.stamp_ns);
  w.Key("version");
  w.String(state.version);
  w.Key("authenticated");
  w.Bool(state.authenticated);
  w.Key("calibration");
  WriteCalibration(w, state.calibration);
  w.Key("sensors");
  w.BeginArray();
  for (const auto& s : state.sensors) WriteSensor(w, s);
  w.EndArray();
  w.Key("tracks");
  w.BeginArray();
  for (const auto& t : state.tracks) WriteTrack(w, t);
  w.EndArray();
  w.Key("fused");
  w.BeginArray();
  for (const auto& f : state.fused) WriteFused(w, f);
  w.EndArray();
  w.Key("hidden");
  w.BeginArray();
  for (const LiveHiddenTrack& h : state.hidden) {
    w.BeginObject();
    w.Key("id");
    w.UInt(h.id);
    w.Key("x_m");
    w.Metres(h.x_m);
    w.Key("y_m");
    w.Metres(h.y_m);
    w.Key("age_s");
    w.Metres(h.age_s);
    w.Key("sensor");
    w.String(h.sensor);
    w.EndObject();
  }
  w.EndArray();
  w.Key("zones");
  w.BeginArray();
  for (const LiveZone& z : state.zones) {
    w.BeginObject();
    w.Key("name");
    w.String(z.name);
    w.Key("kind");
    w.String(z.kind);
    w.Key("points");
    w.BeginArray();
    for (const auto& p : z.points) {
      w.BeginArray();
      w.Metres(p[0]);
      w.Metres(p[1]);
      w.EndArray();
    }
    w.EndArray();
    w.Key("occupancy");
    w.UInt(z.occupancy);
    w.Key("inbound");
    w.UInt(z.inbound);
    w.Key("outbound");
    w.UInt(z.outbound);
    w.EndObject();
  }
  w.EndArray();
  w.EndObject();
  return out;
}

}  // namespace lrfnet::daemon
