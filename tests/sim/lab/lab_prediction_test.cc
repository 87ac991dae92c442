// The lab's comparison of each unit's predicted error with its measured one (lab_prediction.h):
// what is read from the runner's report, the ratios, and what a missing side reads as.
#include "sim/lab/lab_prediction.h"

#include <string>

#include <gtest/gtest.h>

namespace sandtable::sim {
namespace {

constexpr double kExact = 1e-12;

ErrorStats Stats(int count, double rms_mm, double rms_px) {
  ErrorStats s;
  s.count = count;
  s.rms_mm = rms_mm;
  s.rms_px = rms_px;
  return s;
}

RegistrationReport Measured() {
  RegistrationReport r;
  r.per_unit[1].all = Stats(500, 0.2, 0.10);
  r.per_unit[1].table = Stats(400, 0.16, 0.08);
  r.per_unit[2].all = Stats(300, 0.5, 0.30);
  r.per_unit[2].table = Stats(0, 0.0, 0.0);  // nothing of it on the table
  r.per_unit[3].all = Stats(200, 0.3, 0.2);
  r.per_unit[3].table = Stats(100, 0.3, 0.2);
  return r;
}

nlohmann::json RunnerReport() {
  return nlohmann::json::parse(R"({"bundle": {"sigma_px": 0.02, "undetermined": "",
    "units": {
      "1": {"predicted_rms_px": 0.05, "predicted_rms_mm": 0.1,
            "weak_direction": "the image shifts (along x), 80 % of it: unit 1 focal fx",
            "weak_share": 0.7},
      "2": {"predicted_rms_px": 0.05, "predicted_rms_mm": -1},
      "3": {"projector_rms_px": 0.04}}}})");
}

TEST(LabPrediction, ReadsThePredictionAndFormsTheRatios) {
  const PredictionComparison c = ComparePrediction(Measured(), RunnerReport());
  ASSERT_EQ(c.units.size(), 3u);
  EXPECT_NEAR(c.sigma_px, 0.02, kExact);
  const PredictionRow& u1 = c.units[0];
  EXPECT_EQ(u1.unit, 1u);
  EXPECT_NEAR(u1.ratio_px(), 0.10 / 0.05, kExact);
  EXPECT_NEAR(u1.ratio_mm(), 0.16 / 0.1, kExact);
  // Unit 2: no table pairs and no mm prediction: no mm ratio, the px one stands.
  EXPECT_LT(c.units[1].ratio_mm(), 0.0);
  EXPECT_NEAR(c.units[1].ratio_px(), 6.0, kExact);
  // Unit 3: nothing predicted: no ratio at all.
  EXPECT_LT(c.units[2].ratio_px(), 0.0);
  EXPECT_LT(c.units[2].ratio_mm(), 0.0);
}

TEST(LabPrediction, TheReportMarksWhatIsOutsideAndWhatIsMissing) {
  const std::string md = PredictionMarkdown(ComparePrediction(Measured(), RunnerReport()));
  EXPECT_NE(md.find("| 1 | 0.050 | 0.100 | 2.00 | 0.100 | 0.160 | 1.60 |"), std::string::npos)
      << md;
  EXPECT_NE(md.find("**6.00**"), std::string::npos) << md;  // outside 2x: bold
  EXPECT_NE(md.find("not predicted"), std::string::npos);
  EXPECT_NE(md.find("not measured"), std::string::npos);
  EXPECT_NE(md.find("80 % of it: unit 1 focal fx (70 % of the variance)"), std::string::npos);
  const nlohmann::json j = PredictionJson(ComparePrediction(Measured(), RunnerReport()));
  EXPECT_NEAR(j["units"]["1"]["ratio_px"].get<double>(), 2.0, kExact);
  EXPECT_LT(j["units"]["3"]["ratio_px"].get<double>(), 0.0);
}

TEST(LabPrediction, AReportWithoutABundleLeavesEveryUnitUnpredicted) {
  const PredictionComparison c =
      ComparePrediction(Measured(), nlohmann::json::parse(R"({"ok": false})"));
  ASSERT_EQ(c.units.size(), 3u);
  for (const PredictionRow& r : c.units) EXPECT_LT(r.ratio_px(), 0.0);
}

}  // namespace
}  // namespace sandtable::sim
