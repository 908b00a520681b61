#include "central_daemon/io/udp_receiver.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <time.h>

#include <array>
#include <boost/asio/ip/address.hpp>
#include <boost/asio/ip/v6_only.hpp>
#include <boost/asio/post.hpp>
#include <boost/asio/ip/udp.hpp>
#include <cerrno>
#include <cstring>
#include <unordered_map>

namespace lrfnet::daemon {
namespace {

namespace asio = boost::asio;
using asio::ip::udp;

// Largest UDP payload over IPv4/IPv6 without jumbograms: nothing is ever cut.
constexpr std::size_t kSlotBytes = 65536;
// SO_TIMESTAMPNS (timespec) and SO_RXQ_OVFL (uint32) control messages.
constexpr std::size_t kControlBytes = CMSG_SPACE(sizeof(timespec)) + CMSG_SPACE(sizeof(std::uint32_t));

common::UtcNs RealtimeNs() {
  timespec ts{};
  ::clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<common::UtcNs>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

// Raw sender address as a hashable key (sockaddr_in6 is the largest we receive).
struct AddressKey {
  std::array<std::uint8_t, sizeof(sockaddr_in6)> bytes{};
  std::uint32_t length = 0;
  bool operator==(const AddressKey& o) const {
    return length == o.length && std::memcmp(bytes.data(), o.bytes.data(), length) == 0;
  }
};
struct AddressKeyHash {
  std::size_t operator()(const AddressKey& k) const {
    std::size_t h = 1469598103934665603ULL;  // FNV-1a
    for (std::uint32_t i = 0; i < k.length; ++i) h = (h ^ k.bytes[i]) * 1099511628211ULL;
    return h;
  }
};

std::string FormatSender(const sockaddr_storage& address) {
  char text[INET6_ADDRSTRLEN] = {};
  if (address.ss_family == AF_INET) {
    const auto& a = reinterpret_cast<const sockaddr_in&>(address);
    ::inet_ntop(AF_INET, &a.sin_addr, text, sizeof(text));
    return std::string(text) + ":" + std::to_string(ntohs(a.sin_port));
  }
  if (address.ss_family == AF_INET6) {
    const auto& a = reinterpret_cast<const sockaddr_in6&>(address);
    if (IN6_IS_ADDR_V4MAPPED(&a.sin6_addr)) {
      ::inet_ntop(AF_INET, &a.sin6_addr.s6_addr[12], text, sizeof(text));
      return std::string(text) + ":" + std::to_string(ntohs(a.sin6_port));
    }
    ::inet_ntop(AF_INET6, &a.sin6_addr, text, sizeof(text));
    return "[" + std::string(text) + "]:" + std::to_string(ntohs(a.sin6_port));
  }
  return "unknown:0";
}

}  // namespace

struct UdpReceiver::Slots {
  std::vector<std::uint8_t> buffers;
  std::vector<sockaddr_storage> addresses;
  std::vector<std::array<std::uint8_t, kControlBytes>> controls;
  std::vector<iovec> iovecs;
  std::vector<mmsghdr> headers;
  std::unordered_map<AddressKey, std::string, AddressKeyHash> names;
  std::unordered_map<std::string, AddressKey> addresses_by_name;

  explicit Slots(std::size_t n)
      : buffers(n * kSlotBytes), addresses(n), controls(n), iovecs(n), headers(n) {}

  void Arm() {
    for (std::size_t i = 0; i < headers.size(); ++i) {
      iovecs[i] = {buffers.data() + i * kSlotBytes, kSlotBytes};
      msghdr& h = headers[i].msg_hdr;
      h = msghdr{};
      h.msg_name = &addresses[i];
      h.msg_namelen = sizeof(sockaddr_storage);
      h.msg_iov = &iovecs[i];
      h.msg_iovlen = 1;
      h.msg_control = controls[i].data();
      h.msg_controllen = controls[i].size();
      headers[i].msg_len = 0;
    }
  }

