// ScanSource for a device without a recording: a room seen by one scanner, with a walking blob.

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numbers>
#include <random>

#include "tools/scan_source.h"

namespace lrfnet::tools {
namespace {

struct ModelSpec {
  const char* key;
  const char* ident_name;
  const char* firmware;
  std::uint16_t points;
  std::int32_t start_angle_raw;  // 1/10000 °, SICK convention (90° = forward)
  std::uint16_t step_raw;        // 1/10000 °
  std::uint32_t frequency_raw;   // 1/100 Hz (telegrams; the MRS1104 sends one layer per telegram)
  double max_range_m;
  std::uint8_t rssi_bits;  // 0 = no RSSI channel
  std::uint32_t serial;
  std::uint8_t layers;  // 1, or 4 for the MRS1104
};

// Geometry and channel layout as the real devices send them (see the shared captures' README);
// one model per device family (sopas_device.h).
constexpr ModelSpec kModels[] = {
    {"lms511", "LMS511-10100", "V1.80", 1141, -50000, 1667, 2500, 80.0, 8, 10000511, 1},
    {"lms111", "LMS111-10100", "V1.80", 541, -450000, 5000, 5000, 20.0, 0, 10000111, 1},
    {"tim561", "TiM561-2050101", "V3.13", 811, -450000, 3333, 1500, 10.0, 16, 10000561, 1},
    {"tim781", "TiM781-2174101", "V3.13", 811, -450000, 3333, 1500, 25.0, 16, 10000781, 1},
    {"tim781s", "TiM781S-2174104", "V3.13", 811, -450000, 3333, 1500, 25.0, 16, 10007815, 1},
    {"mrs1104", "MRS1xxxx", "V 1.0.0", 1101, -475000, 2500, 5000, 64.0, 8, 10001104, 4},
};

// The MRS1104's layer angle field per telegram, in its capture's order (1/100 °).
constexpr std::int16_t kMrsLayerAngles[] = {250, -500, 0, -250};

const ModelSpec* FindModel(const std::string& key) {
  for (const ModelSpec& m : kModels) {
    if (key == m.key) return &m;
  }
  return nullptr;
}

// The scene in the sensor frame (x forward, y left, metres): the sensor stands half a metre in
// front of the back wall of a 10 m × 8 m room with one pillar; a blob of a person's size walks an
// ellipse.
constexpr double kRoomMinX = -0.5, kRoomMaxX = 9.5, kRoomMinY = -4.0, kRoomMaxY = 4.0;
constexpr double kPillarX = 6.0, kPillarY = -2.0, kPillarRadius = 0.3;
constexpr double kBlobRadius = 0.25;
constexpr double kBlobCenterX = 4.5, kBlobCenterY = 0.5, kBlobAxisX = 2.5, kBlobAxisY = 2.0;
constexpr double kBlobLapS = 10.0;
constexpr std::uint32_t kFirstTickUs = 10'000'000;
constexpr std::uint32_t kTransmissionDelayUs = 5'000;

enum class Surface { kNone, kWall, kPillar, kBlob };

// Distance along the unit ray (dx, dy) from the origin to a circle, or +inf.
double RayCircle(double dx, double dy, double cx, double cy, double r) {
  const double b = dx * cx + dy * cy;
  const double disc = b * b - (cx * cx + cy * cy - r * r);
  if (disc < 0) return INFINITY;
  const double t = b - std::sqrt(disc);
  return t > 0 ? t : INFINITY;
}

// Distance from the origin (inside the box) to the room's walls along the unit ray (dx, dy).
double RayRoom(double dx, double dy) {
  double t = INFINITY;
  if (dx > 0) t = std::min(t, kRoomMaxX / dx);
  if (dx < 0) t = std::min(t, kRoomMinX / dx);
  if (dy > 0) t = std::min(t, kRoomMaxY / dy);
  if (dy < 0) t = std::min(t, kRoomMinY / dy);
  return t;
}

void SetName(cola::ScanChannel* channel, const char* name5) {
  channel->name = {};
  std::memcpy(channel->name.data(), name5, 5);
}

class SyntheticScanSource : public ScanSource {
 public:
  SyntheticScanSource(const ModelSpec& model, const SyntheticScanOptions& options)
      : model_(model), options_(options) {
    identity_.name = model.ident_name;
    identity_.version = "synthetic";
    identity_.firmware_version = model.firmware;
    identity_.serial_number = std::to_string(model.serial);
    identity_.geometry = {model.start_angle_raw, model.step_raw, model.points, model.frequency_raw,
                          model.rssi_bits};
  }

