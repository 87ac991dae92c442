// Replays the checked-in fuzz corpus (tests/fuzz/corpus/) and a set of mutations of it
// through the same handlers the libFuzzer target runs, with the normal compiler, so every CI
// run covers them. SANDTABLE_WRITE_CORPUS=<dir> writes the seed messages instead.
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>

#include "proto/envelope_stamper.h"
#include "tests/fuzz/message_handlers.h"

namespace sandtable::fuzz {
namespace {

constexpr const char* kCorpusDir = "tests/fuzz/corpus";
constexpr int kMutationsPerSeed = 200;

std::vector<std::string> Seeds() {
  proto::EnvelopeStamper s(3, 77);
  std::vector<wire::Envelope> e;
  e.push_back(s.Next());
  e.back().mutable_hello()->mutable_endpoints()->set_peer_router("tcp://127.0.0.1:40000");
  e.push_back(s.Next());
  e.back().mutable_heartbeat()->set_incarnation(77);
  e.push_back(s.Next());
  e.back().mutable_time_reply()->set_t1_server_receive_ns(5);
  e.push_back(s.Next());
  e.back().mutable_goodbye()->set_reason("bye");
  e.push_back(s.Next());
  e.back().mutable_tracker_pose()->mutable_table_from_sensor()->mutable_rotation()->set_w(1);
  e.push_back(s.Next());
  e.back().mutable_calibration_result()->mutable_projector_model()->set_fx_px(1000);
  e.push_back(s.Next());
  e.back().mutable_blend_share()->mutable_distance_m()->Resize(4000, 0.5f);  // compressed
  std::vector<std::string> out;
  for (auto& env : e) out.push_back(*proto::EncodeEnvelope(env));
  return out;
}

TEST(CorpusReplayTest, CorpusAndMutationsNeverCrash) {
  if (const char* dir = std::getenv("SANDTABLE_WRITE_CORPUS")) {
    int i = 0;
    for (const std::string& seed : Seeds()) {
      std::ofstream(std::string(dir) + "/seed_" + std::to_string(i++), std::ios::binary) << seed;
    }
  }
  std::vector<std::string> inputs = Seeds();
  size_t from_disk = 0;
  if (std::filesystem::is_directory(kCorpusDir)) {
    for (const auto& entry : std::filesystem::directory_iterator(kCorpusDir)) {
      std::ifstream in(entry.path(), std::ios::binary);
      std::stringstream bytes;
      bytes << in.rdbuf();
      inputs.push_back(bytes.str());
      ++from_disk;
    }
  }
  EXPECT_GT(from_disk, 0u) << "run from the project root; corpus at " << kCorpusDir;
  HandlerState state;
  size_t accepted = 0, runs = 0;
  std::mt19937 rng(1234);
  for (const std::string& input : inputs) {
    accepted += HandleUntrustedMessage(reinterpret_cast<const uint8_t*>(input.data()), input.size(),
                                       &state);
    ++runs;
    for (int m = 0; m < kMutationsPerSeed && !input.empty(); ++m) {
      std::string mutated = input;
      switch (rng() % 4) {
        case 0:
          mutated[rng() % mutated.size()] ^= static_cast<char>(1 + rng() % 255);
          break;
        case 1:
          mutated.resize(rng() % mutated.size());
          break;  // truncate
        case 2:
          mutated.insert(rng() % mutated.size(), 1, static_cast<char>(rng()));
          break;
        default:
          mutated += mutated.substr(0, rng() % mutated.size());
          break;
      }
      accepted += HandleUntrustedMessage(reinterpret_cast<const uint8_t*>(mutated.data()),
                                         mutated.size(), &state);
      ++runs;
    }
  }
  std::printf("[ MEASURED ] %zu inputs, %zu accepted, %s\n", runs, accepted,
              state.counters.ToString().c_str());
  EXPECT_GT(state.counters.total_rejected(), 0u);
  EXPECT_GT(accepted, 0u);
}

}  // namespace
}  // namespace sandtable::fuzz
