// The live view in a real browser: Debian's chromium, headless, driven over the DevTools protocol
// on a pipe (--remote-debugging-pipe), so the test decides when the page has seen enough messages
// (--dump-dom with --virtual-time-budget dumps after one or two WebSocket messages: virtual time
// does not wait for them). The page is checked through its machine-readable summary, its tables
// and the pixels of a screenshot, which is kept in test_artifacts/ for a person to look at.

#include <fcntl.h>
#include <gtest/gtest.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <array>
#include <boost/asio/executor_work_guard.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/steady_timer.hpp>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <functional>
#include <future>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <regex>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "central_daemon/app/foxglove_feed.h"
#include "central_daemon/app/live_state.h"
#include "central_daemon/io/live_view_server.h"
#include "common/geometry.h"
#include "tests/node_clients.h"
#include "tests/process_harness.h"

extern char** environ;

namespace lrfnet::daemon {
namespace {

namespace asio = boost::asio;
using nlohmann::json;
using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

constexpr const char* kChromium = "/usr/bin/chromium";
constexpr int kWidthPx = 1400, kHeightPx = 860;
constexpr int kCanvasWidthPx = kWidthPx - 360;  // the page's side panel is 360 px wide
// The page gives sensors the colours of its palette in the order they are listed.
constexpr std::array<std::uint32_t, 6> kSensorColours = {0x4e9cf5, 0xf58e4e, 0x5cd18b,
                                                         0xe767b8, 0xb590f5, 0xf2d252};

// ---- what is published: six sensors around a 16 m x 10 m room, two people walking ------------

struct RoomSensor {
  const char* id;
  const char* model;
  double x_m, y_m, yaw_deg, fov_deg, max_range_m;
};
constexpr std::array<RoomSensor, 6> kRoom = {{
    {"s1", "lms111", 0.3, 0.3, 45, 270, 20},
    {"s2", "lms511", 8.0, 0.3, 90, 190, 80},
    {"s3", "tim561", 15.7, 0.3, 135, 270, 10},
    {"s4", "tim781", 15.7, 9.7, -135, 270, 25},
    {"s5", "lms511", 8.0, 9.7, -90, 190, 80},
    {"s6", "lms111", 0.3, 9.7, -45, 270, 20},
}};
constexpr double kRoomWidthM = 16.0, kRoomHeightM = 10.0;

// Where a beam from (x, y) in direction a meets the room's walls.
double WallDistance(double x, double y, double a) {
  const double c = std::cos(a), s = std::sin(a);
  double d = 1e9;
  if (c > 1e-9) d = std::min(d, (kRoomWidthM - x) / c);
  if (c < -1e-9) d = std::min(d, -x / c);
  if (s > 1e-9) d = std::min(d, (kRoomHeightM - y) / s);
  if (s < -1e-9) d = std::min(d, -y / s);
  return d;
}

// Person 1 walks back and forth along y = 4 m, person 2 circles; both at 1 m/s.
std::array<double, 4> Person(int k, double t_s) {
  if (k == 0) {
    const double phase = std::fmod(t_s, 20.0);
    const double x = phase < 10.0 ? 3.0 + phase : 13.0 - (phase - 10.0);
    return {x, 4.0, phase < 10.0 ? 1.0 : -1.0, 0.0};
  }
  const double w = 0.5, r = 2.0, a = w * t_s;
  return {8.0 + r * std::cos(a), 6.5 + r * std::sin(a), -r * w * std::sin(a), r * w * std::cos(a)};
}

LiveState RoomState(double t_s, bool placed) {
  LiveState state;
  state.stamp_ns = 1'700'000'000'000'000'000 + static_cast<common::UtcNs>(t_s * 1e9);
  state.version = "0.1.0";
  if (placed) {
    state.calibration = {"calibrated", 1.0, "6 sensors calibrated; track residual 2.8 cm", "s1",
                         0.028};
  } else {
    state.calibration = {"collecting", 0.45, "walk between s2 and s5: 35 s of overlap still needed",
                         "", 0.0};
  }
  for (std::size_t i = 0; i < kRoom.size(); ++i) {
    const RoomSensor& r = kRoom[i];
    LiveSensor s;
    s.id = r.id;
    s.model = r.model;
    s.placed = placed;
    const common::Pose2 world_from_sensor{r.x_m, r.y_m, common::DegToRad(r.yaw_deg)};
    if (placed) {
      s.world_from_sensor = world_from_sensor;
      // The calibration's word on each sensor: s1 the reference; s2's radial bias estimated, the
      // others' held at their prior; s3's tracks leg-sized under shape.mount: torso.
      LiveSensor::Calibration& c = s.calibration;
      c.calibrated = true;
      c.sigma_x_m = i == 0 ? 0.0 : 0.011;
      c.sigma_y_m = i == 0 ? 0.0 : 0.0098;
      c.sigma_yaw_rad = i == 0 ? 0.0 : common::DegToRad(0.051);
      c.has_radial_bias = true;
      c.radial_bias_m = i == 1 ? -0.0183 : 0.0;
      c.sigma_radial_bias_m = i == 1 ? 0.0061 : 0.02;
      c.radial_bias_estimated = i == 1;
      c.mount_looks_like_legs = i == 2;
      if (i == 2) c.flag = "s3: tracks look like legs; set shape.mount: legs on its tracker";
    }
    s.fov_rad = common::DegToRad(r.fov_deg);
    s.first_angle_rad = -s.fov_rad / 2;
    s.max_range_m = r.max_range_m;
    s.status = i == 4 ? "silent" : "active";
    s.datagram_rate_hz = 25.0 + static_cast<double>(i);
    s.loss = 0.002 * static_cast<double>(i);
    s.clock_sync = i == 2 ? "unsynchronized" : "synchronized";
    s.track_frames = 1000 * i;
    // A beam every 2.5 degrees to the walls.
    s.background_first_angle_rad = s.first_angle_rad;
    s.background_angle_step_rad = common::DegToRad(2.5);
    for (double a = 0; a <= r.fov_deg; a += 2.5) {
      const double beam_rad = s.first_angle_rad + common::DegToRad(a);
      const double world_rad = world_from_sensor.yaw_rad + beam_rad;
      const double d = WallDistance(r.x_m, r.y_m, world_rad);
      s.background_ranges_m.push_back(d > r.max_range_m ? 0.0f : static_cast<float>(d));
      if (d > r.max_range_m) continue;
      const Eigen::Vector2d local(d * std::cos(beam_rad), d * std::sin(beam_rad));
      const Eigen::Vector2d p = placed ? world_from_sensor * local : local;
      s.background_xy.push_back({static_cast<float>(p.x()), static_cast<float>(p.y())});
    }
    state.sensors.push_back(std::move(s));
  }
  for (int k = 0; k < 2; ++k) {
    const auto [x, y, vx, vy] = Person(k, t_s);
    if (placed) {
      LiveFusedTrack f;
      f.id = 7 + static_cast<std::uint64_t>(k);
      f.state = "confirmed";
      f.x_m = x;
      f.y_m = y;
      f.vx_mps = vx;
      f.vy_mps = vy;
      f.cov_xx = f.cov_yy = 0.0025;
      f.sensors = {"s1", "s2", "s5"};
      state.fused.push_back(f);
    }
    for (std::size_t i = 0; i < kRoom.size(); ++i) {
      const RoomSensor& r = kRoom[i];
      const common::Pose2 world_from_sensor{r.x_m, r.y_m, common::DegToRad(r.yaw_deg)};
      // Each sensor's estimate a few centimetres off the truth, as real ones are.
      const Eigen::Vector2d seen(x + 0.12 * std::cos(static_cast<double>(i)),
                                 y + 0.12 * std::sin(static_cast<double>(i)));
      const Eigen::Vector2d p = placed ? seen : world_from_sensor.inverse() * seen;
      const Eigen::Vector2d v =
          placed
              ? Eigen::Vector2d(vx, vy)
              : Eigen::Vector2d(world_from_sensor.rotation().transpose() * Eigen::Vector2d(vx, vy));
      LiveTrack t;
      t.sensor_id = r.id;
      t.track_id = static_cast<std::uint32_t>(10 * i + static_cast<std::size_t>(k));
      t.state = "confirmed";
      t.x_m = p.x();
      t.y_m = p.y();
      t.vx_mps = v.x();
      t.vy_mps = v.y();
      if (placed) t.fused_id = 7 + static_cast<std::uint64_t>(k);
      state.tracks.push_back(t);
    }
  }
  state.zones.push_back({"door", "line", {{6.0, 1.0}, {6.0, 5.0}}, 0, 4, 3});
  state.zones.push_back(
      {"lobby", "polygon", {{9.0, 1.0}, {13.0, 1.0}, {13.0, 4.0}, {9.0, 4.0}}, 1, 5, 4});
  return state;
}

// ---- Chromium over the DevTools pipe -------------------------------------------------------

std::vector<std::uint8_t> Base64Decode(const std::string& text) {
  std::array<int, 256> value;
  value.fill(-1);
  const std::string alphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  for (std::size_t i = 0; i < alphabet.size(); ++i) {
    value[static_cast<unsigned char>(alphabet[i])] = static_cast<int>(i);
  }
  std::vector<std::uint8_t> out;
  unsigned bits = 0;
  int count = 0;
  for (const char c : text) {
    const int v = value[static_cast<unsigned char>(c)];
    if (v < 0) continue;  // '=' and line breaks
    bits = (bits << 6) | static_cast<unsigned>(v);
    count += 6;
    if (count >= 8) {
      count -= 8;
      out.push_back(static_cast<std::uint8_t>((bits >> count) & 0xFF));
    }
  }
  return out;
}

// A fd number above the ones a child keeps (0-4), close-on-exec.
int HighFd(int fd) {
  const int high = ::fcntl(fd, F_DUPFD_CLOEXEC, 10);
  ::close(fd);
  return high;
}

class Browser {
 public:
  ~Browser() { Close(); }

