#include "central_daemon/io/live_view_http.h"

#include <algorithm>
#include <boost/asio/buffer.hpp>
#include <boost/beast/core/string.hpp>
#include <boost/beast/http/error.hpp>
#include <boost/beast/websocket/rfc6455.hpp>
#include <cctype>
#include <cstdint>
#include <limits>

#include "common/datagram_auth.h"

namespace lrfnet::daemon {
namespace {

namespace http = boost::beast::http;

// The page is self-contained; the policy makes the browser enforce that (no external scripts,
// styles, images or connections) and keeps the page out of other sites' frames.
constexpr std::string_view kPagePolicy =
    "default-src 'none'; script-src 'unsafe-inline'; style-src 'unsafe-inline'; "
    "img-src data:; connect-src 'self'; base-uri 'none'; form-action 'none'; "
    "frame-ancestors 'none'";

// Beast 1.74 takes boost::string_view.
boost::beast::string_view Bsv(std::string_view s) { return {s.data(), s.size()}; }

std::string_view PathOf(const HttpRequest& request) {
  const std::string_view target(request.target().data(), request.target().size());
  return target.substr(0, target.find('?'));
}

bool IsGetOrHead(const HttpRequest& request) {
  return request.method() == http::verb::get || request.method() == http::verb::head;
}

bool EqualsIgnoringCase(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (std::tolower(static_cast<unsigned char>(a[i])) !=
        std::tolower(static_cast<unsigned char>(b[i]))) {
      return false;
    }
  }
  return true;
}

bool OriginMatchesHost(const HttpRequest& request) {
  const auto origin_it = request.find(http::field::origin);
  if (origin_it == request.end()) return true;
  const std::string_view origin(origin_it->value().data(), origin_it->value().size());
  const auto host_it = request.find(http::field::host);
  if (host_it == request.end()) return false;
  const std::string_view host(host_it->value().data(), host_it->value().size());
  if (host.empty()) return false;
  for (const std::string_view scheme :
       {std::string_view("http://"), std::string_view("https://")}) {
    if (origin.size() == scheme.size() + host.size() &&
        EqualsIgnoringCase(origin.substr(0, scheme.size()), scheme) &&
        EqualsIgnoringCase(origin.substr(scheme.size()), host)) {
      return true;
    }
  }
  return false;
}

HttpResponse Response(const HttpRequest& request, http::status status,
                      std::string_view content_type, std::string body) {
  HttpResponse response(status, request.version() == 10 ? 10 : 11);
  response.set(http::field::server, "lrfnetd");
  response.set(http::field::content_type, Bsv(content_type));
  response.set(http::field::cache_control, "no-store");
  response.set("X-Content-Type-Options", "nosniff");
  response.keep_alive(request.keep_alive());
  if (request.method() == http::verb::head) {
    response.content_length(body.size());  // what GET would send; the body stays empty
  } else {
    response.body() = std::move(body);
    response.prepare_payload();
  }
  return response;
}

}  // namespace

RequestReader::RequestReader(std::size_t max_request_bytes)
    : max_request_bytes_(max_request_bytes) {
  parser_.header_limit(static_cast<std::uint32_t>(
      std::min<std::size_t>(max_request_bytes, std::numeric_limits<std::uint32_t>::max())));
  parser_.body_limit(static_cast<std::uint64_t>(max_request_bytes));
  // Not eager: put() then stops right after the header, so its size can be checked on its own.
  parser_.eager(false);
}

RequestReader::Result RequestReader::Bad(std::string error, std::size_t consumed) {
  error_ = std::move(error);
  return {Status::kBad, consumed};
}

