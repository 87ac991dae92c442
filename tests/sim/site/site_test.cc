#include "sim/site/site.h"

#include <cmath>

#include <gtest/gtest.h>

#include "common/base/units.h"
#include "sim/site/factory_calibration.h"
#include "sim/site/site_json.h"
#include "sim/site/site_presets.h"

namespace sandtable::sim {
namespace {

constexpr double kTolerance_m = 1e-9;
constexpr double kAngleTolerance_deg = 1e-6;

TEST(SitePresets, Sandtable3MatchesTr09017) {
  Expected<Site> site = MakeSitePreset("sandtable-3");
  ASSERT_TRUE(site.ok()) << site.status().ToString();
  ASSERT_EQ(site->units.size(), 3u);
  for (size_t i = 0; i < 3; ++i) {
    const UnitSpec& u = site->units[i];
    EXPECT_EQ(u.projector.model.width_px, 1280);
    EXPECT_EQ(u.projector.model.height_px, 800);
    EXPECT_NEAR(u.projector.model.fx_px / u.projector.model.width_px, 1.27, 1e-12);
    ASSERT_TRUE(u.camera.has_value());
    // Optical axis 20 degrees from straight down.
    const Eigen::Vector3d axis =
        u.projector.table_from_projector.rotation * Eigen::Vector3d::UnitZ();
    EXPECT_NEAR(RadToDeg(std::acos(-axis.z())), 20.0, kAngleTolerance_deg);
    EXPECT_NEAR(u.projector.table_from_projector.translation.z(), 1.55, kTolerance_m);
  }
  // 120 degrees apart in azimuth.
  const Eigen::Vector3d a = site->units[0].projector.table_from_projector.translation;
  const Eigen::Vector3d b = site->units[1].projector.table_from_projector.translation;
  const double angle_deg =
      RadToDeg(std::acos(a.head<2>().normalized().dot(b.head<2>().normalized())));
  EXPECT_NEAR(angle_deg, 120.0, kAngleTolerance_deg);
}

TEST(SitePresets, GridAndFlat) {
  for (const char* name : {"grid-1", "grid-7", "grid-32", "grid-64", "flat-4"}) {
    Expected<Site> site = MakeSitePreset(name);
    ASSERT_TRUE(site.ok()) << name << ": " << site.status().ToString();
  }
  EXPECT_EQ(MakeSitePreset("grid-64")->units.size(), 64u);
  EXPECT_FALSE(MakeSitePreset("grid-65").ok());
  EXPECT_FALSE(MakeSitePreset("grid-x").ok());
  EXPECT_FALSE(MakeSitePreset("moon").ok());
}

// The camera exposure follows the throw outside 1.6..2.6 m, so that the white stays in range.
TEST(SitePresets, GridExposureFollowsTheThrow) {
  auto exposure = [](const char* name) {
    return MakeSitePreset(name)->units[0].camera->exposure_s;
  };
  auto throw_m = [](const char* name) {
    return MakeSitePreset(name)->units[0].projector.table_from_projector.translation.z();
  };
  constexpr double kPresetExposure_s = 0.005;
  EXPECT_DOUBLE_EQ(exposure("grid-8"), kPresetExposure_s);  // 2.54 m
  EXPECT_DOUBLE_EQ(exposure("grid-4"), kPresetExposure_s);
  // The light goes as 1 / throw^2, the exposure as throw^2: equal signal at both ends.
  const double long_ratio = exposure("grid-2") / kPresetExposure_s;
  EXPECT_NEAR(long_ratio, std::pow(throw_m("grid-2") / 2.6, 2), 1e-12);
  EXPECT_GT(long_ratio, 3.0);
  const double short_ratio = exposure("grid-64") / kPresetExposure_s;
  EXPECT_NEAR(short_ratio, std::pow(throw_m("grid-64") / 1.6, 2), 1e-12);
  EXPECT_LT(short_ratio, 0.2);
}

// A scaled site keeps every ray: a table point seen at u in the full-resolution image is seen
// at (u + 0.5) * w' / w - 0.5 in the scaled one; the field of view and the poses are unchanged.
TEST(SitePresets, ScaleSiteResolutionKeepsTheRays) {
  Site site = *MakeSitePreset("sandtable-3");
  const Site full = site;
  ASSERT_TRUE(ScaleSiteResolution(0.5, &site).ok());
  constexpr double kRayTolerance_px = 1e-9;
  for (size_t i = 0; i < site.units.size(); ++i) {
    for (const bool camera : {false, true}) {
      const CameraModel& a = camera ? full.units[i].camera->model : full.units[i].projector.model;
      const CameraModel& b = camera ? site.units[i].camera->model : site.units[i].projector.model;
      EXPECT_EQ(b.width_px, a.width_px / 2);
      EXPECT_EQ(b.height_px, a.height_px / 2);
      for (const Eigen::Vector3d& x : {Eigen::Vector3d(0.05, -0.1, 1.0),
                                       Eigen::Vector3d(-0.3, 0.2, 1.0), Eigen::Vector3d(0, 0, 1)}) {
        const std::optional<Eigen::Vector2d> ua = a.Project(x), ub = b.Project(x);
        ASSERT_TRUE(ua && ub);
        EXPECT_NEAR(ub->x(), (ua->x() + 0.5) * b.width_px / a.width_px - 0.5, kRayTolerance_px);
        EXPECT_NEAR(ub->y(), (ua->y() + 0.5) * b.height_px / a.height_px - 0.5, kRayTolerance_px);
      }
    }
    EXPECT_TRUE(site.units[i].projector.table_from_projector.ToMatrix4().isApprox(
        full.units[i].projector.table_from_projector.ToMatrix4()));
  }
  EXPECT_FALSE(ScaleSiteResolution(0.0, &site).ok());
  EXPECT_FALSE(ScaleSiteResolution(1.5, &site).ok());
  const Status tiny = ScaleSiteResolution(0.01, &site);
  EXPECT_FALSE(tiny.ok());
  EXPECT_NE(tiny.message().find("under 32 px"), std::string::npos) << tiny.ToString();
}

TEST(SiteCheck, ErrorsNameUnitAndField) {
  Site site = *MakeSitePreset("sandtable-3");
  {
    Site bad = site;
    bad.units[1].projector.model.fx_px = -3;
    const Status s = bad.Check();
    ASSERT_FALSE(s.ok());
    EXPECT_NE(s.message().find("unit 1"), std::string::npos) << s.message();
    EXPECT_NE(s.message().find("projector.fx_px"), std::string::npos) << s.message();
  }
  {
    Site bad = site;
    bad.units[2].id = 0;
    const Status s = bad.Check();
    ASSERT_FALSE(s.ok());
    EXPECT_NE(s.message().find("duplicate id 0"), std::string::npos) << s.message();
  }
  {
    Site bad = site;  // turned to look at the ceiling
    bad.units[0].projector.table_from_projector =
        *TableFromDeviceLookAt({0, 0, 1.5}, {0, 0, 3.0}, Eigen::Vector3d::UnitY());
    const Status s = bad.Check();
    ASSERT_FALSE(s.ok());
    EXPECT_NE(s.message().find("unit 0"), std::string::npos) << s.message();
    EXPECT_NE(s.message().find("sees nothing of the table"), std::string::npos) << s.message();
  }
  {
    Site bad = site;
    bad.units[2].camera->bit_depth = 17;
    const Status s = bad.Check();
    ASSERT_FALSE(s.ok());
    EXPECT_NE(s.message().find("camera.bit_depth"), std::string::npos) << s.message();
  }
}

TEST(SiteJson, RoundTripAndErrors) {
  const Site site = *MakeSitePreset("flat-4");
  const nlohmann::json j = SiteToJson(site);
  Expected<Site> back = SiteFromJson(j);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  ASSERT_EQ(back->units.size(), 4u);
  EXPECT_NEAR((back->units[3].projector.table_from_projector.translation -
               site.units[3].projector.table_from_projector.translation)
                  .norm(),
              0.0, kTolerance_m);
  EXPECT_NEAR(back->units[3].camera->model.fx_px, site.units[3].camera->model.fx_px, 1e-9);

  nlohmann::json typo = j;
  typo["units"][2]["projector"]["fx"] = 10;
  Expected<Site> e1 = SiteFromJson(typo);
  ASSERT_FALSE(e1.ok());
  EXPECT_NE(e1.status().message().find("site.units[2].projector has unknown key 'fx'"),
            std::string::npos)
      << e1.status().message();

  nlohmann::json wrong_type = j;
  wrong_type["units"][1]["camera"]["fy_px"] = "big";
  Expected<Site> e2 = SiteFromJson(wrong_type);
  ASSERT_FALSE(e2.ok());
  EXPECT_NE(e2.status().message().find("units[1].camera.fy_px"), std::string::npos)
      << e2.status().message();

  // Every written site carries format and version; files without them (older) still load.
  EXPECT_EQ(j.at("format"), kSiteFormat);
  EXPECT_EQ(j.at("version"), kSiteVersion);
  nlohmann::json old_file = j;
  old_file.erase("format");
  old_file.erase("version");
  EXPECT_TRUE(SiteFromJson(old_file).ok());
  nlohmann::json future = j;
  future["version"] = kSiteVersion + 1;
  Expected<Site> e4 = SiteFromJson(future);
  ASSERT_FALSE(e4.ok());
  EXPECT_EQ(e4.status().code(), StatusCode::kParseError);
  EXPECT_NE(e4.status().message().find("site.version"), std::string::npos) << e4.status().message();
  // A bad quaternion names its field.
  nlohmann::json bad_rotation = j;
  bad_rotation["units"][0]["projector"]["table_from_projector"]["rotation_xyzw"] = {0, 0, 0, 2};
  Expected<Site> e5 = SiteFromJson(bad_rotation);
  ASSERT_FALSE(e5.ok());
  EXPECT_NE(
      e5.status().message().find("site.units[0].projector.table_from_projector.rotation_xyzw"),
      std::string::npos)
      << e5.status().message();

  // Throw-ratio form of intrinsics.
  nlohmann::json throw_form = j;
  nlohmann::json& p = throw_form["units"][0]["projector"];
  p.erase("fx_px");
  p.erase("fy_px");
  p.erase("cx_px");
  p.erase("cy_px");
  p["throw_ratio"] = 1.27;
  p["lens_shift_v"] = 0.0;
  Expected<Site> e3 = SiteFromJson(throw_form);
  ASSERT_TRUE(e3.ok()) << e3.status().ToString();
  EXPECT_NEAR(e3->units[0].projector.model.fx_px, 1.27 * 1280, 1e-9);
}

// A unit's device timing (device_timing.h) is written only when it is not the default, read
// back whole, and refused out of its ranges naming unit and field.
TEST(SiteJson, DeviceTimingRoundTripAndRanges) {
  Site site = *MakeSitePreset("flat-4");
  EXPECT_FALSE(SiteToJson(site)["units"][0].contains("timing"));
  site.units[1].timing = RealHardwareTiming();
  const nlohmann::json j = SiteToJson(site);
  Expected<Site> back = SiteFromJson(j);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_TRUE(back->units[1].timing == RealHardwareTiming());
  EXPECT_TRUE(back->units[0].timing == DeviceTiming{});
  EXPECT_FALSE(back->units[1].timing.Ideal());

  nlohmann::json bad = j;
  bad["units"][1]["timing"]["repeat_rate"] = 0.9;
  Expected<Site> refused = SiteFromJson(bad);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("timing.repeat_rate"), std::string::npos)
      << refused.status().message();
  EXPECT_NE(refused.status().message().find("unit 1"), std::string::npos)
      << refused.status().message();
  EXPECT_FALSE(DeviceTimingPreset("fast").ok());
  EXPECT_TRUE(DeviceTimingPreset("real").ok());
}

TEST(FactoryCalibration, SeededErrorsAroundTruth) {
  const Site site = *MakeSitePreset("sandtable-3");
  FactoryCalibrationError error;
  Expected<FactoryCalibration> a = MakeFactoryCalibration(site.units[0], error, 5);
  Expected<FactoryCalibration> b = MakeFactoryCalibration(site.units[0], error, 5);
  Expected<FactoryCalibration> c = MakeFactoryCalibration(site.units[1], error, 5);
  ASSERT_TRUE(a.ok() && b.ok() && c.ok());
  EXPECT_EQ(a->camera.fx_px, b->camera.fx_px);
  EXPECT_NE(a->camera.fx_px - site.units[0].camera->model.fx_px,
            c->camera.fx_px - site.units[1].camera->model.fx_px);
  // Within 6 sigma of the truth.
  EXPECT_LT(std::abs(a->camera.fx_px / site.units[0].camera->model.fx_px - 1),
            6 * error.focal_relative_sigma);
  EXPECT_LT(std::abs(a->projector.cx_px - site.units[0].projector.model.cx_px),
            6 * error.principal_point_sigma_px);
  EXPECT_GT(std::abs(a->camera.fx_px - site.units[0].camera->model.fx_px), 0.0);
  // Zero error reproduces the truth.
  FactoryCalibrationError zero{0, 0, 0, 0, 0};
  Expected<FactoryCalibration> exact = MakeFactoryCalibration(site.units[2], zero, 9);
  ASSERT_TRUE(exact.ok());
  EXPECT_EQ(exact->projector.fx_px, site.units[2].projector.model.fx_px);
  EXPECT_NEAR((exact->projector_from_camera.translation -
               site.units[2].camera->projector_from_camera.translation)
                  .norm(),
              0.0, kTolerance_m);
}

}  // namespace
}  // namespace sandtable::sim
