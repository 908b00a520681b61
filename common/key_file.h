#pragma once
// Key files: the site key and the per-sensor keys on disk (and the live view's access token).
// Part of lrfnet_auth: the file adapter beside the pure envelope code of datagram_auth.h.
//
// A key file is text, one "name value" per line ('#' starts a comment line):
//   lrfnet-key 1
//   kind site | sensor
//   sensor <id>              (sensor keys only)
//   epoch <1..4294967295>
//   key <64 lowercase hex digits>
// Site keys are written as DIR/site-e<epoch>.key by `lrfnet keys init` (and `rotate`), sensor
// keys as DIR/sensor-<id>-e<epoch>.key by `lrfnet keys derive`. Every key file is created with
// mode 0600 (never replaced: a file of that name is an error), and a key file that the group or
// others may read or write is refused when read: a key that others could read is not a secret.
// Paths may start with "$CREDENTIALS_DIRECTORY/" (a systemd credential; ExpandPath).

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "common/datagram_auth.h"

namespace lrfnet::auth {

struct KeyFile {
  enum class Kind : std::uint8_t { kSite, kSensor };
  Kind kind = Kind::kSite;
  std::string sensor_id;  // kSensor only
  std::uint32_t epoch = 1;
  Key key{};
};

// The file's text (with a comment saying what it is).
std::string FormatKeyFile(const KeyFile& file);
// Parses a key file's text; nullopt on success, else one line saying what is wrong.
std::optional<std::string> ParseKeyFile(std::string_view text, KeyFile* out);

std::string SiteKeyPath(const std::string& dir, std::uint32_t epoch);
std::string SensorKeyPath(const std::string& dir, std::string_view sensor_id, std::uint32_t epoch);

// "$CREDENTIALS_DIRECTORY/NAME" (or "${CREDENTIALS_DIRECTORY}/NAME") with the environment's
// value; the path as given otherwise. Error when the variable is used but not set.
std::optional<std::string> ExpandPath(const std::string& path, std::string* expanded);

// Reads a secret (a key file or a token file): refused when it is not a regular file, when the
// group or others have any access to it, or when it is larger than 64 KiB.
std::optional<std::string> ReadSecretFile(const std::string& path, std::string* text);
// Creates `path` with mode 0600 (fails when it exists) and writes `text` (fsync'd).
std::optional<std::string> WriteSecretFile(const std::string& path, const std::string& text);

// ReadSecretFile + ParseKeyFile; errors name the file.
std::optional<std::string> ReadKeyFile(const std::string& path, KeyFile* out);

// The key file of one sensor ($CREDENTIALS_DIRECTORY expanded): an error when it is not a sensor
// key or names another sensor than `sensor_id`.
std::optional<std::string> LoadSensorKey(const std::string& path, std::string_view sensor_id,
                                         KeyFile* out);

// Every key file of `kind` in `dir` (files named *.key), sorted by name. Errors name the file;
// files of the other kind are skipped.
std::optional<std::string> ReadKeyDir(const std::string& dir, KeyFile::Kind kind,
                                      std::vector<KeyFile>* out);

}  // namespace lrfnet::auth
