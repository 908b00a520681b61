#include "central_daemon/io/udp_capture_source.h"

#include <arpa/inet.h>

#include <algorithm>
#include <cstring>
#include <utility>

namespace lrfnet::daemon {

std::string FormatUdpSource(const capture::IpAddress& address, std::uint16_t port) {
  char text[INET6_ADDRSTRLEN] = {};
  const std::uint8_t* bytes = address.bytes.data();
  if (address.family == capture::IpFamily::kIpv4) {
    ::inet_ntop(AF_INET, bytes, text, sizeof(text));
    return std::string(text) + ":" + std::to_string(port);
  }
  if (address.family == capture::IpFamily::kIpv6) {
    static constexpr std::uint8_t kV4MappedPrefix[12] = {0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0xff, 0xff};
    if (std::equal(kV4MappedPrefix, kV4MappedPrefix + 12, bytes)) {
      ::inet_ntop(AF_INET, bytes + 12, text, sizeof(text));
      return std::string(text) + ":" + std::to_string(port);
    }
    ::inet_ntop(AF_INET6, bytes, text, sizeof(text));
    return "[" + std::string(text) + "]:" + std::to_string(port);
  }
  return "unknown:" + std::to_string(port);
}

UdpCaptureSource::UdpCaptureSource(std::string path, const DatagramSourceOptions& options,
                                   std::unique_ptr<capture::PcapReader> reader)
    : path_(std::move(path)), options_(options), reader_(std::move(reader)) {}

std::unique_ptr<UdpCaptureSource> UdpCaptureSource::Open(const std::string& path,
                                                         const DatagramSourceOptions& options,
                                                         std::string* error) {
  std::string reason;
  std::unique_ptr<capture::PcapReader> reader = capture::PcapReader::Open(path, &reason);
  if (reader == nullptr) {
    if (error != nullptr) *error = "capture '" + path + "': " + reason;
    return nullptr;
  }
  if (!capture::IsSupportedLinkType(reader->link_type())) {
    if (error != nullptr) {
      *error = "capture '" + path + "': link type " + std::to_string(reader->link_type()) + " (" +
               reader->link_type_name() + ") is not supported";
    }
    return nullptr;
  }
  return std::unique_ptr<UdpCaptureSource>(new UdpCaptureSource(path, options, std::move(reader)));
}

SourceStatus UdpCaptureSource::Next(ReceivedDatagram* datagram) {
  if (final_ != SourceStatus::kDatagram) return final_;
  capture::RawPacket raw;
  for (;;) {
    const capture::ReadStatus read = reader_->Next(&raw);
    if (read == capture::ReadStatus::kEnd) {
      final_ = SourceStatus::kEnd;
      return final_;
    }
    if (read == capture::ReadStatus::kError) {
      error_ = "capture '" + path_ + "': " + reader_->error() + " after packet " +
               std::to_string(counters_.packets);
      final_ = SourceStatus::kError;
      return final_;
    }
    ++counters_.packets;
    const capture::ParseResult parsed = capture::ParsePacket(raw.link_type, raw.bytes);
    if (parsed.status == capture::ParseStatus::kMalformed) {
      ++counters_.malformed_packets;
      continue;
    }
    if (parsed.status == capture::ParseStatus::kUnsupported) {
      // ParsePacket reports fragments as unsupported (it does not reassemble); here they are lost
      // datagrams, not foreign traffic.
      if (std::strstr(parsed.reason, "fragment") != nullptr) {
        ++counters_.malformed_packets;
      } else {
        ++counters_.other_packets;
      }
      continue;
    }
    const capture::ParsedPacket& packet = parsed.packet;
    if (packet.protocol != capture::TransportProtocol::kUdp ||
        (options_.udp_port != 0 && packet.dst_port != options_.udp_port)) {
      ++counters_.other_packets;
      continue;
    }
    datagram->receive_ns = raw.timestamp_ns;
    datagram->source = FormatUdpSource(packet.src_address, packet.src_port);
    datagram->bytes.assign(packet.payload.begin(), packet.payload.end());
    ++counters_.datagrams;
    return SourceStatus::kDatagram;
  }
}

}  // namespace lrfnet::daemon
