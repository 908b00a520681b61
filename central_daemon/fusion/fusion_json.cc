// The fused-track stream as JSON (FusedTracksJson, FusedTrackDatagrams of fusion.h).

#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "central_daemon/fusion/fusion.h"

namespace lrfnet::fusion {
namespace {

using Json = nlohmann::ordered_json;

// Rounds to a multiple of unit; non-finite values stay (the serializer writes them as null) and
// huge ones are written as they are (rounding would overflow to infinity).
double Rounded(double v, double per_unit) {
  if (!std::isfinite(v) || std::abs(v) > 1e12) return v;
  return std::round(v * per_unit) / per_unit;
}

std::string Dump(const Json& j) {
  // Sensor ids are not guaranteed UTF-8: replace invalid bytes instead of throwing.
  return j.dump(-1, ' ', false, Json::error_handler_t::replace);
}

Json TrackJson(const FusedTrack& t, bool with_sources) {
  Json j;
  j["id"] = t.id;
  j["state"] = ToString(t.state);
  j["x_m"] = Rounded(t.x_m, 1e3);
  j["y_m"] = Rounded(t.y_m, 1e3);
  j["vx_mps"] = Rounded(t.vx_mps, 1e3);
  j["vy_mps"] = Rounded(t.vy_mps, 1e3);
  j["cov_xy"] = Json::array({Rounded(t.covariance(0, 0), 1e6), Rounded(t.covariance(0, 1), 1e6),
                             Rounded(t.covariance(1, 1), 1e6)});
  if (with_sources) {
    Json sources = Json::array();
    for (const FusedSource& s : t.sources) {
      Json js;
      js["sensor"] = s.sensor_id;
      js["track"] = s.track_id;
      sources.push_back(std::move(js));
    }
    j["sources"] = std::move(sources);
  } else {
    j["sources"] = Json::array();
    j["sources_truncated"] = true;
  }
  return j;
}

std::string Prefix(common::UtcNs stamp_ns) {
  return "{\"type\":\"fused\",\"stamp_ns\":" + std::to_string(stamp_ns);
}

}  // namespace

std::string FusedTracksJson(const std::vector<FusedTrack>& tracks, common::UtcNs stamp_ns) {
  std::string out = Prefix(stamp_ns) + ",\"tracks\":[";
  for (std::size_t i = 0; i < tracks.size(); ++i) {
    if (i > 0) out += ',';
    out += Dump(TrackJson(tracks[i], true));
  }
  out += "]}";
  return out;
}

std::vector<std::string> FusedTrackDatagrams(const std::vector<FusedTrack>& tracks,
                                             common::UtcNs stamp_ns, std::size_t max_bytes) {
  // The datagrams are concatenations of complete JSON texts, so their sizes are known before
  // they are written: the header with part and parts at the widest they can be (one datagram per
  // track at most) plus the tracks and their commas.
  const std::string widest = std::to_string(tracks.size() + 1);
  const std::size_t header_bytes =
      (Prefix(stamp_ns) + ",\"part\":" + widest + ",\"parts\":" + widest + ",\"tracks\":[]}")
          .size();
  if (header_bytes > max_bytes) return {};
  const std::size_t room = max_bytes - header_bytes;

  std::vector<std::vector<std::string>> groups;
  std::size_t used = 0;
  for (const FusedTrack& t : tracks) {
    std::string text = Dump(TrackJson(t, true));
    if (text.size() > room) text = Dump(TrackJson(t, false));
    if (text.size() > room) continue;
    if (groups.empty() || used + 1 + text.size() > room) {
      groups.emplace_back();
      used = text.size();
    } else {
      used += 1 + text.size();
    }
    groups.back().push_back(std::move(text));
  }
  if (groups.empty()) groups.emplace_back();

  std::vector<std::string> out;
  out.reserve(groups.size());
  for (std::size_t part = 0; part < groups.size(); ++part) {
    std::string d = Prefix(stamp_ns) + ",\"part\":" + std::to_string(part) +
                    ",\"parts\":" + std::to_string(groups.size()) + ",\"tracks\":[";
    for (std::size_t i = 0; i < groups[part].size(); ++i) {
      if (i > 0) d += ',';
      d += groups[part][i];
    }
    d += "]}";
    out.push_back(std::move(d));
  }
  return out;
}

}  // namespace lrfnet::fusion
