#include "tests/fuzz/foxglove_seeds.h"

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace lrfnet::fuzz {

void WriteFoxgloveSeeds(const std::string& dir) {
  std::filesystem::create_directories(dir);
  // First byte: 0 text, 1 binary.
  const std::vector<std::string> seeds = {
      std::string("\0", 1) +
          R"({"op":"subscribe","subscriptions":[{"id":0,"channelId":1},{"id":1,"channelId":2}]})",
      std::string("\0", 1) + R"({"op":"unsubscribe","subscriptionIds":[0,1]})",
      std::string("\0", 1) + R"({"op":"getParameters","parameterNames":[],"id":"x"})",
      std::string("\0", 1) +
          R"({"op":"advertise","channels":[{"id":1,"topic":"/x","encoding":"json","schemaName":"a"}]})",
      std::string("\0", 1) +
          R"({"op":"subscribe","subscriptions":[{"id":-1,"channelId":4294967296}]})",
      std::string("\0", 1) + R"({"op":"subscribe","subscriptions":{"id":1}})",
      std::string("\0", 1) + R"({"op":5})",
      std::string("\0", 1) + R"([[[[[[[[[[[[[[[[[[[[[[[[[[[[[[]]]]]]]]]]]]]]]]]]]]]]]]]]]]])",
      std::string("\0", 1) + "not json at all \xff\xfe",
      std::string("\x01\x01\x01\x00\x00\x00payload", 13),
      std::string("\x01\x02\x00\x00\x00\x00", 6),
  };
  for (std::size_t i = 0; i < seeds.size(); ++i) {
    std::ofstream(std::filesystem::path(dir) / ("seed_" + std::to_string(i)), std::ios::binary)
        << seeds[i];
  }
}

}  // namespace lrfnet::fuzz
