// ParsePacket on arbitrary frames. Input format: see capture_seeds.h ([link-type selector][frame]).
// Checks: no crash or out-of-bounds read (sanitizers), the payload lies inside the frame, and a
// parsed packet is consistent (TCP/UDP over IPv4/IPv6, a supported link type).

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <span>
#include <vector>

#include "common/capture/packet_parser.h"
#include "tests/fuzz/capture_seeds.h"

namespace {

void Check(bool ok, const char* what) {
  if (!ok) {
    std::fprintf(stderr, "packet_fuzz: check failed: %s\n", what);
    std::abort();
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace lrfnet::capture;
  if (size == 0) return 0;
  const std::uint32_t link_type = lrfnet::fuzz::FuzzLinkType(data[0]);
  // An exactly-sized copy, so that reading one byte past the frame is caught by AddressSanitizer.
  const std::vector<std::uint8_t> frame(data + 1, data + size);
  const ParseResult r = ParsePacket(link_type, frame);
  Check(r.reason != nullptr, "reason is never null");
  if (r.status != ParseStatus::kOk) {
    Check(r.reason[0] != '\0', "a rejected frame has a reason");
    return 0;
  }
  Check(IsSupportedLinkType(link_type), "only supported link types parse");
  const ParsedPacket& p = r.packet;
  Check(p.protocol == TransportProtocol::kTcp || p.protocol == TransportProtocol::kUdp,
        "protocol set");
  Check(p.src_address.family != IpFamily::kNone && p.src_address.family == p.dst_address.family,
        "address family set");
  if (!p.payload.empty()) {
    const std::uint8_t* begin = frame.data();
    const std::uint8_t* end = frame.data() + frame.size();
    Check(p.payload.data() >= begin && p.payload.data() <= end, "payload starts inside the frame");
    Check(p.payload.size() <= static_cast<std::size_t>(end - p.payload.data()),
          "payload ends inside the frame");
    // Headers precede the payload: at least an IPv4 (20) and a UDP (8) header.
    Check(p.payload.data() - begin >= 28, "payload follows the headers");
  }
  return 0;
}
