#pragma once
// The live view's request handling without sockets: reading a request from a connection's bytes
// within limits (Beast's parser inside), the route of a request and the response to it.
// LiveViewServer runs every request through these, and so does the fuzz target
// (tests/fuzz/live_view_fuzz.cc).
// Pure: no clock, no socket, no logging; all functions are thread-compatible.

#include <boost/beast/http/message.hpp>
#include <boost/beast/http/parser.hpp>
#include <boost/beast/http/string_body.hpp>
#include <cstddef>
#include <string>
#include <string_view>

namespace lrfnet::daemon {

using HttpRequest = boost::beast::http::request<boost::beast::http::string_body>;
using HttpResponse = boost::beast::http::response<boost::beast::http::string_body>;
using HttpRequestParser = boost::beast::http::request_parser<boost::beast::http::string_body>;

// The bytes of the page served at "/", built into the binary from live_view_page.html (the same
// function is declared in live_view_server.h).
const std::string& LiveViewPage();

// Reads one request from a connection's bytes as they arrive (Feed(bytes) -> complete, need
// more, bad), with these limits:
//   - the request line and header: at most max_request_bytes in all, however they are split
//     across reads (Beast's own header limit counts the bytes it has not consumed yet, so a
//     header whose first part came alone could exceed it by almost as much again);
//   - the body: Content-Length or chunked data at most max_request_bytes, refused as soon as a
//     larger length is announced;
//   - everything of one request, chunk framing included: at most RequestBufferBytes;
//   - bytes not yet parsed: the caller keeps at most RequestBufferBytes; when that many are
//     offered and none can be used (one line longer than that), the request is bad.
// A reader reads one request; make a new one for the next.
constexpr std::size_t RequestBufferBytes(std::size_t max_request_bytes) {
  return 2 * max_request_bytes;
}

class RequestReader {
 public:
  enum class Status { kNeedMore, kComplete, kBad };
  struct Result {
    Status status = Status::kNeedMore;
    std::size_t consumed = 0;  // bytes of `bytes` used; the rest belongs to later reads
  };

  explicit RequestReader(std::size_t max_request_bytes);

  // Offers the unparsed bytes, oldest first. After kComplete or kBad, do not feed again.
  Result Feed(std::string_view bytes);
  // The peer will send nothing more: kBad (a truncated request) when a request was begun, else
  // kNeedMore (a clean end between requests).
  Status EndOfStream();

  // Bytes of this request used so far (0: nothing yet, e.g. an idle keep-alive connection).
  std::size_t request_bytes() const { return request_bytes_; }
  // Why the request is bad.
  const std::string& error() const { return error_; }
  // The request, after kComplete.
  HttpRequest Take() { return parser_.release(); }

 private:
  Result Bad(std::string error, std::size_t consumed);

  std::size_t max_request_bytes_;
  HttpRequestParser parser_;
  std::size_t request_bytes_ = 0;
  bool header_done_ = false;
  std::string error_;
};

// Request admission, the first step for every request before it is routed (the page, /state, the
// WebSocket and any other upgrade or path): with an access token configured (non-empty), a
// request must carry it, as a `token` query parameter (?token=...) or as "Authorization: Bearer
// <token>"; the comparison takes the same time wherever the strings differ
// (auth::ConstantTimeEquals). Without a token every request is admitted (the server then listens
// on loopback only: the daemon's config refuses anything else).
enum class Admission { kAdmitted, kUnauthorized };
Admission AdmitRequest(const HttpRequest& request, std::string_view access_token);

// 401 with "WWW-Authenticate: Bearer" and a plain-text hint; the connection is closed.
HttpResponse UnauthorizedResponse(const HttpRequest& request);

enum class LiveViewRoute {
  kPage,              // GET/HEAD /
  kState,             // GET/HEAD /state
  kWebSocket,         // GET /ws (or / with an upgrade) with a valid-looking upgrade: the caller
                      // performs the handshake
  kUpgradeRequired,   // /ws without an upgrade: 426
  kForbiddenOrigin,   // /ws upgrade from a page of another origin: 403
  kMethodNotAllowed,  // a known path with a method other than GET/HEAD: 405
  kNotFound,          // 404
};
const char* ToString(LiveViewRoute route);

// Routes on the path (the query string is ignored). A WebSocket upgrade that carries an Origin
// header must come from a page served by this host (Origin "http://" + Host, case-insensitive):
// a browser sends Origin on every WebSocket, so another web site open in the same browser cannot
// read the live view through it; clients that send no Origin (tools, tests) are accepted.
LiveViewRoute RouteOf(const HttpRequest& request);

// The response to a request routed to anything but kWebSocket. `latest_json` is the latest
// published message, or null before the first (then /state is 503). HEAD gets the headers of GET
// with an empty body. Keep-alive follows the request.
HttpResponse RespondTo(const HttpRequest& request, LiveViewRoute route,
                       const std::string* latest_json);

// The response sent before closing a connection whose request could not be parsed or was too
// large (400, "Connection: close"); `reason` becomes the plain-text body.
HttpResponse BadRequestResponse(std::string_view reason);

// The complete bytes sent to a connection refused because max_clients are connected (503).
std::string_view BusyResponseBytes();

// One request from the start of `bytes`, fed to a RequestReader in windows of
// RequestBufferBytes as a server with fast reads would (tests and the fuzz target).
struct ParsedRequest {
  RequestReader::Status status = RequestReader::Status::kNeedMore;
  HttpRequest request;       // valid when kComplete
  std::size_t consumed = 0;  // bytes of this request when kComplete
  std::string error;         // why, when kBad
};
ParsedRequest ParseRequest(std::string_view bytes, std::size_t max_request_bytes);

}  // namespace lrfnet::daemon
