#pragma once
// Field evaluation of LMS1xx / LMS5xx / TiM7xx devices (pure): the layout of `sRA fieldNNN`, the
// fields an emulated device has by default, the evaluation of a scan against them, and the
// values of the telegrams that report it (LFErec) and the I/O state (LIDoutputstate,
// LIDinputstate).
//
// Field layout, from the LMS111 and LMS511 replies in the shared captures (every recorded field
// decodes by kFieldSchema and encodes back to the same bytes) and sick_scan_xd's field parser:
//   distance scale f32, distance offset f32 (mm), angle scale u32, angle offset i32 (1/10000°),
//   field type u8 (1 rectangle, 2 segmented, 3 dynamic), field number u8 (0: not configured),
//   segmented flag u16 [+ count u16 × (angle index u16, start distance u16, stop distance u16)],
//   rectangle flag u16 [+ reference angle i32, reference distance u16, rotation i32 (1/10000°),
//   width u32, length u32 (mm)], radial flag u16 (always 0),
//   dynamic flag u16 [+ the rectangle's five values, maximum speed i16, maximum length u32],
//   u16 (1 in every recorded field), field name (flex string), u16 (0 in every recorded field).
// Unused field slots beyond the device's field count answer one byte 0.
//
// Geometry (as sick_scan_xd draws the fields, x forward = the 90° beam, y left): a segmented
// field is the polygon from the origin through its points at their stop distances, a point at
// angle index k lying at k × angle scale + angle offset; a rectangle has its base corner at the
// reference point and extends `length` along its rotation and `width` to its right.

#include <cstdint>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include "firmware_tracker/cola/scan_telegram.h"
#include "firmware_tracker/cola/sopas_value.h"
#include "tools/scan_source.h"

namespace lrfnet::tools {

using SopasValueMap = std::map<std::string, cola::SopasValues, std::less<>>;

inline constexpr std::string_view kFieldSchema =
    "f32 f32 u32 i32 u8 u8 u16?[u16[u16 u16 u16]] u16?[i32 u16 i32 u32 u32] u16"
    " u16?[i32 u16 i32 u32 u32 i16 u32] u16 str u16";
// LIDinputstate: version u16, system counter u32, 4 input states u8, time flag u16 [+ time].
inline constexpr std::string_view kInputStateSchema = "u16 u32 4*[u8] u16?[u16 u8 u8 u8 u8 u8 u32]";
// LIDoutputstate: version u16, system counter u32, per output (state u8: 0 off, 1 on, 2 unused;
// activation count u32), time flag u16 [+ time] (sick_scan_xd's parser; 11 outputs on the
// LMS111, 14 on the LMS511, 5 on the TiM781S).
std::string OutputStateSchema(int outputs);
// LFErec: field count u16, per field: version u16, field number u8, system counter u32, the
// field's distance scale f32 and offset f32, angle scale u32 and offset i32, result u8 (0 not
// evaluated, 1 free, 2 infringed), 3 × u16, time flag u16 [+ time].
inline constexpr std::string_view kLfeRecSchema =
    "u16[u16 u8 u32 f32 f32 u32 i32 u8 u16 u16 u16 u16?[u16 u8 u8 u8 u8 u8 u32]]";

struct FieldFamily {
  int fields = 0;                  // fieldNNN slots
  bool field_sets = false;         // TiM7xx: LFErec reports the active set's three fields
  double rect_ref_offset_deg = 0;  // LMS1xx: rectangle reference angles count from −45°
};

// Field `index` of a fresh device: field000 is segmented (#1, 1 m ahead over the front 90°),
// field001 a rectangle (#2, 1 m wide and 2 m long, 1 m ahead), the others not configured.
cola::SopasValues DefaultField(const ScanGeometry& geometry, int index, double rect_ref_offset_deg);

// Per field slot: 0 not configured, 1 free, 2 infringed (an echo of DIST1 inside the field).
std::vector<std::uint8_t> EvaluateFields(const FieldFamily& family, const SopasValueMap& values,
                                         const cola::ScanTelegram& scan);

// The live telegrams' values at device tick `tick_us` (clock unset: 1970-01-01 plus the tick).
cola::SopasValues InputStateValues(std::uint16_t version, std::uint8_t input_state, bool time_block,
                                   std::uint32_t tick_us);
cola::SopasValues OutputStateValues(std::uint16_t version, const std::vector<std::uint8_t>& states,
                                    const std::vector<std::uint32_t>& counts, bool time_block,
                                    std::uint32_t tick_us);
cola::SopasValues LfeRecValues(const FieldFamily& family, const SopasValueMap& values,
                               const std::vector<std::uint8_t>& results, std::uint32_t tick_us);

}  // namespace lrfnet::tools
