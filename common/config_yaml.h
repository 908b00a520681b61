#pragma once
// YAML front end of ConfigVisitor (config_schema.h): load a config file into option structs, print
// the documented defaults, list the keys.

#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "common/config_schema.h"

namespace lrfnet::common {

// Calls the visitor on every option of one config object.
using ConfigVisit = std::function<void(ConfigVisitor&)>;

// Reads `yaml_text` into the object `visit` describes. Options absent from the text keep their
// current values; an empty document changes nothing. Errors (one line, naming the key, e.g.
// "tracking.gate_mahalanobis_sq: expected a number, got 'abc'"): YAML syntax, a top level that is
// not a map, unknown sections or keys, wrong types, integers out of range, unknown choices. On
// error the object may be partly updated.
std::optional<std::string> LoadYamlConfig(std::string_view yaml_text, const ConfigVisit& visit);

// The object's current values as a YAML document: `header` as comment lines, every section and
// option preceded by its documentation as comments. LoadYamlConfig of the result reproduces the
// values exactly (doubles are printed in shortest round-trip form).
std::string PrintYamlConfig(const ConfigVisit& visit, std::string_view header);

// "section.key" of every option, in visiting order.
std::vector<std::string> ConfigKeys(const ConfigVisit& visit);

}  // namespace lrfnet::common