  // Starts chromium on `url`; its stderr goes to `log_path`.
  bool Start(const std::string& url, const std::string& profile_dir, const std::string& log_path) {
    int to_chrome[2], from_chrome[2];
    if (::pipe(to_chrome) != 0 || ::pipe(from_chrome) != 0) return false;
    const int chrome_in = HighFd(to_chrome[0]), chrome_out = HighFd(from_chrome[1]);
    write_fd_ = HighFd(to_chrome[1]);
    read_fd_ = HighFd(from_chrome[0]);
    std::vector<std::string> args = {
        kChromium,
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--no-first-run",
        "--hide-scrollbars",
        "--mute-audio",
        "--remote-debugging-pipe",
        "--user-data-dir=" + profile_dir,
        "--window-size=" + std::to_string(kWidthPx) + "," + std::to_string(kHeightPx),
        url};
    std::vector<char*> argv;
    for (std::string& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    // The DevTools pipe: the browser reads commands on fd 3 and writes answers on fd 4.
    posix_spawn_file_actions_adddup2(&actions, chrome_in, 3);
    posix_spawn_file_actions_adddup2(&actions, chrome_out, 4);
    posix_spawn_file_actions_addopen(&actions, 1, "/dev/null", O_WRONLY, 0);
    posix_spawn_file_actions_addopen(&actions, 2, log_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC,
                                     0644);
    posix_spawnattr_t attributes;
    posix_spawnattr_init(&attributes);
    // Its own process group, so a browser that hangs can be ended with all its helpers.
    posix_spawnattr_setflags(&attributes, POSIX_SPAWN_SETPGROUP);
    posix_spawnattr_setpgroup(&attributes, 0);
    const int rc = posix_spawn(&pid_, kChromium, &actions, &attributes, argv.data(), environ);
    posix_spawn_file_actions_destroy(&actions);
    posix_spawnattr_destroy(&attributes);
    ::close(chrome_in);
    ::close(chrome_out);
    if (rc != 0) pid_ = -1;
    return rc == 0;
  }

  // Sends one command and waits for its answer ("result"), skipping events. nullopt on an error
  // answer, a closed pipe or the deadline.
  std::optional<json> Call(const std::string& method, json params = json::object(),
                           std::chrono::milliseconds timeout = 10s) {
    const int id = ++last_id_;
    json command = {{"id", id}, {"method", method}, {"params", std::move(params)}};
    if (!session_.empty()) command["sessionId"] = session_;
    std::string bytes = command.dump();
    bytes.push_back('\0');
    for (std::size_t done = 0; done < bytes.size();) {
      const ssize_t n = ::write(write_fd_, bytes.data() + done, bytes.size() - done);
      if (n <= 0) return std::nullopt;
      done += static_cast<std::size_t>(n);
    }
    const auto deadline = Clock::now() + timeout;
    while (true) {
      for (std::size_t end; (end = buffer_.find('\0')) != std::string::npos;) {
        json message = json::parse(buffer_.substr(0, end), nullptr, false);
        buffer_.erase(0, end + 1);
        if (message.is_object() && message.value("id", -1) == id) {
          if (message.contains("error")) {
            last_error_ = message["error"].dump();
            return std::nullopt;
          }
          return message["result"];
        }
      }
      const auto left =
          std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now());
      if (left.count() <= 0) {
        last_error_ = method + ": no answer in time";
        return std::nullopt;
      }
      pollfd p{read_fd_, POLLIN, 0};
      if (::poll(&p, 1, static_cast<int>(left.count())) <= 0) continue;
      char chunk[65536];
      const ssize_t n = ::read(read_fd_, chunk, sizeof(chunk));
      if (n <= 0) {
        last_error_ = method + ": the browser closed the pipe";
        return std::nullopt;
      }
      buffer_.append(chunk, static_cast<std::size_t>(n));
    }
  }

