#pragma once
// Configuration of lrfnet-tracker: every option of the link, the clock mapping, the tracking
// pipeline and the uplink, loaded from a YAML file (`--config FILE`) and printed with its
// documentation by `--print-config`. Command-line flags override the file.

#include <cstdint>
#include <optional>
#include <string>

#include "common/config_yaml.h"
#include "firmware_tracker/io/sick_client.h"
#include "firmware_tracker/io/system_clock.h"
#include "firmware_tracker/tracking/clock_mapper.h"
#include "firmware_tracker/tracking/pipeline.h"

namespace lrfnet::tracker {

using common::ConfigVisitor;

// When and what the tracker publishes (see TrackerNode).
struct PublishOptions {
  std::uint32_t frame_every_n_scans = 1;   // track frames of every n-th scan (1: every scan)
  double health_period_s = 1.0;            // Health datagram period
  double snapshot_period_s = 30.0;         // background snapshot at least this often
  double snapshot_min_interval_s = 2.0;    // and at most this often when the background changes
  // A new snapshot when this fraction of beams changed by more than the background margin since
  // the last one (a door opened, a cart parked).
  double snapshot_change_fraction = 0.01;
};
std::optional<std::string> Validate(const PublishOptions& options);

struct TrackerConfig {
  std::string sensor_id;        // [A-Za-z0-9_.-]{1,32}
  std::string sensor_address;   // HOST[:PORT] of the scanner (live)
  std::string uplink_address;   // HOST:PORT of lrfnetd (empty: no UDP)
  std::string key_file;         // this sensor's key file (empty: datagrams are not sealed)
  bool encrypt = false;         // encrypt the payload of the sealed datagrams
  io::SickClientOptions link;
  tracking::ClockMapperOptions clock;
  io::ClockStatusOptions clock_status;
  tracking::TrackerOptions tracking;
  PublishOptions publish;
};

// Lists every option of `config` (sections sensor, auth, link, clock, background, segmentation,
// measurement, shape, tracking, publish).
void VisitTrackerConfig(TrackerConfig& config, ConfigVisitor& visitor);

// Every option, with the prefix of its section ("tracking.confirm_hits: must be ...").
std::optional<std::string> Validate(const TrackerConfig& config);

// Loads a YAML document over `config` and validates the result.
std::optional<std::string> LoadTrackerConfig(std::string_view yaml_text, TrackerConfig& config);

// The documented YAML of `config` (the defaults for a default-constructed one).
std::string PrintTrackerConfig(const TrackerConfig& config);

}  // namespace lrfnet::tracker
