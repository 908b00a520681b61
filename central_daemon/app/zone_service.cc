#include "central_daemon/app/zone_service.h"

namespace lrfnet::daemon {

ZoneService::ZoneService(const DaemonConfig& config)
    : zones_(config.zones),
      period_ns_(static_cast<common::DurationNs>(1e9 / config.zones_update_hz)) {
  if (!zones_.empty()) counter_.emplace(zones_, config.zone_options);
}

bool ZoneService::OnTick(const FusionService& fusion) {
  if (!counter_ || !fusion.calibrated()) return false;
  const common::UtcNs now_ns = fusion.now_ns();
  if (now_ns == 0) return false;
  // Timer jitter: due slightly early counts. A clock step back restarts the rhythm.
  if (updates_ > 0 && now_ns >= stamp_ns_ && now_ns - stamp_ns_ < period_ns_ * 9 / 10) return false;
  if (fusion.generation() != generation_) {
    if (updates_ > 0) counter_->EndAll(now_ns);
    generation_ = fusion.generation();
  }
  const fusion::FusionOutput& output = fusion.Output();
  std::vector<zones::ZoneTrack> tracks;
  tracks.reserve(output.tracks.size());
  for (const fusion::FusedTrack& t : output.tracks) {
    tracks.push_back({t.id, t.x_m, t.y_m, t.state != fusion::FusedState::kCoasting});
  }
  std::vector<std::uint64_t> hidden;
  hidden.reserve(output.hidden.size());
  for (const fusion::HiddenFusedTrack& h : output.hidden) hidden.push_back(h.id);
  std::vector<zones::ZoneEnded> ended;
  ended.reserve(output.ended.size());
  for (const fusion::EndedFusedTrack& e : output.ended) ended.push_back({e.id, e.merged_into});
  if (!counter_->Update(tracks, hidden, ended, now_ns)) return false;
  stamp_ns_ = now_ns;
  ++updates_;
  return true;
}

std::vector<zones::ZoneState> ZoneService::States() const {
  return counter_ ? counter_->States() : std::vector<zones::ZoneState>{};
}

}  // namespace lrfnet::daemon
