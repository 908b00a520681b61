// Fuzz target for the live view's request handling: arbitrary bytes as what a client sends on one
// connection, through Beast's request parser with the server's limits, then routed and answered by
// the same functions the server uses (central_daemon/io/live_view_http.h).
//
// Input: the bytes of the connection, parsed as pipelined requests until one is incomplete or
// bad. The first byte also picks how the bytes arrive in a second, incremental parse (1..256
// bytes per read, as from a socket; the server's own loop) and whether a message has been
// published yet.
// Properties checked with __builtin_trap:
//   - parsing the whole input and parsing it read by read give the same complete requests (an
//     incomplete one may be found bad sooner or later, depending on how its bytes arrived);
//   - a complete request used at least one byte and at most RequestBufferBytes, its body at most
//     max_request_bytes; a bad one says why;
//   - every route gets the status it promises, HEAD gets no body, every other body matches its
//     Content-Length and comes from the page, the published message or a short fixed text;
//   - every response serializes.

#include <algorithm>
#include <boost/beast/http/write.hpp>
#include <cstddef>
#include <cstdint>
#include <sstream>
#include <string>
#include <string_view>

#include "central_daemon/io/live_view_http.h"

namespace {

namespace http = boost::beast::http;
using lrfnet::daemon::HttpRequest;
using lrfnet::daemon::HttpResponse;
using lrfnet::daemon::LiveViewRoute;
using lrfnet::daemon::ParsedRequest;
using lrfnet::daemon::RequestReader;

// Small, so the header and body limits are reached often.
constexpr std::size_t kMaxRequestBytes = 1024;
constexpr std::size_t kBufferBytes = lrfnet::daemon::RequestBufferBytes(kMaxRequestBytes);
constexpr int kMaxRequests = 64;
const std::string kPublished = R"({"type":"state","sensors":[],"tracks":[],"fused":[]})";

void Check(bool ok) {
  if (!ok) __builtin_trap();
}

struct Outcome {
  RequestReader::Status status = RequestReader::Status::kNeedMore;
  HttpRequest request;
  std::size_t consumed = 0;
};

// The server's way (HttpSession::Parse): bytes arrive in reads of `read_size` into a buffer of at
// most kBufferBytes, whose unparsed part is fed to the request reader after every read.
Outcome ParseIncrementally(std::string_view bytes, std::size_t read_size) {
  Outcome out;
  RequestReader reader(kMaxRequestBytes);
  std::string unparsed;
  std::size_t offered = 0;
  while (true) {
    if (!unparsed.empty()) {
      const RequestReader::Result r = reader.Feed(unparsed);
      Check(r.consumed <= unparsed.size());
      unparsed.erase(0, r.consumed);
      out.consumed += r.consumed;
      out.status = r.status;
      if (r.status == RequestReader::Status::kBad) {
        Check(!reader.error().empty());
        return out;
      }
      if (r.status == RequestReader::Status::kComplete) {
        out.request = reader.Take();
        return out;
      }
    }
    if (offered == bytes.size()) return out;
    Check(unparsed.size() < kBufferBytes);  // a full buffer that parses no further is bad
    const std::size_t take =
        std::min({read_size, bytes.size() - offered, kBufferBytes - unparsed.size()});
    unparsed.append(bytes.substr(offered, take));
    offered += take;
  }
}

bool SameRequest(const HttpRequest& a, const HttpRequest& b) {
  return a.method_string() == b.method_string() && a.target() == b.target() &&
         a.version() == b.version() && a.body() == b.body() && a.keep_alive() == b.keep_alive();
}

bool IsFixedText(const std::string& body) { return body.size() < 200; }

void CheckResponse(const HttpRequest& request, LiveViewRoute route, const HttpResponse& response,
                   bool published) {
  const unsigned status = response.result_int();
  switch (route) {
    case LiveViewRoute::kPage:
      Check(status == 200);
      break;
    case LiveViewRoute::kState:
      Check(status == (published ? 200u : 503u));
      break;
    case LiveViewRoute::kWebSocket:
    case LiveViewRoute::kUpgradeRequired:
      Check(status == 426);
      break;
    case LiveViewRoute::kForbiddenOrigin:
      Check(status == 403 && !response.keep_alive());
      break;
    case LiveViewRoute::kMethodNotAllowed:
      Check(status == 405 && response.count(http::field::allow) == 1);
      break;
    case LiveViewRoute::kNotFound:
      Check(status == 404);
      break;
  }
  if (request.method() == http::verb::head) {
    Check(response.body().empty());
  } else {
    Check(response[http::field::content_length] == std::to_string(response.body().size()));
    Check(response.body() == lrfnet::daemon::LiveViewPage() ||
          (published && response.body() == kPublished) || IsFixedText(response.body()));
  }
  std::ostringstream wire;
  wire << response;
  Check(wire.str().size() > response.body().size());
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view input(reinterpret_cast<const char*>(data), size);
  const std::size_t read_size = size > 0 ? 1 + static_cast<std::size_t>(data[0]) : 1;
  const bool published = size > 0 && (data[0] & 1) != 0;

  std::string_view rest = input;
  for (int n = 0; n < kMaxRequests; ++n) {
    const ParsedRequest whole = lrfnet::daemon::ParseRequest(rest, kMaxRequestBytes);
    const Outcome pieces = ParseIncrementally(rest, read_size);
    // Beast may find a bad header line early or only once more bytes came, depending on how the
    // bytes arrived; a complete request must come out the same either way.
    Check((whole.status == RequestReader::Status::kComplete) ==
          (pieces.status == RequestReader::Status::kComplete));
    if (whole.status == RequestReader::Status::kBad) {
      Check(!whole.error.empty());
      break;
    }
    if (whole.status == RequestReader::Status::kNeedMore) break;
    Check(whole.consumed > 0 && whole.consumed <= rest.size());
    Check(whole.consumed <= kBufferBytes);
    Check(whole.consumed == pieces.consumed && SameRequest(whole.request, pieces.request));
    Check(whole.request.body().size() <= kMaxRequestBytes);

    const LiveViewRoute route = lrfnet::daemon::RouteOf(whole.request);
    Check(lrfnet::daemon::ToString(route) != std::string_view("unknown"));
    if (route == LiveViewRoute::kWebSocket) Check(whole.request.method() == http::verb::get);
    const HttpResponse response =
        lrfnet::daemon::RespondTo(whole.request, route, published ? &kPublished : nullptr);
    CheckResponse(whole.request, route, response, published);
    rest.remove_prefix(whole.consumed);
  }
  return 0;
}
