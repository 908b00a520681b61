#include "tests/fuzz/live_view_seeds.h"

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace lrfnet::fuzz {

void WriteLiveViewSeeds(const std::string& dir) {
  std::filesystem::create_directories(dir);
  const std::string upgrade =
      "GET /ws HTTP/1.1\r\nHost: 127.0.0.1:8080\r\nConnection: Upgrade\r\nUpgrade: websocket\r\n"
      "Sec-WebSocket-Version: 13\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n";
  const std::vector<std::string> seeds = {
      "GET / HTTP/1.1\r\nHost: 127.0.0.1:8080\r\nAccept: text/html\r\n\r\n",
      "GET /state HTTP/1.1\r\nHost: localhost\r\nConnection: close\r\n\r\n",
      "HEAD / HTTP/1.1\r\nHost: x\r\n\r\nHEAD /state HTTP/1.1\r\nHost: x\r\n\r\n",
      upgrade + "\r\n",
      upgrade + "Origin: http://127.0.0.1:8080\r\n\r\n",
      upgrade + "Origin: http://evil.example\r\n\r\n",
      "GET /ws HTTP/1.1\r\nHost: x\r\n\r\n",
      "GET /?a=1 HTTP/1.1\r\nHost: x\r\n\r\nGET /state?b HTTP/1.1\r\nHost: x\r\n\r\n"
      "GET /favicon.ico HTTP/1.1\r\nHost: x\r\n\r\n",
      "GET / HTTP/1.0\r\n\r\n",
      "POST /state HTTP/1.1\r\nHost: x\r\nContent-Length: 5\r\n\r\nhello",
      "PUT / HTTP/1.1\r\nHost: x\r\nTransfer-Encoding: chunked\r\n\r\n5\r\nhello\r\n0\r\n\r\n",
      "DELETE /ws HTTP/1.1\r\nHost: x\r\n\r\n",
      "OPTIONS * HTTP/1.1\r\nHost: x\r\n\r\n",
      // hostile
      std::string("\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03", 11) + std::string(40, '\x5a'),
      "GARBAGE\r\n\r\n",
      "GET / HTTP/1.1\r\nHost: x\r\nX-Big: " + std::string(1100, 'a') + "\r\n\r\n",
      "POST / HTTP/1.1\r\nHost: x\r\nContent-Length: 100000000000\r\n\r\nxxxx",
      "POST / HTTP/1.1\r\nHost: x\r\nContent-Length: 10\r\n\r\nabc",
      "GET / HTTP/1.1\r\nHost: x\r\n",
      "GET / HTTP/9.9\r\nHost: x\r\n\r\n",
      "GET / HTTP/1.1\nHost: x\n\n",
      "GET / HTTP/1.1\r\nHost: x\r\nContent-Length: 1\r\nContent-Length: 2\r\n\r\nab",
      "POST / HTTP/1.1\r\nHost: x\r\nTransfer-Encoding: chunked\r\n\r\nffffffffffffffff\r\n",
      "POST / HTTP/1.1\r\nHost: x\r\nTransfer-Encoding: chunked\r\n\r\n1;" +
          std::string(3000, 'e') + "\r\na\r\n0\r\n\r\n",
      "GET / HTTP/1.1\r\nHost: x\r\nX-Folded: a\r\n b\r\n\r\n",
  };
  for (std::size_t i = 0; i < seeds.size(); ++i) {
    std::ofstream(std::filesystem::path(dir) / ("request_" + std::to_string(i)), std::ios::binary)
        .write(seeds[i].data(), static_cast<std::streamsize>(seeds[i].size()));
  }
}

}  // namespace lrfnet::fuzz
