#pragma once
// The SOPAS side of a SICK laser scanner as a pure state machine: what a device of each family
// (LMS1xx, LMS5xx, TiM5xx, TiM7xx, TiM7xxS, MRS1xxx) answers to every request a driver sends, in
// the dialect the request came in (CoLa-A or CoLa-B), and which event telegrams it sends. No
// sockets, no clock: the emulator feeds request payloads with the time, sends the replies, and
// asks before every scan whether (and how) it goes out.
//
// What is modelled (sources: the real devices' replies in the shared captures, SICK's telegram
// listings, and the requests of SICK's sick_scan_xd driver):
//   - reads `sRN` / writes `sWN` of the family's variables, with the value kept and read back;
//     writes need the authorized-client level and values the device accepts;
//   - methods `sMN`: SetAccessMode (each user level with its own password hash), Run,
//     LMCstartmeas / LMCstopmeas, mLMPsetscancfg, mEEwriteall, LMCstandby, mSCreboot;
//   - events `sEN` with a subscription per connection: LMDscandata, and where the family has field
//     evaluation and I/O: LFErec, LIDoutputstate, LIDinputstate;
//   - the device state machine: a granted login enters configuration mode (SCdevicestate 0, no
//     scans); Run leaves it and the device is busy until it is ready (MRS1xxx about 14.5 s, as the
//     MRS1104 capture shows; LMS1xx 0.5 s); scans go out only while measuring (LMCstartmeas, on at
//     power-up; LMCstopmeas stops them), ready, and subscribed;
//   - the output configuration applied to every scan: LMDscandatacfg (echo channels, remission
//     on/off and width, time block, every n-th scan), LMPoutputRange (angular crop), and the
//     MRS1xxx ScanLayerFilter;
//   - the `sFA` code a device answers what it refuses: unknown variable 3, unknown method 2,
//     unknown event 15, access denied 1 (methods) / 10 (writes), a value it does not accept 4,
//     arguments too short 8 / too long 7, CoLa-A characters 17 / overflow 16, unknown command 12.
//
// Thread-safety: none (one emulator thread).

#include <array>
#include <cstdint>
#include <map>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "common/time.h"
#include "firmware_tracker/cola/scan_telegram.h"
#include "firmware_tracker/cola/sopas_value.h"
#include "tools/scan_source.h"
#include "tools/sopas_fields.h"

namespace lrfnet::tools {

enum class DeviceFamily : std::uint8_t { kLms1xx, kLms5xx, kTim5xx, kTim7xx, kTim7xxS, kMrs1xxx };
const char* DeviceFamilyName(DeviceFamily f);  // "LMS1xx", ..., "TiM7xxS", "MRS1xxx"
// The family of a DeviceIdent name: "LMS111-10100" -> LMS1xx, "LMS511" -> LMS5xx,
// "TiM561-2050101" -> TiM5xx, "TiM781-2174101" -> TiM7xx, "TiM781S-2174104" -> TiM7xxS,
// "MRS1104C" / "MRS1xxxx" -> MRS1xxx. Nullopt when it names none of them.
std::optional<DeviceFamily> FamilyFromDeviceName(std::string_view name);
// Parses "lms1xx", "LMS5xx", "tim7xxs", ... (case-insensitive).
std::optional<DeviceFamily> ParseDeviceFamily(std::string_view text);

struct SopasDeviceOptions {
  DeviceFamily family = DeviceFamily::kLms5xx;
  // Identity, native scan geometry and recorded reads (scan_source.h). Recorded reads of stored
  // variables replace the family's defaults when their bytes decode by the variable's layout.
  DeviceIdentity identity;
  // Seconds from `sMN Run` until SCdevicestate reports ready; negative: the family's value.
  double ready_after_run_s = -1.0;
};
std::optional<std::string> Validate(const SopasDeviceOptions& options);

// One telegram the device sends: a reply or an event.
struct SopasOutput {
  cola::Dialect dialect = cola::Dialect::kColaB;
  std::vector<std::uint8_t> payload;
};

struct SopasDeviceCounters {
  std::uint64_t requests = 0;                   // telegrams received (well-formed or not)
  std::uint64_t requests_cola_a = 0;            // of them in CoLa-A
  std::uint64_t replies = 0;                    // positive replies (sRA / sWA / sAN / sEA)
  std::uint64_t sfa = 0;                        // sFA replies
  std::array<std::uint64_t, 32> sfa_by_code{};  // index: SOPAS error code (above 31: slot 31)
  std::uint64_t unknown_commands = 0;  // not a request telegram, or a name the family lacks
  std::uint64_t access_denied = 0;     // methods / writes below the needed user level
  std::uint64_t bad_arguments = 0;     // arguments that do not decode or are not accepted
  std::uint64_t logins_granted = 0;
  std::uint64_t logins_refused = 0;    // wrong password hash or unknown user level
  std::uint64_t scans_suppressed = 0;  // scans not sent: output interval, layer filter
  std::uint64_t events_sent = 0;       // sSN LFErec / LIDoutputstate / LIDinputstate
  std::uint64_t reboots = 0;
  std::uint64_t recorded_reads_used = 0;     // recorded values that replaced a default
  std::uint64_t recorded_reads_ignored = 0;  // recorded values of live or unknown variables, or
                                             // whose bytes did not decode
};

class SopasDevice {
 public:
  explicit SopasDevice(const SopasDeviceOptions& options);  // options must Validate (aborts)

