// Denial-of-service limits that the sandtable-coordinator program enforces at start
// (docs/reliability.md): a --timeline file past kMaxTimelineTracks exits 2 naming the limit;
// --status on a CURVE site needs a token (exit 2).
#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <string>

#include "tests/coordinator/membership/child_process.h"

namespace sandtable {
namespace {

using std::chrono::milliseconds;

constexpr milliseconds kStartDeadline{15000};

TEST(DosProgramTest, TimelineOverTheTrackLimitExitsTwoNamingIt) {
  const std::filesystem::path path = std::filesystem::temp_directory_path() /
                                     ("dos_timeline_" + std::to_string(getpid()) + ".csv");
  {
    std::ofstream out(path);
    out << "track_id,t_s,x_m,y_m,z_m\n";
    for (int track = 0; track < 1025; ++track) out << track << ",0,0,0,0\n";
  }
  std::string output;
  const int code = testing::RunProgram(SANDTABLE_COORDINATOR_BIN, {"--timeline", path.string()},
                                       kStartDeadline, &output);
  std::filesystem::remove(path);
  EXPECT_EQ(code, 2) << output;
  EXPECT_NE(output.find("kMaxTimelineTracks"), std::string::npos) << output;
}

TEST(DosProgramTest, StatusOnACurveSiteNeedsAToken) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("dos_curve_" + std::to_string(getpid()));
  std::filesystem::create_directories(dir);
  const std::string keys = (dir / "site.key").string();
  std::string output;
  ASSERT_EQ(testing::RunProgram(SANDTABLE_COORDINATOR_BIN, {"--generate-curve-keys", keys},
                                kStartDeadline, &output),
            0)
      << output;
  const int code = testing::RunProgram(SANDTABLE_COORDINATOR_BIN,
                                       {"--curve-keys", keys, "--status", "127.0.0.1:0"},
                                       kStartDeadline, &output);
  EXPECT_EQ(code, 2) << output;
  EXPECT_NE(output.find("--status-token-file"), std::string::npos) << output;

  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace sandtable
