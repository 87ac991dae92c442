// Replays a libFuzzer target's checked-in corpus (tests/fuzz/<name>_corpus/, the directory in
// SANDTABLE_FUZZ_CORPUS) and seeded mutations of it through the target's own
// LLVMFuzzerTestOneInput, built with the normal compiler, so every CI run covers what the fuzzer
// found interesting: each input returns (is accepted or refused) within a bounded time, without
// a crash. Linked with every target of sandtable_add_fuzz_target (tests/fuzz/CMakeLists.txt).
#include <chrono>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size);

namespace sandtable {
namespace {

constexpr int kMinSeeds = 2;
constexpr int kMutationsPerSeed = 200;
constexpr double kMaxInputTime_s = 5.0;  // one input, accepted or refused (a hang otherwise)

std::vector<std::pair<std::string, std::string>> Corpus() {
  std::vector<std::pair<std::string, std::string>> out;
  if (!std::filesystem::is_directory(SANDTABLE_FUZZ_CORPUS)) return out;
  for (const auto& entry : std::filesystem::directory_iterator(SANDTABLE_FUZZ_CORPUS)) {
    if (!entry.is_regular_file()) continue;
    std::ifstream in(entry.path(), std::ios::binary);
    std::stringstream bytes;
    bytes << in.rdbuf();
    out.emplace_back(entry.path().filename().string(), bytes.str());
  }
  return out;
}

double RunOne(const std::string& bytes) {
  const auto start = std::chrono::steady_clock::now();
  LLVMFuzzerTestOneInput(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size());
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// One to four edits of the kinds that found bugs before: flipped bytes, cuts, inserted bytes,
// numbers made huge or negative, deleted runs, a duplicated run.
std::string Mutate(const std::string& seed, std::mt19937& rng) {
  std::string m = seed;
  const int edits = 1 + static_cast<int>(rng() % 4);
  for (int e = 0; e < edits && !m.empty(); ++e) {
    const size_t at = rng() % m.size();
    switch (rng() % 7) {
      case 0:
        m[at] = static_cast<char>(m[at] ^ (1 + rng() % 255));
        break;
      case 1:
        m.resize(at);
        break;
      case 2:
        m.insert(at, 1, static_cast<char>(rng()));
        break;
      case 3:
        if (m[at] >= '0' && m[at] <= '9') m.insert(at, "18446744073709551");
        break;
      case 4:
        if (m[at] >= '0' && m[at] <= '9') m.insert(at, "-");
        break;
      case 5:
        m.insert(at, m.substr(at, 1 + rng() % 64));
        break;
      default:
        m.erase(at, 1 + rng() % 16);
        break;
    }
  }
  return m;
}

TEST(FuzzReplayTest, SeedsRun) {
  const auto corpus = Corpus();
  ASSERT_GE(corpus.size(), static_cast<size_t>(kMinSeeds))
      << "run from the project root; corpus at " << SANDTABLE_FUZZ_CORPUS;
  for (const auto& [name, bytes] : corpus) {
    EXPECT_LT(RunOne(bytes), kMaxInputTime_s) << name;
  }
}

TEST(FuzzReplayTest, MutationsNeverCrashOrHang) {
  std::mt19937 rng(20261201);
  const auto corpus = Corpus();
  ASSERT_FALSE(corpus.empty());
  for (const auto& [name, seed] : corpus) {
    for (int i = 0; i < kMutationsPerSeed; ++i) {
      EXPECT_LT(RunOne(Mutate(seed, rng)), kMaxInputTime_s) << name << " mutation " << i;
    }
  }
  // Degenerate inputs every parser must refuse quietly.
  for (const std::string& bytes : {std::string(), std::string(1, '\0'), std::string(4096, '{'),
                                   std::string(4096, '['), std::string(65536, '9')}) {
    EXPECT_LT(RunOne(bytes), kMaxInputTime_s);
  }
}

}  // namespace
}  // namespace sandtable
