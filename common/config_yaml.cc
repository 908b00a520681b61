#include "common/config_yaml.h"
#include "common/one_line.h"

#include <spdlog/fmt/fmt.h>
#include <spdlog/fmt/ranges.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <set>
#include <sstream>

namespace lrfnet::common {
namespace {

void SetFlowStyle(YAML::Node node) {
  if (node.IsSequence() || node.IsMap()) node.SetStyle(YAML::EmitterStyle::Flow);
  if (node.IsSequence()) {
    for (YAML::Node child : node) SetFlowStyle(child);
  } else if (node.IsMap()) {
    for (auto entry : node) SetFlowStyle(entry.second);
  }
}

std::string Scalar(const YAML::Node& node) { return node.IsScalar() ? node.Scalar() : "<not a scalar>"; }

class Loader final : public ConfigVisitor {
 public:
  explicit Loader(const YAML::Node& root) : root_(root) {}

  void Section(std::string_view name, std::string_view) override {
    section_name_ = std::string(name);
    known_.insert(section_name_);
    // Node::reset rebinds; operator= would overwrite the previous section inside the document
    // (yaml-cpp nodes have reference semantics).
    section_.reset();
    if (!error_.empty()) return;
    const YAML::Node node = root_[section_name_];
    if (!node || node.IsNull()) return;
    if (!node.IsMap()) {
      Fail(section_name_, "expected a map of options");
      return;
    }
    section_.reset(node);
  }

  void Field(std::string_view key, double& value, std::string_view) override {
    const YAML::Node node = Find(key);
    if (!node) return;
    double parsed = 0.0;
    if (!node.IsScalar() || !YAML::convert<double>::decode(node, parsed) || !std::isfinite(parsed)) {
      Fail(Path(key), fmt::format("expected a finite number, got '{}'", Scalar(node)));
      return;
    }
    value = parsed;
  }
  void Field(std::string_view key, bool& value, std::string_view) override {
    const YAML::Node node = Find(key);
    if (!node) return;
    bool parsed = false;
    if (!node.IsScalar() || !YAML::convert<bool>::decode(node, parsed)) {
      Fail(Path(key), fmt::format("expected true or false, got '{}'", Scalar(node)));
      return;
    }
    value = parsed;
  }
  void Field(std::string_view key, std::string& value, std::string_view) override {
    const YAML::Node node = Find(key);
    if (!node) return;
    if (!node.IsScalar()) {
      Fail(Path(key), "expected a string");
      return;
    }
    value = node.Scalar();
  }
  void Field(std::string_view key, std::int64_t& value, std::int64_t min, std::int64_t max,
             std::string_view) override {
    const YAML::Node node = Find(key);
    if (!node) return;
    long long parsed = 0;
    if (!node.IsScalar() || !YAML::convert<long long>::decode(node, parsed)) {
      Fail(Path(key), fmt::format("expected an integer, got '{}'", Scalar(node)));
      return;
    }
    if (parsed < min || parsed > max) {
      Fail(Path(key), fmt::format("{} is out of range [{}, {}]", parsed, min, max));
      return;
    }
    value = parsed;
  }
  void Choice(std::string_view key, int& index, std::span<const std::string_view> names,
              std::string_view) override {
    const YAML::Node node = Find(key);
    if (!node) return;
    const std::string text = Scalar(node);
    for (std::size_t i = 0; i < names.size(); ++i) {
      if (names[i] == text) {
        index = static_cast<int>(i);
        return;
      }
    }
    Fail(Path(key), fmt::format("unknown value '{}' (one of: {})", text, fmt::join(names, ", ")));
  }

  void StructuredField(std::string_view key, std::string& flow_yaml, std::string_view) override {
    const YAML::Node node = Find(key);
    if (!node) return;
    // Nodes keep the style they were written in: set flow style on a copy, all the way down.
    YAML::Node copy = YAML::Clone(node);
    SetFlowStyle(copy);
    YAML::Emitter emitter;
    emitter << copy;
    flow_yaml = emitter.c_str();
  }

  // Unknown sections and keys: everything in the document the visit did not name.
  void CheckUnknown() {
    if (!error_.empty()) return;
    for (const auto& entry : root_) {
      const std::string name = entry.first.as<std::string>();
      if (known_.count(name) == 0) {
        Fail(name, fmt::format("unknown section (known: {})", fmt::join(sections_in_order_, ", ")));
        return;
      }
      if (!entry.second.IsMap()) continue;
      for (const auto& field : entry.second) {
        const std::string key = name + "." + field.first.as<std::string>();
        if (known_.count(key) == 0) {
          Fail(key, "unknown option");
          return;
        }
      }
    }
  }

  const std::string& error() const { return error_; }
  std::vector<std::string> sections_in_order_;

 private:
  YAML::Node Find(std::string_view key) {
    known_.insert(Path(key));
    if (!error_.empty() || !section_) return YAML::Node();
    const YAML::Node& section = section_;
    YAML::Node node = section[std::string(key)];  // const lookup: never inserts
    if (node && node.IsNull()) {
      Fail(Path(key), "has no value");
      return YAML::Node();
    }
    return node;
  }
  std::string Path(std::string_view key) const { return section_name_ + "." + std::string(key); }
  void Fail(const std::string& where, const std::string& what) {
    // Keys and values come from the file: one line, a hostile one cut short.
    if (error_.empty()) error_ = OneLine(where, 80) + ": " + OneLine(what, 600);
  }

