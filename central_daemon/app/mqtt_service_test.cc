// lrfnetd's zones and MQTT output with a fused id that leaves the fused tracks and comes back
// (fusion.report_sourceless off: a person no tracker holds is not published until a sensor sees
// them again), through a real mosquitto broker (skipped when it is not installed).

#include "central_daemon/app/mqtt_service.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <boost/asio/io_context.hpp>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <set>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "central_daemon/app/calibration_service.h"
#include "central_daemon/app/config.h"
#include "central_daemon/app/daemon.h"
#include "central_daemon/app/fusion_service.h"
#include "central_daemon/app/live_feed.h"
#include "central_daemon/app/monitoring_service.h"
#include "central_daemon/app/mqtt_output.h"
#include "central_daemon/app/run_report.h"
#include "central_daemon/app/zone_service.h"
#include "central_daemon/io/mqtt_publisher.h"
#include "tests/mosquitto_broker.h"
#include "tests/mqtt_subscriber.h"

namespace lrfnet::daemon {
namespace {

using lrfnet::testing::MosquittoBroker;
using lrfnet::testing::MqttSubscriber;
using lrfnet::testing::ReceivedMessage;

constexpr common::UtcNs kT0 = 1'700'000'000'000'000'000;

common::UtcNs At(double t_s) { return kT0 + static_cast<common::DurationNs>(t_s * 1e9); }

calib::CalibrationResult OneSensorAtTheOrigin() {
  calib::CalibrationResult r;
  r.method = "quenzel";
  r.reference = "s1";
  calib::SensorPose p;
  p.id = "s1";
  p.calibrated = true;
  p.covariance = Eigen::Matrix3d::Identity() * 1e-6;
  r.sensors.push_back(p);
  return r;
}

// A standing person's track at (x, y) in the sensor's frame.
TrackObservation Standing(std::uint32_t track_id, double x_m = 3.0, double y_m = 1.0) {
  TrackObservation track;
  track.track_id = track_id;
  track.state = TrackState::kConfirmed;
  track.x_m = static_cast<float>(x_m);
  track.y_m = static_cast<float>(y_m);
  track.covariance = {0.0025f, 0, 0, 0, 0.0025f, 0, 0, 0.01f, 0, 0.01f};
  return track;
}

TrackFrameData FrameWith(double t_s, std::uint32_t scan, std::vector<TrackObservation> tracks) {
  TrackFrameData frame;
  frame.session_id = 1;
  frame.scan_start_ns = At(t_s);
  frame.scan_period_s = 0.04;
  frame.scan_counter = scan;
  frame.tracks = std::move(tracks);
  return frame;
}

struct HideRun {
  std::vector<nlohmann::json> zone;     // the zone's messages, in order
  std::vector<nlohmann::json> objects;  // the object lists, in order
  std::vector<nlohmann::json> ended;    // the objects/ended messages, in order
  MqttServiceCounters counters;
  nlohmann::json zone_stats;  // --stats-out's "zones"
};

using TracksAt = std::function<std::vector<TrackObservation>(double t_s)>;
HideRun RunScene(std::uint16_t port, double absent_hold_s, const TracksAt& tracks_at);

// One sensor at the origin sees a person standing at (3, 1), inside the zone "room". Its tracker
// drops the person at 2 s and starts a new track on them hidden_s later (the fused id is left out
// of the fused tracks once the old track timed out, and taken up again by the new track when it
// comes within fusion.max_coast_s). Everything runs through lrfnetd's fusion, zones and MQTT
// services, published to a real broker; returns what a subscriber received.
HideRun RunHide(std::uint16_t port, double hidden_s, double absent_hold_s) {
  return RunScene(port, absent_hold_s, [hidden_s](double t) {
    std::vector<TrackObservation> tracks;
    if (t < 2.0) tracks.push_back(Standing(1));
    if (t >= 2.0 + hidden_s) tracks.push_back(Standing(2));
    return tracks;
  });
}

// The same services and broker on the tracks tracks_at gives the sensor every 0.04 s for 8 s.
HideRun RunScene(std::uint16_t port, double absent_hold_s, const TracksAt& tracks_at) {
  DaemonConfig config;
  config.zones_list = "[{name: room, polygon: [[2, 0], [4, 0], [4, 2], [2, 2]]}]";
  config.absent_hold_s = absent_hold_s;
  config.fusion.report_sourceless = false;
  config.mqtt.broker = "127.0.0.1:" + std::to_string(port);
  static int runs = 0;  // a site of its own per run: the zone messages are retained
  config.mqtt.site = "lab" + std::to_string(++runs);
  config.mqtt.client_id = "lrfnet-service-test-" + std::to_string(::getpid());
  config.mqtt.objects_hz = 10.0;
  config.mqtt.path_points = 40;  // 20 s of path
  EXPECT_EQ(Validate(config), std::nullopt);

  const std::string topics = "lrfnet/" + config.mqtt.site + "/";
  MqttSubscriber subscriber(port, topics + "#");
  EXPECT_TRUE(subscriber.WaitSubscribed());
  DaemonOptions options;
  options.send_requests = false;
  Daemon daemon(options, nullptr, nullptr, 1);
  boost::asio::io_context io;
  FusionService fusion(io, config);
  fusion.SetCalibration(OneSensorAtTheOrigin());
  ZoneService zones(config);
  MqttPublisherSink sink(nullptr);
  MqttService mqtt(config, &sink, "test");
  MqttPublisher real(PublisherOptions(config, mqtt));
  sink.set_publisher(&real);
  std::string error;
  EXPECT_TRUE(real.Start(&error)) << error;
  EXPECT_TRUE(real.WaitConnected(20.0)) << real.last_error();

  std::uint32_t scan = 0;
  for (double t = 0.0; t < 8.0 - 1e-9; t += 0.04) {
    fusion.OnFrame("s1", FrameWith(t, scan++, tracks_at(t)));
    if (scan % 5 == 0) {  // every 0.2 s
      fusion.OnTick(t);
      zones.OnTick(fusion);
      mqtt.OnTick(At(t), daemon, fusion, zones);
      // Sent before the next (a retained message still queued is replaced by a newer one).
      EXPECT_TRUE(real.Flush(5.0));
    }
  }
  EXPECT_TRUE(real.Flush(20.0));
  const std::size_t sent =
      mqtt.counters().objects + mqtt.counters().zones + mqtt.counters().objects_ended_messages;
  EXPECT_TRUE(subscriber.WaitFor([&](const std::vector<ReceivedMessage>& m) {
    std::size_t n = 0;
    for (const ReceivedMessage& r : m) n += r.topic.ends_with("/health") ? 0 : 1;
    return n >= sent;
  })) << "sent "
      << sent << ", received " << subscriber.messages().size();
  real.Stop();
  HideRun run;
  for (const ReceivedMessage& m : subscriber.messages()) {
    if (m.topic == topics + "zones/room") run.zone.push_back(nlohmann::json::parse(m.payload));
    if (m.topic == topics + "objects") run.objects.push_back(nlohmann::json::parse(m.payload));
    if (m.topic == topics + "objects/ended") run.ended.push_back(nlohmann::json::parse(m.payload));
  }
  run.counters = mqtt.counters();
  // What --stats-out says of the zones' hold.
  const std::filesystem::path stats =
      std::filesystem::temp_directory_path() /
      ("lrfnet-hide-stats-" + std::to_string(::getpid()) + "-" + config.mqtt.site + ".json");
  MonitoringService monitoring(config);
  EXPECT_TRUE(
      WriteStats(stats.string(), daemon, nullptr, nullptr, monitoring, nullptr, &fusion, &zones));
  std::ifstream in(stats);
  run.zone_stats = nlohmann::json::parse(in).at("zones");
  std::filesystem::remove(stats);
  return run;
}

// The ids present in each zone message, and the exits it reports (lost inside, dwells ended).
std::vector<std::set<std::uint64_t>> PresentIds(const HideRun& run) {
  std::vector<std::set<std::uint64_t>> out;
  for (const nlohmann::json& z : run.zone) {
    std::set<std::uint64_t> ids;
    for (const auto& p : z["present"]) ids.insert(p["id"].get<std::uint64_t>());
    out.push_back(ids);
  }
  return out;
}

// The number of times an id leaves the zone's present list and later comes back to it.
int ExitEnterPairs(const std::vector<std::set<std::uint64_t>>& present) {
  int pairs = 0;
  std::set<std::uint64_t> seen, left;
  for (const auto& ids : present) {
    for (const std::uint64_t id : seen) {
      if (ids.count(id) == 0) left.insert(id);
    }
    for (const std::uint64_t id : ids) {
      if (left.erase(id) != 0) ++pairs;
      seen.insert(id);
    }
  }
  return pairs;
}

// Collects what the service publishes (no broker).
class CollectingSink final : public MqttSink {
 public:
  void Publish(const std::string& topic, std::string payload, int, bool) override {
    messages.emplace_back(topic, std::move(payload));
  }
  std::vector<std::pair<std::string, std::string>> messages;
};

// A person stands in a room; at 3 s lrfnetd reloads its config with `change` applied; the run
// goes on to `duration_s`. What the fusion, the zones and MQTT said of it.
struct RestartRun {
  std::uint64_t generation = 0;
  std::uint64_t zone_restarts = 0;
  std::uint64_t objects_ended = 0;
  zones::ZoneState room;
  std::vector<std::string> ended_reasons;  // of every objects/ended message's first entry
};

RestartRun RunRestart(double duration_s, const std::function<void(DaemonConfig&)>& change) {
  DaemonConfig config;
  config.zones_list = "[{name: room, polygon: [[2, 0], [4, 0], [4, 2], [2, 2]]}]";
  config.mqtt.objects_hz = 10.0;
  EXPECT_EQ(Validate(config), std::nullopt);
  DaemonOptions options;
  options.send_requests = false;
  Daemon daemon(options, nullptr, nullptr, 1);
  boost::asio::io_context io;
  FusionService fusion(io, config);
  fusion.SetCalibration(OneSensorAtTheOrigin());
  ZoneService zones(config);
  CollectingSink sink;
  MqttService mqtt(config, &sink, "test");
  std::uint32_t scan = 0;
  for (double t = 0.0; t < duration_s - 1e-9; t += 0.04) {
    if (std::abs(t - 3.0) < 0.02) {
      DaemonConfig changed = config;
      change(changed);
      fusion.Reconfigure(changed);
    }
    fusion.OnFrame("s1", FrameWith(t, scan++, {Standing(1)}));
    if (scan % 5 == 0) {
      fusion.OnTick(t);
      zones.OnTick(fusion);
      mqtt.OnTick(At(t), daemon, fusion, zones);
    }
  }
  RestartRun run;
  run.generation = fusion.generation();
  run.zone_restarts = zones.counters().restarts;
  run.objects_ended = mqtt.counters().objects_ended;
  run.room = zones.States().at(0);
  for (const auto& [topic, payload] : sink.messages) {
    if (!topic.ends_with("/objects/ended")) continue;
    run.ended_reasons.push_back(nlohmann::json::parse(payload)["ended"][0]["reason"]);
  }
  return run;
}

// The fusion's options change at 3 s (lrfnetd reloads its config): a new fuser starts. Every id
// known to the zones and MQTT ends then, and the person standing in the room comes back as the
// new fuser's id.
TEST(MqttServiceRestart, ANewFuserEndsEveryIdKnown) {
  const RestartRun run = RunRestart(6.0, [](DaemonConfig& c) { c.fusion.max_coast_s = 2.0; });
  EXPECT_EQ(run.generation, 1u);
  EXPECT_EQ(run.zone_restarts, 1u);
  EXPECT_EQ(run.objects_ended, 1u);
  EXPECT_EQ(run.room.present_ids.size(), 1u);  // the new fuser's id for the person
  EXPECT_EQ(run.room.lost_inside, 1u);         // the old fuser's id, ended at the restart
  EXPECT_EQ(run.room.dwells_completed, 1u);
  EXPECT_EQ(run.ended_reasons, std::vector<std::string>{"fusion_restarted"});
}

// A new fuser's ids go on from the old one's (no id is given twice in a run); a reload that
// changes only fusion.ended_report_s keeps the fuser and its ids.
TEST(MqttServiceRestart, ANewFuserGoesOnFromTheOldIdsAndEndedReportAloneKeepsIt) {
  DaemonConfig config;
  ASSERT_EQ(Validate(config), std::nullopt);
  boost::asio::io_context io;
  FusionService fusion(io, config);
  fusion.SetCalibration(OneSensorAtTheOrigin());
  std::uint32_t scan = 0;
  std::set<std::uint64_t> ids_before, ids_after;
  std::set<std::uint64_t>* ids = &ids_before;
  for (double t = 0.0; t < 9.0 - 1e-9; t += 0.04) {
    if (std::abs(t - 3.0) < 0.02) {
      DaemonConfig changed = config;
      changed.fusion.ended_report_s = 60.0;
      fusion.Reconfigure(changed);
      EXPECT_EQ(fusion.generation(), 0u);
      EXPECT_EQ(fusion.fuser().options().ended_report_s, 60.0);
    }
    if (std::abs(t - 6.0) < 0.02) {
      DaemonConfig changed = config;
      changed.fusion.max_coast_s = 2.0;
      fusion.Reconfigure(changed);
      EXPECT_EQ(fusion.generation(), 1u);
      ids = &ids_after;
    }
    fusion.OnFrame("s1", FrameWith(t, scan++, {Standing(1)}));
    if (scan % 5 == 0) {
      fusion.OnTick(t);
      for (const fusion::FusedTrack& f : fusion.fuser().Snapshot(fusion.now_ns())) {
        ids->insert(f.id);
      }
    }
  }
  ASSERT_EQ(ids_before.size(), 1u);  // the same id before and after the ended_report_s change
  ASSERT_EQ(ids_after.size(), 1u);
  EXPECT_GT(*ids_after.begin(), *ids_before.begin());
}

// Fusion disabled at 3 s (lrfnetd reloads its config): the fuser gets no frames and no Tick any
// more, so its ids can neither go on nor end. Every id known to the zones and MQTT ends then
// (fusion_restarted), instead of being held as hidden for good.
TEST(MqttServiceRestart, FusionDisabledEndsEveryIdKnown) {
  const RestartRun run = RunRestart(30.0, [](DaemonConfig& c) { c.fusion_enabled = false; });
  EXPECT_EQ(run.generation, 1u);
  EXPECT_EQ(run.zone_restarts, 1u);
  EXPECT_EQ(run.objects_ended, 1u);
  EXPECT_TRUE(run.room.present_ids.empty());
  EXPECT_EQ(run.room.lost_inside, 1u);
  EXPECT_EQ(run.ended_reasons, std::vector<std::string>{"fusion_restarted"});
}

class MqttServiceHide : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!lrfnet::testing::HaveBinary(lrfnet::testing::kMosquitto))
      GTEST_SKIP() << "mosquitto is not installed (scripts/install_deps.sh adds it)";
    ASSERT_TRUE(broker_.Start());
  }
  MosquittoBroker broker_;
};

