#pragma once
// Seeds for sopas_fuzz (the device side of both SOPAS dialects), written by make_fuzz_corpus.

#include <string>

namespace lrfnet::fuzz {

// The start-up dialogue SICK's driver sends to each device family, in CoLa-B and in CoLa-A (the
// first byte picks the family and the read size), and hostile inputs: garbage, cut and oversized
// frames, unknown commands and types, wrong argument counts and CoLa-A numbers, both dialects
// mixed on one stream.
void WriteSopasSeeds(const std::string& dir);

}  // namespace lrfnet::fuzz
