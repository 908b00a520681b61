#pragma once
// Seeds for foxglove_fuzz (what a Foxglove client sends the live view), written by
// make_fuzz_corpus.

#include <string>

namespace lrfnet::fuzz {

// What Foxglove sends (subscribe, unsubscribe, parameter and service requests, client publishing)
// and hostile messages (not JSON, wrong types, negative and huge ids, deep nesting, binary).
void WriteFoxgloveSeeds(const std::string& dir);

}  // namespace lrfnet::fuzz
