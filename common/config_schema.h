#pragma once
// A small reflection layer for configuration structs: one visiting function lists every option
// once (section, key, reference, documentation), and the same list drives the YAML loader (unknown
// keys and wrong types are one-line errors naming the key), the documented YAML printer
// (`--print-config`) and the test that the shipped file documents every option.
//
// Layout: top-level keys are sections (maps); each section holds scalar options. Not thread-safe.

#include <chrono>
#include <cstdint>
#include <limits>
#include <type_traits>
#include <optional>
#include <span>
#include <string>
#include <string_view>

namespace lrfnet::common {

class ConfigVisitor {
 public:
  virtual ~ConfigVisitor() = default;
  // Starts a section; fields until the next Section belong to it.
  virtual void Section(std::string_view name, std::string_view doc) = 0;
  virtual void Field(std::string_view key, double& value, std::string_view doc) = 0;
  virtual void Field(std::string_view key, bool& value, std::string_view doc) = 0;
  virtual void Field(std::string_view key, std::string& value, std::string_view doc) = 0;
  // An integer within [min, max] (the loader rejects values outside).
  virtual void Field(std::string_view key, std::int64_t& value, std::int64_t min, std::int64_t max,
                     std::string_view doc) = 0;
  // One of `names`; `index` is the position in `names`.
  virtual void Choice(std::string_view key, int& index, std::span<const std::string_view> names,
                      std::string_view doc) = 0;
  // A structured value (a list or map, e.g. the daemon's zones) kept as YAML text in flow style
  // ("[{name: door, line: [[0, 0], [1, 0]]}]"); the owner parses and validates it. The loader takes
  // any YAML value under the key and writes it back in flow style, the printer writes the text.
  // Visitors that do not handle structured values ignore them.
  virtual void StructuredField(std::string_view key, std::string& flow_yaml, std::string_view doc) {
    (void)key, (void)flow_yaml, (void)doc;
  }
};

// Adapters for the integer and duration types of the option structs (range-checked on load).
template <typename Int>
void VisitInteger(ConfigVisitor& v, std::string_view key, Int& value, std::string_view doc) {
  auto wide = static_cast<std::int64_t>(value);
  std::int64_t max = std::numeric_limits<std::int64_t>::max();
  if constexpr (!(std::is_unsigned_v<Int> && sizeof(Int) >= sizeof(std::int64_t))) {
    max = static_cast<std::int64_t>(std::numeric_limits<Int>::max());
  }
  v.Field(key, wide, static_cast<std::int64_t>(std::numeric_limits<Int>::min()), max, doc);
  value = static_cast<Int>(wide);
}
inline void VisitMs(ConfigVisitor& v, std::string_view key, std::chrono::milliseconds& value,
                    std::string_view doc) {
  std::int64_t ms = value.count();
  v.Field(key, ms, 0, std::int64_t{24} * 3600 * 1000, doc);
  value = std::chrono::milliseconds(ms);
}
template <typename Enum>
void VisitEnum(ConfigVisitor& v, std::string_view key, Enum& value,
               std::span<const std::string_view> names, std::string_view doc) {
  int index = static_cast<int>(value);
  v.Choice(key, index, names, doc);
  value = static_cast<Enum>(index);
}

}  // namespace lrfnet::common
