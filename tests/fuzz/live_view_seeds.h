#pragma once
// Seeds for http_request_fuzz (the live view's request handling), written by make_fuzz_corpus.

#include <string>

namespace lrfnet::fuzz {

// Requests a browser or tool sends (the page, the state, HEAD, a WebSocket upgrade, keep-alive
// pipelines, HTTP/1.0, a chunked body) and hostile ones (garbage, a TLS hello, a header over the
// limit, a huge Content-Length, a truncated request, bad versions and line endings, a foreign
// Origin). The first byte of a seed also picks the read size of the incremental parse.
void WriteLiveViewSeeds(const std::string& dir);

}  // namespace lrfnet::fuzz
