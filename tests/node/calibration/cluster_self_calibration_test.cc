// The cluster self-calibration end to end in one process against the simulated world
// (tests/testing/self_calibration_sim.h): sandtable-3 with factory errors and noise, the model
// at an unknown placement; the registration metric of the lab on the result.
#include <cmath>

#include <gtest/gtest.h>

#include "common/scene/procedural_scene.h"
#include "sim/site/site_presets.h"
#include "tests/testing/self_calibration_sim.h"

namespace sandtable {
namespace {

// The acceptance figures (docs/calibration.md gives the measured values).
constexpr double kMaxRms_mm = 0.3;
constexpr double kMaxRms_px = 0.25;
constexpr double kMaxError_mm = 1.5;
constexpr double kModelOffset_mm = 0.3;
constexpr double kModelOffset_deg = 0.05;

TEST(ClusterSelfCalibration, Sandtable3ReachesTheAcceptanceFigures) {
  Expected<sim::Site> site = sim::MakeSitePreset("sandtable-3");
  ASSERT_TRUE(site.ok());
  Expected<ProceduralScene> scene = MakeProceduralScene({});
  ASSERT_TRUE(scene.ok());
  testing::SimCalibrationOptions options;
  options.seed = 1;
  options.model_from_table =
      Rigid3d(Eigen::AngleAxisd(7.0 * M_PI / 180.0, Eigen::Vector3d::UnitZ()).toRotationMatrix(),
              Eigen::Vector3d(0.03, -0.02, 0.0));
  Expected<testing::SimCalibrationResult> r =
      testing::RunSimCalibration(*site, scene->scene, options);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_EQ(r->solution.calibrations.size(), 3u);
  ASSERT_TRUE(r->solution.model.has_value());
  const auto& m = r->metric.site;
  EXPECT_LT(m.table.rms_mm, kMaxRms_mm);
  EXPECT_LT(m.buildings.rms_mm, kMaxRms_mm);
  EXPECT_LT(m.table.rms_px, kMaxRms_px);
  EXPECT_LT(m.buildings.rms_px, kMaxRms_px);
  EXPECT_LT(m.table.max_mm, kMaxError_mm);
  EXPECT_LT(m.buildings.max_mm, kMaxError_mm);
  EXPECT_LT(r->model_offset_mm, kModelOffset_mm);
  EXPECT_LT(r->model_offset_deg, kModelOffset_deg);
  EXPECT_FALSE(r->solution.planar);
}

}  // namespace
}  // namespace sandtable