  const std::string& Name(const sockaddr_storage& address, socklen_t length) {
    AddressKey key;
    key.length = std::min<std::uint32_t>(length, sizeof(key.bytes));
    std::memcpy(key.bytes.data(), &address, key.length);
    auto it = names.find(key);
    if (it == names.end()) {
      it = names.emplace(key, FormatSender(address)).first;
      addresses_by_name[it->second] = key;
    }
    return it->second;
  }
};

std::optional<std::string> Validate(const UdpReceiverOptions& o) {
  if (o.address.empty()) return "listen address is empty";
  if (o.receive_buffer_bytes < 65536) return "receive_buffer_bytes must be >= 65536";
  if (o.batch_datagrams < 1 || o.batch_datagrams > 1024) return "batch_datagrams must be 1..1024";
  if (o.max_datagrams_per_wakeup < o.batch_datagrams)
    return "max_datagrams_per_wakeup must be >= batch_datagrams";
  return std::nullopt;
}

UdpReceiver::UdpReceiver(asio::io_context& io, const UdpReceiverOptions& options, Handler handler)
    : io_(io), options_(options), handler_(std::move(handler)), socket_(io) {}

UdpReceiver::~UdpReceiver() { Close(); }

std::optional<std::string> UdpReceiver::Open() {
  if (auto e = Validate(options_)) return *e;
  Close();
  boost::system::error_code ec;
  udp::resolver resolver(io_);
  const auto results = resolver.resolve(options_.address, std::to_string(options_.port),
                                        udp::resolver::passive | udp::resolver::numeric_service, ec);
  if (ec || results.empty())
    return "cannot resolve '" + options_.address + "': " + (ec ? ec.message() : "no address");
  std::string last_error;
  for (const auto& entry : results) {
    const udp::endpoint endpoint = entry.endpoint();
    socket_.open(endpoint.protocol(), ec);
    if (ec) {
      last_error = ec.message();
      continue;
    }
    if (endpoint.address().is_v6()) {
      // Dual stack where the system allows it: "::" then also takes IPv4 trackers.
      socket_.set_option(asio::ip::v6_only(false), ec);
    }
    socket_.bind(endpoint, ec);
    if (!ec) break;
    last_error = ec.message();
    socket_.close();
  }
  if (!socket_.is_open())
    return "cannot bind " + options_.address + ":" + std::to_string(options_.port) + ": " +
           last_error;

  const int fd = socket_.native_handle();
  int size = options_.receive_buffer_bytes;
  // SO_RCVBUFFORCE passes net.core.rmem_max when permitted (CAP_NET_ADMIN); else the capped request.
  if (::setsockopt(fd, SOL_SOCKET, SO_RCVBUFFORCE, &size, sizeof(size)) != 0)
    ::setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &size, sizeof(size));
  socklen_t length = sizeof(size);
  if (::getsockopt(fd, SOL_SOCKET, SO_RCVBUF, &size, &length) == 0)
    granted_buffer_bytes_ = size / 2;  // the kernel reports twice the usable size
  const int on = 1;
  ::setsockopt(fd, SOL_SOCKET, SO_TIMESTAMPNS, &on, sizeof(on));
  ::setsockopt(fd, SOL_SOCKET, SO_RXQ_OVFL, &on, sizeof(on));
  socket_.non_blocking(true, ec);
  if (ec) return "cannot make the socket non-blocking: " + ec.message();