RequestReader::Result RequestReader::Feed(std::string_view bytes) {
  std::size_t used = 0;
  while (!parser_.is_done() && used < bytes.size()) {
    boost::system::error_code ec;
    const std::size_t n =
        parser_.put(boost::asio::const_buffer(bytes.data() + used, bytes.size() - used), ec);
    used += n;
    request_bytes_ += n;
    if (!header_done_) {
      // Not eager, so the put() that completes the header stops there: request_bytes_ is then
      // exactly the header's size.
      header_done_ = parser_.is_header_done();
      if (request_bytes_ > max_request_bytes_) {
        return Bad("request header larger than " + std::to_string(max_request_bytes_) + " bytes",
                   used);
      }
    }
    if (request_bytes_ > RequestBufferBytes(max_request_bytes_)) {
      return Bad("request larger than " + std::to_string(RequestBufferBytes(max_request_bytes_)) +
                     " bytes",
                 used);
    }
    if (ec == http::error::need_more) {
      if (n == 0) break;
      continue;
    }
    if (ec) return Bad(ec.message(), used);
    if (n == 0) break;
  }
  if (parser_.is_done()) return {Status::kComplete, used};
  if (used == 0 && bytes.size() >= RequestBufferBytes(max_request_bytes_)) {
    return Bad("request line or header line longer than " +
                   std::to_string(RequestBufferBytes(max_request_bytes_)) + " bytes",
               0);
  }
  return {Status::kNeedMore, used};
}

RequestReader::Status RequestReader::EndOfStream() {
  if (request_bytes_ == 0) return Status::kNeedMore;
  error_ = "connection closed in the middle of a request";
  return Status::kBad;
}

const char* ToString(LiveViewRoute route) {
  switch (route) {
    case LiveViewRoute::kPage:
      return "page";
    case LiveViewRoute::kState:
      return "state";
    case LiveViewRoute::kWebSocket:
      return "websocket";
    case LiveViewRoute::kUpgradeRequired:
      return "upgrade_required";
    case LiveViewRoute::kForbiddenOrigin:
      return "forbidden_origin";
    case LiveViewRoute::kMethodNotAllowed:
      return "method_not_allowed";
    case LiveViewRoute::kNotFound:
      return "not_found";
  }
  return "unknown";
}

Admission AdmitRequest(const HttpRequest& request, std::string_view access_token) {
  if (access_token.empty()) return Admission::kAdmitted;
  bool admitted = false;
  // Every candidate is compared (no early exit), so the time does not say which one matched.
  const std::string_view target(request.target().data(), request.target().size());
  const std::size_t query = target.find('?');
  if (query != std::string_view::npos) {
    std::string_view rest = target.substr(query + 1);
    while (!rest.empty()) {
      const std::size_t amp = rest.find('&');
      const std::string_view pair = rest.substr(0, amp);
      rest = amp == std::string_view::npos ? std::string_view() : rest.substr(amp + 1);
      if (pair.rfind("token=", 0) == 0) {
        admitted |= auth::ConstantTimeEquals(pair.substr(6), access_token);
      }
    }
  }
  const auto authorization = request.find(http::field::authorization);
  if (authorization != request.end()) {
    const std::string_view value(authorization->value().data(), authorization->value().size());
    if (value.size() > 7 && EqualsIgnoringCase(value.substr(0, 7), "bearer ")) {
      admitted |= auth::ConstantTimeEquals(value.substr(7), access_token);
    }
  }
  return admitted ? Admission::kAdmitted : Admission::kUnauthorized;
}

HttpResponse UnauthorizedResponse(const HttpRequest& request) {
  HttpResponse r = Response(request, http::status::unauthorized, "text/plain",
                            "the live view needs its access token: open /?token=TOKEN (the "
                            "token in lrfnetd's live_view.token_file)\n");
  r.set(http::field::www_authenticate, "Bearer");
  r.keep_alive(false);
  return r;
}

LiveViewRoute RouteOf(const HttpRequest& request) {
  const std::string_view path = PathOf(request);
  // A WebSocket client (Foxglove) given only the address connects to "/".
  if (path == "/ws" || (path == "/" && boost::beast::websocket::is_upgrade(request))) {
    if (request.method() != http::verb::get) return LiveViewRoute::kMethodNotAllowed;
    if (!boost::beast::websocket::is_upgrade(request)) return LiveViewRoute::kUpgradeRequired;
    if (!OriginMatchesHost(request)) return LiveViewRoute::kForbiddenOrigin;
    return LiveViewRoute::kWebSocket;
  }
  if (path == "/" || path == "/state") {
    if (!IsGetOrHead(request)) return LiveViewRoute::kMethodNotAllowed;
    return path == "/" ? LiveViewRoute::kPage : LiveViewRoute::kState;
  }
  return LiveViewRoute::kNotFound;
}