TEST_F(MqttServiceHide, AnIdHiddenAndBackWithinTheHoldGivesNoExitAndNoEntry) {
  // 1 s hidden: the fused id is absent from the fused tracks from about 2.5 s to 3 s.
  const HideRun held = RunHide(broker_.port(), 1.0, -1.0);  // hold: fusion.max_coast_s
  ASSERT_FALSE(held.zone.empty());
  ASSERT_FALSE(held.objects.empty());
  // The id did leave the object list for a while and came back (what the zones are held over).
  std::vector<std::uint64_t> object_ids;
  int lists_without = 0;
  for (const nlohmann::json& o : held.objects) {
    if (o["objects"].empty()) {
      if (!object_ids.empty()) ++lists_without;
      continue;
    }
    ASSERT_EQ(o["objects"].size(), 1u);
    const auto id = o["objects"][0]["id"].get<std::uint64_t>();
    if (object_ids.empty() || object_ids.back() != id) object_ids.push_back(id);
  }
  EXPECT_GT(lists_without, 0);
  ASSERT_EQ(object_ids.size(), 1u);
  EXPECT_EQ(held.counters.objects_returned, 1u);
  EXPECT_EQ(held.zone_stats["absent_held"], 1) << held.zone_stats.dump();
  EXPECT_EQ(held.zone_stats["absent_returned"], 1) << held.zone_stats.dump();
  EXPECT_EQ(held.zone_stats["absent_gone"], 0) << held.zone_stats.dump();
  // The object's path goes on from before the hiding (its oldest point is from about 0.2 s).
  EXPECT_LT(held.objects.back()["objects"][0]["path"][0][2].get<double>(), -6.0);
  // The zone: the id present in every message from its entry on, nothing lost, no dwell ended.
  const auto present = PresentIds(held);
  EXPECT_EQ(ExitEnterPairs(present), 0);
  for (const nlohmann::json& z : held.zone) {
    EXPECT_EQ(z["lost_inside"], 0) << z.dump();
    EXPECT_EQ(z["dwell"]["completed"], 0) << z.dump();
  }
  EXPECT_EQ(present.back(), std::set<std::uint64_t>{object_ids[0]});

  EXPECT_TRUE(held.ended.empty());

  // zones.absent_hold_s 0 (earlier releases: an exit and an entry of the same id) or longer than
  // the fusion keeps an id: the same, the fusion says the id is hidden.
  for (const double hold_s : {0.0, 5.0}) {
    const HideRun other = RunHide(broker_.port(), 1.0, hold_s);
    EXPECT_EQ(ExitEnterPairs(PresentIds(other)), 0) << hold_s;
    EXPECT_EQ(other.zone.back()["lost_inside"], 0) << hold_s;
    EXPECT_EQ(other.counters.objects_returned, 1u) << hold_s;
  }
}

