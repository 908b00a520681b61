#include "tests/fuzz/sopas_seeds.h"

#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>
#include <vector>

#include "firmware_tracker/cola/sopas_framer.h"
#include "firmware_tracker/cola/sopas_value.h"

namespace lrfnet::fuzz {
namespace {

using cola::CommandType;
using cola::Dialect;
using cola::SopasValues;
using S = cola::SopasScalar;
using Bytes = std::vector<std::uint8_t>;

struct Request {
  CommandType type;
  std::string name;
  SopasValues args;
};

void Append(Bytes* out, Dialect d, const Request& r) {
  const Bytes f = cola::EncodeSopasFrame(d, cola::EncodeSopasTelegram(d, r.type, r.name, r.args));
  out->insert(out->end(), f.begin(), f.end());
}

void Write(const std::filesystem::path& path, std::uint8_t first, const Bytes& body) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.put(static_cast<char>(first));
  out.write(reinterpret_cast<const char*>(body.data()), static_cast<std::streamsize>(body.size()));
}

// What sick_scan_xd 3.9 sends to each family (its logs against the emulator), shortened where it
// repeats itself (field000..029 / 047, the SCdevicestate polls).
std::vector<Request> DriverDialogue(int family) {
  const bool lms = family <= 1;
  const bool tim7 = family == 3 || family == 4;
  const bool mrs = family == 5;
  const std::uint32_t hash = family == 4 ? 0x6FD62C05 : 0xF4724744;
  std::vector<Request> r = {
      {CommandType::kRead, "SCdevicestate", {}},
      {CommandType::kMethod, "SetAccessMode", {S::U8(3), S::U32(hash)}},
      {CommandType::kWrite, "EIHstCola", {S::U8(1)}},
  };
  if (mrs) {
    r.push_back({CommandType::kMethod, "LMCstopmeas", {}});
    r.push_back({CommandType::kRead, "SetActiveApplications", {}});
    r.push_back({CommandType::kRead, "DeviceIdent", {}});
    r.push_back(
        {CommandType::kWrite, "SetActiveApplications", {S::U16(1), S::Fixed("FEVL", 4), S::U8(0)}});
    r.push_back({CommandType::kRead, "SerialNumber", {}});
  }
  for (const char* n : {"FirmwareVersion", "SCdevicestate", "ODoprh", "ODpwrc", "LocationName"}) {
    r.push_back({CommandType::kRead, n, {}});
  }
  if (mrs) {
    r.push_back({CommandType::kWrite,
                 "ScanLayerFilter",
                 {S::U16(4), S::U8(1), S::U8(0), S::U8(1), S::U8(1)}});
    r.push_back({CommandType::kMethod, "Run", {}});
    r.push_back({CommandType::kMethod, "SetAccessMode", {S::U8(3), S::U32(hash)}});
  }
  r.push_back({CommandType::kRead, "LMPoutputRange", {}});
  r.push_back({CommandType::kWrite,
               "LMPoutputRange",
               {S::U16(1), S::U32(5000), S::I32(-449997), S::I32(2249997)}});
  if (lms || tim7) {
    for (const char* n : {"field000", "field001", "field010", "field030"}) {
      r.push_back({CommandType::kRead, n, {}});
    }
    r.push_back({CommandType::kRead, "LIDinputstate", {}});
  }
  r.push_back({CommandType::kWrite,
               "LMDscandatacfg",
               {S::U8(1), S::U8(0), S::U8(1), S::U8(1), S::U8(0), S::U8(0), S::U8(0), S::U8(0),
                S::U8(0), S::U8(0), S::U8(1), S::U16(2)}});
  r.push_back({CommandType::kRead, "LMDscandatacfg", {}});
  if (lms) {
    r.push_back({CommandType::kMethod,
                 "mLMPsetscancfg",
                 {S::U32(5000), S::U16(1), S::U32(5000), S::I32(-450000), S::I32(2250000)}});
    r.push_back({CommandType::kRead, "LMPscancfg", {}});
  }
  if (mrs || family == 1) r.push_back({CommandType::kWrite, "FREchoFilter", {S::U8(2)}});
  if (lms || tim7) {
    for (const char* e : {"LFErec", "LIDoutputstate", "LIDinputstate"}) {
      r.push_back({CommandType::kEvent, e, {S::U8(1)}});
    }
  }
  if (tim7) r.push_back({CommandType::kRead, "LFErec", {}});
  r.push_back({CommandType::kMethod, "LMCstartmeas", {}});
  r.push_back({CommandType::kMethod, "Run", {}});
  r.push_back({CommandType::kRead, "SCdevicestate", {}});
  r.push_back({CommandType::kEvent, "LMDscandata", {S::U8(1)}});
  if (mrs) r.push_back({CommandType::kEvent, "InertialMeasurementUnit", {S::U8(1)}});
  r.push_back({CommandType::kMethod, "SetAccessMode", {S::U8(3), S::U32(hash)}});
  r.push_back({CommandType::kMethod, "LMCstopmeas", {}});
  r.push_back({CommandType::kMethod, "mSCreboot", {}});
  return r;
}

Bytes Text(std::string_view s) { return Bytes(s.begin(), s.end()); }

}  // namespace

