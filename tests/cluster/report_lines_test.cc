// The report lines (cluster/report_lines.h): every kind written and read back unchanged, the
// lines today's programs print read as the kind they are, and bad lines refused with the reason.
#include <string>
#include <variant>

#include <gtest/gtest.h>

#include "cluster/report_lines.h"

namespace sandtable::report {
namespace {

// One line of every kind, every field set to something other than its default.
std::vector<ReportLine> OneOfEach() {
  Calibrated calibrated;
  calibrated.id = 3;
  calibrated.source = "self";
  calibrated.json = "out/unit-3.json";
  calibrated.yaml = "out/unit-3.yaml";
  calibrated.report = "out/self_calibration_report.json";
  calibrated.mpcdi = "out/site.mpcdi";
  calibrated.join_report = "out/join_report-unit-3.json";
  calibrated.round = 2;
  calibrated.verified = true;
  calibrated.compute_s = 1.25;
  calibrated.messages_sent = 10;
  calibrated.messages_received = 11;
  calibrated.bytes_sent = 1000;
  calibrated.bytes_received = 2000;
  Verification verification{4, 2, 0.5, 0.25, false, 30, 28, 5, 0.4, 0.9, 0.7, 1.5, "moved"};
  RenderSummary summary;
  summary.id = 2;
  summary.frames = 600;
  summary.failed = 1;
  summary.unchanged = 300;
  summary.rewarped = 4;
  summary.groups_culled = 7;
  summary.frame_ms_p50 = 12.5;
  summary.frame_ms_p99 = 30.25;
  summary.first_frame_ms = 812.5;
  summary.floor_ms = 2.5;
  summary.show_ms_p50 = 1.5;
  summary.passes = {{"scene", 10}, {"warp", 600}};
  summary.context = "llvmpipe";
  BlendShown reblend;
  reblend.id = 1;
  reblend.reblend = true;
  reblend.cause = "left";
  reblend.peer = 2;
  reblend.detected_ns = 123456789;
  reblend.noticed_by = "connection";
  reblend.neighbours = {3};
  reblend.waiting_for = {4};
  reblend.level_per_m2 = 80.5;
  reblend.faces_below_level = 2;
  reblend.face_level_min_per_m2 = 60.25;
  reblend.black_target_per_m2 = 0.5;
  reblend.lift_max = 0.01;
  reblend.compose_ms = 40.5;
  reblend.cast_ms = 3.5;
  reblend.shown_ns = 223456789;
  reblend.frame = {1.0, 2.0, 3.0, 4.0, 5.0, true, false, true};
  reblend.bytes_sent = 5;
  reblend.bytes_received = 6;
  BlendShown blended = reblend;
  blended.reblend = false;
  blended.cause = "field";
  blended.peer = kInvalidNodeId;
  blended.detected_ns = 0;
  blended.noticed_by.clear();
  blended.black_target_per_m2.reset();
  blended.lift_max.reset();
  return {WorldReady{"tcp://127.0.0.1:1", true},
          CoordinatorReady{"tcp://127.0.0.1:2", "tcp://127.0.0.1:3", "http://127.0.0.1:4"},
          NodeReady{3, "tcp://127.0.0.1:5"},
          calibrated,
          CalibrationFailed{3, "unit 3: camera video:0: no such device"},
          verification,
          RenderUnavailable{2, "no GL context"},
          RenderPattern{2, "white"},
          summary,
          BlendExported{1, "out/site.mpcdi", 3},
          reblend,
          blended,
          Messages{3, 100, 2, 3, 4},
          RoundProgress{
              1, 2, 57, "structured light, colour 1", "colour 1 frame 12 capture", {0, 2}, 14.25},
          LabPhase{"hold", 10.0},
          LabDone{"ok", "out/report.md"}};
}

TEST(ReportLines, EveryKindReadsBackAsItWasWritten) {
  for (const ReportLine& line : OneOfEach()) {
    SCOPED_TRACE(KindName(line));
    const std::string text = ToText(line);
    Expected<ReportLine> read = ParseReportLineText(text);
    ASSERT_TRUE(read.ok()) << read.status().ToString() << "\n" << text;
    EXPECT_EQ(read->index(), line.index());
    // Written again, the line is the same text: no field lost or changed on the way.
    EXPECT_EQ(ToText(*read), text);
  }
}

TEST(ReportLines, ReadsTheLinesAsTheProgramsPrintThem) {
  // A held calibration's line has only its first four fields.
  Expected<ReportLine> held = ParseReportLineText(
      R"({"calibrated":3,"source":"factory+true_pose","json":"d/unit-3.json","yaml":"d/unit-3.yaml"})");
  ASSERT_TRUE(held.ok()) << held.status().ToString();
  ASSERT_TRUE(std::holds_alternative<Calibrated>(*held));
  EXPECT_EQ(std::get<Calibrated>(*held).id, 3u);
  EXPECT_EQ(std::get<Calibrated>(*held).round, 0u);
  // A field a newer writer adds is ignored.
  Expected<ReportLine> node = ParseReportLineText(
      R"({"ready":"sandtable-node","id":7,"peer":"tcp://10.0.0.7:5000","host":"unit-7"})");
  ASSERT_TRUE(node.ok()) << node.status().ToString();
  EXPECT_EQ(std::get<NodeReady>(*node).peer, "tcp://10.0.0.7:5000");
  // The render kinds are told apart by their second key.
  EXPECT_TRUE(std::holds_alternative<RenderPattern>(
      *ParseReportLineText(R"({"render":2,"pattern":"grid"})")));
  EXPECT_TRUE(std::holds_alternative<RenderUnavailable>(
      *ParseReportLineText(R"({"render":2,"unavailable":"no display"})")));
  EXPECT_TRUE(
      std::holds_alternative<RenderSummary>(*ParseReportLineText(R"({"render":2,"frames":0})")));
  EXPECT_TRUE(std::holds_alternative<BlendExported>(
      *ParseReportLineText(R"({"blend":1,"mpcdi":"x/site.mpcdi","alpha_from":2})")));
}

TEST(ReportLines, RefusesWhatIsNotAReportLineAndSaysWhy) {
  struct Case {
    const char* text;
    const char* says;
  };
  const Case cases[] = {
      {"{not json", "not JSON"},
      {"[1, 2]", "not a JSON object"},
      {R"({"hello":1})", "no kind of line has the keys hello"},
      {R"({"ready":"sandtable-toaster"})", "unknown program"},
      {R"({"ready":"sandtable-node","peer":"tcp://x:1"})", "no \"id\""},
      {R"({"calibrated":true,"source":"s","json":"j","yaml":"y"})", "\"calibrated\" is true"},
      {R"({"calibrated":-1,"source":"s","json":"j","yaml":"y"})", "\"calibrated\" is -1"},
      {R"({"calibrated":5000000000,"source":"s","json":"j","yaml":"y"})", "5000000000"},
      {R"({"blend":1,"blended":true,"neighbours":[1,"two"]})", "\"neighbours\""},
      {R"({"blend":1,"blended":true,"frame":3})", "\"frame\" is 3"},
      {R"({"render":2,"frames":"many"})", "\"frames\" is \"many\""},
      {R"({"lab":"dancing"})", "unknown lab line"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.text);
    Expected<ReportLine> read = ParseReportLineText(c.text);
    ASSERT_FALSE(read.ok());
    EXPECT_EQ(read.status().code(), StatusCode::kInvalidArgument);
    EXPECT_NE(read.status().message().find(c.says), std::string::npos) << read.status().message();
  }
}

}  // namespace
}  // namespace sandtable::report