  // Attaches to the page showing `url` (it may take a moment to appear).
  bool AttachToPage(const std::string& url) {
    const auto deadline = Clock::now() + 10s;
    while (Clock::now() < deadline) {
      const auto targets = Call("Target.getTargets");
      if (!targets) return false;
      for (const json& t : (*targets)["targetInfos"]) {
        if (t.value("type", "") != "page" || t.value("url", "").rfind(url, 0) != 0) continue;
        const auto attached =
            Call("Target.attachToTarget", {{"targetId", t["targetId"]}, {"flatten", true}});
        if (!attached) return false;
        session_ = (*attached)["sessionId"].get<std::string>();
        return Call("Emulation.setDeviceMetricsOverride", {{"width", kWidthPx},
                                                           {"height", kHeightPx},
                                                           {"deviceScaleFactor", 1},
                                                           {"mobile", false}})
            .has_value();
      }
      std::this_thread::sleep_for(50ms);
    }
    return false;
  }

  // The value of a JavaScript expression in the page (null when it failed).
  json Evaluate(const std::string& expression) {
    const auto r = Call("Runtime.evaluate", {{"expression", expression}, {"returnByValue", true}});
    if (!r || r->contains("exceptionDetails")) return nullptr;
    return (*r)["result"].value("value", json());
  }

