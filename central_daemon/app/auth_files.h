#pragma once
// lrfnetd's files of authenticated datagrams (the adapters around the ingest's DatagramVerifier):
// the sensor keys of --keys DIR, and the replay state kept in the state directory across restarts.

#include <cstdint>
#include <optional>
#include <string>

#include "central_daemon/ingest/datagram_verifier.h"
#include "central_daemon/ingest/ingest.h"

namespace lrfnet::daemon {

// Every sensor key in `dir` ($CREDENTIALS_DIRECTORY expanded) into auth->keys. An error when the
// folder cannot be read, a key file is broken or readable by others, or there is no sensor key.
std::optional<std::string> LoadSensorKeys(const std::string& dir, AuthOptions* auth);

// The live view's access token: the first line of a secret file (mode 0600, $CREDENTIALS_DIRECTORY
// expanded), at least 16 characters, no spaces.
std::optional<std::string> LoadAccessToken(const std::string& path, std::string* token);

// The replay state file (<state dir>/auth-state): loaded at start, written (atomically) at most
// once a second while sealed datagrams are accepted, and at exit.
class AuthStateFile {
 public:
  // `state_dir` empty: $STATE_DIRECTORY when set, else nothing is kept (path() empty).
  explicit AuthStateFile(const std::string& state_dir);
  const std::string& path() const { return path_; }
  // The stored state (none when the file does not exist yet); an error when it is unreadable.
  std::optional<std::string> Load(std::vector<StoredAuthState>* state) const;
  // Writes when the ingest accepted sealed datagrams since the last write and `now_s` (a
  // monotonic clock) is at least 1 s after it, or always with force. Empty, or the error.
  std::string Save(const Ingest& ingest, double now_s, bool force);

 private:
  std::string path_;
  std::uint64_t saved_changes_ = 0;
  double saved_s_ = -1e300;
};

}  // namespace lrfnet::daemon
