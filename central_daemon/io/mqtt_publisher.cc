#include "central_daemon/io/mqtt_publisher.h"

#include <mosquitto.h>
#include <poll.h>
#include <sys/eventfd.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <map>
#include <mutex>
#include <random>
#include <thread>
#include <unordered_map>
#include <unordered_set>

namespace lrfnet::daemon {
namespace {

using Clock = std::chrono::steady_clock;

Clock::duration Seconds(double s) {
  return std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(s));
}

struct Message {
  std::string topic;
  std::string payload;
  int qos = 0;
  bool retain = false;
  bool resend = false;  // a retained message sent again after a reconnect (not a new submission)
};

struct InFlight {
  int qos = 0;
  bool resend = false;
};

}  // namespace

std::optional<std::string> Validate(const MqttOptions& o) {
  if (o.host.empty()) return "mqtt: no broker host";
  if (o.client_id.empty() || o.client_id.size() > 128) return "mqtt: client id of 1-128 bytes";
  if (o.keepalive_s < 5 || o.keepalive_s > 3600) return "mqtt: keepalive_s must be in [5, 3600]";
  if (o.queue_messages < 1 || o.queue_messages > 1000000) return "mqtt: queue_messages in [1, 1e6]";
  if (o.max_in_flight < 1 || o.max_in_flight > 65535) return "mqtt: max_in_flight in [1, 65535]";
  if (!(o.reconnect_min_s > 0.0 && o.reconnect_min_s <= o.reconnect_max_s &&
        o.reconnect_max_s <= 3600.0)) {
    return "mqtt: need 0 < reconnect_min_s <= reconnect_max_s <= 3600";
  }
  if (!(o.connect_timeout_s > 0.0 && o.connect_timeout_s <= 600.0)) {
    return "mqtt: connect_timeout_s in (0, 600]";
  }
  if (o.will_qos < 0 || o.will_qos > 1) return "mqtt: will_qos must be 0 or 1";
  if (o.tls_cert_file.empty() != o.tls_key_file.empty()) {
    return "mqtt: a client certificate needs its key and the other way round";
  }
  return std::nullopt;
}

struct MqttPublisher::Impl {
  explicit Impl(const MqttOptions& o) : options(o) {}

  const MqttOptions options;
  mosquitto* mosq = nullptr;
  int wake_fd = -1;
  std::thread thread;

  // Shared with the callers' threads.
  mutable std::mutex mutex;
  std::condition_variable changed;                 // queue drained, connected, in-flight done
  std::deque<Message> queue;                       // not retained
  std::map<std::string, Message> retained_unsent;  // newest per topic, sent after connect
  std::map<std::string, Message> retained_all;     // newest per topic, sent again after reconnect
  MqttCounters counters;
  bool connected = false;
  bool stopping = false;
  std::size_t in_flight = 0;      // handed to the library (resends included): the limit
  std::size_t in_flight_new = 0;  // of which first sends: the gauge
  std::string last_error;

  // Network thread only.
  std::unordered_map<int, InFlight> in_flight_qos;  // mid -> what
  std::unordered_set<int> completed_early;
  bool connecting = false;
  bool ever_connected = false;
  Clock::time_point connect_started{};
  Clock::time_point next_attempt{};
  double backoff_s = 0.0;
  std::mt19937 jitter{std::random_device{}()};

  void Wake() const {
    const std::uint64_t one = 1;
    [[maybe_unused]] const ssize_t n = ::write(wake_fd, &one, sizeof one);
  }

  static void OnConnect(mosquitto*, void* self, int rc) { static_cast<Impl*>(self)->Connected(rc); }
  static void OnDisconnect(mosquitto*, void* self, int rc) {
    static_cast<Impl*>(self)->Disconnected(rc);
  }
  static void OnPublish(mosquitto*, void* self, int mid) { static_cast<Impl*>(self)->Sent(mid); }

  void Connected(int rc) {
    connecting = false;
    std::lock_guard lock(mutex);
    if (rc != 0) {
      ++counters.connect_failures;
      last_error = std::string("broker refused the connection: ") + mosquitto_connack_string(rc);
      ScheduleRetryLocked();
      return;
    }
    connected = true;
    ever_connected = true;
    ++counters.connects;
    backoff_s = 0.0;
    last_error.clear();
    // Every retained message again: the broker may have restarted without its store. A newer
    // one still waiting is sent as it is.
    for (const auto& [topic, m] : retained_all) {
      if (retained_unsent.count(topic) != 0) continue;
      Message again = m;
      again.resend = true;
      retained_unsent.emplace(topic, std::move(again));
    }
    changed.notify_all();
  }