TEST_F(MqttServiceHide, AnIdHiddenForLongerThanTheHoldExitsExactlyOnce) {
  // 3 s hidden: the fused track is deleted max_coast_s after its last update; the new track
  // starts a new id.
  const HideRun run = RunHide(broker_.port(), 3.0, -1.0);
  ASSERT_FALSE(run.zone.empty());
  const auto present = PresentIds(run);
  EXPECT_EQ(ExitEnterPairs(present), 0);
  std::set<std::uint64_t> ids;
  for (const auto& p : present) ids.insert(p.begin(), p.end());
  EXPECT_EQ(ids.size(), 2u);  // the first id and the new one
  // lost_inside goes 0 -> 1 once and stays.
  int changes = 0;
  for (std::size_t i = 1; i < run.zone.size(); ++i) {
    if (run.zone[i]["lost_inside"] != run.zone[i - 1]["lost_inside"]) ++changes;
  }
  EXPECT_EQ(changes, 1) << run.zone.size() << " zone messages, the last " << run.zone.back().dump();
  EXPECT_EQ(run.zone.back()["lost_inside"], 1);
  EXPECT_EQ(run.zone.back()["dwell"]["completed"], 1);
  EXPECT_EQ(run.counters.objects_returned, 0u);
  EXPECT_EQ(run.counters.objects_ended, 1u);  // the fusion said it timed out
  EXPECT_EQ(run.counters.objects_gone, 0u);
  EXPECT_EQ(run.zone_stats["absent_held"], 1) << run.zone_stats.dump();
  EXPECT_EQ(run.zone_stats["absent_returned"], 0) << run.zone_stats.dump();
  EXPECT_EQ(run.zone_stats["absent_gone"], 1) << run.zone_stats.dump();
  EXPECT_EQ(run.zone_stats["ended"], 1) << run.zone_stats.dump();
  EXPECT_EQ(run.zone_stats["expired"], 0) << run.zone_stats.dump();
  // The object's end, published once with why.
  ASSERT_EQ(run.ended.size(), 1u);
  ASSERT_EQ(run.ended[0]["ended"].size(), 1u);
  EXPECT_EQ(run.ended[0]["ended"][0]["reason"], "timed_out");
  EXPECT_TRUE(run.ended[0]["ended"][0]["merged_into"].is_null());
  // The exit is as of the disappearance: the dwell ended when the id left the object list
  // (about 2.5 s, its source's timeout), not when the fusion deleted it (about 3.5 s).
  EXPECT_NEAR(run.zone.back()["dwell"]["max_s"].get<double>(), 2.4, 0.25) << run.zone.back().dump();
}

