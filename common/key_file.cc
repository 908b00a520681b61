#include "common/key_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cstdlib>
#include <cstring>
#include <filesystem>

#include "common/one_line.h"

namespace lrfnet::auth {
namespace {

constexpr std::size_t kMaxSecretBytes = 64 * 1024;

std::string Errno(const std::string& what, const std::string& path) {
  return what + " " + path + ": " + std::strerror(errno);
}

std::string_view Trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t' || s.front() == '\r'))
    s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r'))
    s.remove_suffix(1);
  return s;
}

}  // namespace

std::string FormatKeyFile(const KeyFile& f) {
  std::string text;
  if (f.kind == KeyFile::Kind::kSite) {
    text +=
        "# lrfnet site key: keep it secret (mode 0600) and on the daemon's host. The sensors'\n"
        "# keys are derived from it (lrfnet keys derive).\n";
  } else {
    text += "# lrfnet sensor key of '" + f.sensor_id +
            "': keep it secret (mode 0600); for this sensor's\n"
            "# gateway (lrfnet-tracker --key) and lrfnetd's key folder (lrfnetd --keys).\n";
  }
  text += "lrfnet-key 1\n";
  text += std::string("kind ") + (f.kind == KeyFile::Kind::kSite ? "site" : "sensor") + "\n";
  if (f.kind == KeyFile::Kind::kSensor) text += "sensor " + f.sensor_id + "\n";
  text += "epoch " + std::to_string(f.epoch) + "\n";
  text += "key " + ToHex(f.key) + "\n";
  return text;
}

std::optional<std::string> ParseKeyFile(std::string_view text, KeyFile* out) {
  KeyFile f;
  bool has_format = false, has_kind = false, has_sensor = false, has_epoch = false, has_key = false;
  std::size_t line_number = 0;
  while (!text.empty()) {
    const std::size_t end = text.find('\n');
    std::string_view line = Trim(text.substr(0, end));
    text = end == std::string_view::npos ? std::string_view() : text.substr(end + 1);
    ++line_number;
    if (line.empty() || line.front() == '#') continue;
    const std::size_t space = line.find_first_of(" \t");
    const std::string_view name = line.substr(0, space);
    const std::string_view value =
        space == std::string_view::npos ? std::string_view() : Trim(line.substr(space));
    const std::string where = "line " + std::to_string(line_number) + ": ";
    const auto once = [&](bool& seen) -> std::optional<std::string> {
      if (seen) return where + "'" + common::OneLine(name, 40) + "' given twice";
      seen = true;
      return std::nullopt;
    };
    if (name == "lrfnet-key") {
      if (auto e = once(has_format)) return e;
      if (value != "1") return where + "unknown key file format '" + common::OneLine(value, 40) + "'";
    } else if (name == "kind") {
      if (auto e = once(has_kind)) return e;
      if (value == "site") {
        f.kind = KeyFile::Kind::kSite;
      } else if (value == "sensor") {
        f.kind = KeyFile::Kind::kSensor;
      } else {
        return where + "kind must be site or sensor";
      }
    } else if (name == "sensor") {
      if (auto e = once(has_sensor)) return e;
      if (!IsValidSensorId(value)) return where + "sensor id must match [A-Za-z0-9_.-]{1,32}";
      f.sensor_id.assign(value);
    } else if (name == "epoch") {
      if (auto e = once(has_epoch)) return e;
      std::uint32_t epoch = 0;
      const auto [ptr, ec] = std::from_chars(value.data(), value.data() + value.size(), epoch);
      if (ec != std::errc() || ptr != value.data() + value.size() || epoch == 0)
        return where + "epoch must be 1..4294967295";
      f.epoch = epoch;
    } else if (name == "key") {
      if (auto e = once(has_key)) return e;
      if (!FromHex(value, f.key)) return where + "key must be 64 hex digits";
    } else {
      return where + "unknown entry '" + common::OneLine(name, 40) + "'";
    }
  }
  if (!has_format) return "not an lrfnet key file (no 'lrfnet-key 1' line)";
  if (!has_kind) return "missing 'kind'";
  if (!has_epoch) return "missing 'epoch'";
  if (!has_key) return "missing 'key'";
  if (f.kind == KeyFile::Kind::kSensor && !has_sensor) return "a sensor key needs 'sensor'";
  if (f.kind == KeyFile::Kind::kSite && has_sensor) return "a site key has no 'sensor'";
  *out = f;
  return std::nullopt;
}

std::string SiteKeyPath(const std::string& dir, std::uint32_t epoch) {
  return (std::filesystem::path(dir) / ("site-e" + std::to_string(epoch) + ".key")).string();
}

