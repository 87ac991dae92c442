// Replays the checked-in glTF fuzz corpus (tests/fuzz/gltf_corpus/) and mutations of it through
// the loader the libFuzzer target fuzz_gltf_loader runs, with the normal compiler, so every CI
// run covers them: each input is loaded or refused, within a bounded time, without a crash.
#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "common/scene/gltf_loader.h"

namespace sandtable {
namespace {

constexpr const char* kCorpusDir = "tests/fuzz/gltf_corpus";
constexpr int kMutationsPerSeed = 300;
constexpr double kMaxLoadTime_s = 5.0;  // one input, loaded or refused

std::vector<std::pair<std::string, std::string>> Corpus() {
  std::vector<std::pair<std::string, std::string>> out;
  if (!std::filesystem::is_directory(kCorpusDir)) return out;
  for (const auto& entry : std::filesystem::directory_iterator(kCorpusDir)) {
    if (!entry.is_regular_file()) continue;
    std::ifstream in(entry.path(), std::ios::binary);
    std::stringstream bytes;
    bytes << in.rdbuf();
    out.emplace_back(entry.path().filename().string(), bytes.str());
  }
  return out;
}

double Seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

TEST(GltfCorpusReplayTest, SeedsLoad) {
  const auto corpus = Corpus();
  ASSERT_GE(corpus.size(), 3u) << "run from the project root; corpus at " << kCorpusDir;
  for (const auto& [name, bytes] : corpus) {
    Expected<Scene> scene = LoadGltfSceneFromBytes(bytes, name);
    ASSERT_TRUE(scene.ok()) << name << ": " << scene.status().ToString();
    EXPECT_GT(scene->NumTriangles(), 0) << name;
  }
}

TEST(GltfCorpusReplayTest, MutationsNeverCrashOrHang) {
  std::mt19937 rng(4321);
  size_t loaded = 0, refused = 0;
  for (const auto& [name, seed] : Corpus()) {
    for (int m = 0; m < kMutationsPerSeed; ++m) {
      std::string mutated = seed;
      const int edits = 1 + static_cast<int>(rng() % 4);
      for (int e = 0; e < edits && !mutated.empty(); ++e) {
        const size_t at = rng() % mutated.size();
        switch (rng() % 5) {
          case 0:
            mutated[at] = static_cast<char>(mutated[at] ^ (1 + rng() % 255));
            break;
          case 1:
            mutated.resize(at);  // truncate
            break;
          case 2:
            mutated.insert(at, 1, static_cast<char>(rng()));
            break;
          case 3:  // a digit made huge: counts and offsets near 2^64
            if (mutated[at] >= '0' && mutated[at] <= '9') mutated.insert(at, "1844674407370955");
            break;
          default:
            mutated.erase(at, 1 + rng() % 16);
            break;
        }
      }
      const auto start = std::chrono::steady_clock::now();
      Expected<Scene> scene = LoadGltfSceneFromBytes(mutated, name);
      EXPECT_LT(Seconds(start), kMaxLoadTime_s) << name << " mutation " << m;
      if (scene.ok()) {
        ++loaded;
      } else {
        ++refused;
        EXPECT_NE(scene.status().message().find(name), std::string::npos)
            << scene.status().message();
      }
    }
  }
  EXPECT_GT(refused, 0u);
  RecordProperty("loaded", static_cast<int>(loaded));
  RecordProperty("refused", static_cast<int>(refused));
}

}  // namespace
}  // namespace sandtable