// The person's tracker starts a second track (2) on them 0.1 m beside the first at 2 s and drops
// the first at 2.3 s: the fusion has two fused ids for one person until it merges the new one
// into the older id. From the merge on the room counts one person, with no exit and nothing lost
// (the person's dwell goes on from the first entry); the merged object leaves the object list at
// once and its end says which id it goes on as. Before (the merged id held as absent for
// absent_hold_s): two in the room for 1.5 s more, then one lost inside.
TEST_F(MqttServiceHide, AMergedIdLeavesAtOnceAndIsNotLostInside) {
  const HideRun run = RunScene(broker_.port(), -1.0, [](double t) {
    std::vector<TrackObservation> tracks;
    if (t < 2.3) tracks.push_back(Standing(1));
    if (t >= 2.0) tracks.push_back(Standing(2, 3.0, 1.1));
    return tracks;
  });
  ASSERT_FALSE(run.zone.empty());
  EXPECT_EQ(run.counters.objects_merged, 1u);
  EXPECT_EQ(run.zone_stats["merged"], 1) << run.zone_stats.dump();
  ASSERT_EQ(run.ended.size(), 1u);
  ASSERT_EQ(run.ended[0]["ended"].size(), 1u);
  const nlohmann::json& end = run.ended[0]["ended"][0];
  EXPECT_EQ(end["reason"], "merged");
  const auto merged = end["id"].get<std::uint64_t>();
  const auto survivor = end["merged_into"].get<std::uint64_t>();
  EXPECT_LT(survivor, merged);
  // The object lists: never the merged id after its end, the survivor in every one after it.
  const auto ended_stamp = run.ended[0]["stamp_ns"].get<std::int64_t>();
  for (const nlohmann::json& o : run.objects) {
    if (o["stamp_ns"].get<std::int64_t>() < ended_stamp) continue;
    ASSERT_EQ(o["objects"].size(), 1u) << o.dump();
    EXPECT_EQ(o["objects"][0]["id"], survivor);
  }
  // The zone: one person from the merge on, the merged id never back, nothing lost, no dwell
  // ended; the survivor's dwell from its first entry (0 s) to the end (about 7.8 s).
  const auto present = PresentIds(run);
  EXPECT_EQ(ExitEnterPairs(present), 0);
  bool after_merge = false;
  for (std::size_t i = 0; i < run.zone.size(); ++i) {
    if (run.zone[i]["stamp_ns"].get<std::int64_t>() >= ended_stamp) after_merge = true;
    if (after_merge) {
      EXPECT_EQ(present[i], std::set<std::uint64_t>{survivor}) << run.zone[i].dump();
    }
    EXPECT_EQ(run.zone[i]["lost_inside"], 0) << run.zone[i].dump();
    EXPECT_EQ(run.zone[i]["dwell"]["completed"], 0) << run.zone[i].dump();
  }
  EXPECT_TRUE(after_merge);
  EXPECT_GT(run.zone.back()["present"][0]["dwell_s"].get<double>(), 7.0) << run.zone.back().dump();
}

