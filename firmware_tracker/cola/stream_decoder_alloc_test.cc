// Counts heap allocations while StreamDecoder decodes thousands of scan frames: there must be none
// after construction. The global allocation functions are replaced for this whole binary
// (lrfnet_alloc_counter), hence its own executable.

#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>
#include <memory>
#include <new>
#include <vector>

#include "firmware_tracker/cola/cola_test_util.h"
#include "firmware_tracker/cola/stream_decoder.h"
#include "tests/support/alloc_counter.h"
#include "tests/support/test_data.h"

namespace lrfnet::cola {
namespace {

class CountingScope {
 public:
  CountingScope() { ::lrfnet::testing::StartCountingAllocations(); }
  ~CountingScope() { Stop(); }
  std::size_t allocations() { return Stop(); }

 private:
  std::size_t Stop() {
    if (!stopped_) allocations_ = ::lrfnet::testing::StopCountingAllocations();
    stopped_ = true;
    return allocations_;
  }
  bool stopped_ = false;
  std::size_t allocations_ = 0;
};

struct Tally : TelegramListener {
  std::uint64_t scans = 0;
  std::uint64_t points = 0;
  std::uint64_t others = 0;
  std::uint64_t errors = 0;
  void OnScan(const ScanTelegram& scan, common::UtcNs) override {
    ++scans;
    points += scan.channels16.empty() ? 0 : scan.channels16[0].count;
  }
  void OnTelegram(const TelegramHeader&, std::span<const std::uint8_t>, common::UtcNs) override {
    ++others;
  }
  void OnError(const char*, common::UtcNs) override { ++errors; }
};

TEST(AllocationCounterTest, CountsAnAllocation) {
  // The hook itself works: without this the zero below would prove nothing.
  CountingScope scope;
  auto* volatile p = new int(3);
  delete p;
  EXPECT_GE(scope.allocations(), 1u);
}

TEST(StreamDecoderAllocationTest, NoHeapAllocationWhileDecodingThousandsOfScans) {
  // Input made before counting: synthetic frames (every block, multi-echo, 8-bit channels) and,
  // when the shared data is present, the real sensor streams, all fed in TCP-sized chunks.
  std::vector<std::vector<std::uint8_t>> streams;
  std::vector<std::uint8_t> synthetic;
  for (std::uint16_t i = 0; i < 200; ++i) {
    const auto frame = test::EncodeScanFrame(*test::MakeSimpleScan(811, i));
    synthetic.insert(synthetic.end(), frame.begin(), frame.end());
  }
  const auto full = test::EncodeScanFrame(*test::MakeFullScan(1141));
  for (int i = 0; i < 50; ++i) synthetic.insert(synthetic.end(), full.begin(), full.end());
  synthetic.insert(synthetic.end(), {'n', 'o', 'i', 's', 'e', 2, 2, 2, 2, 0xFF, 0, 0, 0});
  streams.push_back(std::move(synthetic));
  for (const auto& name : testing::SickCaptureNames()) {
    if (const auto path = testing::SharedFile("data/sick/" + name)) {
      streams.push_back(test::SensorStreamFromCapture(testing::ReadFileBytes(*path)));
    }
  }

  auto decoder = std::make_unique<StreamDecoder>();
  Tally tally;
  std::size_t allocations = 0;
  {
    CountingScope scope;
    for (int round = 0; round < 8; ++round) {
      for (const auto& stream : streams) {
        std::span<const std::uint8_t> rest(stream);
        while (!rest.empty()) {
          const std::size_t n = std::min<std::size_t>(rest.size(), 1448);
          decoder->Feed(rest.first(n), 0, tally);
          rest = rest.subspan(n);
        }
        decoder->Reset();
      }
    }
    allocations = scope.allocations();
  }
  EXPECT_EQ(allocations, 0u);
  EXPECT_GT(decoder->counters().scans, 1000u);
  EXPECT_GE(tally.scans, 8u * 250u);
  EXPECT_GT(tally.points, 0u);
  EXPECT_GT(tally.errors, 0u);  // the noise at the end of the synthetic stream
}

}  // namespace
}  // namespace lrfnet::cola