  // Polls a summary attribute until it reaches `at_least`; returns the last value.
  double WaitForSummary(const std::string& attribute, double at_least,
                        std::chrono::milliseconds timeout) {
    const auto deadline = Clock::now() + timeout;
    double value = -1;
    while (Clock::now() < deadline) {
      const json v =
          Evaluate("Number(document.getElementById('summary').dataset." + attribute + ")");
      value = v.is_number() ? v.get<double>() : -1;
      if (value >= at_least) break;
      std::this_thread::sleep_for(50ms);
    }
    return value;
  }

  std::optional<std::vector<std::uint8_t>> Screenshot() {
    const auto r = Call("Page.captureScreenshot", {{"format", "png"}});
    if (!r) return std::nullopt;
    return Base64Decode((*r)["data"].get<std::string>());
  }

  void Close() {
    if (pid_ <= 0) return;
    session_.clear();
    Call("Browser.close", json::object(), 3s);
    const auto deadline = Clock::now() + 5s;
    int status = 0;
    while (::waitpid(pid_, &status, WNOHANG) == 0) {
      if (Clock::now() > deadline) {
        ::kill(-pid_, SIGKILL);
        ::waitpid(pid_, &status, 0);
        break;
      }
      std::this_thread::sleep_for(20ms);
    }
    pid_ = -1;
    ::close(write_fd_);
    ::close(read_fd_);
  }

  const std::string& last_error() const { return last_error_; }

 private:
  pid_t pid_ = -1;
  int write_fd_ = -1, read_fd_ = -1;
  int last_id_ = 0;
  std::string buffer_, session_, last_error_;
};

// ---- a minimal PNG reader for the screenshot (8-bit RGB/RGBA, not interlaced) ----------------

struct Image {
  int width = 0, height = 0;
  std::vector<std::uint32_t> rgb;  // 0xRRGGBB per pixel
  std::uint32_t At(int x, int y) const {
    return rgb[static_cast<std::size_t>(y) * static_cast<std::size_t>(width) +
               static_cast<std::size_t>(x)];
  }
};

std::uint32_t BigEndian32(const std::uint8_t* p) {
  return (std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) | (std::uint32_t{p[2]} << 8) |
         p[3];
}

std::optional<Image> DecodePng(const std::vector<std::uint8_t>& png, std::string* error) {
  static constexpr std::uint8_t kSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};
  if (png.size() < 8 || !std::equal(kSignature, kSignature + 8, png.begin())) {
    *error = "no PNG signature";
    return std::nullopt;
  }
  Image image;
  int channels = 0;
  std::vector<std::uint8_t> compressed;
  for (std::size_t at = 8; at + 12 <= png.size();) {
    const std::uint32_t length = BigEndian32(&png[at]);
    if (length > png.size() - at - 12) {
      *error = "chunk past the end";
      return std::nullopt;
    }
    const std::string type(reinterpret_cast<const char*>(&png[at + 4]), 4);
    const std::uint8_t* data = &png[at + 8];
    if (type == "IHDR") {
      image.width = static_cast<int>(BigEndian32(data));
      image.height = static_cast<int>(BigEndian32(data + 4));
      if (data[8] != 8 || (data[9] != 2 && data[9] != 6) || data[12] != 0) {
        *error = "not 8-bit RGB/RGBA without interlace";
        return std::nullopt;
      }
      channels = data[9] == 6 ? 4 : 3;
    } else if (type == "IDAT") {
      compressed.insert(compressed.end(), data, data + length);
    }
    at += 12 + length;
  }
  if (channels == 0 || image.width <= 0 || image.height <= 0 || image.width > 10000 ||
      image.height > 10000) {
    *error = "bad or missing IHDR";
    return std::nullopt;
  }
  const std::size_t stride = static_cast<std::size_t>(image.width) * channels;
  std::vector<std::uint8_t> raw((stride + 1) * static_cast<std::size_t>(image.height));
  uLongf raw_size = static_cast<uLongf>(raw.size());
  if (uncompress(raw.data(), &raw_size, compressed.data(), static_cast<uLong>(compressed.size())) !=
          Z_OK ||
      raw_size != raw.size()) {
    *error = "image data does not inflate to the image size";
    return std::nullopt;
  }
  // Undo the row filters (PNG spec, section 9).
  std::vector<std::uint8_t> previous(stride, 0), row(stride);
  image.rgb.reserve(static_cast<std::size_t>(image.width) * static_cast<std::size_t>(image.height));
  for (int y = 0; y < image.height; ++y) {
    const std::uint8_t* line = &raw[static_cast<std::size_t>(y) * (stride + 1)];
    const std::uint8_t filter = line[0];
    for (std::size_t i = 0; i < stride; ++i) {
      const int a = i >= static_cast<std::size_t>(channels) ? row[i - channels] : 0;
      const int b = previous[i];
      const int c = i >= static_cast<std::size_t>(channels) ? previous[i - channels] : 0;
      int predictor = 0;
      switch (filter) {
        case 0:
          break;
        case 1:
          predictor = a;
          break;
        case 2:
          predictor = b;
          break;
        case 3:
          predictor = (a + b) / 2;
          break;
        case 4: {
          const int p = a + b - c, pa = std::abs(p - a), pb = std::abs(p - b), pc = std::abs(p - c);
          predictor = (pa <= pb && pa <= pc) ? a : (pb <= pc ? b : c);
          break;
        }
        default:
          *error = "bad row filter";
          return std::nullopt;
      }
      row[i] = static_cast<std::uint8_t>(line[1 + i] + predictor);
    }
    for (int x = 0; x < image.width; ++x) {
      const std::uint8_t* p = &row[static_cast<std::size_t>(x) * channels];
      image.rgb.push_back((std::uint32_t{p[0]} << 16) | (std::uint32_t{p[1]} << 8) | p[2]);
    }
    std::swap(previous, row);
  }
  return image;
}

// ---- the test ------------------------------------------------------------------------------

int Attribute(const std::string& html, const std::string& name) {
  const std::regex re("id=\"summary\"[^>]*\\b" + name + "=\"([0-9.]+)\"");
  std::smatch m;
  return std::regex_search(html, m, re) ? static_cast<int>(std::lround(std::stod(m[1]))) : -1;
}

class LiveViewBrowserTest : public ::testing::Test {
 protected:
  void SetUp() override {
    if (::access(kChromium, X_OK) != 0) {
      GTEST_SKIP() << kChromium
                   << " is absent: install Debian's chromium package to run the "
                      "browser test of the live view";
    }
    std::filesystem::create_directories(LRFNET_TEST_ARTIFACTS_DIR);
    // A browser that dies must fail the test, not end it by SIGPIPE on the DevTools pipe.
    ::signal(SIGPIPE, SIG_IGN);
  }

