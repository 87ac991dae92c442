// The lab's verdict: a completed run fails what it did not measure or did not reach, and its
// report says why first.
#include "sim/lab/lab_verdict.h"

#include <gtest/gtest.h>

#include "sim/lab/lab_report.h"

namespace sandtable::sim {
namespace {

constexpr int kEnoughPairs = 5000;

LabResult MeasuredRun(double rms_mm) {
  LabResult r;
  RegistrationReport reg;
  reg.site.all.count = kEnoughPairs;
  reg.site.all.rms_mm = rms_mm;
  reg.num_building_points = 100;
  reg.per_unit[0].all.count = kEnoughPairs / 2;
  reg.per_unit[1].all.count = kEnoughPairs / 2;
  r.registration = reg;
  r.photometric = {{"max_step_pct_per_5mm", {{"table", 0.5}, {"walls", 1.0}}},
                   {"table", {{"pairs", kEnoughPairs}}},
                   {"walls", {{"pairs", kEnoughPairs}}}};
  return r;
}

bool Has(const std::vector<LabReason>& reasons, const std::string& what) {
  for (const LabReason& r : reasons) {
    if (r.what == what) return true;
  }
  return false;
}

TEST(LabVerdict, AMeasuredRunUnderItsBarPasses) {
  EXPECT_TRUE(JudgeLabRun(MeasuredRun(0.2), LabVerdictOptions{}).empty());
}

TEST(LabVerdict, RegistrationOverTheBarFailsAndZeroTurnsTheBarOff) {
  LabVerdictOptions options;
  options.max_rms_mm = 1.0;
  const std::vector<LabReason> reasons = JudgeLabRun(MeasuredRun(9.4), options);
  ASSERT_EQ(reasons.size(), 1u);
  EXPECT_EQ(reasons[0].what, "registration over its bar");
  EXPECT_NE(reasons[0].detail.find("9.400 mm rms > 1.000 mm"), std::string::npos)
      << reasons[0].detail;
  options.max_rms_mm = 0.0;
  EXPECT_TRUE(JudgeLabRun(MeasuredRun(9.4), options).empty());
}

TEST(LabVerdict, TooFewSamplesAreNotMeasuredNeverAPass) {
  // The unseen site: the photometric metric found 58 table samples and reported 0.00 %.
  LabResult r = MeasuredRun(0.2);
  r.photometric["table"]["pairs"] = 58;
  r.photometric["max_step_pct_per_5mm"]["table"] = 0.0;
  std::vector<LabReason> reasons = JudgeLabRun(r, LabVerdictOptions{});
  ASSERT_EQ(reasons.size(), 1u);
  EXPECT_EQ(reasons[0].what, "a blend figure not measured");
  EXPECT_NE(reasons[0].detail.find("58 pairs"), std::string::npos);
  r.min_step_pairs = LabVerdictOptions{}.min_step_pairs;
  const std::string md = LabReportMarkdown(r);
  EXPECT_EQ(md.find("| largest step per 5 mm, table | 0.00 %"), std::string::npos) << md;
  EXPECT_NE(md.find("| largest step per 5 mm, table | not measured"), std::string::npos) << md;

  LabResult thin = MeasuredRun(0.2);
  thin.registration->site.all.count = 12;
  EXPECT_TRUE(Has(JudgeLabRun(thin, LabVerdictOptions{}), "registration not measured"));
  LabResult one_unit = MeasuredRun(0.2);
  one_unit.registration->per_unit[1].all.count = 3;
  reasons = JudgeLabRun(one_unit, LabVerdictOptions{});
  ASSERT_TRUE(Has(reasons, "registration not measured"));
  EXPECT_NE(reasons[0].detail.find("unit 1"), std::string::npos);
  LabResult none;
  EXPECT_TRUE(Has(JudgeLabRun(none, LabVerdictOptions{}), "registration not measured"));
}

TEST(LabVerdict, ModelNotFoundAndUnitsLeftOutFailButNotTheUnitTheLabKilled) {
  LabResult r = MeasuredRun(0.2);
  r.measured_with_true_placement = true;
  r.unit_failures[2] = "unit 2: its own camera triangulated 1 of the 1 points";
  r.unit_failures[3] = "unit 3: killed by the lab 1.2 s into the calibration (--kill-unit)";
  r.kill = {{"unit", 3}};
  const std::vector<LabReason> reasons = JudgeLabRun(r, LabVerdictOptions{});
  ASSERT_EQ(reasons.size(), 2u);
  EXPECT_EQ(reasons[0].what, "model not found");
  EXPECT_EQ(reasons[1].what, "a unit left out");
  EXPECT_NE(reasons[1].detail.find("unit 2"), std::string::npos);
}

TEST(LabVerdict, AFailedRunsReasonsComeFirstInItsReport) {
  LabResult r = MeasuredRun(9.4);
  r.status = "failed";
  r.reasons = JudgeLabRun(r, LabVerdictOptions{});
  const std::string md = LabReportMarkdown(r);
  const size_t why = md.find("## Why it failed");
  ASSERT_NE(why, std::string::npos) << md;
  EXPECT_LT(why, md.find("## Summary"));
  EXPECT_NE(md.find("Status: **failed**: 1 reason"), std::string::npos);
  EXPECT_EQ(LabReportJson(r)["reasons"][0]["what"], "registration over its bar");
}

TEST(LabVerdict, AnInterruptedOrCrashedRunIsJudgedByItsFailureAlone) {
  LabResult r;
  r.failure = LabFailure{};
  EXPECT_TRUE(JudgeLabRun(r, LabVerdictOptions{}).empty());
  LabVerdictOptions bad;
  bad.max_rms_mm = -1;
  EXPECT_FALSE(bad.Check().ok());
}

// An "ok" run still says which targets of its summary it missed, and a timing figure says it
// depends on the machine's load.
TEST(LabVerdict, TheStatusLineCountsTheTargetsMissedAndTimingsGiveTheLoad) {
  LabResult r = MeasuredRun(0.2);
  r.max_rms_mm = 1.0;
  r.photometric["max_step_pct_per_5mm"]["table"] = 2.3;  // over its 1.5 % target
  r.render = {{"frame_ms_p50", 30.0}, {"floor_ms", 5.0}, {"context", "llvmpipe"}};
  r.load_average = 1.5;
  r.cores = 2;
  ASSERT_TRUE(JudgeLabRun(r, LabVerdictOptions{}).empty()) << "the verdict is the registration's";
  const std::string md = LabReportMarkdown(r);
  EXPECT_NE(md.find("Status: **ok**; 3 of 5 targets missed: frame time p50 (llvmpipe), frame time "
                    "p50 / floor, largest step per 5 mm, table."),
            std::string::npos)
      << md;
  EXPECT_NE(md.find("| frame time p50 (llvmpipe) * |"), std::string::npos) << md;
  EXPECT_NE(md.find("load average 1.50 on 2 cores"), std::string::npos) << md;
  EXPECT_EQ(LabReportJson(r)["machine"]["cores"], 2);
}

}  // namespace
}  // namespace sandtable::sim
