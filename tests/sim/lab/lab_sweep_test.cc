// sandtable-lab sweep: the Pareto front marking and the CSV in-process; the subcommand as a
// real program over two configurations (each a full site run, `--render off`).
#include "sim/lab/lab_sweep.h"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

#include <gtest/gtest.h>

#include "tests/common/cli/help_text.h"
#include "tests/coordinator/membership/child_process.h"

namespace sandtable::sim {
namespace {

SweepPoint Point(const std::string& name, double rms_mm, double device_s, double compute_s) {
  SweepPoint p;
  p.config.name = name;
  p.config.knob = name == "defaults" ? "" : "k";
  p.ok = true;
  p.rms_mm = rms_mm;
  p.device_time_s = device_s;
  p.compute_s = compute_s;
  return p;
}

TEST(SweepFrontTest, APointBeatenOnBothAxesIsOffTheFront) {
  std::vector<SweepPoint> points = {Point("defaults", 0.12, 2.7, 3.4),
                                    Point("fast", 0.14, 2.3, 3.6),   // faster projection
                                    Point("worse", 0.20, 2.8, 3.5),  // beaten by defaults
                                    Point("slowest", 0.11, 3.5, 5.0)};
  SweepPoint failed = Point("failed", 0.01, 0.1, 0.1);
  failed.ok = false;  // never on a front, never beats anyone
  points.push_back(failed);
  MarkParetoFronts(points);
  EXPECT_TRUE(points[0].front_device);
  EXPECT_TRUE(points[0].front_compute);
  EXPECT_TRUE(points[1].front_device);
  EXPECT_FALSE(points[1].front_compute);  // defaults: less error and less compute
  EXPECT_FALSE(points[2].front_device);
  EXPECT_FALSE(points[2].front_compute);
  EXPECT_TRUE(points[3].front_device);
  EXPECT_TRUE(points[3].front_compute);
  EXPECT_FALSE(points[4].front_device);
  EXPECT_FALSE(points[4].front_compute);
}

TEST(SweepFrontTest, EqualPointsStayOnTheFront) {
  std::vector<SweepPoint> points = {Point("a", 0.1, 1.0, 1.0), Point("b", 0.1, 1.0, 1.0)};
  MarkParetoFronts(points);
  EXPECT_TRUE(points[0].front_device && points[1].front_device);
}

TEST(SweepCsvTest, OneLinePerPointAndErrorsQuoted) {
  std::vector<SweepPoint> points = {Point("defaults", 0.125, 2.76, 3.36)};
  SweepPoint failed = Point("phase-steps=4", 0, 0, 0);
  failed.ok = false;
  failed.error = "units failed: {\"2\":\"no camera, sees it\"}";
  points.push_back(failed);
  const std::string csv = SweepCsv(points);
  std::istringstream lines(csv);
  std::string header, first, second, extra;
  std::getline(lines, header);
  std::getline(lines, first);
  std::getline(lines, second);
  EXPECT_FALSE(std::getline(lines, extra));
  EXPECT_EQ(header.rfind("config,knob,value,ok,", 0), 0u) << header;
  EXPECT_EQ(first.rfind("defaults,,,1,", 0), 0u) << first;
  EXPECT_NE(first.find(",0.1250,"), std::string::npos) << first;
  // The error's commas and quotes cannot break the columns.
  EXPECT_EQ(std::count(second.begin(), second.end(), ','),
            std::count(header.begin(), header.end(), ','))
      << second;
}

TEST(SweepConfigTest, DefaultsFirstThenOneKnobAtATime) {
  const std::vector<SweepConfig> configs = DefaultSweep();
  ASSERT_GE(configs.size(), 5u);
  EXPECT_EQ(configs[0].name, "defaults");
  EXPECT_TRUE(configs[0].node_args.empty());
  EXPECT_FALSE(configs[0].blend);
  int blend_defaults = 0, blend_knobs = 0;
  for (size_t i = 1; i < configs.size(); ++i) {
    if (configs[i].knob.empty()) {  // the shipped blend, shown and blended
      EXPECT_TRUE(configs[i].blend) << configs[i].name;
      EXPECT_TRUE(configs[i].node_args.empty());
      ++blend_defaults;
      continue;
    }
    // One flag, to the nodes or to `sandtable-lab run`.
    const std::vector<std::string>& args =
        configs[i].lab_args.empty() ? configs[i].node_args : configs[i].lab_args;
    EXPECT_EQ(configs[i].node_args.size() + configs[i].lab_args.size(), 1u) << configs[i].name;
    ASSERT_EQ(args.size(), 1u) << configs[i].name;
    EXPECT_EQ(args[0], "--" + configs[i].knob + "=" + configs[i].value);
    blend_knobs += configs[i].blend;
    // Blend knobs are the node's blend flags.
    EXPECT_EQ(configs[i].blend, configs[i].knob.rfind("blend-", 0) == 0) << configs[i].name;
  }
  EXPECT_EQ(blend_defaults, 1);
  EXPECT_GE(blend_knobs, 2);
}

// The flags `program args` lists in its --help.
std::set<std::string> FlagsOf(const std::string& program, const std::vector<std::string>& args) {
  std::string help;
  EXPECT_EQ(testing::RunProgram(program, args, std::chrono::milliseconds(20000), &help), 0)
      << program << ": " << help;
  return testing::FlagsInHelp(help);
}

// Every knob the sweep turns is a flag of sandtable-node, or of `sandtable-lab run` where the
// lab passes it on itself (a renamed flag, or one the lab also gives, would otherwise only
// show as a failed configuration in a 10-minute sweep).
TEST(SweepConfigTest, EveryKnobIsAFlagOfTheNodeOrTheLab) {
  const std::set<std::string> node_flags = FlagsOf(SANDTABLE_NODE_BIN, {"--help"});
  const std::set<std::string> lab_flags = FlagsOf(SANDTABLE_LAB_BIN, {"run", "--help"});
  int knobs = 0;
  for (const SweepConfig& c : DefaultSweep()) {
    if (c.knob.empty()) continue;
    ++knobs;
    const std::string flag = "--" + c.knob;
    if (c.lab_args.empty()) {
      EXPECT_TRUE(node_flags.count(flag)) << c.name << " is no flag of sandtable-node";
      // Not one the lab gives its nodes already (CLI11 refuses it twice).
      EXPECT_FALSE(lab_flags.count(flag)) << c.name << " is the lab's own";
    } else {
      EXPECT_TRUE(lab_flags.count(flag)) << c.name << " is no flag of sandtable-lab run";
    }
  }
  EXPECT_GE(knobs, 10);
}

// Blend points have a front of their own (walls' p99 against cast time), apart from the
// calibration's: a blend run never beats a calibration run, nor the other way round.
TEST(SweepFrontTest, BlendPointsHaveTheirOwnFront) {
  std::vector<SweepPoint> points = {Point("defaults", 0.12, 2.7, 3.4)};
  auto blend = [](const std::string& name, double walls_p99, double cast_ms) {
    SweepPoint p = Point(name, 0.01, 0.1, 0.1);  // better calibration figures than any
    p.config.blend = true;
    p.walls_p99_pct = walls_p99;
    p.cast_ms = cast_ms;
    return p;
  };
  points.push_back(blend("blend", 3.8, 700));
  points.push_back(blend("blend-step-px=4", 3.9, 1200));  // beaten by the shipped blend
  points.push_back(blend("blend-step-px=16", 3.6, 650));  // beats it
  MarkParetoFronts(points);
  EXPECT_TRUE(points[0].front_device && points[0].front_compute);
  EXPECT_FALSE(points[0].front_blend);
  EXPECT_FALSE(points[1].front_blend);
  EXPECT_FALSE(points[2].front_blend);
  EXPECT_TRUE(points[3].front_blend);
  for (size_t i = 1; i < points.size(); ++i) {
    EXPECT_FALSE(points[i].front_device || points[i].front_compute) << points[i].config.name;
  }
  const std::string csv = SweepCsv(points);
  EXPECT_NE(csv.find("blend-step-px=16,k,,1,"), std::string::npos) << csv;
  EXPECT_NE(csv.find(",3.600,"), std::string::npos) << csv;
}

// The subcommand end to end: two configurations, CSV, both plots, sweep.md and sweep.html.
TEST(LabSweepTest, TwoConfigurationsGiveTheCsvThePlotsAndTheReport) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("sandtable_sweep_" + std::to_string(getpid()));
  std::filesystem::remove_all(dir);
  testing::ChildProcess lab({SANDTABLE_LAB_BIN, "sweep", "--out", dir.string(), "--samples", "3000",
                             "--only", "defaults", "--only", "bundle-iterations=3"});
  while (lab.ReadLine(std::chrono::milliseconds(400000))) {
  }
  EXPECT_EQ(lab.Wait(), 0);
  std::ifstream csv(dir / "sweep.csv");
  std::string line;
  int rows = 0;
  std::getline(csv, line);
  while (std::getline(csv, line)) {
    ++rows;
    EXPECT_NE(line.find(",1,"), std::string::npos) << "not ok: " << line;
  }
  EXPECT_EQ(rows, 2);
  for (const char* file : {"sweep_projection.png", "sweep_compute.png", "sweep.md", "sweep.html"}) {
    EXPECT_GT(std::filesystem::exists(dir / file) ? std::filesystem::file_size(dir / file) : 0u,
              1000u)
        << file;
  }
  std::ifstream md(dir / "sweep.md");
  const std::string text((std::istreambuf_iterator<char>(md)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("The shipped defaults are"), std::string::npos);
  EXPECT_NE(text.find("`bundle-iterations=3`"), std::string::npos);
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace sandtable::sim