void WriteSopasSeeds(const std::string& dir) {
  std::filesystem::create_directories(dir);
  const std::filesystem::path d(dir);
  for (int family = 0; family < 6; ++family) {
    for (const Dialect dialect : {Dialect::kColaB, Dialect::kColaA}) {
      Bytes body;
      for (const Request& r : DriverDialogue(family)) Append(&body, dialect, r);
      const std::string name =
          "dialogue_" + std::to_string(family) + (dialect == Dialect::kColaA ? "_a" : "_b");
      // First byte: family in the low bits, the read size above.
      Write(d / name,
            static_cast<std::uint8_t>(family | (dialect == Dialect::kColaA ? 0x30 : 0x08)), body);
    }
  }
  // Both dialects on one stream, as the driver's probe sends them.
  Bytes mixed;
  Append(&mixed, Dialect::kColaB, {CommandType::kRead, "SCdevicestate", {}});
  Append(&mixed, Dialect::kColaA, {CommandType::kRead, "SCdevicestate", {}});
  Append(&mixed, Dialect::kColaA,
         {CommandType::kMethod, "SetAccessMode", {S::U8(3), S::U32(0xF4724744)}});
  Append(&mixed, Dialect::kColaB, {CommandType::kWrite, "EIHstCola", {S::U8(0)}});
  Write(d / "mixed", 0x13, mixed);
  // Hostile: unknown types and names, wrong arguments, CoLa-A numbers, cut and empty frames.
  Bytes hostile =
      Text("garbage\x02sXY Foo\x03\x02\x03\x02sRN\x03\x02sMN SetAccessMode 3 F47247XX\x03");
  const std::string_view more[] = {"\x02sMN SetAccessMode 300 F4724744\x03",
                                   "\x02sWN LMPoutputRange FFFF 1\x03",
                                   "\x02sWN LocationName FFFF abc\x03",
                                   "\x02sEN LMDscandata 1 1\x03",
                                   "\x02sRA SCdevicestate 1\x03",
                                   "\x02sWN LMDscandatacfg 1 0 1 1 0 0 0 0 0 0 1 0\x03",
                                   "\x02sRN SCdevicestate\x02sRN Cut"};
  for (const std::string_view m : more) {
    const Bytes b = Text(m);
    hostile.insert(hostile.end(), b.begin(), b.end());
  }
  Append(&hostile, Dialect::kColaB, {CommandType::kWrite, "LMPoutputRange", {S::U16(65535)}});
  Append(&hostile, Dialect::kColaB,
         {CommandType::kMethod, "mLMPsetscancfg", {S::U32(1), S::U16(9)}});
  const Bytes huge = {0x02, 0x02, 0x02, 0x02, 0x7F, 0xFF, 0xFF, 0xFF, 's'};
  hostile.insert(hostile.end(), huge.begin(), huge.end());
  Write(d / "hostile", 0x02, hostile);
}

}  // namespace lrfnet::fuzz
