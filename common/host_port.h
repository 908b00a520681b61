#pragma once
// Network addresses as users write them on command lines and in config files: "HOST", "HOST:PORT",
// "[IPv6]" or "[IPv6]:PORT"; a bare IPv6 address (several colons) has no port. Pure string parsing
// (no resolution).

#include <cstdint>
#include <cstdlib>
#include <optional>
#include <string>

namespace lrfnet::common {

struct HostPort {
  std::string host;
  std::uint16_t port = 0;
};

// `what` names the option in errors (e.g. "--listen"); `default_port` 0 means a port is required.
// `allow_port_zero`: an explicit port 0 is accepted (a socket to bind on any free port).
inline std::optional<HostPort> ParseHostPort(const std::string& text, const std::string& what,
                                             std::uint16_t default_port, std::string* error,
                                             bool allow_port_zero = false) {
  HostPort out;
  out.port = default_port;
  std::string port_text;
  bool has_port = false;
  if (!text.empty() && text.front() == '[') {
    const auto close = text.find(']');
    if (close == std::string::npos) {
      *error = what + ": missing ']' in '" + text + "'";
      return std::nullopt;
    }
    out.host = text.substr(1, close - 1);
    if (close + 1 < text.size()) {
      if (text[close + 1] != ':') {
        *error = what + ": expected ':PORT' after ']' in '" + text + "'";
        return std::nullopt;
      }
      port_text = text.substr(close + 2);
      has_port = true;
    }
  } else if (text.find(':') != std::string::npos && text.find(':') == text.rfind(':')) {
    out.host = text.substr(0, text.find(':'));
    port_text = text.substr(text.find(':') + 1);
    has_port = true;
  } else {
    out.host = text;
  }
  if (out.host.empty()) {
    *error = what + ": empty host in '" + text + "'";
    return std::nullopt;
  }
  if (has_port) {
    char* end = nullptr;
    const long port = std::strtol(port_text.c_str(), &end, 10);
    const long min_port = allow_port_zero ? 0 : 1;
    if (port_text.empty() || *end != '\0' || port < min_port || port > 65535) {
      *error = what + ": bad port '" + port_text + "' (" + std::to_string(min_port) + "..65535)";
      return std::nullopt;
    }
    out.port = static_cast<std::uint16_t>(port);
    if (allow_port_zero) return out;
  }
  if (out.port == 0) {
    *error = what + ": a port is required, HOST:PORT or [IPv6]:PORT";
    return std::nullopt;
  }
  return out;
}

}  // namespace lrfnet::common