  const YAML::Node& root_;
  YAML::Node section_;
  std::string section_name_;
  std::set<std::string> known_;
  std::string error_;
};

// Shortest text that reads back as the same double, always with a '.' or exponent so YAML keeps
// it a float for a human reader.
std::string FormatDouble(double value) {
  std::string text = fmt::format("{}", value);
  if (text.find_first_of(".eEn") == std::string::npos) text += ".0";
  return text;
}

// Comment lines of at most ~96 columns.
void WriteComment(std::ostringstream& out, std::string_view indent, std::string_view text) {
  std::istringstream words{std::string(text)};
  std::string word;
  std::string line;
  while (words >> word) {
    if (!line.empty() && indent.size() + 2 + line.size() + 1 + word.size() > 96) {
      out << indent << "# " << line << "\n";
      line.clear();
    }
    line += (line.empty() ? "" : " ") + word;
  }
  if (!line.empty()) out << indent << "# " << line << "\n";
}

// A YAML-safe scalar for strings: quoted whenever plain style could change the meaning.
std::string QuoteString(const std::string& value) {
  YAML::Emitter emitter;
  emitter << YAML::DoubleQuoted << value;
  return emitter.c_str();
}

class Printer final : public ConfigVisitor {
 public:
  explicit Printer(std::ostringstream& out) : out_(out) {}
  void Section(std::string_view name, std::string_view doc) override {
    out_ << "\n";
    WriteComment(out_, "", doc);
    out_ << name << ":\n";
  }
  void Field(std::string_view key, double& value, std::string_view doc) override {
    Line(key, FormatDouble(value), doc);
  }
  void Field(std::string_view key, bool& value, std::string_view doc) override {
    Line(key, value ? "true" : "false", doc);
  }
  void Field(std::string_view key, std::string& value, std::string_view doc) override {
    Line(key, QuoteString(value), doc);
  }
  void Field(std::string_view key, std::int64_t& value, std::int64_t, std::int64_t,
             std::string_view doc) override {
    Line(key, std::to_string(value), doc);
  }
  void Choice(std::string_view key, int& index, std::span<const std::string_view> names,
              std::string_view doc) override {
    const auto i = static_cast<std::size_t>(index);
    const std::string_view name = i < names.size() ? names[i] : std::string_view("?");
    Line(key, std::string(name), fmt::format("{} One of: {}.", doc, fmt::join(names, ", ")));
  }
  void StructuredField(std::string_view key, std::string& flow_yaml,
                       std::string_view doc) override {
    Line(key, flow_yaml.empty() ? "[]" : flow_yaml, doc);
  }

 private:
  void Line(std::string_view key, const std::string& value, std::string_view doc) {
    WriteComment(out_, "  ", doc);
    out_ << "  " << key << ": " << value << "\n";
  }
  std::ostringstream& out_;
};

class KeyLister final : public ConfigVisitor {
 public:
  std::vector<std::string> keys;
  void Section(std::string_view name, std::string_view) override { section_ = std::string(name); }
  void Field(std::string_view key, double&, std::string_view) override { Add(key); }
  void Field(std::string_view key, bool&, std::string_view) override { Add(key); }
  void Field(std::string_view key, std::string&, std::string_view) override { Add(key); }
  void Field(std::string_view key, std::int64_t&, std::int64_t, std::int64_t,
             std::string_view) override {
    Add(key);
  }
  void Choice(std::string_view key, int&, std::span<const std::string_view>,
              std::string_view) override {
    Add(key);
  }
  void StructuredField(std::string_view key, std::string&, std::string_view) override { Add(key); }

 private:
  void Add(std::string_view key) { keys.push_back(section_ + "." + std::string(key)); }
  std::string section_;
};

class SectionLister final : public ConfigVisitor {
 public:
  std::vector<std::string> sections;
  void Section(std::string_view name, std::string_view) override { sections.emplace_back(name); }
  void Field(std::string_view, double&, std::string_view) override {}
  void Field(std::string_view, bool&, std::string_view) override {}
  void Field(std::string_view, std::string&, std::string_view) override {}
  void Field(std::string_view, std::int64_t&, std::int64_t, std::int64_t,
             std::string_view) override {}
  void Choice(std::string_view, int&, std::span<const std::string_view>, std::string_view) override {}
};

}  // namespace

std::optional<std::string> LoadYamlConfig(std::string_view yaml_text, const ConfigVisit& visit) {
  YAML::Node root;
  try {
    root = YAML::Load(std::string(yaml_text));
  } catch (const YAML::Exception& e) {
    return fmt::format("YAML syntax error at line {}, column {}: {}", e.mark.line + 1,
                       e.mark.column + 1, OneLine(e.msg));
  }
  if (!root || root.IsNull()) return std::nullopt;
  if (!root.IsMap()) return std::string("the top level must be a map of sections");
  SectionLister sections;
  visit(sections);
  Loader loader(root);
  loader.sections_in_order_ = sections.sections;
  try {
    visit(loader);
    loader.CheckUnknown();
  } catch (const YAML::Exception& e) {
    return fmt::format("malformed config: {}", OneLine(e.msg));
  }
  if (!loader.error().empty()) return loader.error();
  return std::nullopt;
}

std::string PrintYamlConfig(const ConfigVisit& visit, std::string_view header) {
  std::ostringstream out;
  std::istringstream lines{std::string(header)};
  for (std::string line; std::getline(lines, line);) out << (line.empty() ? "#" : "# " + line) << "\n";
  Printer printer(out);
  visit(printer);
  return out.str();
}

std::vector<std::string> ConfigKeys(const ConfigVisit& visit) {
  KeyLister lister;
  visit(lister);
  return std::move(lister.keys);
}

}  // namespace lrfnet::common