  const DeviceIdentity& identity() const override { return identity_; }
  void Rewind() override {}
  common::DurationNs nominal_period_ns() const override { return PeriodUs() * common::kNsPerUs; }

  bool Next(cola::ScanTelegram* scan, common::DurationNs* since_previous_ns) override {
    Fill(index_, scan);
    *since_previous_ns = index_ == 0 ? 0 : nominal_period_ns();
    ++index_;
    return true;
  }

 private:
  std::int64_t PeriodUs() const { return 100'000'000 / model_.frequency_raw; }

  void Fill(std::uint64_t k, cola::ScanTelegram* scan) const {
    // Field by field rather than assigning a fresh ScanTelegram: that would be a 100 kB temporary
    // per scan.
    scan->encoders.clear();
    scan->channels16.clear();
    scan->channels8.clear();
    scan->has_position = scan->has_name = scan->has_comment = scan->has_event = false;
    scan->device_status = {0, 0};
    scan->digital_inputs = scan->digital_outputs = 0;
    scan->layer_angle_raw = model_.layers == 4 ? kMrsLayerAngles[k % 4] : std::int16_t{0};
    const auto tick_us =
        static_cast<std::uint32_t>(kFirstTickUs + k * static_cast<std::uint64_t>(PeriodUs()));
    scan->version = 1;
    scan->device_number = 1;
    scan->serial_number = model_.serial;
    scan->telegram_counter = static_cast<std::uint16_t>(k + 1);
    scan->scan_counter = static_cast<std::uint16_t>(k + 1);
    scan->time_since_startup_us = tick_us;
    scan->time_of_transmission_us = tick_us + kTransmissionDelayUs;
    scan->scan_frequency_raw = model_.frequency_raw;
    // Measurement frequency field: 100 Hz units, the spot rate over a whole turn of the mirror
    // (every real capture: TiM781S 162 = 360° / 0.3333° × 15 Hz / 100, LMS111 360, LMS511 540,
    // MRS1104 180 with its four layers per turn). SICK's driver derives the beam time from it.
    const double turns_per_s = model_.frequency_raw / 100.0 / model_.layers;
    scan->measurement_frequency_raw = static_cast<std::uint32_t>(
        std::lround(360.0 / (model_.step_raw / 10000.0) * turns_per_s / 100.0));

    cola::ScanChannel* dist = scan->channels16.emplace_slot();
    SetName(dist, "DIST1");
    dist->bits = 16;
    dist->start_angle_raw = model_.start_angle_raw;
    dist->angle_step_raw = model_.step_raw;
    dist->count = model_.points;
    cola::ScanChannel* rssi = nullptr;
    if (model_.rssi_bits == 16) rssi = scan->channels16.emplace_slot();
    if (model_.rssi_bits == 8) rssi = scan->channels8.emplace_slot();
    if (rssi != nullptr) {
      SetName(rssi, "RSSI1");
      rssi->bits = model_.rssi_bits;
      rssi->start_angle_raw = model_.start_angle_raw;
      rssi->angle_step_raw = model_.step_raw;
      rssi->count = model_.points;
    }

    const double t_s = static_cast<double>(k) * static_cast<double>(PeriodUs()) * 1e-6;
    const double phase = 2.0 * std::numbers::pi * t_s / kBlobLapS;
    const double blob_x = kBlobCenterX + kBlobAxisX * std::cos(phase);
    const double blob_y = kBlobCenterY + kBlobAxisY * std::sin(phase);
    // Noise depends on (seed, scan index) only, so scan k is the same whatever was generated before
    // it.
    std::mt19937_64 rng(options_.seed * 0x9E3779B97F4A7C15ull + k);
    std::uniform_real_distribution<double> noise(-options_.noise_m, options_.noise_m);

    for (std::uint16_t i = 0; i < model_.points; ++i) {
      // Sensor frame: the telegram's 90° beam is x forward.
      const double raw_deg =
          (model_.start_angle_raw + static_cast<double>(i) * model_.step_raw) / 10000.0;
      const double a = (raw_deg - 90.0) * std::numbers::pi / 180.0;
      const double dx = std::cos(a), dy = std::sin(a);
      double range = RayRoom(dx, dy);
      Surface surface = Surface::kWall;
      if (const double t = RayCircle(dx, dy, kPillarX, kPillarY, kPillarRadius); t < range) {
        range = t;
        surface = Surface::kPillar;
      }
      if (const double t = RayCircle(dx, dy, blob_x, blob_y, kBlobRadius); t < range) {
        range = t;
        surface = Surface::kBlob;
      }
      range += noise(rng);
      if (!(range > 0.05 && range <= model_.max_range_m)) surface = Surface::kNone;
      dist->raw[i] =
          surface == Surface::kNone
              ? 0
              : static_cast<std::uint16_t>(std::clamp(std::lround(range * 1000.0), 1L, 65535L));
      if (rssi != nullptr) {
        static constexpr std::uint16_t kRssi8[] = {0, 180, 220, 254};
        static constexpr std::uint16_t kRssi16[] = {0, 12000, 16000, 20000};
        const auto s = static_cast<std::size_t>(surface);
        rssi->raw[i] = model_.rssi_bits == 8 ? kRssi8[s] : kRssi16[s];
      }
    }

    // Time block as the devices send it with an unset clock: 1970-01-01 plus the time since
    // power-up.
    scan->has_time = true;
    scan->time.year = 1970;
    scan->time.month = 1;
    scan->time.day = 1;
    const std::uint64_t seconds = tick_us / 1'000'000u;
    scan->time.hour = static_cast<std::uint8_t>((seconds / 3600) % 24);
    scan->time.minute = static_cast<std::uint8_t>((seconds / 60) % 60);
    scan->time.second = static_cast<std::uint8_t>(seconds % 60);
    scan->time.microsecond = tick_us % 1'000'000u;
  }

  ModelSpec model_;
  SyntheticScanOptions options_;
  DeviceIdentity identity_;
  std::uint64_t index_ = 0;
};

}  // namespace

const std::vector<std::string>& SyntheticModels() {
  static const std::vector<std::string> kKeys = [] {
    std::vector<std::string> keys;
    for (const ModelSpec& m : kModels) keys.emplace_back(m.key);
    return keys;
  }();
  return kKeys;
}

std::optional<std::string> Validate(const SyntheticScanOptions& options) {
  if (FindModel(options.model) == nullptr) {
    std::string known;
    for (const std::string& k : SyntheticModels()) known += (known.empty() ? "" : ", ") + k;
    return "unknown synthetic model '" + options.model + "' (known: " + known + ")";
  }
  if (!(options.noise_m >= 0.0 && options.noise_m <= 1.0)) return "synthetic noise must be 0..1 m";
  return std::nullopt;
}

std::unique_ptr<ScanSource> MakeSyntheticScanSource(const SyntheticScanOptions& options) {
  const ModelSpec* model = FindModel(options.model);
  if (model == nullptr) return nullptr;
  return std::make_unique<SyntheticScanSource>(*model, options);
}

}  // namespace lrfnet::tools