  void Disconnected(int rc) {
    const bool was_connecting = connecting;
    connecting = false;
    std::lock_guard lock(mutex);
    if (!connected && was_connecting) {
      ++counters.connect_failures;
      last_error = "cannot connect to " + options.host + ":" + std::to_string(options.port) + ": " +
                   mosquitto_strerror(rc) +
                   (rc == MOSQ_ERR_ERRNO ? std::string(" (") + std::strerror(errno) + ")" : "");
    }
    if (connected) {
      ++counters.disconnects;
      if (rc != 0) last_error = std::string("connection lost: ") + mosquitto_strerror(rc);
    }
    connected = false;
    // QoS 0 messages in the library's hands are gone; QoS 1 ones are sent again after reconnect.
    for (auto it = in_flight_qos.begin(); it != in_flight_qos.end();) {
      if (it->second.qos == 0) {
        if (!it->second.resend) {
          ++counters.lost_in_flight;
          --in_flight_new;
        }
        --in_flight;
        it = in_flight_qos.erase(it);
      } else {
        ++it;
      }
    }
    if (!stopping) ScheduleRetryLocked();
    changed.notify_all();
  }

  void Sent(int mid) {
    std::lock_guard lock(mutex);
    const auto it = in_flight_qos.find(mid);
    if (it == in_flight_qos.end()) {
      // A QoS 0 message written inside mosquitto_publish, before its mid was registered.
      completed_early.insert(mid);
      return;
    }
    Completed(it->second.resend);
    in_flight_qos.erase(it);
  }

  // A message written (QoS 0) or acknowledged (QoS 1). Under the lock.
  void Completed(bool resend) {
    --in_flight;
    if (resend) {
      ++counters.resent;
    } else {
      --in_flight_new;
      ++counters.sent;
    }
    changed.notify_all();
  }

  void ScheduleRetryLocked() {
    backoff_s = backoff_s == 0.0 ? options.reconnect_min_s
                                 : std::min(options.reconnect_max_s, 2.0 * backoff_s);
    const double jittered = backoff_s * std::uniform_real_distribution<double>(1.0, 1.25)(jitter);
    next_attempt = Clock::now() + Seconds(jittered);
  }

  void TryConnect() {
    {
      std::lock_guard lock(mutex);
      if (stopping) return;
    }
    connecting = true;
    connect_started = Clock::now();
    const int rc = ever_connected || attempted
                       ? mosquitto_reconnect_async(mosq)
                       : mosquitto_connect_async(mosq, options.host.c_str(), options.port,
                                                 options.keepalive_s);
    attempted = true;
    if (rc != MOSQ_ERR_SUCCESS) {
      connecting = false;
      std::lock_guard lock(mutex);
      ++counters.connect_failures;
      last_error = std::string("cannot connect to ") + options.host + ":" +
                   std::to_string(options.port) + ": " +
                   (rc == MOSQ_ERR_ERRNO ? std::strerror(errno) : mosquitto_strerror(rc));
      ScheduleRetryLocked();
    }
  }
  bool attempted = false;

  // Hands queued messages to the library while connected and in-flight allows.
  void Drain() {
    while (true) {
      Message m;
      {
        std::lock_guard lock(mutex);
        if (!connected || in_flight >= options.max_in_flight) return;
        if (!retained_unsent.empty()) {
          m = std::move(retained_unsent.begin()->second);
          retained_unsent.erase(retained_unsent.begin());
        } else if (!queue.empty()) {
          m = std::move(queue.front());
          queue.pop_front();
        } else {
          return;
        }
        // Counted in flight from here, so Flush never sees it neither queued nor in flight.
        ++in_flight;
        if (!m.resend) ++in_flight_new;
      }
      int mid = 0;
      const int rc =
          mosquitto_publish(mosq, &mid, m.topic.c_str(), static_cast<int>(m.payload.size()),
                            m.payload.data(), m.qos, m.retain);
      std::lock_guard lock(mutex);
      if (rc == MOSQ_ERR_SUCCESS) {
        // Outside the library's own thread mosquitto_publish writes at once, so a QoS 0 message
        // may be complete (Sent called) before its mid is known here.
        if (completed_early.erase(mid) != 0) {
          Completed(m.resend);
        } else {
          in_flight_qos[mid] = {m.qos, m.resend};
        }
        continue;
      }
      --in_flight;
      if (!m.resend) --in_flight_new;
      changed.notify_all();
      if (rc == MOSQ_ERR_NO_CONN || rc == MOSQ_ERR_CONN_LOST) {
        if (m.retain) {
          retained_unsent.try_emplace(m.topic, std::move(m));
        } else if (!m.resend) {
          ++counters.dropped_disconnected;
        }
      } else {
        if (!m.resend) ++counters.publish_errors;
        last_error = std::string("publish refused: ") + mosquitto_strerror(rc);
      }
    }
  }