// lrfnetd's fusion, zones and MQTT services (and what the live view needs) on one sensor at the
// origin, the MQTT messages collected.
struct Services {
  explicit Services(DaemonConfig c)
      : config(Validated(std::move(c))),
        daemon(NoRequests(), nullptr, nullptr, 1),
        fusion(io, config),
        calibration(io, config),
        zones(config),
        mqtt(config, &sink, "test") {
    fusion.SetCalibration(OneSensorAtTheOrigin());
  }
  static DaemonConfig Validated(DaemonConfig c) {
    EXPECT_EQ(Validate(c), std::nullopt);
    return c;
  }
  static DaemonOptions NoRequests() {
    DaemonOptions options;
    options.send_requests = false;
    return options;
  }
  // The messages on topics ending in `suffix`, parsed.
  std::vector<nlohmann::json> Messages(std::string_view suffix, std::size_t from = 0) const {
    std::vector<nlohmann::json> out;
    for (std::size_t i = from; i < sink.messages.size(); ++i) {
      if (sink.messages[i].first.ends_with(suffix)) {
        out.push_back(nlohmann::json::parse(sink.messages[i].second));
      }
    }
    return out;
  }

  DaemonConfig config;
  boost::asio::io_context io;
  Daemon daemon;
  FusionService fusion;
  CalibrationService calibration;
  ZoneService zones;
  CollectingSink sink;
  MqttService mqtt;
};

// The fusion service computes the fuser's Output once per output time and hands the same object
// to every consumer: its publish, the zones, MQTT and the live view see the same tracks.
TEST(MqttServiceOutput, EveryConsumerSeesOneOutputPerPeriod) {
  DaemonConfig config;
  config.zones_list = "[{name: room, polygon: [[2, 0], [4, 0], [4, 2], [2, 2]]}]";
  config.mqtt.objects_hz = 10.0;
  Services x(config);
  FusionService& fusion = x.fusion;
  LiveFeed feed(100);
  std::uint32_t scan = 0;
  int periods = 0;
  for (double t = 0.0; t < 4.0 - 1e-9; t += 0.04) {
    // One person standing in the room, a second walking past it.
    fusion.OnFrame("s1", FrameWith(t, scan++, {Standing(1), Standing(2, 1.0 + 0.5 * t, -1.0)}));
    if (scan % 5 != 0) continue;
    const std::uint64_t computed = fusion.counters().outputs_computed;
    const std::size_t messages = x.sink.messages.size();
    fusion.OnTick(t);
    const fusion::FusionOutput* output = &fusion.Output();
    ASSERT_TRUE(x.zones.OnTick(fusion));
    x.mqtt.OnTick(At(t), x.daemon, fusion, x.zones);
    const LiveState live = feed.Build(x.daemon, x.calibration, fusion, At(t), "test", &x.zones);
    // One output computed for the publish, the zones, MQTT and the live view.
    EXPECT_EQ(fusion.counters().outputs_computed, computed + 1);
    // What MQTT published is the output's tracks.
    std::vector<std::pair<std::uint64_t, double>> published, fused, drawn;
    for (const fusion::FusedTrack& f : output->tracks) fused.emplace_back(f.id, f.x_m);
    for (const LiveFusedTrack& f : live.fused) drawn.emplace_back(f.id, f.x_m);
    for (const nlohmann::json& list : x.Messages("/objects", messages)) {
      for (const auto& o : list["objects"]) {
        published.emplace_back(o["id"].get<std::uint64_t>(), o["x_m"].get<double>());
      }
    }
    EXPECT_EQ(drawn, fused);
    ASSERT_EQ(published.size(), fused.size());
    for (std::size_t i = 0; i < fused.size(); ++i) {
      EXPECT_EQ(published[i].first, fused[i].first);
      EXPECT_NEAR(published[i].second, fused[i].second, 1e-3);
    }
    // The zone counts the output's tracks inside it (the standing person).
    std::vector<std::uint64_t> inside;
    for (const fusion::FusedTrack& f : output->tracks) {
      if (f.x_m > 2.3 && f.x_m < 3.7 && f.y_m > 0.3 && f.y_m < 1.7) inside.push_back(f.id);
    }
    EXPECT_EQ(x.zones.States().at(0).present_ids, inside);
    ++periods;
  }
  EXPECT_EQ(periods, 20);
  EXPECT_EQ(fusion.counters().outputs_computed, 20u);
}

