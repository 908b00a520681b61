#pragma once
// Error messages stay one line: a hostile file's bytes quoted in a message (a YAML parser's own
// message quotes the character it stopped at) must not break it or smuggle a line into a log.

#include <algorithm>
#include <cstddef>
#include <string>
#include <string_view>

namespace lrfnet::common {

// `text` with control characters (below 0x20 and 0x7f) shown as '?', cut after `max_chars`
// characters with "..." appended.
inline std::string OneLine(std::string_view text, std::size_t max_chars = 120) {
  std::string out;
  out.reserve(std::min(text.size(), max_chars) + 3);
  for (const char ch : text.substr(0, max_chars)) {
    const auto c = static_cast<unsigned char>(ch);
    out += c < 0x20 || c == 0x7f ? '?' : ch;
  }
  return text.size() > max_chars ? out + "..." : out;
}

}  // namespace lrfnet::common
