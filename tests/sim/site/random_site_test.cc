#include "sim/site/random_site.h"

#include <cmath>
#include <set>

#include <gtest/gtest.h>

#include "common/base/units.h"
#include "sim/site/site_json.h"
#include "sim/site/site_presets.h"

namespace sandtable::sim {
namespace {

constexpr double kTolerance_m = 1e-9;
constexpr int kSeeds = 20;  // the acceptance seeds 1-20

TEST(RandomSite, EverySeedGivesASoundSiteWithinTheRanges) {
  std::set<int> unit_counts, projector_widths, camera_bits;
  double most_tilt_deg = 0.0;
  for (uint64_t seed = 1; seed <= kSeeds; ++seed) {
    RandomSiteReport report;
    Expected<Site> site = MakeRandomSite(seed, &report);
    ASSERT_TRUE(site.ok()) << "seed " << seed << ": " << site.status().ToString();
    EXPECT_TRUE(CheckSiteSoundness(*site).ok()) << "seed " << seed;
    EXPECT_EQ(report.draws, static_cast<int>(report.rejections.size()) + 1);
    ASSERT_GE(site->units.size(), 3u);
    ASSERT_LE(site->units.size(), 8u);
    unit_counts.insert(static_cast<int>(site->units.size()));
    for (const UnitSpec& unit : site->units) {
      const CameraModel& p = unit.projector.model;
      projector_widths.insert(p.width_px);
      EXPECT_GE(p.width_px, 1024);
      EXPECT_LE(p.width_px, 1920);
      const double throw_ratio = p.fx_px / p.width_px;
      EXPECT_GE(throw_ratio, 0.8 - 1e-12);
      EXPECT_LE(throw_ratio, 1.6 + 1e-12);
      ASSERT_TRUE(unit.camera.has_value());
      camera_bits.insert(unit.camera->bit_depth);
      EXPECT_GE(unit.camera->model.fx_px, 700.0 * 0.998);
      EXPECT_LE(unit.camera->model.fx_px, 1100.0 * 1.002);
      const double mount_m = unit.camera->projector_from_camera.translation.norm();
      EXPECT_GE(mount_m, 0.05 - kTolerance_m);
      EXPECT_LE(mount_m, 0.20 + kTolerance_m);
      EXPECT_GE(unit.projector.table_from_projector.translation.z(), 0.6 - 1e-6);
      const Eigen::Vector3d axis =
          unit.projector.table_from_projector.rotation * Eigen::Vector3d::UnitZ();
      most_tilt_deg = std::max(most_tilt_deg, RadToDeg(std::acos(-axis.z())));
    }
  }
  // The seeds span the ranges, not one corner of them.
  EXPECT_GE(unit_counts.size(), 4u);
  EXPECT_GE(projector_widths.size(), 3u);
  EXPECT_GE(camera_bits.size(), 4u);
  EXPECT_GT(most_tilt_deg, 30.0);
}

TEST(RandomSite, ASeedIsOneSiteAndThePresetNameReachesIt) {
  Expected<Site> a = MakeRandomSite(7);
  Expected<Site> b = MakeSitePreset("random:7");
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(SiteToJson(*a).dump(), SiteToJson(*b).dump());
  Expected<Site> other = MakeRandomSite(8);
  ASSERT_TRUE(other.ok());
  EXPECT_NE(SiteToJson(*a).dump(), SiteToJson(*other).dump());
  EXPECT_FALSE(MakeSitePreset("random:").ok());
  EXPECT_FALSE(MakeSitePreset("random:x1").ok());
  EXPECT_FALSE(MakeSitePreset("random:-1").ok());
}

TEST(RandomSite, SoundnessRefusesACameraThatMissesItsLightAndALoneUnit) {
  Expected<Site> site = MakeSitePreset("sandtable-3");
  ASSERT_TRUE(site.ok());
  EXPECT_TRUE(CheckSiteSoundness(*site).ok());

  Site blind = *site;
  // The camera turned to look up, away from the table.
  blind.units[1].camera->projector_from_camera.rotation =
      Eigen::AngleAxisd(3.14159265358979, Eigen::Vector3d::UnitX()).toRotationMatrix();
  const Status blind_status = CheckSiteSoundness(blind);
  EXPECT_FALSE(blind_status.ok());
  EXPECT_NE(blind_status.message().find("unit 1: its camera sees"), std::string::npos)
      << blind_status.message();

  Site apart = *site;
  // Unit 2 moved 20 m sideways: it lights nothing of the table.
  apart.units[2].projector.table_from_projector.translation.x() += 20.0;
  EXPECT_FALSE(CheckSiteSoundness(apart).ok());
}

}  // namespace
}  // namespace sandtable::sim