  void StartServer(bool placed, std::uint16_t port = 0) {
    placed_ = placed;
    LiveViewOptions options;
    options.port = port;
    server_ = std::make_unique<LiveViewServer>(io_, options);
    std::string error;
    ASSERT_TRUE(server_->Start(&error)) << error;
    port_ = server_->port();
  }
  void RunIo() {
    start_ = Clock::now();
    PublishEvery100Ms();
    thread_ = std::thread([this] { io_.run(); });
  }
  template <typename F>
  auto OnIo(F f) {
    std::packaged_task<decltype(f())()> task(std::move(f));
    auto result = task.get_future();
    asio::post(io_, [&task] { task(); });
    return result.get();
  }

  void TearDown() override {
    if (!thread_.joinable()) return;
    OnIo([this] {
      // A wait that has already completed is not cancelled any more: the flag ends the chain.
      publishing_ = false;
      timer_.cancel();
      if (server_) server_->Stop();
    });
    guard_.reset();
    thread_.join();
  }

  // The publisher lives on the io thread (the server is not thread-safe): a timer at 10 Hz.
  void PublishEvery100Ms() {
    if (server_) {
      const double t_s = std::chrono::duration<double>(Clock::now() - start_).count();
      const LiveState state = RoomState(t_s, placed_);
      server_->PublishFoxglove(FoxgloveMessagesOf(state));
      server_->Publish(LiveStateJson(state));
    }
    timer_.expires_after(100ms);
    timer_.async_wait([this](const boost::system::error_code& ec) {
      if (!ec && publishing_) PublishEvery100Ms();
    });
  }

  std::string Url() const { return "http://127.0.0.1:" + std::to_string(port_) + "/"; }

