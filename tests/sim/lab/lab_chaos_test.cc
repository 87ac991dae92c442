// sandtable-lab chaos: the seeded fault plan, a run's report read into an outcome, and the
// subcommand end to end on sandtable-3 (one real site run with every fault: a late joiner on a
// lossy link, a node killed, one stopped, the coordinator killed and restarted, annotations
// painted throughout and checked).
#include "sim/lab/lab_chaos.h"

#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <set>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "tests/coordinator/membership/child_process.h"

namespace sandtable::sim {
namespace {

TEST(ChaosPlanTest, SeededDistinctUnitsInsideTheHold) {
  for (uint64_t seed = 1; seed <= 20; ++seed) {
    const ChaosPlan a = MakeChaosPlan(seed, 3), b = MakeChaosPlan(seed, 3);
    EXPECT_EQ(a.RunArgs(), b.RunArgs()) << "seed " << seed;
    const std::set<int> units = {a.join_unit, a.kill_unit, a.stall_unit};
    EXPECT_EQ(units.size(), 3u);
    for (int u : units) EXPECT_TRUE(u >= 0 && u < 3);
    // In order, none overlapping the next, all inside the hold.
    EXPECT_LT(a.kill_at_s, a.stall_at_s);
    EXPECT_LT(a.stall_at_s + a.stall_for_s, a.coordinator_at_s);
    EXPECT_LT(a.coordinator_at_s + 2.0, a.hold_s);
    EXPECT_GT(a.drop_share, 0.0);
    EXPECT_GT(a.corrupt_share, 0.0);
    EXPECT_LT(a.drop_share + a.corrupt_share, 0.1);
  }
  EXPECT_NE(MakeChaosPlan(1, 3).RunArgs(), MakeChaosPlan(2, 3).RunArgs());
  const ChaosPlan big = MakeChaosPlan(3, 16);
  EXPECT_TRUE(big.join_unit >= 0 && big.join_unit < 16);
}

TEST(ChaosReportTest, ReadsFaultsAnnotationsLinksAndCrashes) {
  nlohmann::json report = {
      {"status", "ok"},
      {"calibration", {{"join", {{"joined", true}, {"wall_s", 12.5}}}}},
      {"live", {{"join_reblend_ms", 300.0}}},
      {"chaos",
       {{"processes_crashed", 0},
        {"annotations",
         {{"points_acknowledged", 400}, {"points_present", 400}, {"points_lost", 0}}},
        {"faults",
         {{{"fault", "SIGKILL node-1"},
           {"detected_ms", 50.0},
           {"recovered_ms", 190.0},
           {"frames_lost_max", 3}},
          {{"fault", "SIGKILL coordinator, restart on the same database"},
           {"detected_ms", 45.0},
           {"recovered_ms", 120.0},
           {"frames_lost_max", 0}}}},
        {"links",
         {{"node-2", {{"faults_dropped", 10}, {"faults_corrupted", 3}, {"rejected", 1}}},
          {"node-0", {{"faults_dropped", 0}, {"faults_corrupted", 0}, {"rejected", 2}}}}}}}};
  const std::string path = (std::filesystem::temp_directory_path() /
                            ("sandtable_chaos_report_" + std::to_string(getpid()) + ".json"))
                               .string();
  std::ofstream(path) << report.dump();
  ChaosOutcome o;
  ReadChaosRun(path, &o);
  EXPECT_TRUE(o.ran);
  EXPECT_TRUE(o.passed()) << o.error;
  EXPECT_EQ(o.acknowledged, 400);
  EXPECT_EQ(o.lost, 0);
  EXPECT_DOUBLE_EQ(o.kill_detected_ms, 50.0);
  EXPECT_DOUBLE_EQ(o.kill_reblend_ms, 190.0);
  EXPECT_DOUBLE_EQ(o.coordinator_ready_ms, 45.0);
  EXPECT_DOUBLE_EQ(o.annotations_back_ms, 120.0);
  EXPECT_DOUBLE_EQ(o.join_ms, 12500.0);
  EXPECT_EQ(o.frames_lost_max, 3);
  EXPECT_EQ(o.dropped, 10);
  EXPECT_EQ(o.corrupted, 3);
  EXPECT_EQ(o.rejected, 3);

  // One acknowledged point missing, a crash, a failed join: not passed, and it says why.
  report["chaos"]["annotations"]["points_lost"] = 1;
  report["chaos"]["processes_crashed"] = 1;
  report["calibration"]["join"] = {{"joined", false}, {"error", "unit 2: no answer"}};
  std::ofstream(path) << report.dump();
  ChaosOutcome bad;
  ReadChaosRun(path, &bad);
  std::filesystem::remove(path);
  EXPECT_FALSE(bad.passed());
  EXPECT_EQ(bad.lost, 1);
  EXPECT_EQ(bad.crashed, 1);
  EXPECT_NE(bad.error.find("no answer"), std::string::npos) << bad.error;

  // A run that completed and failed its verdict says which (not an empty phase and reason).
  nlohmann::json verdict = {{"status", "failed"},
                            {"reasons",
                             {{{"what", "registration over its bar"},
                               {"detail", "3.445 mm rms > 1.000 mm (--max-rms-mm)"}}}}};
  std::ofstream(path) << verdict.dump();
  ChaosOutcome judged;
  ReadChaosRun(path, &judged);
  std::filesystem::remove(path);
  EXPECT_NE(judged.error.find("failed its verdict: registration over its bar: 3.445 mm"),
            std::string::npos)
      << judged.error;
}

TEST(LabChaosTest, Sandtable3SeedOneLosesNoAnnotationAndCrashesNothing) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("sandtable_chaos_" + std::to_string(getpid()));
  std::filesystem::remove_all(dir);
  testing::ChildProcess lab({SANDTABLE_LAB_BIN, "chaos", "--runs", "1", "--seed", "1", "--out",
                             dir.string(), "--samples", "2000"});
  while (lab.ReadLine(std::chrono::milliseconds(800000))) {
  }
  EXPECT_EQ(lab.Wait(), 0);
  std::ifstream csv(dir / "chaos.csv");
  std::string header, row;
  std::getline(csv, header);
  std::getline(csv, row);
  // seed 1, passed, 0 crashed.
  EXPECT_EQ(row.rfind("1,1,0,", 0), 0u) << row;
  for (const char* file : {"chaos.md", "chaos.html", "runs/seed-1/report.md"}) {
    EXPECT_TRUE(std::filesystem::exists(dir / file)) << file;
  }
  if (!::testing::Test::HasFailure() && !getenv("SANDTABLE_KEEP_LAB_DIR")) {
    std::filesystem::remove_all(dir);
  }
}

}  // namespace
}  // namespace sandtable::sim
