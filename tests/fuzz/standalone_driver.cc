// Runs a libFuzzer target without libFuzzer: every seed file in the given folders, then a fixed number of
// deterministic mutations of them (bit flips, byte changes, insertions, deletions, truncations, splices).
// This keeps every fuzz target exercised in the ordinary build and test run; coverage-guided fuzzing runs
// the same targets under libFuzzer (scripts/test.sh).
//
//   <target> [--mutations N] [--seed S] DIR_OR_FILE...

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size);

namespace {

struct Rng {
  std::uint64_t s;
  std::uint64_t Next() {  // xorshift64*
    s ^= s >> 12;
    s ^= s << 25;
    s ^= s >> 27;
    return s * 0x2545F4914F6CDD1Dull;
  }
  std::size_t Below(std::size_t n) { return n == 0 ? 0 : static_cast<std::size_t>(Next() % n); }
};

void Mutate(std::vector<std::uint8_t>& d, const std::vector<std::vector<std::uint8_t>>& seeds, Rng& rng) {
  const int steps = 1 + static_cast<int>(rng.Below(4));
  for (int k = 0; k < steps; ++k) {
    switch (rng.Below(7)) {
      case 0:  // flip a bit
        if (!d.empty()) d[rng.Below(d.size())] ^= static_cast<std::uint8_t>(1u << rng.Below(8));
        break;
      case 1:  // set a byte to an interesting value
        if (!d.empty()) {
          static constexpr std::uint8_t kInteresting[] = {0x00, 0x01, 0x02, 0x7f, 0x80, 0xff, 0x20};
          d[rng.Below(d.size())] = kInteresting[rng.Below(sizeof(kInteresting))];
        }
        break;
      case 2:  // insert random bytes
        {
          const std::size_t at = rng.Below(d.size() + 1), n = 1 + rng.Below(8);
          std::vector<std::uint8_t> ins(n);
          for (auto& b : ins) b = static_cast<std::uint8_t>(rng.Next());
          d.insert(d.begin() + static_cast<std::ptrdiff_t>(at), ins.begin(), ins.end());
        }
        break;
      case 3:  // delete a range
        if (!d.empty()) {
          const std::size_t at = rng.Below(d.size());
          const std::size_t n = 1 + rng.Below(std::min<std::size_t>(64, d.size() - at));
          d.erase(d.begin() + static_cast<std::ptrdiff_t>(at), d.begin() + static_cast<std::ptrdiff_t>(at + n));
        }
        break;
      case 4:  // truncate
        d.resize(rng.Below(d.size() + 1));
        break;
      case 5:  // overwrite 4 bytes with a big-endian extreme (lengths, counts)
        if (d.size() >= 4) {
          const std::size_t at = rng.Below(d.size() - 3);
          const std::uint32_t v = rng.Below(2) ? 0xFFFFFFFFu : static_cast<std::uint32_t>(rng.Next());
          for (int i = 0; i < 4; ++i) d[at + static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(v >> (24 - 8 * i));
        }
        break;
      default:  // splice with another seed
        if (!seeds.empty()) {
          const auto& o = seeds[rng.Below(seeds.size())];
          const std::size_t cut = rng.Below(d.size() + 1), from = rng.Below(o.size() + 1);
          d.resize(cut);
          d.insert(d.end(), o.begin() + static_cast<std::ptrdiff_t>(from), o.end());
        }
        break;
    }
  }
}

std::vector<std::uint8_t> ReadAll(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), {}};
}

}  // namespace

int main(int argc, char** argv) {
  long mutations = 0;
  std::uint64_t seed = 0x5eed;
  std::vector<std::vector<std::uint8_t>> seeds;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--mutations" && i + 1 < argc) {
      mutations = std::strtol(argv[++i], nullptr, 10);
    } else if (a == "--seed" && i + 1 < argc) {
      seed = std::strtoull(argv[++i], nullptr, 10);
    } else if (std::filesystem::is_directory(a)) {
      std::vector<std::filesystem::path> files;
      for (const auto& e : std::filesystem::directory_iterator(a)) {
        if (e.is_regular_file()) files.push_back(e.path());
      }
      std::sort(files.begin(), files.end());  // deterministic order
      for (const auto& f : files) seeds.push_back(ReadAll(f));
    } else if (std::filesystem::is_regular_file(a)) {
      seeds.push_back(ReadAll(a));
    } else {
      std::fprintf(stderr, "%s: no such seed file or folder: %s\n", argv[0], a.c_str());
      return 2;
    }
  }
  if (seeds.empty()) {
    std::fprintf(stderr, "%s: no seeds given\n", argv[0]);
    return 2;
  }
  for (const auto& s : seeds) LLVMFuzzerTestOneInput(s.data(), s.size());
  Rng rng{seed};
  std::vector<std::uint8_t> buf;
  for (long m = 0; m < mutations; ++m) {
    buf = seeds[rng.Below(seeds.size())];
    Mutate(buf, seeds, rng);
    LLVMFuzzerTestOneInput(buf.data(), buf.size());
  }
  std::printf("%s: %zu seeds and %ld mutations ran without a crash\n", argv[0], seeds.size(), mutations);
  return 0;
}