// MQTT alone follows the ids, every 10 s of data (objects_hz 0.1; ends kept for 20 s). A person
// stands in front of the sensor until 12 s; their fused id ends (timed out) at about 13.5 s,
// after MQTT's last object list; the data stop at 14 s and resume 60 s later. The fused tracks'
// publish (10 Hz) and the live view only look at the outputs in between: the end is still
// reported when MQTT next reads, which ends the object as timed out with its path. Before (a look
// marked the end as read): forgotten at the publish 0.2 s after the data resumed, the object
// ended as hold_expired.
TEST(MqttServiceOutput, AnEndOnlyLookedAtIsKeptUntilTheFollowersReadIt) {
  DaemonConfig config;
  config.fusion.report_sourceless = false;
  config.fusion.ended_report_s = 20.0;
  config.mqtt.objects_hz = 0.1;
  config.mqtt.path_points = 40;
  Services x(config);
  FusionService& fusion = x.fusion;
  LiveFeed feed(100);
  std::uint32_t scan = 0;
  std::uint64_t id = 0;
  for (double t = 0.0; t < 90.0 - 1e-9; t += 0.04) {
    if (t >= 14.0 && t < 74.0) continue;  // no data
    std::vector<TrackObservation> tracks;
    if (t < 12.0) tracks.push_back(Standing(1));
    fusion.OnFrame("s1", FrameWith(t, scan++, tracks));
    if (scan % 5 == 0) {
      fusion.OnTick(t);
      feed.Build(x.daemon, x.calibration, fusion, At(t), "test", &x.zones);
      if (id == 0 && !fusion.PeekOutput().tracks.empty()) id = fusion.PeekOutput().tracks[0].id;
    }
    if (scan % 25 == 0) x.mqtt.OnTick(At(t), x.daemon, fusion, x.zones);
  }
  ASSERT_NE(id, 0u);
  const std::vector<nlohmann::json> ended = x.Messages("/objects/ended");
  ASSERT_EQ(ended.size(), 1u);
  ASSERT_EQ(ended[0]["ended"].size(), 1u);
  EXPECT_EQ(ended[0]["ended"][0]["id"], id);
  EXPECT_EQ(ended[0]["ended"][0]["reason"], "timed_out");
  // Read after the data resumed.
  EXPECT_GT(ended[0]["stamp_ns"].get<common::UtcNs>(), At(74.0));
  EXPECT_EQ(x.mqtt.counters().objects_ended, 1u);
  EXPECT_EQ(x.mqtt.counters().objects_gone, 0u);
}

// The fusion service's output is computed for the publish (a look) and then read by a consumer
// that follows ids at the same data time: the read comes from the cache and still marks the ends
// it lists as read, so their ended_report_s runs from then. A person is seen until 1 s (their id
// ends at about 3 s); the end is read at 4 s, then only looked at until 30 s (ended_report_s
// 20 s): read again then, and forgotten at the next publish.
TEST(MqttServiceOutput, AReadOfACachedLookMarksTheEnds) {
  DaemonConfig config;
  config.fusion.report_sourceless = false;
  config.fusion.ended_report_s = 20.0;
  Services x(config);
  FusionService& fusion = x.fusion;
  std::uint32_t scan = 0;
  bool read = false;
  for (double t = 0.0; t < 30.0 - 1e-9; t += 0.04) {
    std::vector<TrackObservation> tracks;
    if (t < 1.0) tracks.push_back(Standing(1));
    fusion.OnFrame("s1", FrameWith(t, scan++, tracks));
    if (scan % 5 != 0) continue;
    fusion.OnTick(t);  // the publish looks
    if (!read && t >= 4.0) {
      const std::uint64_t computed = fusion.counters().outputs_computed;
      ASSERT_EQ(fusion.Output().ended.size(), 1u);  // read from the cached look
      EXPECT_EQ(fusion.counters().outputs_computed, computed);
      read = true;
    }
  }
  ASSERT_TRUE(read);
  ASSERT_EQ(fusion.Output().ended.size(), 1u);  // read at 30 s: more than 20 s after 4 s
  fusion.OnTick(40.0);                          // a publish: its Tick forgets the end
  EXPECT_TRUE(fusion.PeekOutput().ended.empty());
}

// Two sensors at the origin (the same place: they see a person at the same point).
calib::CalibrationResult TwoSensorsAtTheOrigin() {
  calib::CalibrationResult r = OneSensorAtTheOrigin();
  calib::SensorPose p = r.sensors.front();
  p.id = "s2";
  r.sensors.push_back(p);
  return r;
}

// The sensors' ids of the output's only track.
std::set<std::string> SourcesOfTheTrack(const fusion::FusionOutput& output) {
  std::set<std::string> out;
  if (output.tracks.size() != 1) return out;
  for (const fusion::FusedSource& s : output.tracks[0].sources) out.insert(s.sensor_id);
  return out;
}

