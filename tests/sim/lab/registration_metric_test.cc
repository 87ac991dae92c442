// The registration metric itself (sim/lab/registration_metric.h): a calibration equal to the
// truth scores 0, a projector shifted by 1 mm scores 1 mm where the geometry says so, and one
// rotated by 0.1 degree scores what the closed form below gives.
#include "sim/lab/registration_metric.h"

#include <algorithm>
#include <cmath>

#include <gtest/gtest.h>

#include "common/base/units.h"
#include "common/scene/procedural_scene.h"
#include "sim/site/site_presets.h"

namespace sandtable::sim {
namespace {

// Double rounding of a ray-plane intersection 1.5 m away plus the Newton undistortion's
// tolerance (1e-10 normalized, ~1.6e-7 mm at 1.6 m): well under 1e-6 mm.
constexpr double kExactTolerance_mm = 1e-6;
constexpr double kExactTolerance_px = 1e-6;
constexpr uint64_t kSeed = 7;

std::unique_ptr<World> SandtableWorld() {
  Expected<Site> site = MakeSitePreset("sandtable-3");
  ProceduralSceneOptions options;
  options.preset = ScenePreset::kSandtable;
  options.seed = 1;
  Expected<ProceduralScene> scene = MakeProceduralScene(options);
  EXPECT_TRUE(site.ok() && scene.ok());
  Expected<std::unique_ptr<World>> world = World::Create(*site, scene->scene);
  EXPECT_TRUE(world.ok()) << world.status().ToString();
  return std::move(*world);
}

std::vector<EstimatedRegistration> TrueEstimates(const Site& site) {
  std::vector<EstimatedRegistration> out;
  for (const UnitSpec& unit : site.units) {
    out.push_back(
        {unit.id, unit.projector.model, unit.projector.table_from_projector, Rigid3d::Identity()});
  }
  return out;
}

TEST(RegistrationMetricTest, TruthScoresZero) {
  std::unique_ptr<World> world = SandtableWorld();
  RegistrationMetricOptions options;
  options.num_samples = 20000;
  options.seed = kSeed;
  Expected<RegistrationReport> report =
      MeasureRegistration(*world, TrueEstimates(world->site()), options);
  ASSERT_TRUE(report.ok()) << report.status().ToString();
  EXPECT_GT(report->num_table_points, 1000);
  EXPECT_GT(report->num_building_points, 100);
  EXPECT_GT(report->site.table.count, 0);
  EXPECT_GT(report->site.buildings.count, 0);
  EXPECT_EQ(report->site.unmeasured, 0);
  EXPECT_LT(report->site.all.max_mm, kExactTolerance_mm);
  EXPECT_LT(report->site.all.max_px, kExactTolerance_px);
  ASSERT_EQ(report->per_unit.size(), 3u);
  for (const auto& [id, errors] : report->per_unit) {
    EXPECT_GT(errors.all.count, 1000) << "unit " << id;
    EXPECT_LT(errors.all.max_mm, kExactTolerance_mm) << "unit " << id;
  }
}

TEST(RegistrationMetricTest, SameSeedSameSamples) {
  std::unique_ptr<World> world = SandtableWorld();
  RegistrationMetricOptions options;
  options.num_samples = 2000;
  std::vector<EstimatedRegistration> estimates = TrueEstimates(world->site());
  estimates[0].projector.fx_px *= 1.001;
  Expected<RegistrationReport> a = MeasureRegistration(*world, estimates, options);
  Expected<RegistrationReport> b = MeasureRegistration(*world, estimates, options);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(a->site.all.count, b->site.all.count);
  EXPECT_EQ(a->site.all.rms_mm, b->site.all.rms_mm);
}

// Every projector's estimate moved by d = 1 mm along the table's x axis, same rotation and
// intrinsics. Its estimated pixel of X is where a projector at c + d sees X, so the true ray
// (from c) through u_hat runs parallel to X - (c + d), i.e. through X - d:
//   x(s) = X - d + s r,  r = X - c - d.
// On the plane n . (x - X) = 0 it lands at X' = X - d + r (n . d) / (n . r), so
//   |X' - X| = |r (n . d) / (n . r) - d|.
// On every face with n perpendicular to d (the table, flat roofs, walls facing +-y) that is
// exactly |d| = 1 mm; on other walls and gabled roofs it is larger, up to
// |d| (1 + 1 / cos(84 deg)) = 10.6 mm at the incidence cut-off. The test checks the formula
// for every sample (exact to 1e-6 mm), 1 mm on the table, and that the site's median is 1 mm:
// "about 1 mm" (the site RMS is pulled up by the walls the shift is not parallel to).
TEST(RegistrationMetricTest, ShiftedByOneMillimetreScoresOneMillimetre) {
  std::unique_ptr<World> world = SandtableWorld();
  RegistrationMetricOptions options;
  options.num_samples = 20000;
  options.seed = kSeed;
  std::vector<EstimatedRegistration> estimates = TrueEstimates(world->site());
  const Eigen::Vector3d d_m(MmToM(1.0), 0.0, 0.0);
  for (EstimatedRegistration& e : estimates) e.table_from_projector.translation += d_m;
  Expected<RegistrationReport> report = MeasureRegistration(*world, estimates, options);
  ASSERT_TRUE(report.ok()) << report.status().ToString();
  const ErrorStats& table = report->site.table;
  ASSERT_GT(table.count, 1000);
  ASSERT_GT(report->site.buildings.count, 100);
  EXPECT_NEAR(table.rms_mm, 1.0, kExactTolerance_mm);
  EXPECT_NEAR(table.max_mm, 1.0, kExactTolerance_mm);
  EXPECT_NEAR(table.mean_mm, 1.0, kExactTolerance_mm);
  std::vector<double> all_mm;
  for (const RegistrationSample& s : report->samples) {
    const Eigen::Vector3d c =
        world->site().FindUnit(s.unit_id)->projector.table_from_projector.translation;
    const Eigen::Vector3d n = world->scene().FaceNormal(s.triangle);
    const Eigen::Vector3d r = s.point_in_table_m - c - d_m;
    const double expected_mm = MToMm((r * n.dot(d_m) / n.dot(r) - d_m).norm());
    EXPECT_NEAR(s.error_mm, expected_mm, kExactTolerance_mm);
    if (s.surface == SurfaceClass::kTable) {
      EXPECT_NEAR(s.error_mm, 1.0, kExactTolerance_mm);
    }
    all_mm.push_back(s.error_mm);
  }
  std::nth_element(all_mm.begin(), all_mm.begin() + all_mm.size() / 2, all_mm.end());
  EXPECT_NEAR(all_mm[all_mm.size() / 2], 1.0, kExactTolerance_mm);
  const double kMaxAtCutoff_mm = 1.0 + 1.0 / std::cos(DegToRad(options.max_incidence_deg));
  EXPECT_LT(report->site.buildings.max_mm, kMaxAtCutoff_mm);
}

// One projector straight down from h = 1.5 m over a flat rectangle (no distortion, square
// pixels, principal point at the image centre), its estimate rotated by theta = 0.1 degree
// about its own optical axis: table_from_projector_est = table_from_projector * Rz(theta).
// Then u_hat = K pi(Rz(theta)^T p) with p = X in the projector frame, and the true ray through
// u_hat has the direction Rz(-theta) p (Rz keeps z, and K, pi invert exactly). The optical
// axis is the vertical through the projector centre c, so the ray is the ray to X turned by
// theta about that vertical: it meets the table (z = 0) at X turned by theta about the nadir N
// of c, at the same distance r = |X - N|. Hence per sample
//   |X' - X| = 2 r sin(theta / 2),   |u_hat - u_true| = 2 rho sin(theta / 2)
// with rho the distance of u_true from the principal point (fx = fy). Over the footprint, a
// W x H rectangle centred on N (W = h 1280 / fx, H = h 800 / fy: the image spans
// [-0.5, w - 0.5] with cx = (w - 1) / 2), samples are uniform, so E[r^2] = (W^2 + H^2) / 12 and
//   RMS = 2 sin(theta / 2) sqrt((W^2 + H^2) / 12).
// h = 1.5 m, throw ratio 1.27 (fx = 1625.6 px): W = 1.1811 m, H = 0.7382 m, RMS = 0.7018 mm.
TEST(RegistrationMetricTest, RotatedByATenthOfADegreeScoresTheClosedForm) {
  constexpr double kHeight_m = 1.5;
  const double theta_rad = DegToRad(0.1);
  Site site;
  site.name = "one-down";
  site.table.is_disc = false;
  site.table.size_m = Eigen::Vector2d(1.4, 1.0);
  UnitSpec unit;
  unit.id = 0;
  unit.name = "unit-0";
  unit.projector = DefaultProjector();
  unit.projector.model.distortion = BrownDistortion{};
  unit.projector.model.cx_px = (unit.projector.model.width_px - 1) / 2.0;
  unit.projector.model.cy_px = (unit.projector.model.height_px - 1) / 2.0;
  unit.projector.table_from_projector =
      *TableFromDeviceLookAt({0, 0, kHeight_m}, {0, 0, 0}, Eigen::Vector3d::UnitY());
  unit.camera = DefaultCamera();
  unit.camera->projector_from_camera = Rigid3d::Identity();
  site.units.push_back(unit);
  Scene scene;
  scene.materials.push_back(Material{"table", {0.8, 0.8, 0.8, 1.0}, -1});
  scene.Append(MakeRectangleMesh(site.table.size_m, 0));
  Expected<std::unique_ptr<World>> world = World::Create(site, scene);
  ASSERT_TRUE(world.ok()) << world.status().ToString();

  EstimatedRegistration estimate{
      0, unit.projector.model,
      unit.projector.table_from_projector *
          Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(theta_rad, Eigen::Vector3d::UnitZ())),
                  Eigen::Vector3d::Zero()),
      Rigid3d::Identity()};
  RegistrationMetricOptions options;
  options.num_samples = 20000;
  options.seed = kSeed;
  Expected<RegistrationReport> report = MeasureRegistration(**world, {estimate}, options);
  ASSERT_TRUE(report.ok()) << report.status().ToString();
  ASSERT_GT(report->site.table.count, 5000);
  EXPECT_EQ(report->site.buildings.count, 0);
  const double chord = 2.0 * std::sin(theta_rad / 2.0);
  const Eigen::Vector2d nadir = unit.projector.table_from_projector.translation.head<2>();
  const Eigen::Vector2d principal(unit.projector.model.cx_px, unit.projector.model.cy_px);
  for (const RegistrationSample& s : report->samples) {
    const double r_m = (s.point_in_table_m.head<2>() - nadir).norm();
    EXPECT_NEAR(s.error_mm, MToMm(chord * r_m), kExactTolerance_mm);
    EXPECT_NEAR(s.error_px, chord * (s.true_pixel_px - principal).norm(), kExactTolerance_px);
  }
  const CameraModel& m = unit.projector.model;
  const double w_m = kHeight_m * m.width_px / m.fx_px, h_m = kHeight_m * m.height_px / m.fy_px;
  const double expected_rms_mm = MToMm(chord * std::sqrt((w_m * w_m + h_m * h_m) / 12.0));
  EXPECT_NEAR(expected_rms_mm, 0.7018, 1e-4);  // the number worked out above
  // Sampling: ~12 000 uniform points; r^2 has a coefficient of variation ~0.6 over the
  // rectangle, so the RMS has a relative standard error of ~0.3 %: 1.5 % is 5 sigma.
  constexpr double kSamplingTolerance = 0.015;
  EXPECT_NEAR(report->site.all.rms_mm, expected_rms_mm, kSamplingTolerance * expected_rms_mm);
}

TEST(RegistrationMetricTest, BadInputIsAnError) {
  std::unique_ptr<World> world = SandtableWorld();
  std::vector<EstimatedRegistration> estimates = TrueEstimates(world->site());
  estimates[0].unit_id = 42;
  Expected<RegistrationReport> unknown = MeasureRegistration(*world, estimates, {});
  ASSERT_FALSE(unknown.ok());
  EXPECT_NE(unknown.status().message().find("unit 42"), std::string::npos);
  RegistrationMetricOptions bad;
  bad.num_samples = 0;
  EXPECT_FALSE(MeasureRegistration(*world, TrueEstimates(world->site()), bad).ok());
  estimates = TrueEstimates(world->site());
  estimates[1].projector.fx_px = -1;
  EXPECT_FALSE(MeasureRegistration(*world, estimates, {}).ok());
}

}  // namespace
}  // namespace sandtable::sim