  // One request (a frame payload in `dialect`) at `now_ns` (any monotonic origin): appends
  // exactly one reply to *out, and event telegrams the request triggers after it.
  void HandleRequest(cola::Dialect dialect, std::span<const std::uint8_t> payload,
                     common::DurationNs now_ns, std::vector<SopasOutput>* out);

  // The client's connection ended: user level, configuration mode and subscriptions are per
  // connection; the measurement and every variable stay.
  void OnDisconnect();
  // Power cycle: everything not saved with mEEwriteall returns to its saved value, measuring
  // again, power-on counter + 1.
  void Reboot(common::DurationNs now_ns);

  // Whether scans go out now (measuring, not configuring, ready, LMDscandata subscribed).
  bool ScanOutputEnabled(common::DurationNs now_ns) const;
  // Applies the output configuration to a scan about to be sent (crop, channels, time block) and
  // returns false when this scan is not sent (output interval, disabled MRS layer). Then
  // evaluates the fields on it and appends the event telegrams that changed (LFErec,
  // LIDoutputstate) for the subscribed events.
  bool PrepareScan(cola::ScanTelegram* scan, common::DurationNs now_ns,
                   std::vector<SopasOutput>* events);
  // The scan telegram in the dialect LMDscandata was subscribed in (empty payload: it cannot be
  // encoded).
  SopasOutput EncodeScan(const cola::ScanTelegram& scan) const;
  // `sEN LMDscandata 1` is in force on this connection (scans may still wait for the device).
  bool ScanSubscribed() const;

  // SCdevicestate: 0 busy, 1 ready.
  std::uint8_t DeviceState(common::DurationNs now_ns) const;
  std::uint8_t user_level() const { return level_; }
  bool measuring() const { return measuring_; }
  bool configuring() const { return configuring_; }
  cola::Dialect host_dialect() const;  // EIHstCola
  DeviceFamily family() const { return family_; }
  const SopasDeviceCounters& counters() const { return counters_; }
  // The current value of a stored variable (tests); nullptr when the family has none of it.
  const cola::SopasValues* Value(std::string_view name) const;

  struct Variable;  // the family's variable table entry (sopas_device.cc)
  struct Subscription {
    bool on = false;
    cola::Dialect dialect = cola::Dialect::kColaB;
  };

 private:
  void Reply(cola::Dialect d, cola::CommandType type, std::string_view name,
             const cola::SopasValues& values, std::vector<SopasOutput>* out,
             bool space_when_empty = false);
  void Error(cola::Dialect d, std::uint16_t code, std::vector<SopasOutput>* out);
  void Read(cola::Dialect d, std::string_view name, std::span<const std::uint8_t> args,
            common::DurationNs now_ns, std::vector<SopasOutput>* out);
  void Write(cola::Dialect d, std::string_view name, std::span<const std::uint8_t> args,
             std::vector<SopasOutput>* out);
  void Method(cola::Dialect d, std::string_view name, std::span<const std::uint8_t> args,
              common::DurationNs now_ns, std::vector<SopasOutput>* out);
  void Event(cola::Dialect d, std::string_view name, std::span<const std::uint8_t> args,
             common::DurationNs now_ns, std::vector<SopasOutput>* out);
  bool LiveValue(std::string_view name, common::DurationNs now_ns, cola::SopasValues* out) const;
  std::optional<std::uint16_t> CheckWrite(std::string_view name,
                                          const cola::SopasValues& values) const;
  void ApplyDefaults();
  void ApplyRecorded(const DeviceIdentity& identity);
  void SendEvent(std::string_view name, common::DurationNs now_ns, std::vector<SopasOutput>* out);
  std::uint32_t TickUs(common::DurationNs now_ns) const;

  DeviceFamily family_;
  SopasDeviceOptions options_;
  double ready_after_run_s_;
  const std::vector<Variable>* variables_;
  SopasValueMap values_;
  SopasValueMap saved_;  // mEEwriteall
  std::map<std::string, Subscription, std::less<>> subscriptions_;

  std::uint8_t level_ = 0;    // 0 = run level (no login)
  bool configuring_ = false;  // a login was granted and Run has not come yet
  bool measuring_ = true;
  common::DurationNs ready_at_ns_ = 0;
  common::DurationNs boot_ns_ = 0;
  std::uint32_t power_on_count_ = 0;
  std::uint64_t scans_seen_ = 0;      // for the output interval
  std::uint32_t system_counter_ = 0;  // LIDoutputstate / LIDinputstate

  // Field evaluation: per field of the family, 0 = not evaluated, 1 = free, 2 = infringed.
  std::vector<std::uint8_t> field_results_;
  std::vector<std::uint8_t> output_states_;  // LIDoutputstate: 0 off, 1 on, 2 unused
  std::vector<std::uint32_t> output_counts_;
  bool evaluated_once_ = false;

  SopasDeviceCounters counters_;
};

}  // namespace lrfnet::tools