// A frame that comes after a publish with a scan time no later than the newest (a second
// sensor's, at the same time) is in the next output at that time, not the one cached before it.
TEST(MqttServiceOutput, ALateFrameAfterAPublishIsInTheOutput) {
  Services x(DaemonConfig{});
  FusionService& fusion = x.fusion;
  fusion.SetCalibration(TwoSensorsAtTheOrigin());
  std::uint32_t scan = 0;
  for (double t = 0.0; t < 1.0 - 1e-9; t += 0.04) {
    fusion.OnFrame("s1", FrameWith(t, scan++, {Standing(1)}));
    fusion.OnTick(t);
  }
  const common::UtcNs now_ns = fusion.now_ns();
  EXPECT_EQ(SourcesOfTheTrack(fusion.Output()), (std::set<std::string>{"s1"}));
  TrackFrameData late = FrameWith(0.0, 0, {Standing(7)});
  late.scan_start_ns = now_ns;
  fusion.OnFrame("s2", late);
  ASSERT_EQ(fusion.now_ns(), now_ns);
  EXPECT_EQ(SourcesOfTheTrack(fusion.Output()), (std::set<std::string>{"s1", "s2"}));
}

// Excluding the only sensor (or a calibration that no longer places it) drops its bindings at
// once: at the same data time the person's id is no longer in the output's tracks (hidden).
TEST(MqttServiceOutput, ExcludingOrUnplacingASensorShowsInTheOutputAtOnce) {
  for (const bool exclude : {true, false}) {
    SCOPED_TRACE(exclude ? "SetExcluded" : "SetCalibration");
    DaemonConfig config;
    config.fusion.report_sourceless = false;
    Services x(config);
    FusionService& fusion = x.fusion;
    std::uint32_t scan = 0;
    for (double t = 0.0; t < 1.0 - 1e-9; t += 0.04) {
      fusion.OnFrame("s1", FrameWith(t, scan++, {Standing(1)}));
      fusion.OnTick(t);
    }
    ASSERT_EQ(fusion.Output().tracks.size(), 1u);
    const std::uint64_t id = fusion.Output().tracks[0].id;
    if (exclude) {
      fusion.SetExcluded({"s1"});
    } else {
      calib::CalibrationResult unplaced = OneSensorAtTheOrigin();
      unplaced.sensors[0].calibrated = false;
      fusion.SetCalibration(unplaced);
    }
    const fusion::FusionOutput& output = fusion.Output();
    EXPECT_TRUE(output.tracks.empty());
    ASSERT_EQ(output.hidden.size(), 1u);
    EXPECT_EQ(output.hidden[0].id, id);
  }
}

// The person's fused id is due to end (no update for more than max_coast_s) when a frame comes
// at 5 s; the live view looks at the output first, then the publish's Tick ends the id at the
// same data time: the zones and MQTT reading after it are told of the end (no data follows, so
// they learn of it then or never).
TEST(MqttServiceOutput, AnEndByATickAtTheSameTimeIsListedToTheFollowers) {
  DaemonConfig config;
  config.zones_list = "[{name: room, polygon: [[2, 0], [4, 0], [4, 2], [2, 2]]}]";
  config.fusion.report_sourceless = false;
  config.mqtt.objects_hz = 10.0;
  Services x(config);
  FusionService& fusion = x.fusion;
  LiveFeed feed(100);
  std::uint32_t scan = 0;
  std::uint64_t id = 0;
  for (double t = 0.0; t < 5.0 + 1e-9; t += 0.04) {
    if (t >= 1.2 && t < 5.0 - 1e-9) continue;  // no data
    std::vector<TrackObservation> tracks;
    if (t < 1.0) tracks.push_back(Standing(1));
    fusion.OnFrame("s1", FrameWith(t, scan++, tracks));
    feed.Build(x.daemon, x.calibration, fusion, At(t), "test", &x.zones);  // a look first
    fusion.OnTick(t);
    x.zones.OnTick(fusion);
    x.mqtt.OnTick(At(t), x.daemon, fusion, x.zones);
    if (id == 0 && !fusion.PeekOutput().tracks.empty()) id = fusion.PeekOutput().tracks[0].id;
  }
  ASSERT_NE(id, 0u);
  const std::vector<nlohmann::json> ended = x.Messages("/objects/ended");
  ASSERT_EQ(ended.size(), 1u);
  EXPECT_EQ(ended[0]["ended"][0]["id"], id);
  EXPECT_EQ(ended[0]["ended"][0]["reason"], "timed_out");
  EXPECT_EQ(x.zones.counters().ended, 1u);
  EXPECT_EQ(x.zones.counters().expired, 0u);
  EXPECT_TRUE(x.zones.States().at(0).present_ids.empty());
}

