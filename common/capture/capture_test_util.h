#pragma once
// Test helpers for writing small captures byte by byte (not part of the library).

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace lrfnet::capture::test {

using Bytes = std::vector<std::uint8_t>;

// Big-endian (network order) 16 and 32-bit values at `at`.
inline void Put16(Bytes* b, std::size_t at, std::uint32_t v) {
  (*b)[at] = static_cast<std::uint8_t>(v >> 8);
  (*b)[at + 1] = static_cast<std::uint8_t>(v);
}
inline void Put32(Bytes* b, std::size_t at, std::uint32_t v) {
  Put16(b, at, v >> 16);
  Put16(b, at + 2, v & 0xFFFF);
}

// a followed by b.
inline Bytes Cat(Bytes a, const Bytes& b) {
  a.insert(a.end(), b.begin(), b.end());
  return a;
}

// The bytes of a text.
inline Bytes Text(const std::string& s) { return Bytes(s.begin(), s.end()); }

}  // namespace lrfnet::capture::test
