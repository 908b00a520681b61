// Fuzz target for the device side of both SOPAS dialects: the bytes a client sends go through the
// SopasFramer (in chunks whose size the first byte picks) into a SopasDevice of the family the
// first byte picks, as the emulator feeds them; after every request a scan goes through the
// device's output configuration when it is subscribed. The arguments of every frame are also
// decoded by a few schemas in both dialects. Properties checked with __builtin_trap:
//   - every request gets exactly one reply first, in its own dialect, that parses back and frames;
//   - every event telegram and every scan the device sends frames and decodes;
//   - decoded values encode and decode to the same values (and CoLa-B to the same bytes);
//   - requests == replies + sFA in the device's counters.

#include <array>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <memory>
#include <span>
#include <vector>

#include "firmware_tracker/cola/scan_telegram.h"
#include "firmware_tracker/cola/sopas_framer.h"
#include "firmware_tracker/cola/sopas_value.h"
#include "tools/sopas_device.h"

namespace {

using lrfnet::cola::Dialect;
namespace cola = lrfnet::cola;
namespace tools = lrfnet::tools;

void Check(bool ok) {
  if (!ok) __builtin_trap();
}

constexpr const char* kNames[] = {"LMS111-10100",   "LMS511-10100",    "TiM561-2050101",
                                  "TiM781-2174101", "TiM781S-2174104", "MRS1xxxx"};

const tools::SopasDeviceOptions& Options(std::size_t family) {
  static const auto* options = [] {
    auto* o = new std::array<tools::SopasDeviceOptions, 6>();
    for (std::size_t i = 0; i < 6; ++i) {
      (*o)[i].family = *tools::FamilyFromDeviceName(kNames[i]);
      (*o)[i].identity.name = kNames[i];
      (*o)[i].ready_after_run_s = 0.0;
    }
    return o;
  }();
  return (*options)[family];
}

// A scan of the family's typical geometry, made once per family (DIST1 + RSSI1 + time block).
const cola::ScanTelegram& BaseScan(const tools::SopasDevice& device) {
  static std::array<std::unique_ptr<cola::ScanTelegram>, 6> scans;
  auto& s = scans[static_cast<std::size_t>(device.family())];
  if (!s) {
    s = std::make_unique<cola::ScanTelegram>();
    const cola::SopasValues* range = device.Value("LMPoutputRange");
    const auto step = static_cast<std::uint16_t>((*range)[1].bits);
    const auto start = static_cast<std::int32_t>((*range)[2].AsInt());
    const auto stop = static_cast<std::int32_t>((*range)[3].AsInt());
    const auto count = static_cast<std::uint16_t>((stop - start) / step + 1);
    for (const char* name : {"DIST1", "RSSI1"}) {
      cola::ScanChannel* ch = s->channels16.emplace_slot();
      std::memcpy(ch->name.data(), name, 5);
      ch->start_angle_raw = start;
      ch->angle_step_raw = step;
      ch->count = count;
      for (std::size_t i = 0; i < count; ++i) ch->raw[i] = static_cast<std::uint16_t>(300 + i * 7);
    }
    s->scan_frequency_raw = 2500;
    s->has_time = true;
    s->time.year = 1970;
  }
  return *s;
}

void CheckTelegram(const tools::SopasOutput& o) {
  Check(!cola::EncodeSopasFrame(o.dialect, o.payload).empty());
  cola::TelegramHeader h;
  Check(cola::ParseSopasTelegram(o.dialect, o.payload, &h) == cola::HeaderStatus::kOk);
}

void CheckValueRoundTrip(std::span<const std::uint8_t> args) {
  static const cola::SopasSchema kSchemas[] = {
      cola::SopasSchema::Compile("u16[u32 i32 i32]"),
      cola::SopasSchema::Compile("str str"),
      cola::SopasSchema::Compile("u16[c4 u8]"),
      cola::SopasSchema::Compile("u8 u8 u8 u8 u8 u8 u8 u8 u8 u8 u8 u16"),
      cola::SopasSchema::Compile(tools::kFieldSchema),
      cola::SopasSchema::Compile(tools::kLfeRecSchema),
      cola::SopasSchema::Compile("f32 i8 i16 sstr c5"),
  };
  for (const auto& schema : kSchemas) {
    for (const Dialect d : {Dialect::kColaB, Dialect::kColaA}) {
      cola::SopasValues v;
      if (!cola::DecodeValues(schema, d, args, &v).ok()) continue;
      std::vector<std::uint8_t> again;
      if (!cola::AppendValues(v, d, &again)) continue;  // text CoLa-A cannot carry
      cola::SopasValues v2;
      Check(cola::DecodeValues(schema, d, again, &v2).ok());
      Check(v2 == v);
      if (d == Dialect::kColaB)
        Check(again.size() == args.size() &&
              std::memcmp(again.data(), args.data(), args.size()) == 0);
    }
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  const std::size_t family = data[0] % 6;
  const std::size_t chunk = 1 + (data[0] >> 3);
  const std::span<const std::uint8_t> bytes(data + 1, size - 1);

  tools::SopasDevice device(Options(family));
  cola::SopasFramerOptions framer_options;
  framer_options.max_payload_bytes = 4096;
  cola::SopasFramer framer(framer_options);
  auto scan = std::make_unique<cola::ScanTelegram>();
  lrfnet::common::DurationNs now = 0;
  std::vector<tools::SopasOutput> out;
  int scans_prepared = 0;
  for (std::size_t i = 0; i < bytes.size(); i += chunk) {
    framer.FeedAll(
        bytes.subspan(i, std::min(chunk, bytes.size() - i)),
        [&](Dialect dialect, std::span<const std::uint8_t> payload) {
          now += 1'000'000;
          out.clear();
          device.HandleRequest(dialect, payload, now, &out);
          Check(!out.empty());
          Check(out[0].dialect == dialect);
          cola::TelegramHeader reply;
          Check(cola::ParseSopasTelegram(dialect, out[0].payload, &reply) ==
                cola::HeaderStatus::kOk);
          Check(reply.type == cola::CommandType::kReadAnswer ||
                reply.type == cola::CommandType::kWriteAnswer ||
                reply.type == cola::CommandType::kMethodAnswer ||
                reply.type == cola::CommandType::kEventAnswer ||
                reply.type == cola::CommandType::kError);
          for (const auto& o : out) CheckTelegram(o);
          cola::TelegramHeader request;
          if (cola::ParseSopasTelegram(dialect, payload, &request) == cola::HeaderStatus::kOk) {
            CheckValueRoundTrip(request.args);
          }
          // A scan is ~100 kB: the output path runs for the first few requests after the
          // subscription only (enough to cover every configuration the input wrote before).
          if (device.ScanSubscribed() && scans_prepared < 3) {
            ++scans_prepared;
            *scan = BaseScan(device);
            std::vector<tools::SopasOutput> events;
            if (device.PrepareScan(scan.get(), now, &events)) {
              const tools::SopasOutput encoded = device.EncodeScan(*scan);
              Check(!cola::EncodeSopasFrame(encoded.dialect, encoded.payload).empty());
              if (encoded.dialect == Dialect::kColaB) {
                static auto* decoded = new cola::ScanTelegram();
                Check(cola::DecodeScanTelegram(encoded.payload, decoded).ok);
              } else {
                cola::SopasValues v;
                Check(cola::DecodeValues(cola::ScanTelegramSchema(), Dialect::kColaA,
                                         std::span<const std::uint8_t>(encoded.payload).subspan(16),
                                         &v)
                          .ok());
              }
            }
            for (const auto& e : events) CheckTelegram(e);
          }
        },
        [](const char*) {});
  }
  const auto& c = device.counters();
  Check(c.requests == c.replies + c.sfa);
  return 0;
}
