#pragma once
// Test-only: the npm test clients of tests/node (installed by scripts/install_deps.sh with npm ci).
// A test that needs them skips with a clear message when node or node_modules is missing.

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <utility>
#include <vector>

#include "tests/process_harness.h"

namespace lrfnet::testing {

inline constexpr const char* kNode = "/usr/bin/node";

// "" when the clients can run, else why not.
inline std::string NodeClientsMissing() {
  if (::access(kNode, X_OK) != 0) return "node is not installed (/usr/bin/node)";
  const std::filesystem::path modules = std::filesystem::path(LRFNET_NODE_DIR) / "node_modules";
  if (!std::filesystem::exists(modules / "ajv") || !std::filesystem::exists(modules / "ws") ||
      !std::filesystem::exists(modules / "@foxglove" / "ws-protocol")) {
    return "the npm test clients are not installed: run scripts/install_deps.sh (npm ci in " +
           std::string(LRFNET_NODE_DIR) + ")";
  }
  return "";
}

#ifdef LRFNET_SCHEMA_DIR
// Validates (schema file name, JSON text) pairs against central_daemon/schemas with ajv. Returns
// the validator's output; *ok tells whether every message was valid.
inline std::string ValidateJsonMessages(
    const std::vector<std::pair<std::string, std::string>>& messages,
    const std::string& scratch_file, bool* ok) {
  {
    std::ofstream out(scratch_file);
    for (const auto& [schema, text] : messages) out << schema << "\t" << text << "\n";
  }
  Process node(kNode, {std::string(LRFNET_NODE_DIR) + "/validate_json.mjs", LRFNET_SCHEMA_DIR,
                       scratch_file});
  *ok = node.Wait(std::chrono::milliseconds(60'000)) == 0;
  return node.out() + node.err();
}
#endif

}  // namespace lrfnet::testing
