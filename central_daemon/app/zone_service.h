#pragma once
// lrfnetd's zones (an adapter around zones::ZoneCounter): the fused tracks are run through the
// zones of the config at zones.update_hz of fused-track time (gateway UTC scan times, so a
// recording replayed offline counts exactly like the live stream). Confirmed and coasting fused
// tracks count; coasting ones keep their state. The fuser's output says which ids it keeps
// without publishing them (held: a hidden person stays where it was last seen) and which ended and
// why (a merged id is folded into the id that goes on, any other is gone at once); an id it says
// nothing of is held for zones.absent_hold_s (see zones.h). When the fusion starts afresh (new
// options, or disabled: FusionService::generation) every id known is gone. The output is the
// fusion service's shared one (FusionService::Output).
// Thread-safety: called on the io thread.

#include <optional>
#include <vector>

#include "central_daemon/app/config.h"
#include "central_daemon/app/fusion_service.h"
#include "central_daemon/zones/zones.h"

namespace lrfnet::daemon {

class ZoneService {
 public:
  explicit ZoneService(const DaemonConfig& config);

  bool enabled() const { return counter_.has_value(); }
  // Evaluates the zones when due. True when it did.
  bool OnTick(const FusionService& fusion);

  // As of the last evaluation (empty when disabled).
  std::vector<zones::ZoneState> States() const;
  const std::vector<zones::Zone>& zones() const { return zones_; }
  common::UtcNs stamp_ns() const { return stamp_ns_; }
  std::uint64_t updates() const { return updates_; }
  // What became of absent ids (zeros when disabled).
  zones::ZoneCounters counters() const {
    return counter_ ? counter_->counters() : zones::ZoneCounters{};
  }

 private:
  std::vector<zones::Zone> zones_;
  std::optional<zones::ZoneCounter> counter_;
  common::DurationNs period_ns_;
  common::UtcNs stamp_ns_ = 0;
  std::uint64_t updates_ = 0;
  std::uint64_t generation_ = 0;  // the fusion's, as of the last evaluation
};

}  // namespace lrfnet::daemon
