#pragma once
// A simulated sensor as a tools::ScanSource, so `lrfnet sim --serve` runs one tools::Emulator per
// sensor.
//
// All sensors of a scenario share one scenario clock (`now_s`: scenario seconds since serving
// started, already scaled by the emulator's speed), as real devices keep measuring whether or not a
// client listens: a client that connects at scenario time t gets the scan transmitted last before t
// at once, then each later scan at its own transmission time. The emulator schedules scans by the
// gaps this source returns; after a resynchronisation (first scan, a late client, a reconnect) the
// next gap is shortened or lengthened by how far the resynchronised scan was from `now_s`, so every
// sensor's scans leave at their scenario times and the sensors stay consistent with each other.
// With the emulator's loop option the scenario repeats (pass p adds p × duration_s).
//
// Thread-safety: none (the emulator calls it on its io_context thread). The Simulator is shared
// read-only between the sources of one scenario.

#include <functional>
#include <memory>

#include "tools/scan_source.h"
#include "tools/sim/simulator.h"

namespace lrfnet::sim {

std::unique_ptr<tools::ScanSource> MakeSimScanSource(std::shared_ptr<const Simulator> sim,
                                                     std::size_t sensor,
                                                     std::function<double()> now_s);

}  // namespace lrfnet::sim
