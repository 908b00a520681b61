#pragma once
// A pcap/pcapng capture of the UDP stream as a DatagramSource: every UDP payload to the selected
// destination port (options.udp_port, 0 = any), IPv4 or IPv6, with the packet's capture time as
// receive time and its sender as source ("ip:port", "[ipv6]:port": the daemon's receiver formats
// live senders the same way). Packets are read with lrfnet_capture's PcapReader and ParsePacket.
//
// Skipped and counted: packets that are not UDP or go to another port (other_packets); truncated or
// inconsistent headers and IP fragments (malformed_packets: a fragmented datagram cannot be
// delivered; the tracker never sends one). A file that ends in a torn packet record ends the stream
// with kError after every whole packet before it.
//
// Not thread-safe.

#include <cstdint>
#include <memory>
#include <string>

#include "central_daemon/io/datagram_source.h"
#include "common/capture/packet_parser.h"
#include "common/capture/pcap_reader.h"

namespace lrfnet::daemon {

// "a.b.c.d:port" for IPv4 (and IPv4-mapped IPv6), "[v6]:port" for IPv6 (RFC 5952 text).
std::string FormatUdpSource(const capture::IpAddress& address, std::uint16_t port);

class UdpCaptureSource final : public DatagramSource {
 public:
  // nullptr and a one-line *error naming the file when libpcap cannot read it or its link type is
  // not one ParsePacket knows.
  static std::unique_ptr<UdpCaptureSource> Open(const std::string& path,
                                                const DatagramSourceOptions& options,
                                                std::string* error);

  SourceStatus Next(ReceivedDatagram* datagram) override;
  DatagramFileKind kind() const override { return DatagramFileKind::kCapture; }
  const DatagramSourceCounters& counters() const override { return counters_; }
  const std::string& error() const override { return error_; }
  const std::string& writer() const override { return writer_; }

 private:
  UdpCaptureSource(std::string path, const DatagramSourceOptions& options,
                   std::unique_ptr<capture::PcapReader> reader);

  std::string path_;
  DatagramSourceOptions options_;
  std::unique_ptr<capture::PcapReader> reader_;
  DatagramSourceCounters counters_;
  SourceStatus final_ = SourceStatus::kDatagram;
  std::string error_;
  std::string writer_;  // always empty
};

}  // namespace lrfnet::daemon