std::string SensorKeyPath(const std::string& dir, std::string_view sensor_id, std::uint32_t epoch) {
  return (std::filesystem::path(dir) /
          ("sensor-" + std::string(sensor_id) + "-e" + std::to_string(epoch) + ".key"))
      .string();
}

std::optional<std::string> ExpandPath(const std::string& path, std::string* expanded) {
  for (const std::string_view prefix :
       {std::string_view("$CREDENTIALS_DIRECTORY"), std::string_view("${CREDENTIALS_DIRECTORY}")}) {
    if (path.rfind(prefix, 0) != 0) continue;
    const char* dir = std::getenv("CREDENTIALS_DIRECTORY");
    if (dir == nullptr || *dir == '\0')
      return path + ": $CREDENTIALS_DIRECTORY is not set (no systemd credentials)";
    *expanded = std::string(dir) + path.substr(prefix.size());
    return std::nullopt;
  }
  *expanded = path;
  return std::nullopt;
}

std::optional<std::string> ReadSecretFile(const std::string& path, std::string* text) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NOFOLLOW);
  if (fd < 0) return Errno("cannot open", path);
  struct stat st {};
  if (::fstat(fd, &st) != 0) {
    const std::string e = Errno("cannot stat", path);
    ::close(fd);
    return e;
  }
  if (!S_ISREG(st.st_mode)) {
    ::close(fd);
    return path + ": not a regular file";
  }
  if ((st.st_mode & 077) != 0) {
    ::close(fd);
    char mode[8];
    std::snprintf(mode, sizeof mode, "%04o", static_cast<unsigned>(st.st_mode & 07777));
    return path + ": group or others may access this secret (mode " + mode + "); chmod 600 it";
  }
  if (st.st_size > static_cast<off_t>(kMaxSecretBytes)) {
    ::close(fd);
    return path + ": larger than 64 KiB, not a key file";
  }
  std::string out(static_cast<std::size_t>(st.st_size), '\0');
  std::size_t got = 0;
  while (got < out.size()) {
    const ssize_t n = ::read(fd, out.data() + got, out.size() - got);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;
    got += static_cast<std::size_t>(n);
  }
  ::close(fd);
  out.resize(got);
  *text = std::move(out);
  return std::nullopt;
}

std::optional<std::string> WriteSecretFile(const std::string& path, const std::string& text) {
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0600);
  if (fd < 0) return Errno("cannot create", path);
  // The umask may have taken bits away, never added; make the mode exact all the same.
  ::fchmod(fd, 0600);
  std::size_t done = 0;
  while (done < text.size()) {
    const ssize_t n = ::write(fd, text.data() + done, text.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const std::string e = Errno("cannot write", path);
      ::close(fd);
      ::unlink(path.c_str());
      return e;
    }
    done += static_cast<std::size_t>(n);
  }
  if (::fsync(fd) != 0 || ::close(fd) != 0) {
    const std::string e = Errno("cannot write", path);
    ::unlink(path.c_str());
    return e;
  }
  return std::nullopt;
}

std::optional<std::string> ReadKeyFile(const std::string& path, KeyFile* out) {
  std::string text;
  if (auto e = ReadSecretFile(path, &text)) return e;
  if (auto e = ParseKeyFile(text, out)) return path + ": " + *e;
  return std::nullopt;
}

std::optional<std::string> LoadSensorKey(const std::string& path, std::string_view sensor_id,
                                         KeyFile* out) {
  std::string expanded;
  if (auto e = ExpandPath(path, &expanded)) return e;
  KeyFile file;
  if (auto e = ReadKeyFile(expanded, &file)) return e;
  if (file.kind != KeyFile::Kind::kSensor)
    return expanded + ": a site key; give the sensor's key (lrfnet keys derive)";
  if (file.sensor_id != sensor_id) {
    return expanded + ": the key of sensor '" + file.sensor_id + "', not of '" +
           std::string(sensor_id) + "'";
  }
  *out = file;
  return std::nullopt;
}

std::optional<std::string> ReadKeyDir(const std::string& dir, KeyFile::Kind kind,
                                      std::vector<KeyFile>* out) {
  std::error_code ec;
  std::vector<std::string> paths;
  for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
    if (entry.path().extension() == ".key") paths.push_back(entry.path().string());
  }
  if (ec) return "cannot read the key folder " + dir + ": " + ec.message();
  std::sort(paths.begin(), paths.end());
  out->clear();
  for (const std::string& path : paths) {
    KeyFile file;
    if (auto e = ReadKeyFile(path, &file)) return e;
    if (file.kind == kind) out->push_back(std::move(file));
  }
  return std::nullopt;
}

}  // namespace lrfnet::auth