  void Run() {
    while (true) {
      {
        std::lock_guard lock(mutex);
        if (stopping) break;
      }
      const auto now = Clock::now();
      bool is_connected;
      {
        std::lock_guard lock(mutex);
        is_connected = connected;
      }
      if (!is_connected && !connecting && now >= next_attempt) TryConnect();
      if (connecting && Clock::now() - connect_started > Seconds(options.connect_timeout_s)) {
        mosquitto_disconnect(mosq);  // closes the half-open attempt; counted as a failure
        connecting = false;
        std::lock_guard lock(mutex);
        ++counters.connect_failures;
        last_error =
            "connecting to " + options.host + ":" + std::to_string(options.port) + " timed out";
        ScheduleRetryLocked();
      }
      Drain();
      pollfd fds[2] = {{wake_fd, POLLIN, 0}, {mosquitto_socket(mosq), POLLIN, 0}};
      nfds_t n = 1;
      if (fds[1].fd >= 0) {
        if (mosquitto_want_write(mosq)) fds[1].events |= POLLOUT;
        n = 2;
      }
      int timeout_ms = 200;
      if (!is_connected && !connecting) {
        const auto wait =
            std::chrono::duration_cast<std::chrono::milliseconds>(next_attempt - Clock::now());
        timeout_ms = static_cast<int>(std::clamp<std::int64_t>(wait.count(), 0, 200));
      }
      ::poll(fds, n, timeout_ms);
      if (fds[0].revents & POLLIN) {
        std::uint64_t count = 0;
        [[maybe_unused]] const ssize_t r = ::read(wake_fd, &count, sizeof count);
      }
      if (n == 2) {
        int rc = MOSQ_ERR_SUCCESS;
        if (fds[1].revents & (POLLIN | POLLHUP | POLLERR)) rc = mosquitto_loop_read(mosq, 16);
        if (rc == MOSQ_ERR_SUCCESS && (fds[1].revents & POLLOUT))
          rc = mosquitto_loop_write(mosq, 16);
        // On an error the library closes the socket and calls on_disconnect (Disconnected).
        (void)rc;
      }
      mosquitto_loop_misc(mosq);
      if (connecting && mosquitto_socket(mosq) < 0) {
        // The attempt ended without a CONNACK and without on_disconnect (e.g. a TLS failure).
        connecting = false;
        std::lock_guard lock(mutex);
        ++counters.connect_failures;
        if (last_error.empty()) last_error = "connection attempt failed";
        ScheduleRetryLocked();
      }
    }
  }
};

MqttPublisher::MqttPublisher(const MqttOptions& options) : impl_(std::make_unique<Impl>(options)) {}

MqttPublisher::~MqttPublisher() { Stop(0.5); }

bool MqttPublisher::Start(std::string* error) {
  static std::once_flag init;
  std::call_once(init, [] { mosquitto_lib_init(); });
  const MqttOptions& o = impl_->options;
  const auto fail = [&](const std::string& what) {
    if (error != nullptr) *error = "mqtt: " + what;
    return false;
  };
  if (auto e = Validate(o)) return fail(*e);
  impl_->mosq = mosquitto_new(o.client_id.c_str(), true, impl_.get());
  if (impl_->mosq == nullptr) return fail("cannot create the client");
  mosquitto_int_option(impl_->mosq, MOSQ_OPT_PROTOCOL_VERSION, MQTT_PROTOCOL_V311);
  mosquitto_connect_callback_set(impl_->mosq, &Impl::OnConnect);
  mosquitto_disconnect_callback_set(impl_->mosq, &Impl::OnDisconnect);
  mosquitto_publish_callback_set(impl_->mosq, &Impl::OnPublish);
  if (!o.username.empty() &&
      mosquitto_username_pw_set(impl_->mosq, o.username.c_str(),
                                o.password.empty() ? nullptr : o.password.c_str()) !=
          MOSQ_ERR_SUCCESS) {
    return fail("cannot set the user name");
  }
  if (o.tls) {
    const int rc =
        mosquitto_tls_set(impl_->mosq, o.tls_ca_file.empty() ? nullptr : o.tls_ca_file.c_str(),
                          o.tls_ca_file.empty() ? "/etc/ssl/certs" : nullptr,
                          o.tls_cert_file.empty() ? nullptr : o.tls_cert_file.c_str(),
                          o.tls_key_file.empty() ? nullptr : o.tls_key_file.c_str(), nullptr);
    if (rc != MOSQ_ERR_SUCCESS) {
      return fail(std::string("TLS setup: ") + mosquitto_strerror(rc) +
                  " (check tls_ca_file, tls_cert_file and tls_key_file)");
    }
    mosquitto_tls_insecure_set(impl_->mosq, o.tls_insecure);
  }
  if (!o.will_topic.empty() &&
      mosquitto_will_set(impl_->mosq, o.will_topic.c_str(), static_cast<int>(o.will_payload.size()),
                         o.will_payload.data(), o.will_qos, true) != MOSQ_ERR_SUCCESS) {
    return fail("cannot set the last will on '" + o.will_topic + "'");
  }
  impl_->wake_fd = ::eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK);
  if (impl_->wake_fd < 0) return fail(std::string("eventfd: ") + std::strerror(errno));
  impl_->thread = std::thread([impl = impl_.get()] { impl->Run(); });
  return true;
}

