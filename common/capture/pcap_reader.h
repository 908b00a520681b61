#pragma once
// Thin libpcap adapter: reads packets from a pcap or pcapng file, whatever link type it carries.
// Timestamps are read at nanosecond precision (libpcap scales microsecond files up), so a file of
// either format gives UTC nanoseconds. Turning packets into addresses and payloads is ParsePacket's
// job.
//
// Thread-safety: none; one reader per thread.

#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include "common/time.h"

namespace lrfnet::capture {

struct RawPacket {
  // Link-layer header type as written in the file format (LINKTYPE_* of the tcpdump.org registry,
  // the kLinkType* constants of packet_parser.h), not libpcap's platform-dependent DLT_* value.
  std::uint32_t link_type = 0;
  common::UtcNs timestamp_ns = 0;       // capture time, UTC
  std::span<const std::uint8_t> bytes;  // captured bytes; valid until the next call to Next()
  // Length on the wire (>= bytes.size() when the snaplen cut the packet).
  std::uint32_t original_length = 0;
};

enum class ReadStatus {
  kPacket,  // *packet is filled
  kEnd,     // clean end of file
  kError,   // the file ended in a read error (e.g. a truncated last record); error() says why
};

class PcapReader {
 public:
  // Opens a pcap or pcapng file. On failure returns nullptr and sets *error to libpcap's reason
  // (without the path: callers add it).
  static std::unique_ptr<PcapReader> Open(const std::string& path, std::string* error);
  ~PcapReader();
  PcapReader(const PcapReader&) = delete;
  PcapReader& operator=(const PcapReader&) = delete;

  // Reads the next packet. After kEnd or kError every further call returns the same status.
  ReadStatus Next(RawPacket* packet);

  // The file's link type (LINKTYPE_* value). pcapng files whose interfaces disagree are rejected by
  // libpcap.
  std::uint32_t link_type() const { return link_type_; }
  // libpcap's name of the link type, e.g. "EN10MB"; "unknown" when libpcap has none.
  std::string link_type_name() const;
  const std::string& error() const { return error_; }

 private:
  struct Handle;
  explicit PcapReader(std::unique_ptr<Handle> handle);

  std::unique_ptr<Handle> handle_;
  std::uint32_t link_type_ = 0;
  int dlt_ = 0;
  ReadStatus final_status_ = ReadStatus::kPacket;
  std::string error_;
};

}  // namespace lrfnet::capture
