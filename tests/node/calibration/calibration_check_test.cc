// The restart check of a saved calibration, through the simulated world: sandtable-3's unit 0
// with its true calibration holds; the same calibration after the unit was moved (the world's
// projector and camera together) does not; bad inputs are refused.
#include "node/calibration/calibration_check.h"

#include <cmath>

#include <gtest/gtest.h>

#include "common/scene/procedural_scene.h"
#include "node/calibration/structured_light_plan.h"
#include "sim/site/site_presets.h"
#include "sim/transport/world.h"

namespace sandtable::node {
namespace {

// A true calibration predicts the dots to the world's rendering and noise: p90 well under the
// check's threshold (1 px).
constexpr double kTrueCalibrationP90_px = 0.5;
constexpr double kPi = 3.14159265358979323846;

UnitCalibration TrueCalibration(const sim::UnitSpec& unit) {
  UnitCalibration c;
  c.unit_id = unit.id;
  c.source = kSourceStructuredLight;
  c.projector = unit.projector.model;
  c.camera = unit.camera->model;
  c.projector_from_camera = unit.camera->projector_from_camera;
  c.table_from_projector = unit.projector.table_from_projector;
  c.table_from_model = Rigid3d::Identity();
  return c;
}

// Shows the plan's two frames on `unit` (every other projector black) and evaluates.
Expected<CalibrationCheckReport> RunCheck(sim::World& world, const sim::UnitSpec& unit,
                                          const CalibrationCheckPlan& plan) {
  for (const sim::UnitSpec& u : world.site().units) {
    ST_RETURN_IF_ERROR(world.SetProjectorUniform(u.id, 0));
  }
  const sim::CaptureNoise noise{.enabled = true, .seed = 7};
  Expected<cv::Mat> black = world.Capture(unit.id, noise);
  if (!black.ok()) return black.status();
  ST_RETURN_IF_ERROR(world.SetProjectorFrame(unit.id, plan.dots_frame));
  Expected<cv::Mat> dots = world.Capture(unit.id, sim::CaptureNoise{.enabled = true, .seed = 8});
  if (!dots.ok()) return dots.status();
  const int bits = unit.camera->bit_depth;
  return EvaluateCalibrationCheck(plan, To8Bit(*black, bits), To8Bit(*dots, bits));
}

class CalibrationCheckTest : public ::testing::Test {
 protected:
  void SetUp() override {
    Expected<sim::Site> s = sim::MakeSitePreset("sandtable-3");
    ASSERT_TRUE(s.ok());
    site_ = *s;
    Expected<ProceduralScene> scene = MakeProceduralScene({});
    ASSERT_TRUE(scene.ok());
    scene_ = scene->scene;
  }
  sim::Site site_;
  Scene scene_;
};

TEST_F(CalibrationCheckTest, ATrueCalibrationHolds) {
  Expected<std::unique_ptr<sim::World>> world = sim::World::Create(site_, scene_);
  ASSERT_TRUE(world.ok()) << world.status().ToString();
  const sim::UnitSpec& unit = site_.units[0];
  Expected<CalibrationCheckPlan> plan = PlanCalibrationCheck(TrueCalibration(unit), &scene_);
  ASSERT_TRUE(plan.ok()) << plan.status().ToString();
  EXPECT_GT(plan->dots.size(), 200u);
  Expected<CalibrationCheckReport> report = RunCheck(**world, unit, *plan);
  ASSERT_TRUE(report.ok()) << report.status().ToString();
  EXPECT_TRUE(report->holds) << report->reason;
  EXPECT_GT(report->found, report->dots * 9 / 10);
  EXPECT_LT(report->p90_px, kTrueCalibrationP90_px);
}

TEST_F(CalibrationCheckTest, AMovedUnitFailsTheCheck) {
  const sim::UnitSpec unit = site_.units[0];
  // The unit bumped: 1 cm sideways and 0.3 degrees about the vertical (its camera with it).
  sim::Site moved = site_;
  Rigid3d& pose = moved.units[0].projector.table_from_projector;
  pose = Rigid3d(Eigen::AngleAxisd(0.3 * kPi / 180.0, Eigen::Vector3d::UnitZ()).toRotationMatrix(),
                 Eigen::Vector3d(0.01, 0.0, 0.0)) *
         pose;
  Expected<std::unique_ptr<sim::World>> world = sim::World::Create(moved, scene_);
  ASSERT_TRUE(world.ok()) << world.status().ToString();
  Expected<CalibrationCheckPlan> plan = PlanCalibrationCheck(TrueCalibration(unit), &scene_);
  ASSERT_TRUE(plan.ok());
  Expected<CalibrationCheckReport> report = RunCheck(**world, moved.units[0], *plan);
  ASSERT_TRUE(report.ok()) << report.status().ToString();
  EXPECT_FALSE(report->holds) << "p90 " << report->p90_px << " px, found " << report->found
                              << " of " << report->dots;
  EXPECT_FALSE(report->reason.empty());
}

TEST_F(CalibrationCheckTest, RefusesWhatItCannotCheck) {
  UnitCalibration no_pose = TrueCalibration(site_.units[0]);
  no_pose.table_from_projector.reset();
  EXPECT_EQ(PlanCalibrationCheck(no_pose, &scene_).status().code(), StatusCode::kInvalidArgument);
  CalibrationCheckOptions bad;
  bad.dot_size_px = 0;
  EXPECT_EQ(PlanCalibrationCheck(TrueCalibration(site_.units[0]), &scene_, bad).status().code(),
            StatusCode::kInvalidArgument);
  // A projector looking away from the table: nothing to predict.
  UnitCalibration away = TrueCalibration(site_.units[0]);
  away.table_from_projector = Rigid3d(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0, 0, 1.5));
  EXPECT_EQ(PlanCalibrationCheck(away, &scene_).status().code(), StatusCode::kDegenerate);
  Expected<CalibrationCheckPlan> plan =
      PlanCalibrationCheck(TrueCalibration(site_.units[0]), &scene_);
  ASSERT_TRUE(plan.ok());
  EXPECT_EQ(EvaluateCalibrationCheck(*plan, cv::Mat(), cv::Mat()).status().code(),
            StatusCode::kInvalidArgument);
  const cv::Mat black = cv::Mat::zeros(800, 1280, CV_8UC1);
  Expected<CalibrationCheckReport> dark = EvaluateCalibrationCheck(*plan, black, black);
  ASSERT_TRUE(dark.ok());
  EXPECT_FALSE(dark->holds);
  EXPECT_EQ(dark->found, 0);
}

}  // namespace
}  // namespace sandtable::node
