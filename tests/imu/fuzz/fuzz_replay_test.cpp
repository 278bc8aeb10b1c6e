// Runs the fuzz target briefly under GoogleTest: every corpus file, then seeded random mutations
// of them (byte flips, insertions, deletions, splices). libFuzzer builds (clang) run the same
// target with coverage guidance: see tests/imu/CMakeLists.txt.
#include <gtest/gtest.h>

#include <dirent.h>

#include <cstdint>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "poise/testing/testing.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size);

namespace {

std::vector<std::string> load_corpus() {
  const std::string dir = poise::testing::source_path("tests/imu/fuzz/corpus");
  std::vector<std::string> out;
  if (DIR* d = ::opendir(dir.c_str())) {
    while (dirent* e = ::readdir(d)) {
      if (e->d_name[0] == '.') continue;
      std::ifstream in(dir + "/" + e->d_name, std::ios::binary);
      std::stringstream ss;
      ss << in.rdbuf();
      out.push_back(ss.str());
    }
    ::closedir(d);
  }
  return out;
}

void run(const std::string& s) {
  LLVMFuzzerTestOneInput(reinterpret_cast<const uint8_t*>(s.data()), s.size());
}

TEST(ImuFuzz, CorpusAndSeededMutationsNeverBreakInvariants) {
  const auto corpus = load_corpus();
  ASSERT_GE(corpus.size(), 3u) << "tests/imu/fuzz/corpus is missing";
  for (const auto& c : corpus) run(c);
  const unsigned seed = 1234;
  SCOPED_TRACE("seed " + std::to_string(seed));
  std::mt19937 rng(seed);
  constexpr int kIterations = 100000;
  const std::string interesting = "$*,#\r\n.-+eE0123456789nanifRAWIMU";
  for (int it = 0; it < kIterations; ++it) {
    std::string s = corpus[rng() % corpus.size()];
    const int edits = 1 + static_cast<int>(rng() % 8);
    for (int e = 0; e < edits; ++e) {
      const std::size_t pos = s.empty() ? 0 : rng() % s.size();
      switch (rng() % 6) {
        case 0: if (!s.empty()) s[pos] = static_cast<char>(s[pos] ^ (1 << (rng() % 8))); break;
        case 1: s.insert(pos, 1, interesting[rng() % interesting.size()]); break;
        case 2: if (!s.empty()) s.erase(pos, 1 + rng() % 4); break;
        case 3: s.insert(pos, 1, static_cast<char>(rng() % 256)); break;
        case 4: { const std::string& o = corpus[rng() % corpus.size()];
                  const std::size_t a = o.empty() ? 0 : rng() % o.size();
                  s.insert(pos, o.substr(a, rng() % 64)); break; }
        default: if (s.size() > 4) s.resize(rng() % s.size()); break;
      }
    }
    run(s);
  }
  SUCCEED() << kIterations << " mutated inputs, invariants held";
}

}  // namespace