// MQTT meets the survivor of a merge only as the merge's target: the person's first fused id (1)
// is hidden (its tracker dropped it; a new track started beside it) before the MQTT output's first
// object list, which holds only the new id; the fusion then merges the new id into 1. The object
// goes on as 1 with its path: one merge, one end message, and 1 published from then on.
TEST(MqttServiceMerge, ASurvivorKnownOnlyAsAMergeTargetIsCountedOnceAndPublished) {
  DaemonConfig config;
  config.fusion.report_sourceless = false;
  // The new track (0.55 m from where the person was last seen) is not taken by the hidden id,
  // but within the merge's distance of it.
  config.fusion.gate_max_distance_m = 0.5;
  config.mqtt.objects_hz = 10.0;
  config.mqtt.path_points = 40;
  Services x(config);
  FusionService& fusion = x.fusion;
  std::uint32_t scan = 0;
  bool started = false;
  std::uint64_t hidden_id = 0, first_id = 0;
  for (double t = 0.0; t < 6.0 - 1e-9; t += 0.04) {
    std::vector<TrackObservation> tracks;
    if (t < 1.0) tracks.push_back(Standing(1));
    if (t >= 1.6) tracks.push_back(Standing(2, 3.0, 1.55));
    fusion.OnFrame("s1", FrameWith(t, scan++, tracks));
    fusion.OnTick(t);
    const fusion::FusionOutput& output = fusion.Output();
    if (!started && output.tracks.size() == 1 && output.hidden.size() == 1) {
      started = true;  // from here on MQTT follows the ids: it never saw the hidden one
      hidden_id = output.hidden[0].id;
      first_id = output.tracks[0].id;
      // The live view draws where the hidden person was last measured, and by which sensor.
      LiveFeed feed(100);
      const nlohmann::json live = nlohmann::json::parse(
          LiveStateJson(feed.Build(x.daemon, x.calibration, fusion, At(t), "test", &x.zones)));
      ASSERT_EQ(live["hidden"].size(), 1u) << live.dump();
      EXPECT_EQ(live["hidden"][0]["id"], hidden_id);
      EXPECT_NEAR(live["hidden"][0]["x_m"].get<double>(), 3.0, 0.05);
      EXPECT_NEAR(live["hidden"][0]["y_m"].get<double>(), 1.0, 0.05);
      EXPECT_EQ(live["hidden"][0]["sensor"], "s1");
      // Last measured by the first track (before 1 s).
      EXPECT_GT(live["hidden"][0]["age_s"].get<double>(), t - 1.0);
      EXPECT_EQ(live["fused"].size(), 1u);
    }
    if (started) x.mqtt.OnTick(At(t), x.daemon, fusion, x.zones);
  }
  ASSERT_TRUE(started);
  ASSERT_LT(hidden_id, first_id);
  const std::vector<nlohmann::json> lists = x.Messages("/objects");
  const std::vector<nlohmann::json> ended = x.Messages("/objects/ended");
  ASSERT_FALSE(lists.empty());
  ASSERT_EQ(lists.front()["objects"].size(), 1u);
  EXPECT_EQ(lists.front()["objects"][0]["id"], first_id);
  // One end: the new id merged into the hidden one.
  ASSERT_EQ(ended.size(), 1u);
  ASSERT_EQ(ended[0]["ended"].size(), 1u);
  EXPECT_EQ(ended[0]["ended"][0]["id"], first_id);
  EXPECT_EQ(ended[0]["ended"][0]["reason"], "merged");
  EXPECT_EQ(ended[0]["ended"][0]["merged_into"], hidden_id);
  const MqttServiceCounters& c = x.mqtt.counters();
  EXPECT_EQ(c.objects_merged, 1u);
  EXPECT_EQ(c.objects_ended, 0u);
  EXPECT_EQ(c.objects_gone, 0u);
  EXPECT_EQ(c.objects_returned, 0u);
  EXPECT_EQ(c.objects_ended_messages, 1u);
  EXPECT_EQ(c.objects, lists.size());
  // From the end on, every list holds the survivor alone, its path going on from the merged
  // id's first point (more than 2 s before the end of the run).
  const auto end_stamp = ended[0]["stamp_ns"].get<std::int64_t>();
  int after = 0;
  for (const nlohmann::json& o : lists) {
    if (o["stamp_ns"].get<std::int64_t>() < end_stamp) continue;
    ASSERT_EQ(o["objects"].size(), 1u) << o.dump();
    EXPECT_EQ(o["objects"][0]["id"], hidden_id);
    ++after;
  }
  EXPECT_GT(after, 10);
  EXPECT_LT(lists.back()["objects"][0]["path"][0][2].get<double>(), -2.0) << lists.back().dump();
}

// --stats-out's "mqtt" says what the id follower dropped or could not follow in the fusion's
// lists, as the service counts it (nothing in an ordinary run).
TEST(MqttServiceStats, TheIdFollowersDropsAreExported) {
  DaemonConfig config;
  config.mqtt.broker = "127.0.0.1:1";
  Services x(config);
  std::uint32_t scan = 0;
  for (double t = 0.0; t < 1.0 - 1e-9; t += 0.04) {
    x.fusion.OnFrame("s1", FrameWith(t, scan++, {Standing(1)}));
    x.fusion.OnTick(t);
    x.mqtt.OnTick(At(t), x.daemon, x.fusion, x.zones);
  }
  MqttOutput out;
  out.service = std::make_unique<MqttService>(x.config, &x.sink, "test");
  out.publisher = std::make_unique<MqttPublisher>(PublisherOptions(x.config, *out.service));
  const nlohmann::json j = MqttJson(out);
  for (const char* key : {"objects_duplicates", "objects_merge_cycles", "objects_merge_chains_cut",
                          "objects_merges_into_ended"}) {
    ASSERT_TRUE(j.contains(key)) << key << " " << j.dump();
    EXPECT_EQ(j[key], 0) << key;
  }
  EXPECT_EQ(x.mqtt.counters().objects_duplicates, 0u);
  EXPECT_GT(x.mqtt.counters().objects, 0u);
}

}  // namespace
}  // namespace lrfnet::daemon
