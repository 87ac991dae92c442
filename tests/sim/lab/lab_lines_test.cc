// LabLines (sim/lab/lab_lines.h): each kind of report line lands where the lab reads it, only
// from the role that prints it.
#include "sim/lab/lab_lines.h"

#include <chrono>
#include <set>

#include <gtest/gtest.h>

namespace sandtable::sim {
namespace {

using Clock = std::chrono::steady_clock;

TEST(LabLinesTest, EachKindFromItsRole) {
  LabLines lines;
  const Clock::time_point t0 = Clock::now();
  lines.Take("world", report::WorldReady{"tcp://127.0.0.1:1", false}, t0);
  lines.Take("coordinator", report::CoordinatorReady{"tcp://127.0.0.1:2", "tcp://127.0.0.1:3", ""},
             t0);
  lines.Take("node", report::NodeReady{3, "tcp://127.0.0.1:4"}, t0);
  report::Calibrated calibrated;
  calibrated.id = 3;
  calibrated.round = 7;
  lines.Take("node", calibrated, t0 + std::chrono::seconds(1));
  lines.Take("node", report::CalibrationFailed{4, ""}, t0);
  lines.Take("node", report::RenderPattern{3, "grid"}, t0);
  lines.Take("node", report::RenderUnavailable{5, "no GL"}, t0);
  report::BlendShown blended;
  blended.id = 3;
  blended.cause = "field";
  report::BlendShown reblend = blended;
  reblend.reblend = true;
  reblend.cause = "left";
  reblend.peer = 4;
  lines.Take("node", blended, t0 + std::chrono::seconds(2));
  lines.Take("node", reblend, t0 + std::chrono::seconds(3));
  lines.Take("node", report::RoundProgress{1, 1, 4, "pre-pass", "pre-pass white 0", {0}, 2.5},
             t0 + std::chrono::seconds(4));
  EXPECT_EQ(lines.world_endpoint, "tcp://127.0.0.1:1");
  EXPECT_EQ(lines.coordinator_requests, "tcp://127.0.0.1:2");
  EXPECT_EQ(lines.coordinator_events, "tcp://127.0.0.1:3");
  EXPECT_EQ(lines.nodes_ready, std::set<NodeId>{3});
  ASSERT_TRUE(lines.calibrated.count(3));
  EXPECT_EQ(lines.calibrated.at(3).round, 7u);
  EXPECT_EQ(lines.calibrated_at.at(3), t0 + std::chrono::seconds(1));
  EXPECT_EQ(lines.calibration_failed.at(4), "(no reason given)");
  EXPECT_EQ(lines.render_pattern.at(3), "grid");
  EXPECT_EQ(lines.render_unavailable.at(5), "no GL");
  // A blend is the node's last; a re-blend goes to its own list; both move the last blend line.
  EXPECT_EQ(lines.blend.at(3).cause, "field");
  EXPECT_EQ(lines.blended.size(), 1u);
  ASSERT_EQ(lines.reblends.size(), 1u);
  EXPECT_EQ(lines.reblends[0].peer, 4u);
  EXPECT_EQ(lines.last_blend_line, t0 + std::chrono::seconds(3));
  ASSERT_TRUE(lines.round_progress.has_value());
  EXPECT_EQ(lines.round_progress->detail, "pre-pass white 0");
  EXPECT_EQ(lines.round_progress_at, t0 + std::chrono::seconds(4));
  EXPECT_EQ(lines.ignored, 0u);
}

TEST(LabLinesTest, ARoundsProgressReadsAsWordsWithItsUnitsAndTime) {
  EXPECT_EQ(
      RoundProgressText(report::RoundProgress{
          0, 1, 57, "structured light, colour 1", "colour 1 frame 12 capture", {0, 2}, 14.25}),
      "round by unit 0: colour 1 frame 12 capture (units 0, 2), 14.2 s in");
  EXPECT_EQ(
      RoundProgressText(
          report::RoundProgress{
              0, 1, 57, "structured light, colour 1", "colour 1 frame 12 capture", {0, 2}, 14.25},
          /*step_only=*/true),
      "round by unit 0: structured light, colour 1 (units 0, 2), 14.2 s in");
  EXPECT_EQ(RoundProgressText(report::RoundProgress{2, 1, 90, "solve", "solve", {}, 30.0}),
            "round by unit 2: solve, 30.0 s in");
  EXPECT_EQ(RoundProgressText(report::RoundProgress{2, 1, 3, "pre-pass", "", {1}, 1.0}),
            "round by unit 2: pre-pass (unit 1), 1.0 s in");
}

TEST(LabLinesTest, ALineFromARoleThatDoesNotPrintItIsIgnoredAndCounted) {
  LabLines lines;
  const Clock::time_point now = Clock::now();
  lines.Take("node", report::WorldReady{"tcp://127.0.0.1:9", false}, now);
  lines.Take("world", report::NodeReady{1, "tcp://127.0.0.1:8"}, now);
  report::Calibrated calibrated;
  calibrated.id = 1;
  lines.Take("coordinator", calibrated, now);
  lines.Take("node", report::LabDone{"ok", "r.md"}, now);
  EXPECT_TRUE(lines.world_endpoint.empty());
  EXPECT_TRUE(lines.nodes_ready.empty());
  EXPECT_TRUE(lines.calibrated.empty());
  EXPECT_EQ(lines.ignored, 4u);
}

}  // namespace
}  // namespace sandtable::sim
