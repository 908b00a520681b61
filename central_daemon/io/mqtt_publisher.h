#pragma once
// An MQTT client that only publishes (libmosquitto, MQTT 3.1.1), with its own network thread so
// that the caller never waits for the broker:
// - Publish() takes the message into a bounded queue and returns; when the queue is full the
//   oldest message that is not retained is dropped (counted). While the client is not connected,
//   messages that are not retained are dropped at once (counted: a stale object list is of no use
//   later); retained messages are kept, the newest per topic, and (re)sent after every connect.
// - The thread connects (TCP or TLS, user name and password when given), sends, answers keep-alive,
//   and after a lost connection or a refused attempt reconnects after reconnect_min_s, doubling
//   the wait after every failure up to reconnect_max_s (with up to 25 % jitter). QoS 0 messages
//   handed to the library but not yet written when the connection drops are lost (counted);
//   QoS 1 messages are sent again by the library.
// - A last will (retained) is registered with the broker and published by it if the daemon
//   vanishes without a clean disconnect.
// Thread-safety: Publish, counters, connected and Flush may be called from any thread; Start and
// Stop from the owning thread.

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>

namespace lrfnet::daemon {

struct MqttOptions {
  std::string host;
  std::uint16_t port = 1883;
  std::string client_id;  // must not be empty
  std::string username;   // empty: none
  std::string password;
  bool tls = false;
  std::string tls_ca_file;  // empty with tls: the system's CA folder (/etc/ssl/certs)
  std::string tls_cert_file;
  std::string tls_key_file;
  bool tls_insecure = false;
  int keepalive_s = 30;
  std::size_t queue_messages = 1000;
  // Messages handed to the library and not yet written (QoS 0) or acknowledged (QoS 1) at most;
  // the rest wait in the queue.
  std::size_t max_in_flight = 64;
  double reconnect_min_s = 0.5;
  double reconnect_max_s = 30.0;
  double connect_timeout_s = 10.0;  // TCP + TLS + CONNACK
  std::string will_topic;           // empty: no will
  std::string will_payload;
  int will_qos = 1;
  // Offline use: Publish waits for room in the queue instead of dropping (never while the broker
  // is unreachable: then it drops like the live mode).
  bool wait_when_full = false;
};
std::optional<std::string> Validate(const MqttOptions& options);

struct MqttCounters {
  std::uint64_t submitted = 0;             // Publish calls
  std::uint64_t sent = 0;                  // written (QoS 0) or acknowledged (QoS 1)
  std::uint64_t dropped_queue_full = 0;    // the queue was full
  std::uint64_t dropped_disconnected = 0;  // not retained, offered while not connected
  std::uint64_t lost_in_flight = 0;        // QoS 0, handed to the library, connection lost
  std::uint64_t retained_replaced = 0;     // a retained message replaced by a newer one unsent
  std::uint64_t publish_errors = 0;        // refused by the library (e.g. too large)
  std::uint64_t connects = 0;              // successful connections (CONNACK accepted)
  std::uint64_t connect_failures = 0;      // attempts that failed or were refused
  std::uint64_t disconnects = 0;           // connections lost
  std::uint64_t resent = 0;  // retained messages sent again after a reconnect (not in `sent`)
  // Now (not totals): waiting in the queue (retained ones included), and handed to the library;
  // resends not included. submitted = sent + dropped_* + lost_in_flight + retained_replaced +
  // publish_errors + queued + in_flight.
  std::uint64_t queued = 0;
  std::uint64_t in_flight = 0;
};

class MqttPublisher {
 public:
  // Precondition: Validate(options).
  explicit MqttPublisher(const MqttOptions& options);
  ~MqttPublisher();  // Stop()
  MqttPublisher(const MqttPublisher&) = delete;
  MqttPublisher& operator=(const MqttPublisher&) = delete;

  // Creates the client and starts the network thread (which connects in the background). False
  // with *error when the client cannot be set up (e.g. a TLS file cannot be read).
  bool Start(std::string* error);
  // Queues a message (see the header). qos 0 or 1.
  void Publish(const std::string& topic, std::string payload, int qos, bool retain);
  // Waits until the queue is empty and nothing is in flight, or timeout_s. True when all was sent.
  bool Flush(double timeout_s);
  // Waits until connected, or timeout_s.
  bool WaitConnected(double timeout_s);
  // Sends what is queued (up to timeout_s), disconnects cleanly (the will is not published) and
  // ends the thread.
  void Stop(double timeout_s = 2.0);

  bool connected() const;
  MqttCounters counters() const;
  // The latest connection problem ("" when none), for the log.
  std::string last_error() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace lrfnet::daemon
