#pragma once
// Test-only: a real mosquitto broker (Debian's `mosquitto`) on a free loopback port, started and
// stopped by the test; optionally with a password file and TLS (certificates made with openssl).

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <thread>

#include "tests/process_harness.h"

namespace lrfnet::testing {

inline bool HaveBinary(const std::string& path) { return ::access(path.c_str(), X_OK) == 0; }
inline constexpr const char* kMosquitto = "/usr/sbin/mosquitto";
inline constexpr const char* kMosquittoSub = "/usr/bin/mosquitto_sub";
inline constexpr const char* kMosquittoPasswd = "/usr/bin/mosquitto_passwd";

// A port that was free a moment ago (bind to 0, read it, close).
inline std::uint16_t FreeTcpPort() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof a);
  socklen_t len = sizeof a;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len);
  ::close(fd);
  return ntohs(a.sin_port);
}

inline bool CanConnect(std::uint16_t port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = htons(port);
  const bool ok = ::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0;
  ::close(fd);
  return ok;
}

struct BrokerOptions {
  std::string username;  // with a password: anonymous clients are refused
  std::string password;
  bool tls = false;  // certificates in the broker's folder: ca.crt, server.crt, server.key
};

class MosquittoBroker {
 public:
  explicit MosquittoBroker(const BrokerOptions& options = {}) : options_(options) {
    port_ = FreeTcpPort();
    dir_ = std::make_unique<ScratchDir>();
    if (options_.tls) MakeCertificates();
    std::ofstream conf(*dir_ / "mosquitto.conf");
    conf << "listener " << port_ << " 127.0.0.1\n"
         << "persistence false\n"
         << "log_dest stderr\n"
         << "log_type error\nlog_type warning\nlog_type notice\n";
    if (!options_.username.empty()) {
      Process passwd(kMosquittoPasswd,
                     {"-b", "-c", *dir_ / "passwd", options_.username, options_.password});
      EXPECT_EQ(passwd.Wait(), 0) << passwd.err();
      std::filesystem::permissions(*dir_ / "passwd", std::filesystem::perms::owner_read |
                                                         std::filesystem::perms::owner_write |
                                                         std::filesystem::perms::group_read |
                                                         std::filesystem::perms::others_read);
      conf << "allow_anonymous false\npassword_file " << (*dir_ / "passwd") << "\n";
    } else {
      conf << "allow_anonymous true\n";
    }
    if (options_.tls) {
      conf << "cafile " << ca_file() << "\ncertfile " << (*dir_ / "server.crt") << "\nkeyfile "
           << (*dir_ / "server.key") << "\n";
    }
  }
  ~MosquittoBroker() { Stop(); }

  // Starts (or restarts) the broker and waits until it accepts connections.
  bool Start() {
    process_ = std::make_unique<Process>(kMosquitto,
                                         std::vector<std::string>{"-c", *dir_ / "mosquitto.conf"});
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
    while (std::chrono::steady_clock::now() < deadline) {
      if (CanConnect(port_)) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return false;
  }
  void Stop() {
    if (!process_) return;
    process_->Signal(SIGTERM);
    process_->Wait(std::chrono::milliseconds(10'000));
    process_.reset();
  }
  std::uint16_t port() const { return port_; }
  std::string address() const { return "127.0.0.1:" + std::to_string(port_); }
  std::string ca_file() const { return *dir_ / "ca.crt"; }
  std::string log() const { return process_ ? process_->err() : ""; }

 private:
  void MakeCertificates() {
    const std::string d = *dir_ / "";
    const std::string script =
        "cd '" + d +
        "' && "
        "openssl req -x509 -newkey rsa:2048 -nodes -days 2 -subj /CN=lrfnet-test-ca "
        "-keyout ca.key -out ca.crt 2>/dev/null && "
        "openssl req -newkey rsa:2048 -nodes -subj /CN=localhost -keyout server.key "
        "-out server.csr 2>/dev/null && "
        "printf 'subjectAltName=DNS:localhost,IP:127.0.0.1\\n' > ext.cnf && "
        "openssl x509 -req -in server.csr -CA ca.crt -CAkey ca.key -CAcreateserial -days 2 "
        "-extfile ext.cnf -out server.crt 2>/dev/null && "
        // mosquitto started as root reads its files as the user "mosquitto".
        "chmod 644 server.key";
    EXPECT_EQ(std::system(script.c_str()), 0) << "openssl failed";
  }

  BrokerOptions options_;
  std::uint16_t port_ = 0;
  std::unique_ptr<ScratchDir> dir_;
  std::unique_ptr<Process> process_;
};

}  // namespace lrfnet::testing