  // Screenshot to test_artifacts/<name>, decoded.
  Image Screenshot(Browser& browser, const std::string& name) {
    const auto png = browser.Screenshot();
    EXPECT_TRUE(png.has_value()) << browser.last_error();
    if (!png) return {};
    const std::string path = std::string(LRFNET_TEST_ARTIFACTS_DIR) + "/" + name;
    std::ofstream(path, std::ios::binary)
        .write(reinterpret_cast<const char*>(png->data()),
               static_cast<std::streamsize>(png->size()));
    EXPECT_GT(png->size(), 20'000u) << path;
    std::string error;
    auto image = DecodePng(*png, &error);
    EXPECT_TRUE(image.has_value()) << path << ": " << error;
    return image.value_or(Image{});
  }

  // The canvas shows every sensor's marker in its colour and is not one flat colour.
  static void ExpectSensorsDrawn(const Image& image) {
    ASSERT_EQ(image.width, kWidthPx);
    ASSERT_EQ(image.height, kHeightPx);
    std::map<std::uint32_t, int> counts;
    for (int y = 0; y < image.height; ++y) {
      for (int x = 0; x < kCanvasWidthPx - 20; ++x) ++counts[image.At(x, y)];
    }
    int most = 0;
    for (const auto& [colour, n] : counts) most = std::max(most, n);
    const int canvas_pixels = (kCanvasWidthPx - 20) * kHeightPx;
    EXPECT_GT(counts.size(), 200u) << "the canvas has hardly any colours";
    EXPECT_LT(most, canvas_pixels * 9 / 10) << "the canvas is nearly one colour";
    for (std::size_t i = 0; i < kSensorColours.size(); ++i) {
      EXPECT_GE(counts[kSensorColours[i]], 30) << "sensor " << kRoom[i].id << " not drawn";
    }
  }

  asio::io_context io_;
  asio::executor_work_guard<asio::io_context::executor_type> guard_{io_.get_executor()};
  asio::steady_timer timer_{io_};
  std::unique_ptr<LiveViewServer> server_;
  std::uint16_t port_ = 0;
  bool placed_ = true;
  bool publishing_ = true;  // io thread only
  Clock::time_point start_;
  std::thread thread_;
  testing::ScratchDir scratch_;
};

TEST_F(LiveViewBrowserTest, ShowsPlacedSensorsAndMovingTracksAndReconnects) {
  StartServer(/*placed=*/true);
  RunIo();
  Browser browser;
  ASSERT_TRUE(browser.Start(Url(), scratch_ / "profile", scratch_ / "chromium.log"));
  ASSERT_TRUE(browser.AttachToPage(Url())) << browser.last_error() << "\n"
                                           << testing::ReadText(scratch_ / "chromium.log");

  // 1.5 s of messages: the people walk 1.5 m.
  EXPECT_GE(browser.WaitForSummary("messages", 15, 15s), 15);
  const Image image = Screenshot(browser, "live_view.png");
  ExpectSensorsDrawn(image);
  const json dom = browser.Evaluate("document.documentElement.outerHTML");
  ASSERT_TRUE(dom.is_string());
  const std::string html = dom.get<std::string>();
  EXPECT_GE(Attribute(html, "data-messages"), 15);
  EXPECT_EQ(Attribute(html, "data-sensors"), 6);
  EXPECT_EQ(Attribute(html, "data-placed"), 6);
  EXPECT_EQ(Attribute(html, "data-tracks"), 12);
  EXPECT_EQ(Attribute(html, "data-fused"), 2);
  EXPECT_EQ(Attribute(html, "data-zones"), 2);
  EXPECT_EQ(
      browser.Evaluate("document.querySelector('#zone-rows tr[data-zone=\"door\"]').textContent"),
      "door (line)043");
  EXPECT_EQ(Attribute(html, "data-errors"), 0);
  EXPECT_EQ(Attribute(html, "data-script-errors"), 0);
  const double moved = browser.WaitForSummary("moved", 0.8, 5s);
  EXPECT_GE(moved, 0.8) << "the tracks did not move on the page";
  EXPECT_LT(moved, 30.0);
  // The health table has a row per sensor and the fused table one per person.
  EXPECT_EQ(browser.Evaluate("document.querySelectorAll('#sensor-rows tr.sensor').length"), 6);
  EXPECT_EQ(browser.Evaluate("document.querySelectorAll('#fused-rows tr').length"), 2);
  EXPECT_EQ(browser.Evaluate("document.getElementById('calib-state').textContent"), "calibrated");
  for (const RoomSensor& r : kRoom) {
    EXPECT_NE(html.find(std::string("</span>") + r.id + "</td>"), std::string::npos) << r.id;
  }
  // Under each sensor its pose's sigmas and radial bias; the knee-height mount where it is seen.
  const auto calibration_row = [&](const std::string& id) {
    const json text = browser.Evaluate(
        "document.querySelector('#sensor-rows tr.calib[data-sensor=\"" + id + "\"]').textContent");
    return text.is_string() ? text.get<std::string>() : std::string();
  };
  EXPECT_EQ(
      calibration_row("s2"),
      "pose 8.00, 0.30 m, 90.0° ± 1.1, 1.0 cm, 0.05° · radial bias -1.8 ± 0.6 cm (estimated)");
  EXPECT_EQ(calibration_row("s1"),
            "pose 0.30, 0.30 m, 45.0° (reference) · radial bias 0.0 ± 2.0 cm (prior)");
  EXPECT_EQ(calibration_row("s3"),
            "pose 15.70, 0.30 m, 135.0° ± 1.1, 1.0 cm, 0.05° · radial bias 0.0 ± 2.0 cm (prior)"
            "scan plane looks like knee height: set shape.mount: legs");
  EXPECT_EQ(browser.Evaluate("document.getElementById('summary').dataset.legSensors"), "s3");

  // The daemon goes away: the page says so, and comes back by itself when it is back.
  OnIo([this] { server_->Stop(); });
  const auto disconnected = [&] {
    return browser.Evaluate("document.getElementById('summary').dataset.connected") == "false";
  };
  const auto deadline = Clock::now() + 5s;
  while (!disconnected() && Clock::now() < deadline) std::this_thread::sleep_for(50ms);
  ASSERT_TRUE(disconnected());
  EXPECT_EQ(browser.Evaluate("document.getElementById('banner').classList.contains('show')"), true);
  Screenshot(browser, "live_view_disconnected.png");
  const double before = browser.WaitForSummary("messages", 0, 1s);
  OnIo([this] {
    server_.reset();
    StartServer(true, port_);
  });
  EXPECT_GE(browser.WaitForSummary("messages", before + 5, 15s), before + 5)
      << "the page did not reconnect";
  EXPECT_EQ(browser.Evaluate("document.getElementById('summary').dataset.connected"), "true");
}

TEST_F(LiveViewBrowserTest, BeforeCalibrationShowsEachSensorInItsOwnFrame) {
  StartServer(/*placed=*/false);
  RunIo();
  Browser browser;
  ASSERT_TRUE(browser.Start(Url(), scratch_ / "profile", scratch_ / "chromium.log"));
  ASSERT_TRUE(browser.AttachToPage(Url())) << browser.last_error();
  EXPECT_GE(browser.WaitForSummary("messages", 10, 15s), 10);
  ExpectSensorsDrawn(Screenshot(browser, "live_view_collecting.png"));
  const json dom = browser.Evaluate("document.documentElement.outerHTML");
  ASSERT_TRUE(dom.is_string());
  const std::string html = dom.get<std::string>();
  EXPECT_EQ(Attribute(html, "data-sensors"), 6);
  EXPECT_EQ(Attribute(html, "data-placed"), 0);
  EXPECT_EQ(Attribute(html, "data-tracks"), 12);
  EXPECT_EQ(Attribute(html, "data-fused"), 0);
  EXPECT_EQ(Attribute(html, "data-script-errors"), 0);
  EXPECT_GE(browser.WaitForSummary("moved", 0.5, 5s), 0.5) << "the tracks did not move";
  EXPECT_EQ(browser.Evaluate("document.getElementById('calib-state').textContent"), "collecting");
  EXPECT_EQ(browser.Evaluate("document.getElementById('calib-percent').textContent"), "45 %");
  EXPECT_EQ(browser.Evaluate("document.getElementById('progress-fill').style.width"), "45%");
  // No calibration yet: no calibration line under the sensors.
  EXPECT_EQ(browser.Evaluate("document.querySelectorAll('#sensor-rows tr.calib').length"), 0);
  EXPECT_EQ(browser.Evaluate("document.querySelectorAll('#sensor-rows tr.sensor').length"), 6);
}

// ---- Foxglove -------------------------------------------------------------------------------

// The same server and state, with the real Foxglove client (@foxglove/ws-protocol, node).
class LiveViewFoxgloveTest : public LiveViewBrowserTest {
 protected:
  void SetUp() override {
    const std::string missing = testing::NodeClientsMissing();
    if (!missing.empty()) GTEST_SKIP() << missing;
  }
  // Runs the client until every channel sent something and `wait_topic` three messages.
  json RunClient(const std::string& path, const std::string& subprotocol,
                 const std::string& wait_topic) {
    testing::Process node(testing::kNode, {std::string(LRFNET_NODE_DIR) + "/foxglove_client.mjs",
                                           "ws://127.0.0.1:" + std::to_string(port_) + path,
                                           subprotocol, wait_topic, "3", "20"});
    EXPECT_EQ(node.Wait(30s), 0) << node.err();
    const json summary = json::parse(node.out(), nullptr, false);
    EXPECT_TRUE(summary.is_object()) << node.out() << node.err();
    return summary;
  }
};

double Yaw(const json& q) { return 2.0 * std::atan2(q["z"].get<double>(), q["w"].get<double>()); }

TEST_F(LiveViewFoxgloveTest, AFoxgloveClientSeesSensorsTracksTransformsAndZones) {
  StartServer(/*placed=*/true);
  RunIo();
  const json summary = RunClient("/", "foxglove.websocket.v1", "/lrfnet/fused");
  ASSERT_TRUE(summary.is_object());
  EXPECT_EQ(summary["subprotocol"], "foxglove.websocket.v1");
  EXPECT_EQ(summary["serverInfo"]["name"], "lrfnetd");
  EXPECT_TRUE(summary["invalid"].empty()) << summary["invalid"].dump(1);
  EXPECT_TRUE(summary["errors"].empty()) << summary["errors"].dump(1);
  std::map<std::string, std::string> schema_of;
  for (const json& c : summary["channels"]) schema_of[c["topic"]] = c["schemaName"];
  EXPECT_EQ(schema_of["/tf"], "foxglove.FrameTransforms");
  EXPECT_EQ(schema_of["/lrfnet/fused"], "foxglove.SceneUpdate");
  EXPECT_EQ(schema_of["/lrfnet/zones"], "foxglove.SceneUpdate");
  EXPECT_EQ(schema_of["/lrfnet/calibration"], "lrfnet.Calibration");
  for (const RoomSensor& r : kRoom) {
    EXPECT_EQ(schema_of["/lrfnet/tracks/" + std::string(r.id)], "foxglove.SceneUpdate") << r.id;
    EXPECT_EQ(schema_of["/lrfnet/background/" + std::string(r.id)], "foxglove.LaserScan") << r.id;
  }
  const json& last = summary["last"];
  // Sensor poses as transforms from the world.
  ASSERT_EQ(last["/tf"]["transforms"].size(), kRoom.size());
  for (const json& t : last["/tf"]["transforms"]) {
    const auto room = std::find_if(kRoom.begin(), kRoom.end(), [&](const RoomSensor& r) {
      return t["child_frame_id"] == r.id;
    });
    ASSERT_NE(room, kRoom.end()) << t.dump();
    EXPECT_EQ(t["parent_frame_id"], "world");
    EXPECT_NEAR(t["translation"]["x"].get<double>(), room->x_m, 1e-9);
    EXPECT_NEAR(t["translation"]["y"].get<double>(), room->y_m, 1e-9);
    EXPECT_NEAR(common::AngleDiff(Yaw(t["rotation"]), common::DegToRad(room->yaw_deg)), 0.0, 1e-9);
  }
  // Two people, each a cylinder at its fused position, with its id; the message's time is the
  // state's.
  const json& fused = last["/lrfnet/fused"];
  ASSERT_EQ(fused["entities"].size(), 2u);
  for (const json& e : fused["entities"]) {
    EXPECT_EQ(e["frame_id"], "world");
    ASSERT_EQ(e["cylinders"].size(), 1u);
    const double x = e["cylinders"][0]["pose"]["position"]["x"].get<double>();
    const double y = e["cylinders"][0]["pose"]["position"]["y"].get<double>();
    EXPECT_GT(x, 0.0);
    EXPECT_LT(x, 16.0);
    EXPECT_GT(y, 0.0);
    EXPECT_LT(y, 12.0);
    EXPECT_TRUE(e["texts"][0]["text"] == "7" || e["texts"][0]["text"] == "8");
  }
  const std::uint64_t stamp = std::stoull(last["/lrfnet/fused#timestamp"].get<std::string>());
  EXPECT_EQ(stamp, fused["entities"][0]["timestamp"]["sec"].get<std::uint64_t>() * 1'000'000'000 +
                       fused["entities"][0]["timestamp"]["nsec"].get<std::uint64_t>());
  // Each sensor's raw tracks; its background as a scan in its own frame.
  EXPECT_EQ(last["/lrfnet/tracks/s1"]["entities"].size(), 2u);
  const json& scan = last["/lrfnet/background/s1"];
  EXPECT_EQ(scan["frame_id"], "s1");
  EXPECT_GT(scan["ranges"].size(), 50u);
  EXPECT_NEAR(scan["start_angle"].get<double>(), -common::DegToRad(kRoom[0].fov_deg) / 2, 1e-9);
  // Zones with their counts; the calibration state.
  ASSERT_EQ(last["/lrfnet/zones"]["entities"].size(), 2u);
  EXPECT_EQ(last["/lrfnet/zones"]["entities"][0]["lines"][0]["points"].size(), 2u);
  EXPECT_EQ(last["/lrfnet/zones"]["entities"][1]["lines"][0]["type"], 1);  // closed polygon
  EXPECT_EQ(last["/lrfnet/calibration"]["state"], "calibrated");
  EXPECT_EQ(last["/lrfnet/calibration"]["sensors"].size(), kRoom.size());
  const json& s2 = last["/lrfnet/calibration"]["sensors"][1];
  EXPECT_DOUBLE_EQ(s2["radial_bias_m"].get<double>(), -0.0183) << s2.dump();
  EXPECT_DOUBLE_EQ(s2["sigma_radial_bias_m"].get<double>(), 0.0061) << s2.dump();
  EXPECT_EQ(s2["radial_bias_estimated"], true) << s2.dump();
  EXPECT_DOUBLE_EQ(s2["sigma_x_m"].get<double>(), 0.011) << s2.dump();
  EXPECT_EQ(last["/lrfnet/calibration"]["sensors"][2]["mount_looks_like_legs"], true);
  // Everything subscribed arrived more than once (moving people), and the counters say so.
  EXPECT_GE(summary["counts"]["/lrfnet/fused"].get<int>(), 3);
  const LiveViewCounters c = OnIo([this] { return server_->counters(); });
  EXPECT_EQ(c.foxglove_clients, 1u);
  std::uint64_t received = 0;
  for (const auto& [topic, n] : summary["counts"].items()) received += n.get<std::uint64_t>();
  EXPECT_GE(c.foxglove_messages_sent, received);
}

TEST_F(LiveViewFoxgloveTest, NewerClientsSubprotocolAndThePagesFeedSideBySide) {
  StartServer(/*placed=*/false);
  RunIo();
  // foxglove.sdk.v1 (newer Foxglove) on /ws: the same protocol; before calibration no transforms.
  const json summary = RunClient("/ws", "foxglove.sdk.v1", "/lrfnet/tracks/s2");
  ASSERT_TRUE(summary.is_object());
  EXPECT_EQ(summary["subprotocol"], "foxglove.sdk.v1");
  EXPECT_TRUE(summary["invalid"].empty()) << summary["invalid"].dump(1);
  EXPECT_TRUE(summary["last"]["/tf"]["transforms"].empty());
  EXPECT_EQ(summary["last"]["/lrfnet/calibration"]["state"], "collecting");
  // Raw tracks in each sensor's own frame.
  EXPECT_EQ(summary["last"]["/lrfnet/tracks/s2"]["entities"][0]["frame_id"], "s2");
}

}  // namespace
}  // namespace lrfnet::daemon
