#include "central_daemon/app/fusion_service.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <boost/asio/ip/address.hpp>
#include <cerrno>
#include <cmath>
#include <cstring>

#include "central_daemon/ingest/sensor_data.h"
#include "common/geometry.h"
#include "common/host_port.h"

namespace lrfnet::daemon {

std::vector<fusion::SensorPlacement> PlacementsOf(const calib::CalibrationResult& result) {
  std::vector<fusion::SensorPlacement> out;
  for (const calib::SensorPose& s : result.sensors) {
    if (!s.calibrated) continue;
    fusion::SensorPlacement p;
    p.id = s.id;
    p.world_from_sensor = s.world_from_sensor;
    p.covariance = s.covariance;
    out.push_back(std::move(p));
  }
  return out;
}

FusionService::FusionService(boost::asio::io_context& io, const DaemonConfig& config)
    : io_(io), config_(config), fuser_(config.fusion) {}

FusionService::~FusionService() { Close(); }

std::string FusionService::Open() {
  if (!config_.fusion_publish.empty()) {
    std::string error;
    const auto hp = common::ParseHostPort(config_.fusion_publish, "fusion.publish", 0, &error);
    if (!hp) return error;
    boost::system::error_code ec;
    const boost::asio::ip::address address = boost::asio::ip::make_address(hp->host, ec);
    if (ec) return "fusion.publish: '" + hp->host + "' is not an IP address";
    destination_ = boost::asio::ip::udp::endpoint(address, hp->port);
    socket_.emplace(io_);
    socket_->open(destination_.protocol(), ec);
    if (ec) return "fusion.publish: " + ec.message();
    socket_->non_blocking(true, ec);
  }
  if (!config_.fusion_record.empty()) {
    record_ = std::fopen(config_.fusion_record.c_str(), "ae");
    if (record_ == nullptr) {
      return "fusion.record: cannot open '" + config_.fusion_record + "': " + std::strerror(errno);
    }
  }
  return "";
}

void FusionService::Reconfigure(const DaemonConfig& config) {
  // Disabled, the fuser gets no frames and no Tick: its ids would neither go on nor end. A new
  // fuser ends every one of them for the zones and MQTT (the generation), cleanly, at once.
  const bool disabled = config_.fusion_enabled && !config.fusion_enabled;
  config_.fusion_enabled = config.fusion_enabled;
  config_.fusion_publish_hz = config.fusion_publish_hz;
  // ended_report_s only says how long ends are reported: the fuser keeps its tracks for it.
  fusion::FusionOptions others = config.fusion;
  others.ended_report_s = config_.fusion.ended_report_s;
  if (others == config_.fusion && !disabled) {
    if (config.fusion.ended_report_s != config_.fusion.ended_report_s) {
      Invalidate();
      fuser_.SetEndedReportS(config.fusion.ended_report_s);
      config_.fusion.ended_report_s = config.fusion.ended_report_s;
    }
    return;  // the fuser keeps its tracks
  }
  config_.fusion = config.fusion;
  Restart();
  if (disabled) {
    spdlog::info("fusion: disabled, every fused track ends");
  } else {
    spdlog::info("fusion: options changed, fused tracks start afresh (method {})",
                 fusion::ToString(config_.fusion.method));
  }
}

void FusionService::Restart() {
  // The new fuser's ids go on from the old one's: an id is never given twice in a run, so a
  // consumer that missed the restart cannot take a new object for an old one.
  const std::uint64_t next_id = fuser_.next_id();
  Invalidate();
  fuser_ = fusion::Fuser(config_.fusion);
  fuser_.ContinueIdsFrom(next_id);
  ++generation_;
  SetExcluded(excluded_);  // the placements without the excluded sensors
  for (const auto& [sensor_id, psd] : tracker_accel_psd_) fuser_.SetTrackerModel(sensor_id, psd);
}

void FusionService::SetCalibration(const calib::CalibrationResult& result) {
  placements_ = PlacementsOf(result);
  calibrated_ = true;
  ++counters_.calibrations;
  SetExcluded(excluded_);
}

void FusionService::SetExcluded(const std::set<std::string>& sensor_ids) {
  excluded_ = sensor_ids;
  std::vector<fusion::SensorPlacement> placed;
  for (const fusion::SensorPlacement& p : placements_) {
    if (excluded_.count(p.id) == 0) placed.push_back(p);
  }
  if (calibrated_) {
    Invalidate();
    fuser_.SetPlacements(placed);
  }
}

void FusionService::OnSensorInfo(const std::string& sensor_id, const SensorDescription& info) {
  // 0: an older tracker that does not say; the fuser then assumes fusion.tracker_accel_psd.
  tracker_accel_psd_[sensor_id] = info.accel_psd_m2ps3;
  Invalidate();
  fuser_.SetTrackerModel(sensor_id, info.accel_psd_m2ps3);
}

void FusionService::OnFrame(const std::string& sensor_id, const TrackFrameData& frame) {
  now_ns_ = std::max(now_ns_, frame.scan_start_ns);
  if (calibrated_ && config_.fusion_enabled && excluded_.count(sensor_id) == 0) {
    Invalidate();
    fuser_.AddFrame(sensor_id, frame);
  }
}

void FusionService::OnTick(double now_s) {
  if (!calibrated_ || !config_.fusion_enabled) return;
  // Timer jitter: a publish counts as due slightly early.
  if (last_publish_s_ && now_s - *last_publish_s_ < 0.9 / config_.fusion_publish_hz &&
      now_s >= *last_publish_s_)
    return;
  last_publish_s_ = now_s;
  Publish();
}

void FusionService::Publish() {
  if (now_ns_ == 0) return;
  Invalidate();
  fuser_.Tick(now_ns_);
  const std::vector<fusion::FusedTrack>& tracks = PeekOutput().tracks;
  ++counters_.publishes;
  if (socket_) {
    for (const std::string& datagram : fusion::FusedTrackDatagrams(tracks, now_ns_)) {
      boost::system::error_code ec;
      socket_->send_to(boost::asio::buffer(datagram), destination_, 0, ec);
      if (ec) {
        if (counters_.send_errors++ == 0) {
          spdlog::warn("fusion: sending to {}: {}", config_.fusion_publish, ec.message());
        }
      } else {
        ++counters_.datagrams_sent;
      }
    }
  }
  if (record_ != nullptr) {
    const std::string line = fusion::FusedTracksJson(tracks, now_ns_) + "\n";
    if (std::fwrite(line.data(), 1, line.size(), record_) != line.size() ||
        std::fflush(record_) != 0) {
      if (counters_.record_errors++ == 0) {
        spdlog::error("fusion: writing {}: {}", config_.fusion_record, std::strerror(errno));
      }
    } else {
      ++counters_.lines_recorded;
    }
  }
}

const fusion::FusionOutput& FusionService::CachedOrFresh(bool mark) const {
  using EndsRead = fusion::Fuser::EndsRead;
  if (!output_ || output_->now_ns != now_ns_ || output_->generation != generation_) {
    output_ =
        CachedOutput{now_ns_, generation_,
                     fuser_.Output(now_ns_, false, mark ? EndsRead::kMark : EndsRead::kPeek), mark};
    ++counters_.outputs_computed;
  } else if (mark && !output_->ends_marked) {
    // Computed for a look: the same ends, read now.
    fuser_.MarkEndsRead(now_ns_);
    output_->ends_marked = true;
  }
  return output_->output;
}

const fusion::FusionOutput& FusionService::Output() const { return CachedOrFresh(true); }

const fusion::FusionOutput& FusionService::PeekOutput() const { return CachedOrFresh(false); }

void FusionService::Close() {
  if (record_ != nullptr) {
    std::fclose(record_);
    record_ = nullptr;
  }
  if (socket_) {
    boost::system::error_code ec;
    socket_->close(ec);
    socket_.reset();
  }
}

nlohmann::json FusionService::StatsJson() const {
  nlohmann::json j;
  j["enabled"] = config_.fusion_enabled;
  j["calibrated"] = calibrated_;
  j["excluded"] = excluded_;
  j["publishes"] = counters_.publishes;
  j["datagrams_sent"] = counters_.datagrams_sent;
  j["send_errors"] = counters_.send_errors;
  j["lines_recorded"] = counters_.lines_recorded;
  j["record_errors"] = counters_.record_errors;
  j["calibrations"] = counters_.calibrations;
  j["outputs_computed"] = counters_.outputs_computed;
  const fusion::FusionCounters& f = fuser_.counters();
  j["frames"] = f.frames;
  j["frames_unplaced"] = f.frames_unplaced;
  j["frames_out_of_order"] = f.frames_out_of_order;
  j["observations"] = f.observations;
  j["observations_invalid"] = f.observations_invalid;
  j["fused_created"] = f.fused_created;
  j["fused_merged"] = f.fused_merged;
  j["ended_evicted"] = f.ended_evicted;
  j["fused_merged_sourceless"] = f.fused_merged_sourceless;
  j["merge_checks_spread"] = f.merge_checks_spread;
  j["merge_sourceless_shadowed"] = f.merge_sourceless_shadowed;
  j["fused_unreported_sourceless"] = f.fused_unreported_sourceless;
  j["handovers"] = f.handovers;
  j["numerical_failures"] = f.numerical_failures;
  nlohmann::json biases = nlohmann::json::array();
  for (const fusion::SensorBias& b : fuser_.sensor_biases()) {
    nlohmann::json x;
    x["sensor_id"] = b.sensor_id;
    x["kind"] = ToString(b.kind);
    x["radial_m"] = b.radial_m;
    x["sigma_m"] = b.sigma_m;
    x["dx_m"] = b.dx_m;
    x["dy_m"] = b.dy_m;
    x["dyaw_deg"] = common::RadToDeg(b.dyaw_rad);
    x["sigma_x_m"] = std::sqrt(std::max(0.0, b.pose_covariance(0, 0)));
    x["sigma_y_m"] = std::sqrt(std::max(0.0, b.pose_covariance(1, 1)));
    x["sigma_yaw_deg"] = common::RadToDeg(std::sqrt(std::max(0.0, b.pose_covariance(2, 2))));
    x["samples"] = b.samples;
    x["applied"] = b.applied;
    x["offset_applied"] = b.offset_applied;
    biases.push_back(std::move(x));
  }
  j["sensor_biases"] = std::move(biases);
  return j;
}

}  // namespace lrfnet::daemon
