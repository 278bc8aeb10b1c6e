// Runs a fuzz target (test suite POISE_FUZZ_SUITE) under GoogleTest in every build: each file of its
// committed seed corpus (POISE_FUZZ_CORPUS), then seeded random mutations of them (byte flips,
// insertions, deletions, splices). With clang the same target also runs coverage-guided under
// libFuzzer + ASan/UBSan (tests/fuzz/CMakeLists.txt).
#include "poise/testing/testing.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size);

namespace {

std::vector<std::string> load_corpus() {
  std::vector<std::string> out;
  for (const auto& e : std::filesystem::directory_iterator(POISE_FUZZ_CORPUS)) {
    std::ifstream in(e.path(), std::ios::binary);
    std::stringstream ss;
    ss << in.rdbuf();
    out.push_back(ss.str());
  }
  return out;
}

void run(const std::string& s) { LLVMFuzzerTestOneInput(reinterpret_cast<const uint8_t*>(s.data()), s.size()); }

TEST(POISE_FUZZ_SUITE, GivenTheSeedCorpusAndSeededMutationsWhenFedToTheTargetThenNoInvariantBreaks) {
  const auto corpus = load_corpus();
  ASSERT_GE(corpus.size(), 3u) << POISE_FUZZ_CORPUS << " is missing";
  for (const auto& c : corpus) run(c);
  const unsigned seed = 19;
  SCOPED_TRACE("seed " + std::to_string(seed));
  std::mt19937 rng(seed);
  constexpr int kIterations = 3000;
  for (int it = 0; it < kIterations; ++it) {
    std::string s = corpus[rng() % corpus.size()];
    const int edits = 1 + static_cast<int>(rng() % 8);
    for (int e = 0; e < edits; ++e) {
      const size_t pos = s.empty() ? 0 : rng() % s.size();
      switch (rng() % 4) {
        case 0:
          if (!s.empty()) s[pos] = static_cast<char>(rng());
          break;
        case 1:
          s.insert(pos, 1, static_cast<char>(rng()));
          break;
        case 2:
          if (!s.empty()) s.erase(pos, 1 + rng() % 8);
          break;
        default: {
          const std::string& other = corpus[rng() % corpus.size()];
          if (!other.empty()) s.insert(pos, other.substr(rng() % other.size(), 1 + rng() % 64));
        }
      }
    }
    run(s);
  }
}

}  // namespace
