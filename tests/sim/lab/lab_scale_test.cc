// sandtable-lab scale: a run's report read into a point, the messages-per-node spread, and the
// subcommand end to end on grid-2 (one real site run).
#include "sim/lab/lab_scale.h"

#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "tests/coordinator/membership/child_process.h"

namespace sandtable::sim {
namespace {

ScalePoint Ok(int nodes, double messages) {
  ScalePoint p;
  p.nodes = nodes;
  p.ok = true;
  p.messages_per_node = messages;
  return p;
}

TEST(ScaleSpreadTest, LargestOverSmallestFromTheGivenSize) {
  std::vector<ScalePoint> points = {Ok(2, 100), Ok(4, 300), Ok(8, 450), Ok(16, 400)};
  EXPECT_DOUBLE_EQ(MessagesSpread(points, 4), 1.5);
  EXPECT_DOUBLE_EQ(MessagesSpread(points, 2), 4.5);
  points[2].ok = false;  // a failed size counts for nothing
  EXPECT_DOUBLE_EQ(MessagesSpread(points, 4), 400.0 / 300.0);
  EXPECT_EQ(MessagesSpread({Ok(8, 10)}, 4), 0.0);  // one point: no spread
}

TEST(ScaleReportTest, ReadsCalibrationProcessesAndReblend) {
  const std::filesystem::path path =
      std::filesystem::temp_directory_path() /
      ("sandtable_scale_report_" + std::to_string(getpid()) + ".json");
  nlohmann::json report = {{"total_s", 40.5},
                           {"calibration",
                            {{"rms_mm", 0.5},
                             {"device_time_s", 3.1},
                             {"compute_time_s", 4.2},
                             {"messages_per_node", 500.0},
                             {"bytes_per_node", 2048.0},
                             {"colours", 3},
                             {"self_calibration_report", {{"wall_s", 20.0}}}}},
                           {"processes",
                            {{{"role", "world"}, {"cpu_s", 10.0}, {"max_rss_mb", 300.0}},
                             {{"role", "coordinator"}, {"cpu_s", 0.5}, {"max_rss_mb", 20.0}},
                             {{"role", "node"}, {"cpu_s", 6.0}, {"max_rss_mb", 150.0}},
                             {{"role", "node"}, {"cpu_s", 8.0}, {"max_rss_mb", 170.0}}}},
                           {"live", {{"reblend_ms_max", 120.0}}}};
  std::ofstream(path) << report.dump();
  ScalePoint p;
  ReadScaleRun(path.string(), &p);
  std::filesystem::remove(path);
  EXPECT_TRUE(p.ok) << p.error;
  EXPECT_EQ(p.colours, 3);
  EXPECT_DOUBLE_EQ(p.messages_per_node, 500.0);
  EXPECT_DOUBLE_EQ(p.coordinator_cpu_s, 0.5);
  EXPECT_DOUBLE_EQ(p.world_cpu_s, 10.0);
  EXPECT_DOUBLE_EQ(p.node_cpu_s_mean, 7.0);
  EXPECT_DOUBLE_EQ(p.node_rss_mb_max, 170.0);
  EXPECT_DOUBLE_EQ(p.reblend_ms, 120.0);
  EXPECT_DOUBLE_EQ(p.round_wall_s, 20.0);

  report["calibration"]["failures"] = {{"1", "projector 1: no camera sees it"}};
  std::ofstream(path) << report.dump();
  ScalePoint failed;
  ReadScaleRun(path.string(), &failed);
  std::filesystem::remove(path);
  EXPECT_FALSE(failed.ok);
  EXPECT_NE(failed.error.find("no camera sees it"), std::string::npos) << failed.error;

  ScalePoint missing;
  ReadScaleRun((path.string() + ".absent"), &missing);
  EXPECT_FALSE(missing.ok);
  EXPECT_NE(missing.error.find("no report"), std::string::npos);
}

TEST(LabScaleTest, Grid2GivesTheCsvThePlotsAndTheReport) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("sandtable_scale_" + std::to_string(getpid()));
  std::filesystem::remove_all(dir);
  testing::ChildProcess lab(
      {SANDTABLE_LAB_BIN, "scale", "--nodes", "2", "--out", dir.string(), "--samples", "2000"});
  while (lab.ReadLine(std::chrono::milliseconds(400000))) {
  }
  EXPECT_EQ(lab.Wait(), 0);
  std::ifstream csv(dir / "scale.csv");
  std::string header, row;
  std::getline(csv, header);
  std::getline(csv, row);
  EXPECT_EQ(row.rfind("2,1,", 0), 0u) << row;
  for (const char* file : {"scale_per_node.png", "scale_time.png", "scale.md", "scale.html"}) {
    EXPECT_GT(std::filesystem::exists(dir / file) ? std::filesystem::file_size(dir / file) : 0u,
              1000u)
        << file;
  }
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace sandtable::sim
