#include "tools/sopas_device.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <numbers>

#include "tools/sopas_fields.h"

namespace lrfnet::tools {

using cola::CommandType;
using cola::Dialect;
using cola::SopasSchema;
using cola::SopasValues;
using S = cola::SopasScalar;

namespace {

// SOPAS error codes (cola::SopasErrorName has them all).
constexpr std::uint16_t kMethodAccessDenied = 1;
constexpr std::uint16_t kMethodUnknown = 2;
constexpr std::uint16_t kVariableUnknown = 3;
constexpr std::uint16_t kLocalConditionFailed = 4;
constexpr std::uint16_t kVariableWriteAccessDenied = 10;
constexpr std::uint16_t kUnknownColaCommand = 12;
constexpr std::uint16_t kEventUnknown = 15;

// SOPAS user levels and their password hashes: maintenance "main", authorized client "client",
// service "servicelevel" (SICK telegram listings; sick_scan_xd uses the client and service ones).
// The TiM7xxS safety scanner's client level has its own hash (sick_scan_xd's
// CMD_SET_ACCESS_MODE_3_SAFETY_SCANNER); the standard one is refused there.
constexpr std::uint8_t kLevelMaintenance = 2;
constexpr std::uint8_t kLevelAuthorizedClient = 3;
constexpr std::uint8_t kLevelService = 4;
constexpr std::uint32_t kMaintenanceHash = 0xB21ACE26;
constexpr std::uint32_t kClientHash = 0xF4724744;
constexpr std::uint32_t kSafetyClientHash = 0x6FD62C05;
constexpr std::uint32_t kServiceHash = 0x81BE23AA;

// Defaults a fresh device reports.
constexpr std::uint32_t kOperatingHoursTenths = 1234;  // ODoprh: 123.4 h
constexpr std::uint32_t kPowerOnCount = 42;            // ODpwrc

struct FamilySpec {
  DeviceFamily family;
  const char* name;
  double ready_after_run_s;  // SCdevicestate busy after Run
  std::uint32_t client_hash;
  int fields;             // fieldNNN variables (0: no field evaluation)
  int structured_fields;  // of them answered with the whole layout; the others with one 0 byte
  int outputs;            // LIDoutputstate entries
  // LIDinputstate / LIDoutputstate as the family sends them: telegram version, state of an
  // unwired input, whether each carries the time block.
  std::uint16_t io_version;
  std::uint8_t idle_input;
  bool input_time_block;
  bool output_time_block;
  bool lferec_readable;   // `sRN LFErec` (TiM7xx)
  bool echo_filter;       // FREchoFilter
  bool mrs_variables;     // SetActiveApplications, ScanLayerFilter, LFPmeanfilter/-medianfilter
  bool field_sets;        // ActiveFieldSet, FieldSetSelectionMethod (TiM7xx)
  ScanGeometry geometry;  // typical scans when the source does not say
};

// Ready delays: the MRS1104 capture reports busy until 15.0 s after Run (polls 1 s apart: busy at
// +14.03 s, ready at +15.03 s); the LMS111 was ready at once (scans 0.2 s after Run), but SICK's
// driver polls it: a short delay keeps that path honest. Field counts: the LMS111 and LMS511
// answer field000-029 (the first ten with the field layout) and refuse field030 on; TiM7xx have
// 16 field sets of 3 (sick_scan_xd reads field000-047). Output counts from the captures' and the
// driver's LIDoutputstate telegrams: LMS111 11, LMS511 14, TiM781S 5.
// I/O telegrams: the LMS111 sends LIDinputstate version 1, inputs 2, no time and LIDoutputstate
// with the time; the LMS511 version 0, inputs 0, both with the time; the TiM781S version 0, no
// time (sick_scan_xd's example telegram).
// clang-format off
const FamilySpec kFamilies[] = {
//   family                 name       ready  hash               fields  outputs    inputs        time (in, out)  LFErec  echo   MRS    sets   geometry
    {DeviceFamily::kLms1xx, "LMS1xx",  0.5,   kClientHash,       30, 10, 11, 1, 2,  false, true,  false,  false, false, false, {-450000, 5000, 541, 5000, 0}},
    {DeviceFamily::kLms5xx, "LMS5xx",  0.0,   kClientHash,       30, 10, 14, 0, 0,  true,  true,  false,  true,  false, false, {-50000, 1667, 1141, 2500, 8}},
    {DeviceFamily::kTim5xx, "TiM5xx",  0.0,   kClientHash,        0,  0,  0, 0, 0,  false, false, false,  false, false, false, {-450000, 3333, 811, 1500, 16}},
    {DeviceFamily::kTim7xx, "TiM7xx",  0.0,   kClientHash,       48, 48,  5, 0, 0,  false, false, true,   false, false, true,  {-450000, 3333, 811, 1500, 16}},
    {DeviceFamily::kTim7xxS, "TiM7xxS", 0.0,  kSafetyClientHash, 48, 48,  5, 0, 0,  false, false, true,   false, false, true,  {-450000, 3333, 811, 1500, 16}},
    {DeviceFamily::kMrs1xxx, "MRS1xxx", 14.5, kClientHash,        0,  0,  0, 0, 0,  false, false, false,  true,  true,  false, {-475000, 2500, 1101, 5000, 0}},
};
// clang-format on

const FamilySpec& Spec(DeviceFamily f) {
  for (const FamilySpec& s : kFamilies) {
    if (s.family == f) return s;
  }
  std::abort();
}

FieldFamily FieldsOf(const FamilySpec& spec) {
  FieldFamily f;
  f.fields = spec.fields;
  f.field_sets = spec.field_sets;
  // sick_scan_xd draws LMS1xx rectangles with their reference angle counted from −45°.
  f.rect_ref_offset_deg = spec.family == DeviceFamily::kLms1xx ? -45.0 : 0.0;
  return f;
}

std::string Lower(std::string_view s) {
  std::string out(s);
  for (char& c : out) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return out;
}

std::string FieldName(int i) {
  char buf[16];
  std::snprintf(buf, sizeof buf, "field%03d", i);
  return buf;
}

// The device's angular range: first beam to last, the last rounded to 0.1° when that is within
// half a step (1140 × 0.1667° = 190.038° is the LMS511's 190°).
std::int32_t StopAngleRaw(const ScanGeometry& g) {
  const std::int64_t last =
      g.start_angle_raw + static_cast<std::int64_t>(g.count - 1) * g.angle_step_raw;
  const std::int64_t rounded =
      static_cast<std::int64_t>(std::llround(static_cast<double>(last) / 1000.0)) * 1000;
  return static_cast<std::int32_t>(std::llabs(rounded - last) * 2 <= g.angle_step_raw ? rounded
                                                                                      : last);
}

int DigitOf(std::string_view channel_name) {
  const char c = channel_name.size() == 5 ? channel_name[4] : '1';
  return (c >= '1' && c <= '9') ? c - '0' : 1;
}

}  // namespace

// ---- families

const char* DeviceFamilyName(DeviceFamily f) { return Spec(f).name; }

std::optional<DeviceFamily> FamilyFromDeviceName(std::string_view name) {
  const std::string n = Lower(name);
  const auto starts = [&](const char* p) { return n.rfind(p, 0) == 0; };
  std::size_t digits = 0;
  while (3 + digits < n.size() && std::isdigit(static_cast<unsigned char>(n[3 + digits]))) {
    ++digits;
  }
  // Three digits after the letters: LMS111, LMS511, TiM561, TiM781 (LMS1104 is an LMS1000).
  if (starts("lms") && digits == 3 && n[3] == '1') return DeviceFamily::kLms1xx;
  if (starts("lms") && digits == 3 && n[3] == '5') return DeviceFamily::kLms5xx;
  if (starts("tim") && digits == 3 && n[3] == '5') return DeviceFamily::kTim5xx;
  if (starts("tim") && digits == 3 && n[3] == '7') {
    // "TiM781S-2174104": an S right after the digits marks the safety variant.
    return n.size() > 6 && n[6] == 's' ? DeviceFamily::kTim7xxS : DeviceFamily::kTim7xx;
  }
  // "MRS1104C", and the MRS1104 of the shared capture calls itself "MRS1xxxx".
  if (starts("mrs1")) return DeviceFamily::kMrs1xxx;
  return std::nullopt;
}

std::optional<DeviceFamily> ParseDeviceFamily(std::string_view text) {
  const std::string t = Lower(text);
  for (const FamilySpec& s : kFamilies) {
    if (t == Lower(s.name)) return s.family;
  }
  return std::nullopt;
}

std::optional<std::string> Validate(const SopasDeviceOptions& options) {
  if (!(options.ready_after_run_s < 3600.0) || std::isnan(options.ready_after_run_s)) {
    return "ready delay after Run must be below 3600 s";
  }
  const ScanGeometry& g = options.identity.geometry;
  if (g.count != 0 && (g.angle_step_raw == 0 || g.scan_frequency_raw == 0)) {
    return "scan geometry: step and frequency must be set with a beam count";
  }
  return std::nullopt;
}

// ---- variables

struct SopasDevice::Variable {
  std::string name;
  SopasSchema schema;
  bool writable = false;
  bool live = false;  // computed on every read, never stored
  bool space_after_write_answer = true;
};

namespace {

using Variable = SopasDevice::Variable;

std::vector<Variable> BuildVariables(const FamilySpec& spec) {
  std::vector<Variable> v;
  const auto add = [&](std::string name, std::string_view schema, bool writable, bool live = false,
                       bool space = true) {
    v.push_back({std::move(name), SopasSchema::Compile(schema), writable, live, space});
  };
  add("DeviceIdent", "str str", false);
  add("SerialNumber", "str", false);
  add("FirmwareVersion", "str", false);
  add("SCdevicestate", "u8", false, true);
  add("ODoprh", "u32", false, true);
  add("ODpwrc", "u32", false, true);
  add("LocationName", "str", true);
  add("EIHstCola", "u8", true);
  add("LMPoutputRange", "u16[u32 i32 i32]", true);
  add("LMDscandatacfg", "u8 u8 u8 u8 u8 u8 u8 u8 u8 u8 u8 u16", true);
  add("LMPscancfg", "u32 u16[u32 i32 i32]", false);
  for (int i = 0; i < spec.fields; ++i) {
    add(FieldName(i), i < spec.structured_fields ? kFieldSchema : "u8", false);
  }
  if (spec.fields > 0) {
    add("LIDinputstate", kInputStateSchema, false, true);
    add("LIDoutputstate", OutputStateSchema(spec.outputs), false, true);
  }
  if (spec.lferec_readable) add("LFErec", kLfeRecSchema, false, true);
  if (spec.field_sets) {
    add("ActiveFieldSet", "u16", true);
    add("FieldSetSelectionMethod", "u8", true);
  }
  // The MRS1104 answers these two writes without the trailing space (shared capture).
  if (spec.echo_filter) add("FREchoFilter", "u8", true, false, !spec.mrs_variables);
  if (spec.mrs_variables) {
    add("SetActiveApplications", "u16[c4 u8]", true, false, false);
    add("ScanLayerFilter", "u16[u8]", true);
    add("LFPmeanfilter", "u8 u16 u8", true);
    add("LFPmedianfilter", "u8 u16", true);
  }
  return v;
}

const std::vector<Variable>& VariablesOf(DeviceFamily f) {
  static const auto* tables = [] {
    auto* t = new std::vector<std::vector<Variable>>();
    for (const FamilySpec& s : kFamilies) t->push_back(BuildVariables(s));
    return t;
  }();
  for (std::size_t i = 0; i < std::size(kFamilies); ++i) {
    if (kFamilies[i].family == f) return (*tables)[i];
  }
  std::abort();
}

const Variable* FindVariable(const std::vector<Variable>& vars, std::string_view name) {
  for (const Variable& v : vars) {
    if (v.name == name) return &v;
  }
  return nullptr;
}

}  // namespace

// ---- construction

SopasDevice::SopasDevice(const SopasDeviceOptions& options)
    : family_(options.family),
      options_(options),
      ready_after_run_s_(options.ready_after_run_s >= 0 ? options.ready_after_run_s
                                                        : Spec(options.family).ready_after_run_s),
      variables_(&VariablesOf(options.family)),
      power_on_count_(kPowerOnCount) {
  if (Validate(options).has_value()) std::abort();
  if (options_.identity.geometry.count == 0) options_.identity.geometry = Spec(family_).geometry;
  ApplyDefaults();
  ApplyRecorded(options_.identity);
  saved_ = values_;
  const FamilySpec& spec = Spec(family_);
  field_results_.assign(static_cast<std::size_t>(spec.fields), 0);
  output_states_.assign(static_cast<std::size_t>(spec.outputs), 2);
  output_counts_.assign(static_cast<std::size_t>(spec.outputs), 0);
}

void SopasDevice::ApplyDefaults() {
  const DeviceIdentity& id = options_.identity;
  const ScanGeometry& g = id.geometry;
  const FamilySpec& spec = Spec(family_);
  values_["DeviceIdent"] = {S::Str(id.name), S::Str(id.version)};
  values_["SerialNumber"] = {S::Str(id.serial_number)};
  values_["FirmwareVersion"] = {S::Str(id.firmware_version)};
  values_["ODoprh"] = {S::U32(kOperatingHoursTenths)};
  values_["LocationName"] = {S::Str("not defined")};
  values_["EIHstCola"] = {S::U8(1)};
  const std::int32_t stop = StopAngleRaw(g);
  values_["LMPoutputRange"] = {S::U16(1), S::U32(g.angle_step_raw), S::I32(g.start_angle_raw),
                               S::I32(stop)};
  values_["LMDscandatacfg"] = {S::U8(1),
                               S::U8(0),
                               S::U8(g.rssi_bits != 0 ? 1 : 0),
                               S::U8(g.rssi_bits == 16 ? 1 : 0),
                               S::U8(0),
                               S::U8(0),
                               S::U8(0),
                               S::U8(0),
                               S::U8(0),
                               S::U8(0),
                               S::U8(1),
                               S::U16(1)};
  values_["LMPscancfg"] = {S::U32(g.scan_frequency_raw), S::U16(1), S::U32(g.angle_step_raw),
                           S::I32(g.start_angle_raw), S::I32(stop)};
  for (int i = 0; i < spec.fields; ++i) {
    values_[FieldName(i)] = i < spec.structured_fields
                                ? DefaultField(g, i, FieldsOf(spec).rect_ref_offset_deg)
                                : SopasValues{S::U8(0)};
  }
  if (spec.field_sets) {
    values_["ActiveFieldSet"] = {S::U16(1)};
    values_["FieldSetSelectionMethod"] = {S::U8(0)};
  }
  if (spec.echo_filter) values_["FREchoFilter"] = {S::U8(spec.mrs_variables ? 2 : 0)};
  if (spec.mrs_variables) {
    values_["SetActiveApplications"] = {S::U16(2), S::Fixed("FEVL", 4), S::U8(0),
                                        S::Fixed("RANG", 4), S::U8(1)};
    values_["ScanLayerFilter"] = {S::U16(4), S::U8(1), S::U8(1), S::U8(1), S::U8(1)};
    values_["LFPmeanfilter"] = {S::U8(0), S::U16(2), S::U8(0)};
    values_["LFPmedianfilter"] = {S::U8(0), S::U16(3)};
  }
}

void SopasDevice::ApplyRecorded(const DeviceIdentity& identity) {
  for (const auto& [name, bytes] : identity.recorded_reads) {
    const Variable* var = FindVariable(*variables_, name);
    if (var == nullptr || (var->live && name != "ODoprh" && name != "ODpwrc")) {
      ++counters_.recorded_reads_ignored;
      continue;
    }
    SopasValues decoded;
    bool ok = cola::DecodeValues(var->schema, Dialect::kColaB, bytes, &decoded).ok();
    if (!ok && name.rfind("field", 0) == 0) {
      // Fields come in two shapes (the whole layout, or one 0 byte); take whichever decodes.
      ok = cola::DecodeValues(SopasSchema::Compile(kFieldSchema), Dialect::kColaB, bytes, &decoded)
               .ok() ||
           cola::DecodeValues(SopasSchema::Compile("u8"), Dialect::kColaB, bytes, &decoded).ok();
    }
    if (!ok) {
      ++counters_.recorded_reads_ignored;
      continue;
    }
    ++counters_.recorded_reads_used;
    if (name == "ODpwrc") {
      power_on_count_ = static_cast<std::uint32_t>(decoded[0].AsInt());
    } else {
      values_[name] = std::move(decoded);
    }
  }
}

const SopasValues* SopasDevice::Value(std::string_view name) const {
  const auto it = values_.find(name);
  return it == values_.end() ? nullptr : &it->second;
}

Dialect SopasDevice::host_dialect() const {
  const SopasValues* v = Value("EIHstCola");
  return (v != nullptr && !v->empty() && (*v)[0].bits == 0) ? Dialect::kColaA : Dialect::kColaB;
}

std::uint8_t SopasDevice::DeviceState(common::DurationNs now_ns) const {
  return (configuring_ || now_ns < ready_at_ns_) ? 0 : 1;
}

bool SopasDevice::ScanOutputEnabled(common::DurationNs now_ns) const {
  return measuring_ && DeviceState(now_ns) == 1 && ScanSubscribed();
}

std::uint32_t SopasDevice::TickUs(common::DurationNs now_ns) const {
  // A device that has been up for a while: ticks start 10 s after its power-up.
  return static_cast<std::uint32_t>(10'000'000 + (now_ns - boot_ns_) / common::kNsPerUs);
}

void SopasDevice::OnDisconnect() {
  level_ = 0;
  configuring_ = false;
  subscriptions_.clear();
}

void SopasDevice::Reboot(common::DurationNs now_ns) {
  ++counters_.reboots;
  OnDisconnect();
  values_ = saved_;
  measuring_ = true;
  ready_at_ns_ = now_ns;
  boot_ns_ = now_ns;
  ++power_on_count_;
  scans_seen_ = 0;
  std::fill(field_results_.begin(), field_results_.end(), std::uint8_t{0});
  evaluated_once_ = false;
}

// ---- requests

void SopasDevice::Reply(Dialect d, CommandType type, std::string_view name,
                        const SopasValues& values, std::vector<SopasOutput>* out,
                        bool space_when_empty) {
  std::vector<std::uint8_t> payload =
      cola::EncodeSopasTelegram(d, type, name, values, space_when_empty);
  if (payload.empty()) {
    // A stored string CoLa-A cannot carry (written over CoLa-B): refused as a device does.
    Error(d, 17, out);
    return;
  }
  ++counters_.replies;
  out->push_back({d, std::move(payload)});
}

void SopasDevice::Error(Dialect d, std::uint16_t code, std::vector<SopasOutput>* out) {
  ++counters_.sfa;
  ++counters_.sfa_by_code[std::min<std::size_t>(code, counters_.sfa_by_code.size() - 1)];
  out->push_back({d, cola::EncodeSopasError(d, code)});
}

void SopasDevice::HandleRequest(Dialect dialect, std::span<const std::uint8_t> payload,
                                common::DurationNs now_ns, std::vector<SopasOutput>* out) {
  ++counters_.requests;
  if (dialect == Dialect::kColaA) ++counters_.requests_cola_a;
  cola::TelegramHeader header;
  if (cola::ParseSopasTelegram(dialect, payload, &header) != cola::HeaderStatus::kOk) {
    ++counters_.unknown_commands;
    Error(dialect, kUnknownColaCommand, out);
    return;
  }
  switch (header.type) {
    case CommandType::kRead:
      Read(dialect, header.name, header.args, now_ns, out);
      return;
    case CommandType::kWrite:
      Write(dialect, header.name, header.args, out);
      return;
    case CommandType::kMethod:
      Method(dialect, header.name, header.args, now_ns, out);
      return;
    case CommandType::kEvent:
      Event(dialect, header.name, header.args, now_ns, out);
      return;
    default:
      // Answers and event telegrams are never sent to a device.
      ++counters_.unknown_commands;
      Error(dialect, kUnknownColaCommand, out);
      return;
  }
}

bool SopasDevice::LiveValue(std::string_view name, common::DurationNs now_ns,
                            SopasValues* out) const {
  if (name == "SCdevicestate") {
    *out = {S::U8(DeviceState(now_ns))};
  } else if (name == "ODoprh") {
    // Operating hours in 0.1 h: the stored count plus the time this device has been running.
    const auto hours_tenths = static_cast<std::uint32_t>(now_ns / (360 * common::kNsPerS));
    *out = {S::U32(static_cast<std::uint32_t>(values_.at("ODoprh")[0].bits + hours_tenths))};
  } else if (name == "ODpwrc") {
    *out = {S::U32(power_on_count_)};
  } else if (name == "LIDinputstate") {
    const FamilySpec& spec = Spec(family_);
    *out =
        InputStateValues(spec.io_version, spec.idle_input, spec.input_time_block, TickUs(now_ns));
  } else if (name == "LIDoutputstate") {
    const FamilySpec& spec = Spec(family_);
    *out = OutputStateValues(spec.io_version, output_states_, output_counts_,
                             spec.output_time_block, TickUs(now_ns));
  } else if (name == "LFErec") {
    *out = LfeRecValues(FieldsOf(Spec(family_)), values_, field_results_, TickUs(now_ns));
  } else {
    return false;
  }
  return true;
}

void SopasDevice::Read(Dialect d, std::string_view name, std::span<const std::uint8_t> args,
                       common::DurationNs now_ns, std::vector<SopasOutput>* out) {
  const Variable* var = FindVariable(*variables_, name);
  if (var == nullptr) {
    ++counters_.unknown_commands;
    Error(d, kVariableUnknown, out);
    return;
  }
  if (!args.empty()) {
    // A read carries no arguments (SICK's driver sends "sRN field%03d" bare).
    ++counters_.bad_arguments;
    Error(d, cola::SopasErrorCodeOf(cola::ValueStatus::kTrailing), out);
    return;
  }
  SopasValues live;
  if (var->live && LiveValue(name, now_ns, &live)) {
    Reply(d, CommandType::kReadAnswer, name, live, out);
    return;
  }
  const auto it = values_.find(var->name);
  if (it == values_.end()) {  // every stored variable has a default; defensive only
    ++counters_.unknown_commands;
    Error(d, kVariableUnknown, out);
    return;
  }
  Reply(d, CommandType::kReadAnswer, name, it->second, out);
}

std::optional<std::uint16_t> SopasDevice::CheckWrite(std::string_view name,
                                                     const SopasValues& v) const {
  const ScanGeometry& g = options_.identity.geometry;
  const auto in = [](std::int64_t x, std::int64_t lo, std::int64_t hi) {
    return x >= lo && x <= hi;
  };
  if (name == "LMPoutputRange") {
    // One sector (LMS5xx: up to four) inside the device's range, at its resolution (the MRS1104
    // refused a range beyond its field of view with sFA 4: shared capture).
    const std::int64_t n = v[0].AsInt();
    if (!in(n, 1, family_ == DeviceFamily::kLms5xx ? 4 : 1)) return kLocalConditionFailed;
    for (std::int64_t s = 0; s < n; ++s) {
      const auto k = static_cast<std::size_t>(1 + 3 * s);
      const std::int64_t start = v[k + 1].AsInt();
      const std::int64_t stop = v[k + 2].AsInt();
      if (v[k].AsInt() != g.angle_step_raw || start < g.start_angle_raw ||
          stop > StopAngleRaw(g) + g.angle_step_raw / 2 || start > stop) {
        return kLocalConditionFailed;
      }
    }
  } else if (name == "LMDscandatacfg") {
    if (v[0].AsInt() == 0 || v[0].AsInt() > 0x1F || !in(v[2].AsInt(), 0, 3) ||
        !in(v[3].AsInt(), 0, 1) || v[11].AsInt() == 0) {
      return kLocalConditionFailed;
    }
  } else if (name == "EIHstCola" || name == "FieldSetSelectionMethod") {
    if (!in(v[0].AsInt(), 0, 1)) return kLocalConditionFailed;
  } else if (name == "FREchoFilter") {
    if (!in(v[0].AsInt(), 0, 2)) return kLocalConditionFailed;
  } else if (name == "ActiveFieldSet") {
    if (!in(v[0].AsInt(), 1, 16)) return kLocalConditionFailed;
  } else if (name == "SetActiveApplications") {
    for (std::size_t i = 1; i + 1 < v.size(); i += 2) {
      if ((v[i].text != "FEVL" && v[i].text != "RANG") || !in(v[i + 1].AsInt(), 0, 1)) {
        return kLocalConditionFailed;
      }
    }
  } else if (name == "ScanLayerFilter") {
    if (v[0].AsInt() != 4) return kLocalConditionFailed;
    for (std::size_t i = 1; i < v.size(); ++i) {
      if (!in(v[i].AsInt(), 0, 1)) return kLocalConditionFailed;
    }
  } else if (name == "LocationName") {
    if (v[0].text.size() > 16) return kLocalConditionFailed;
  } else if (name == "LFPmeanfilter") {
    if (!in(v[0].AsInt(), 0, 1) || !in(v[1].AsInt(), 2, 100)) return kLocalConditionFailed;
  } else if (name == "LFPmedianfilter") {
    if (!in(v[0].AsInt(), 0, 1) || v[1].AsInt() != 3) return kLocalConditionFailed;
  }
  return std::nullopt;
}

void SopasDevice::Write(Dialect d, std::string_view name, std::span<const std::uint8_t> args,
                        std::vector<SopasOutput>* out) {
  const Variable* var = FindVariable(*variables_, name);
  if (var == nullptr) {
    ++counters_.unknown_commands;
    Error(d, kVariableUnknown, out);
    return;
  }
  if (!var->writable || level_ < kLevelAuthorizedClient) {
    ++counters_.access_denied;
    Error(d, kVariableWriteAccessDenied, out);
    return;
  }
  SopasValues values;
  const cola::ValueResult r = cola::DecodeValues(var->schema, d, args, &values);
  if (!r.ok()) {
    ++counters_.bad_arguments;
    Error(d, cola::SopasErrorCodeOf(r.status), out);
    return;
  }
  if (const auto code = CheckWrite(name, values)) {
    ++counters_.bad_arguments;
    Error(d, *code, out);
    return;
  }
  if (name == "SetActiveApplications") {
    // A write names the applications it switches; the others keep their state.
    SopasValues& stored = values_.at(var->name);
    for (std::size_t i = 1; i + 1 < values.size(); i += 2) {
      for (std::size_t j = 1; j + 1 < stored.size(); j += 2) {
        if (stored[j].text == values[i].text) stored[j + 1] = values[i + 1];
      }
    }
  } else {
    values_[var->name] = std::move(values);
  }
  Reply(d, CommandType::kWriteAnswer, name, {}, out, var->space_after_write_answer);
}

void SopasDevice::Method(Dialect d, std::string_view name, std::span<const std::uint8_t> args,
                         common::DurationNs now_ns, std::vector<SopasOutput>* out) {
  static const SopasSchema kNone = SopasSchema::Compile("");
  static const SopasSchema kLogin = SopasSchema::Compile("u8 u32");
  static const SopasSchema kScanCfg = SopasSchema::Compile("u32 u16[u32 i32 i32]");
  struct MethodSpec {
    const char* name;
    const SopasSchema* schema;
    std::uint8_t level;
  };
  const MethodSpec kMethods[] = {
      {"SetAccessMode", &kLogin, 0},
      {"Run", &kNone, 0},
      {"LMCstartmeas", &kNone, kLevelAuthorizedClient},
      {"LMCstopmeas", &kNone, kLevelAuthorizedClient},
      {"LMCstandby", &kNone, kLevelAuthorizedClient},
      {"mLMPsetscancfg", &kScanCfg, kLevelAuthorizedClient},
      {"mEEwriteall", &kNone, kLevelAuthorizedClient},
      {"mSCreboot", &kNone, kLevelAuthorizedClient},
  };
  const MethodSpec* spec = nullptr;
  for (const MethodSpec& m : kMethods) {
    if (name == m.name) spec = &m;
  }
  if (spec == nullptr) {
    ++counters_.unknown_commands;
    Error(d, kMethodUnknown, out);
    return;
  }
  SopasValues in;
  const cola::ValueResult r = cola::DecodeValues(*spec->schema, d, args, &in);
  if (!r.ok()) {
    ++counters_.bad_arguments;
    Error(d, cola::SopasErrorCodeOf(r.status), out);
    return;
  }
  if (level_ < spec->level) {
    ++counters_.access_denied;
    Error(d, kMethodAccessDenied, out);
    return;
  }
  const std::string_view m = spec->name;
  if (m == "SetAccessMode") {
    const auto level = static_cast<std::uint8_t>(in[0].AsInt());
    const std::uint32_t hash = in[1].bits;
    const bool granted = (level == kLevelMaintenance && hash == kMaintenanceHash) ||
                         (level == kLevelAuthorizedClient && hash == Spec(family_).client_hash) ||
                         (level == kLevelService && hash == kServiceHash);
    if (granted) {
      ++counters_.logins_granted;
      level_ = level;
      configuring_ = true;  // a user level stops the measurement output until Run
    } else {
      ++counters_.logins_refused;
    }
    Reply(d, CommandType::kMethodAnswer, m, {S::U8(granted ? 1 : 0)}, out);
  } else if (m == "Run") {
    if (configuring_) {
      ready_at_ns_ = now_ns + common::SecondsToNs(ready_after_run_s_);
      configuring_ = false;
    }
    level_ = 0;  // Run leaves the user level (SICK's driver logs in again after it)
    Reply(d, CommandType::kMethodAnswer, m, {S::U8(1)}, out);
  } else if (m == "LMCstartmeas" || m == "LMCstopmeas") {
    measuring_ = m == "LMCstartmeas";
    Reply(d, CommandType::kMethodAnswer, m, {S::U8(0)}, out);
  } else if (m == "LMCstandby") {
    measuring_ = false;
    Reply(d, CommandType::kMethodAnswer, m, {S::U8(0)}, out);
  } else if (m == "mLMPsetscancfg") {
    // The scans come from a recording or a simulation at their own rate and resolution: a request
    // for another one is refused with the status a device gives an impossible configuration
    // (1 frequency, 2 resolution, 3 both, 4 sector), and the current configuration is returned.
    const ScanGeometry& g = options_.identity.geometry;
    std::uint8_t status = 0;
    if (in[0].bits != g.scan_frequency_raw) status |= 1;
    const std::int64_t sectors = in[1].AsInt();
    for (std::int64_t s = 0; s < sectors; ++s) {
      const auto k = static_cast<std::size_t>(2 + 3 * s);
      if (in[k].bits != g.angle_step_raw) status |= 2;
    }
    if (status == 0 && sectors != 1) status = 4;
    if (status == 0) {
      const std::int64_t start = in[3].AsInt();
      const std::int64_t stop = in[4].AsInt();
      if (start < g.start_angle_raw || stop > StopAngleRaw(g) + g.angle_step_raw / 2 ||
          start > stop) {
        status = 4;
      } else {
        values_["LMPscancfg"] = {S::U32(g.scan_frequency_raw), S::U16(1), S::U32(g.angle_step_raw),
                                 S::I32(static_cast<std::int32_t>(start)),
                                 S::I32(static_cast<std::int32_t>(stop))};
      }
    }
    SopasValues reply = {S::U8(status)};
    const SopasValues& cfg = values_.at("LMPscancfg");
    reply.insert(reply.end(), cfg.begin(), cfg.end());
    Reply(d, CommandType::kMethodAnswer, m, reply, out);
  } else if (m == "mEEwriteall") {
    saved_ = values_;
    Reply(d, CommandType::kMethodAnswer, m, {S::U8(1)}, out);
  } else if (m == "mSCreboot") {
    Reply(d, CommandType::kMethodAnswer, m, {}, out);
    Reboot(now_ns);
  }
}

void SopasDevice::Event(Dialect d, std::string_view name, std::span<const std::uint8_t> args,
                        common::DurationNs now_ns, std::vector<SopasOutput>* out) {
  const FamilySpec& spec = Spec(family_);
  const bool known = name == "LMDscandata" ||
                     (spec.fields > 0 &&
                      (name == "LFErec" || name == "LIDoutputstate" || name == "LIDinputstate"));
  if (!known) {
    // The MRS1104 answers `sEN InertialMeasurementUnit 1` with sFA 15 (shared capture).
    ++counters_.unknown_commands;
    Error(d, kEventUnknown, out);
    return;
  }
  static const SopasSchema kFlag = SopasSchema::Compile("u8");
  SopasValues in;
  const cola::ValueResult r = cola::DecodeValues(kFlag, d, args, &in);
  if (!r.ok()) {
    ++counters_.bad_arguments;
    Error(d, cola::SopasErrorCodeOf(r.status), out);
    return;
  }
  if (in[0].bits > 1) {
    ++counters_.bad_arguments;
    Error(d, kLocalConditionFailed, out);
    return;
  }
  const bool on = in[0].bits == 1;
  subscriptions_[std::string(name)] = Subscription{on, d};
  Reply(d, CommandType::kEventAnswer, name, {S::U8(on ? 1 : 0)}, out);
  // The LMS511 sent its output state right after the subscription was confirmed (shared capture).
  if (on && name == "LIDoutputstate") SendEvent(name, now_ns, out);
}

void SopasDevice::SendEvent(std::string_view name, common::DurationNs now_ns,
                            std::vector<SopasOutput>* out) {
  const auto it = subscriptions_.find(name);
  if (it == subscriptions_.end() || !it->second.on) return;
  SopasValues values;
  if (!LiveValue(name, now_ns, &values)) return;
  std::vector<std::uint8_t> payload =
      cola::EncodeSopasTelegram(it->second.dialect, CommandType::kEventData, name, values);
  if (payload.empty()) return;
  ++counters_.events_sent;
  out->push_back({it->second.dialect, std::move(payload)});
}

// ---- scans

bool SopasDevice::PrepareScan(cola::ScanTelegram* scan, common::DurationNs now_ns,
                              std::vector<SopasOutput>* events) {
  const FamilySpec& spec = Spec(family_);
  // Field evaluation runs on every scan of the measurement, whatever the output configuration.
  if (spec.fields > 0) {
    std::vector<std::uint8_t> results = EvaluateFields(FieldsOf(spec), values_, *scan);
    if (results != field_results_ || !evaluated_once_) {
      const bool first = !evaluated_once_;
      evaluated_once_ = true;
      field_results_ = std::move(results);
      bool outputs_changed = false;
      for (std::size_t i = 0; i < output_states_.size(); ++i) {
        // Output i follows evaluation field i (outputs beyond the configured fields: unused).
        const std::uint8_t state = i < field_results_.size() && field_results_[i] != 0
                                       ? (field_results_[i] == 2 ? 1 : 0)
                                       : 2;
        if (state == 1 && output_states_[i] != 1) ++output_counts_[i];
        if (state != output_states_[i]) outputs_changed = true;
        output_states_[i] = state;
      }
      if (!first) SendEvent("LFErec", now_ns, events);
      if (outputs_changed && !first) SendEvent("LIDoutputstate", now_ns, events);
    }
  }

  ++scans_seen_;
  const SopasValues& cfg = values_.at("LMDscandatacfg");
  const auto interval = static_cast<std::uint64_t>(std::max<std::int64_t>(1, cfg[11].AsInt()));
  if ((scans_seen_ - 1) % interval != 0) {
    ++counters_.scans_suppressed;
    return false;
  }
  if (spec.mrs_variables) {
    // ScanLayerFilter layers 1-4 by elevation: −2.5°, 0°, +2.5°, +5°; the telegram's layer angle
    // field holds the negated elevation in 1/100° (250, 0, −250, −500).
    const int layer = 2 - scan->layer_angle_raw / 250;
    const SopasValues& filter = values_.at("ScanLayerFilter");
    if (layer >= 1 && static_cast<std::size_t>(layer) < filter.size() &&
        filter[static_cast<std::size_t>(layer)].AsInt() == 0) {
      ++counters_.scans_suppressed;
      return false;
    }
  }

  // Echo channels and remission (LMDscandatacfg bytes 0, 2, 3).
  const std::int64_t echo_mask = cfg[0].AsInt();
  const bool remission = cfg[2].AsInt() != 0;
  const bool rssi16 = cfg[3].AsInt() != 0;
  // Kept channels are compacted in place; one whose width changes moves to the other block
  // (rare: a configuration that asks for the other remission width).
  std::vector<cola::ScanChannel> moved;
  for (auto* block : {&scan->channels16, &scan->channels8}) {
    const bool wide = block == &scan->channels16;
    std::size_t kept = 0;
    for (std::size_t k = 0; k < block->size(); ++k) {
      cola::ScanChannel& ch = (*block)[k];
      const std::string_view n = ch.name_view();
      const bool is_rssi = n.substr(0, 4) == "RSSI";
      if (((echo_mask >> (DigitOf(n) - 1)) & 1) == 0) continue;
      if (is_rssi && !remission) continue;
      if (is_rssi && wide != rssi16) {
        // The configured remission width: 8-bit values scale up by 257, 16-bit ones down.
        for (std::size_t i = 0; i < ch.count; ++i) {
          ch.raw[i] = rssi16 ? static_cast<std::uint16_t>(ch.raw[i] * 257)
                             : static_cast<std::uint16_t>(ch.raw[i] / 257);
        }
        ch.bits = rssi16 ? 16 : 8;
        moved.push_back(ch);
        continue;
      }
      if (kept != k) (*block)[kept] = ch;
      ++kept;
    }
    (void)block->resize(kept);  // shrinking never fails
  }
  for (const cola::ScanChannel& ch : moved) {
    auto& target = ch.bits == 16 ? scan->channels16 : scan->channels8;
    if (cola::ScanChannel* slot = target.emplace_slot()) *slot = ch;
  }

  // Angular crop to the first output range sector.
  const SopasValues& range = values_.at("LMPoutputRange");
  const std::int64_t start = range[2].AsInt();
  const std::int64_t stop = range[3].AsInt();
  for (auto* block : {&scan->channels16, &scan->channels8}) {
    for (cola::ScanChannel& ch : *block) {
      if (ch.angle_step_raw == 0 || ch.count == 0) continue;
      // A beam within half a step of the range counts: the LMS111 reports −44.9997° .. 224.9997°
      // and sends its beams at −45° and 225° (shared capture).
      const std::int64_t step = ch.angle_step_raw;
      const std::int64_t before = start - ch.start_angle_raw - step / 2;
      const std::int64_t first = before <= 0 ? 0 : (before + step - 1) / step;
      const std::int64_t last =
          std::min<std::int64_t>(ch.count - 1, (stop + step / 2 - ch.start_angle_raw) / step);
      if (first == 0 && last == ch.count - 1) continue;
      const std::int64_t n = std::max<std::int64_t>(0, last - first + 1);
      std::memmove(ch.raw.data(), ch.raw.data() + first,
                   static_cast<std::size_t>(n) * sizeof(ch.raw[0]));
      ch.start_angle_raw = static_cast<std::int32_t>(ch.start_angle_raw + first * step);
      ch.count = static_cast<std::uint16_t>(n);
    }
  }

  // Time block (LMDscandatacfg byte 10): a device with an unset clock sends 1970-01-01 plus its
  // time since power-up.
  const bool time = cfg[10].AsInt() != 0;
  if (time && !scan->has_time) {
    const std::uint32_t tick = scan->time_since_startup_us;
    const std::uint32_t seconds = tick / 1'000'000u;
    scan->time = {1970,
                  1,
                  1,
                  static_cast<std::uint8_t>((seconds / 3600) % 24),
                  static_cast<std::uint8_t>((seconds / 60) % 60),
                  static_cast<std::uint8_t>(seconds % 60),
                  tick % 1'000'000u};
  }
  scan->has_time = time;
  return true;
}

SopasOutput SopasDevice::EncodeScan(const cola::ScanTelegram& scan) const {
  const auto it = subscriptions_.find("LMDscandata");
  SopasOutput out;
  out.dialect = it != subscriptions_.end() ? it->second.dialect : Dialect::kColaB;
  if (out.dialect == Dialect::kColaB) {
    out.payload.resize(cola::MaxEncodedSize(scan));
    out.payload.resize(cola::EncodeScanTelegram(scan, out.payload));
    return out;
  }
  SopasValues values;
  cola::ScanTelegramToValues(scan, &values);
  out.payload =
      cola::EncodeSopasTelegram(out.dialect, CommandType::kEventData, "LMDscandata", values);
  return out;
}

bool SopasDevice::ScanSubscribed() const {
  const auto it = subscriptions_.find("LMDscandata");
  return it != subscriptions_.end() && it->second.on;
}

}  // namespace lrfnet::tools
