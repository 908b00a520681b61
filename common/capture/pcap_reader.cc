#include "common/capture/pcap_reader.h"

#include <pcap/pcap.h>

#include <limits>

namespace lrfnet::capture {
namespace {

// libpcap reports DLT_* values, which differ from the file's LINKTYPE_* value only where BSDs
// disagreed on numbers; map those back so the pure parser sees platform-independent numbers.
std::uint32_t DltToLinkType(int dlt) {
  if (dlt == DLT_RAW) return 101;   // LINKTYPE_RAW
  if (dlt == DLT_LOOP) return 108;  // LINKTYPE_LOOP
  return static_cast<std::uint32_t>(dlt);
}

common::UtcNs ToUtcNs(const timeval& ts) {
  // With nanosecond precision libpcap puts nanoseconds in tv_usec. A hostile pcapng timestamp can
  // exceed the int64 nanosecond range; saturate instead of overflowing.
  constexpr std::int64_t kMaxSeconds =
      std::numeric_limits<std::int64_t>::max() / common::kNsPerS - 1;
  const std::int64_t seconds = static_cast<std::int64_t>(ts.tv_sec);
  if (seconds > kMaxSeconds) return std::numeric_limits<common::UtcNs>::max();
  if (seconds < -kMaxSeconds) return std::numeric_limits<common::UtcNs>::min();
  return seconds * common::kNsPerS + static_cast<std::int64_t>(ts.tv_usec);
}

}  // namespace

struct PcapReader::Handle {
  pcap_t* pcap = nullptr;
  ~Handle() {
    if (pcap != nullptr) pcap_close(pcap);
  }
};

PcapReader::PcapReader(std::unique_ptr<Handle> handle) : handle_(std::move(handle)) {
  dlt_ = pcap_datalink(handle_->pcap);
  link_type_ = DltToLinkType(dlt_);
}

PcapReader::~PcapReader() = default;

std::unique_ptr<PcapReader> PcapReader::Open(const std::string& path, std::string* error) {
  char errbuf[PCAP_ERRBUF_SIZE] = {};
  auto handle = std::make_unique<Handle>();
  handle->pcap =
      pcap_open_offline_with_tstamp_precision(path.c_str(), PCAP_TSTAMP_PRECISION_NANO, errbuf);
  if (handle->pcap == nullptr) {
    if (error != nullptr) *error = errbuf[0] != '\0' ? errbuf : "cannot open";
    return nullptr;
  }
  return std::unique_ptr<PcapReader>(new PcapReader(std::move(handle)));
}

std::string PcapReader::link_type_name() const {
  const char* name = pcap_datalink_val_to_name(dlt_);
  return name != nullptr ? name : "unknown";
}

ReadStatus PcapReader::Next(RawPacket* packet) {
  if (final_status_ != ReadStatus::kPacket) return final_status_;
  pcap_pkthdr* header = nullptr;
  const u_char* data = nullptr;
  const int rc = pcap_next_ex(handle_->pcap, &header, &data);
  if (rc == 1) {
    packet->link_type = link_type_;
    packet->timestamp_ns = ToUtcNs(header->ts);
    packet->bytes = std::span<const std::uint8_t>(data, header->caplen);
    packet->original_length = header->len;
    return ReadStatus::kPacket;
  }
  if (rc == PCAP_ERROR_BREAK) {
    final_status_ = ReadStatus::kEnd;
  } else {
    final_status_ = ReadStatus::kError;
    const char* reason = pcap_geterr(handle_->pcap);
    error_ = (reason != nullptr && *reason != '\0') ? reason : "read error";
  }
  return final_status_;
}

}  // namespace lrfnet::capture