void MqttPublisher::Publish(const std::string& topic, std::string payload, int qos, bool retain) {
  Impl& d = *impl_;
  {
    std::unique_lock lock(d.mutex);
    ++d.counters.submitted;
    Message m{topic, std::move(payload), qos, retain};
    if (retain) {
      d.retained_all[topic] = m;
      auto [it, inserted] = d.retained_unsent.try_emplace(topic, m);
      if (!inserted) {
        if (!it->second.resend) ++d.counters.retained_replaced;
        it->second = std::move(m);
      }
    } else if (!d.connected) {
      ++d.counters.dropped_disconnected;
      return;
    } else {
      if (d.options.wait_when_full) {
        d.changed.wait(lock, [&] {
          return d.queue.size() < d.options.queue_messages || !d.connected || d.stopping;
        });
        if (!d.connected || d.stopping) {
          ++d.counters.dropped_disconnected;
          return;
        }
      }
      if (d.queue.size() >= d.options.queue_messages) {
        d.queue.pop_front();
        ++d.counters.dropped_queue_full;
      }
      d.queue.push_back(std::move(m));
    }
  }
  if (d.wake_fd >= 0) d.Wake();
}

bool MqttPublisher::Flush(double timeout_s) {
  Impl& d = *impl_;
  std::unique_lock lock(d.mutex);
  return d.changed.wait_for(lock, Seconds(timeout_s), [&] {
    return d.queue.empty() && d.in_flight == 0 && (d.retained_unsent.empty() || !d.connected);
  }) && d.connected;
}

bool MqttPublisher::WaitConnected(double timeout_s) {
  Impl& d = *impl_;
  std::unique_lock lock(d.mutex);
  return d.changed.wait_for(lock, Seconds(timeout_s), [&] { return d.connected; });
}

void MqttPublisher::Stop(double timeout_s) {
  Impl& d = *impl_;
  if (!d.thread.joinable()) {
    if (d.mosq != nullptr) {
      mosquitto_destroy(d.mosq);
      d.mosq = nullptr;
    }
    if (d.wake_fd >= 0) ::close(d.wake_fd);
    d.wake_fd = -1;
    return;
  }
  bool was_connected;
  {
    std::lock_guard lock(d.mutex);
    was_connected = d.connected;
  }
  if (was_connected) Flush(timeout_s);
  {
    std::lock_guard lock(d.mutex);
    d.stopping = true;
    d.changed.notify_all();
  }
  d.Wake();
  d.thread.join();
  // A clean DISCONNECT: the broker discards the will.
  if (was_connected && mosquitto_disconnect(d.mosq) == MOSQ_ERR_SUCCESS) {
    for (int i = 0; i < 10 && mosquitto_want_write(d.mosq); ++i) mosquitto_loop_write(d.mosq, 1);
  }
  mosquitto_destroy(d.mosq);
  d.mosq = nullptr;
  ::close(d.wake_fd);
  d.wake_fd = -1;
}

bool MqttPublisher::connected() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->connected;
}

MqttCounters MqttPublisher::counters() const {
  std::lock_guard lock(impl_->mutex);
  MqttCounters c = impl_->counters;
  c.queued = impl_->queue.size();
  for (const auto& [topic, m] : impl_->retained_unsent) c.queued += m.resend ? 0 : 1;
  c.in_flight = impl_->in_flight_new;
  return c;
}

std::string MqttPublisher::last_error() const {
  std::lock_guard lock(impl_->mutex);
  return impl_->last_error;
}

}  // namespace lrfnet::daemon