  slots_ = std::make_unique<Slots>(options_.batch_datagrams);
  Wait();
  return std::nullopt;
}

void UdpReceiver::Close() {
  boost::system::error_code ec;
  if (socket_.is_open()) socket_.close(ec);
}

std::string UdpReceiver::local_address() const {
  boost::system::error_code ec;
  const udp::endpoint e = socket_.local_endpoint(ec);
  if (ec) return "";
  if (e.address().is_v6()) return "[" + e.address().to_string() + "]:" + std::to_string(e.port());
  return e.address().to_string() + ":" + std::to_string(e.port());
}

std::uint16_t UdpReceiver::local_port() const {
  boost::system::error_code ec;
  const udp::endpoint e = socket_.local_endpoint(ec);
  return ec ? 0 : e.port();
}

void UdpReceiver::Wait() {
  socket_.async_wait(udp::socket::wait_read, [this](const boost::system::error_code& ec) {
    if (ec) return;  // closed
    Drain();
  });
}

void UdpReceiver::Drain() {
  const int fd = socket_.native_handle();
  Slots& s = *slots_;
  std::size_t handled = 0;
  while (handled < options_.max_datagrams_per_wakeup) {
    s.Arm();
    const int n = ::recvmmsg(fd, s.headers.data(), static_cast<unsigned>(s.headers.size()),
                             MSG_DONTWAIT, nullptr);
    if (n < 0) {
      if (errno == EINTR) continue;
      if (errno != EAGAIN && errno != EWOULDBLOCK) ++counters_.receive_errors;
      break;
    }
    if (n == 0) break;
    ++counters_.batches;
    common::UtcNs fallback_ns = 0;
    for (int i = 0; i < n; ++i) {
      const msghdr& h = s.headers[i].msg_hdr;
      const std::size_t size = s.headers[i].msg_len;
      if ((h.msg_flags & MSG_TRUNC) != 0) ++counters_.truncated;
      common::UtcNs receive_ns = 0;
      for (cmsghdr* c = CMSG_FIRSTHDR(&h); c != nullptr; c = CMSG_NXTHDR(const_cast<msghdr*>(&h), c)) {
        if (c->cmsg_level != SOL_SOCKET) continue;
        if (c->cmsg_type == SCM_TIMESTAMPNS) {
          timespec ts{};
          std::memcpy(&ts, CMSG_DATA(c), sizeof(ts));
          receive_ns = static_cast<common::UtcNs>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
        } else if (c->cmsg_type == SO_RXQ_OVFL) {
          std::uint32_t dropped = 0;
          std::memcpy(&dropped, CMSG_DATA(c), sizeof(dropped));
          counters_.kernel_drops = dropped;  // cumulative since the socket was opened
        }
      }
      if (receive_ns == 0) {
        if (fallback_ns == 0) fallback_ns = RealtimeNs();
        receive_ns = fallback_ns;
      }
      ++counters_.datagrams;
      counters_.bytes += size;
      const std::string& source = s.Name(s.addresses[i], h.msg_namelen);
      handler_(std::span<const std::uint8_t>(s.buffers.data() + i * kSlotBytes,
                                             std::min(size, kSlotBytes)),
               source, receive_ns);
      if (!socket_.is_open()) return;  // the handler stopped us
    }
    handled += static_cast<std::size_t>(n);
    if (static_cast<std::size_t>(n) < s.headers.size()) break;  // the queue is empty
  }
  if (handled >= options_.max_datagrams_per_wakeup) {
    // Let timers and signals run, then go on with the queue.
    asio::post(io_, [this] {
      if (socket_.is_open()) Drain();
    });
    return;
  }
  Wait();
}

bool UdpReceiver::SendTo(std::string_view source, std::span<const std::uint8_t> bytes) {
  if (!slots_ || !socket_.is_open()) return false;
  const auto it = slots_->addresses_by_name.find(std::string(source));
  if (it == slots_->addresses_by_name.end()) {
    ++counters_.unknown_destinations;
    return false;
  }
  const ssize_t n = ::sendto(socket_.native_handle(), bytes.data(), bytes.size(), MSG_DONTWAIT,
                             reinterpret_cast<const sockaddr*>(it->second.bytes.data()),
                             it->second.length);
  if (n != static_cast<ssize_t>(bytes.size())) {
    ++counters_.send_errors;
    return false;
  }
  ++counters_.sent;
  return true;
}

}  // namespace lrfnet::daemon
