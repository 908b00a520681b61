#include "central_daemon/app/auth_files.h"

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "central_daemon/app/calibration_service.h"
#include "common/key_file.h"

namespace lrfnet::daemon {

std::optional<std::string> LoadSensorKeys(const std::string& dir, AuthOptions* auth) {
  std::string expanded;
  if (auto e = auth::ExpandPath(dir, &expanded)) return e;
  std::vector<auth::KeyFile> keys;
  if (auto e = auth::ReadKeyDir(expanded, auth::KeyFile::Kind::kSensor, &keys)) return e;
  if (keys.empty()) {
    return "no sensor key in " + expanded + " (lrfnet keys derive --dir " + expanded +
           " SENSOR_ID writes one)";
  }
  auth->keys = std::move(keys);
  if (auto e = Validate(*auth)) return expanded + ": " + *e;
  return std::nullopt;
}

std::optional<std::string> LoadAccessToken(const std::string& path, std::string* token) {
  std::string expanded;
  if (auto e = auth::ExpandPath(path, &expanded)) return e;
  std::string text;
  if (auto e = auth::ReadSecretFile(expanded, &text)) return e;
  std::string line = text.substr(0, text.find('\n'));
  while (!line.empty() && (line.back() == '\r' || line.back() == ' ')) line.pop_back();
  if (line.size() < 16 || line.find_first_of(" \t&?#") != std::string::npos)
    return expanded + ": the token must be at least 16 characters without spaces, '&', '?', '#'";
  *token = line;
  return std::nullopt;
}

AuthStateFile::AuthStateFile(const std::string& state_dir) {
  std::string dir = state_dir;
  if (dir.empty()) {
    // systemd's StateDirectory=: the first of the colon-separated list.
    if (const char* env = std::getenv("STATE_DIRECTORY"); env != nullptr && *env != '\0') {
      dir = env;
      dir = dir.substr(0, dir.find(':'));
    }
  }
  if (!dir.empty()) path_ = (std::filesystem::path(dir) / "auth-state").string();
}

std::optional<std::string> AuthStateFile::Load(std::vector<StoredAuthState>* state) const {
  state->clear();
  if (path_.empty()) return std::nullopt;
  std::error_code ec;
  if (!std::filesystem::exists(path_, ec)) return std::nullopt;
  std::ifstream in(path_);
  if (!in) return "cannot read " + path_;
  std::stringstream text;
  text << in.rdbuf();
  if (auto e = ParseAuthState(text.str(), state)) return path_ + ": " + *e;
  return std::nullopt;
}

std::string AuthStateFile::Save(const Ingest& ingest, double now_s, bool force) {
  if (path_.empty()) return "";
  const std::uint64_t changes = ingest.auth_changes();
  if (changes == saved_changes_) return "";
  if (!force && now_s - saved_s_ < 1.0) return "";
  saved_changes_ = changes;
  saved_s_ = now_s;
  std::error_code ec;
  std::filesystem::create_directories(std::filesystem::path(path_).parent_path(), ec);
  return WriteFileAtomically(path_, FormatAuthState(ingest.AuthState()));
}

}  // namespace lrfnet::daemon