HttpResponse RespondTo(const HttpRequest& request, LiveViewRoute route,
                       const std::string* latest_json) {
  switch (route) {
    case LiveViewRoute::kPage: {
      HttpResponse r =
          Response(request, http::status::ok, "text/html; charset=utf-8", LiveViewPage());
      r.set("Content-Security-Policy", Bsv(kPagePolicy));
      r.set("X-Frame-Options", "DENY");
      // The URL may hold the access token: never sent on as a referrer.
      r.set("Referrer-Policy", "no-referrer");
      return r;
    }
    case LiveViewRoute::kState:
      if (latest_json == nullptr) {
        HttpResponse r = Response(request, http::status::service_unavailable, "application/json",
                                  R"({"error":"no state published yet"})");
        r.set(http::field::retry_after, "1");
        return r;
      }
      return Response(request, http::status::ok, "application/json", *latest_json);
    case LiveViewRoute::kWebSocket:  // the caller upgrades; a plain response means it did not
    case LiveViewRoute::kUpgradeRequired: {
      HttpResponse r = Response(request, http::status::upgrade_required, "text/plain",
                                "/ws is a WebSocket endpoint\n");
      r.set(http::field::upgrade, "websocket");
      r.set(http::field::connection, request.keep_alive() ? "upgrade" : "upgrade, close");
      return r;
    }
    case LiveViewRoute::kForbiddenOrigin: {
      HttpResponse r = Response(request, http::status::forbidden, "text/plain",
                                "WebSocket from a page of another origin\n");
      r.keep_alive(false);
      return r;
    }
    case LiveViewRoute::kMethodNotAllowed: {
      HttpResponse r =
          Response(request, http::status::method_not_allowed, "text/plain", "only GET and HEAD\n");
      r.set(http::field::allow, PathOf(request) == "/ws" ? "GET" : "GET, HEAD");
      return r;
    }
    case LiveViewRoute::kNotFound:
      break;
  }
  return Response(request, http::status::not_found, "text/plain",
                  "not found; the live view is at /\n");
}

HttpResponse BadRequestResponse(std::string_view reason) {
  HttpResponse response(http::status::bad_request, 11);
  response.set(http::field::server, "lrfnetd");
  response.set(http::field::content_type, "text/plain");
  response.set(http::field::cache_control, "no-store");
  response.keep_alive(false);
  response.body() = std::string(reason) + "\n";
  response.prepare_payload();
  return response;
}

std::string_view BusyResponseBytes() {
  return "HTTP/1.1 503 Service Unavailable\r\n"
         "Server: lrfnetd\r\n"
         "Content-Type: text/plain\r\n"
         "Retry-After: 5\r\n"
         "Connection: close\r\n"
         "Content-Length: 32\r\n"
         "\r\n"
         "too many live view clients now\r\n";
}

ParsedRequest ParseRequest(std::string_view bytes, std::size_t max_request_bytes) {
  ParsedRequest out;
  RequestReader reader(max_request_bytes);
  std::size_t used = 0;
  while (true) {
    const std::string_view window =
        bytes.substr(used, std::min(RequestBufferBytes(max_request_bytes), bytes.size() - used));
    const RequestReader::Result r = reader.Feed(window);
    used += r.consumed;
    out.status = r.status;
    if (r.status == RequestReader::Status::kBad) {
      out.error = reader.error();
      return out;
    }
    if (r.status == RequestReader::Status::kComplete) {
      out.consumed = used;
      out.request = reader.Take();
      return out;
    }
    if (r.consumed == 0) return out;  // need more than `bytes` has
  }
}

}  // namespace lrfnet::daemon
