// The MPCDI builder on a synthetic scene (a table plane and a box, a projector looking down at
// them): warp samples lie on the surfaces and reproject to their grid pixels, the frustum is the
// intrinsics' and the pose's, and the built site survives WriteMpcdi + ReadMpcdi.
#include "common/io/mpcdi_builder.h"

#include <cmath>
#include <filesystem>
#include <memory>

#include <unistd.h>

#include <gtest/gtest.h>
#include <Eigen/Geometry>

namespace sandtable {
namespace {

// Hit points are refined in double on the hit triangle's plane, then stored as float (|x| < 2 m:
// float spacing 1.2e-7 m).
constexpr double kOnSurfaceTolerance_m = 1e-4;
// A sample's point projected back into the projector lands on the sample's pixel.
constexpr double kReprojectionTolerance_px = 1e-3;
constexpr double kAngleTolerance_deg = 1e-12;
constexpr double kRotationTolerance = 1e-12;
constexpr double kDegFromRad = 180.0 / M_PI;

constexpr double kTableHalfSize_m = 1.0;
const Eigen::Vector3d kBoxMin_m(-0.15, -0.10, 0.0);
const Eigen::Vector3d kBoxMax_m(0.05, 0.12, 0.25);

// Adds a quad (counter-clockwise seen from its front) as two triangles.
void AddQuad(Scene* scene, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
             const Eigen::Vector3d& c, const Eigen::Vector3d& d) {
  const int base = scene->NumVertices();
  for (const Eigen::Vector3d& p : {a, b, c, d})
    scene->positions_in_table_m.push_back(p.cast<float>());
  scene->triangles.emplace_back(base, base + 1, base + 2);
  scene->triangles.emplace_back(base, base + 2, base + 3);
  scene->triangle_material.push_back(0);
  scene->triangle_material.push_back(0);
}

std::shared_ptr<const Scene> TableAndBox() {
  auto scene = std::make_shared<Scene>();
  scene->materials.push_back(Material{});
  const double h = kTableHalfSize_m;
  AddQuad(scene.get(), {-h, -h, 0}, {h, -h, 0}, {h, h, 0}, {-h, h, 0});
  const Eigen::Vector3d& lo = kBoxMin_m;
  const Eigen::Vector3d& hi = kBoxMax_m;
  AddQuad(scene.get(), {lo.x(), lo.y(), hi.z()}, {hi.x(), lo.y(), hi.z()}, {hi.x(), hi.y(), hi.z()},
          {lo.x(), hi.y(), hi.z()});  // top
  AddQuad(scene.get(), {lo.x(), lo.y(), 0}, {hi.x(), lo.y(), 0}, {hi.x(), lo.y(), hi.z()},
          {lo.x(), lo.y(), hi.z()});  // -y side
  AddQuad(scene.get(), {hi.x(), lo.y(), 0}, {hi.x(), hi.y(), 0}, {hi.x(), hi.y(), hi.z()},
          {hi.x(), lo.y(), hi.z()});  // +x side
  AddQuad(scene.get(), {hi.x(), hi.y(), 0}, {lo.x(), hi.y(), 0}, {lo.x(), hi.y(), hi.z()},
          {hi.x(), hi.y(), hi.z()});  // +y side
  AddQuad(scene.get(), {lo.x(), hi.y(), 0}, {lo.x(), lo.y(), 0}, {lo.x(), lo.y(), hi.z()},
          {lo.x(), hi.y(), hi.z()});  // -x side
  return scene;
}

// Distance of a point from the scene's surfaces (the plane and the box's faces).
double DistanceToScene_m(const Eigen::Vector3d& p) {
  const double h = kTableHalfSize_m;
  double best = (std::abs(p.x()) <= h && std::abs(p.y()) <= h) ? std::abs(p.z()) : 1e9;
  const Eigen::Vector3d& lo = kBoxMin_m;
  const Eigen::Vector3d& hi = kBoxMax_m;
  const bool inside_slab[3] = {
      p.x() >= lo.x() - kOnSurfaceTolerance_m && p.x() <= hi.x() + kOnSurfaceTolerance_m,
      p.y() >= lo.y() - kOnSurfaceTolerance_m && p.y() <= hi.y() + kOnSurfaceTolerance_m,
      p.z() >= lo.z() - kOnSurfaceTolerance_m && p.z() <= hi.z() + kOnSurfaceTolerance_m};
  for (int axis = 0; axis < 3; ++axis) {
    if (!inside_slab[(axis + 1) % 3] || !inside_slab[(axis + 2) % 3]) continue;
    best = std::min({best, std::abs(p[axis] - lo[axis]), std::abs(p[axis] - hi[axis])});
  }
  return best;
}

// A projector 1.4 m above the table, tilted 12 degrees from straight down toward +y, an
// off-centre principal point and a little barrel distortion.
UnitCalibration DownwardUnit() {
  UnitCalibration unit;
  unit.unit_id = 7;
  unit.projector = CameraModel(640, 400, 820.0, 815.0, 301.3, 228.9,
                               BrownDistortion{-0.03, 0.01, 0.0005, -0.0003, 0.0});
  unit.camera = unit.projector;
  Eigen::Matrix3d down;  // columns: projector x (right), y (down), z (ahead) in the table frame
  down << 1, 0, 0,       //
      0, -1, 0,          //
      0, 0, -1;
  const Eigen::Matrix3d tilt =
      Eigen::AngleAxisd(12.0 / kDegFromRad, Eigen::Vector3d::UnitX()).matrix();
  unit.table_from_projector = Rigid3d(tilt * down, Eigen::Vector3d(0.03, -0.25, 1.4));
  return unit;
}

TEST(MpcdiBuilder, FrustumFromIntrinsicsAndPose) {
  const UnitCalibration unit = DownwardUnit();
  const CameraModel& p = unit.projector;
  const MpcdiFrustum f = MpcdiFrustumFromProjector(p, *unit.table_from_projector);
  EXPECT_NEAR(f.right_angle_deg, std::atan((639.5 - p.cx_px) / p.fx_px) * kDegFromRad,
              kAngleTolerance_deg);
  EXPECT_NEAR(f.left_angle_deg, -std::atan((p.cx_px + 0.5) / p.fx_px) * kDegFromRad,
              kAngleTolerance_deg);
  EXPECT_NEAR(f.up_angle_deg, std::atan((p.cy_px + 0.5) / p.fy_px) * kDegFromRad,
              kAngleTolerance_deg);
  EXPECT_NEAR(f.down_angle_deg, -std::atan((399.5 - p.cy_px) / p.fy_px) * kDegFromRad,
              kAngleTolerance_deg);
  EXPECT_GT(f.right_angle_deg, -f.left_angle_deg);  // cx left of centre: more to the right
  // The pose: C * Ry(yaw) Rx(pitch) Rz(roll) is table_from_projector; a projector tilted 12
  // degrees from straight down toward +y has pitch -78 and looks along +y.
  const MpcdiCoordinateFrame frame =
      MpcdiTableCoordinateFrame(unit.table_from_projector->translation);
  EXPECT_NEAR((MpcdiWorldFromViewer(f, frame) - unit.table_from_projector->RotationMatrix()).norm(),
              0.0, kRotationTolerance);
  EXPECT_NEAR(f.pitch_deg, -78.0, 1e-9);
  EXPECT_NEAR(f.yaw_deg, 0.0, 1e-9);
  EXPECT_NEAR(f.roll_deg, 0.0, 1e-9);
}

TEST(MpcdiBuilder, WarpSamplesLieOnTheSceneAndReprojectToTheirPixels) {
  const UnitCalibration unit = DownwardUnit();
  Expected<std::unique_ptr<RayCaster>> caster = RayCaster::Create(TableAndBox());
  ASSERT_TRUE(caster.ok()) << caster.status().ToString();
  const Expected<MpcdiWarp> warp =
      ComputeMpcdiWarp(unit.projector, *unit.table_from_projector, **caster, 16);
  ASSERT_TRUE(warp.ok()) << warp.status().ToString();
  EXPECT_EQ(warp->samples_x, 40);  // ceil(640 / 16)
  EXPECT_EQ(warp->samples_y, 25);  // ceil(400 / 16)
  const Rigid3d projector_from_table = unit.table_from_projector->Inverse();
  int on_box_top = 0, on_table = 0;
  for (int j = 0; j < warp->samples_y; ++j) {
    for (int i = 0; i < warp->samples_x; ++i) {
      const Eigen::Vector3d x = warp->samples[j * warp->samples_x + i].cast<double>();
      ASSERT_TRUE(x.allFinite()) << i << " " << j;  // the table fills the whole frustum
      EXPECT_LE(DistanceToScene_m(x), kOnSurfaceTolerance_m) << x.transpose();
      const std::optional<Eigen::Vector2d> pixel = unit.projector.Project(projector_from_table * x);
      ASSERT_TRUE(pixel.has_value());
      const Eigen::Vector2d expected((i + 0.5) * 640 / 40 - 0.5, (j + 0.5) * 400 / 25 - 0.5);
      EXPECT_NEAR((*pixel - expected).norm(), 0.0, kReprojectionTolerance_px) << i << " " << j;
      if (std::abs(x.z() - kBoxMax_m.z()) < kOnSurfaceTolerance_m) ++on_box_top;
      if (std::abs(x.z()) < kOnSurfaceTolerance_m) ++on_table;
    }
  }
  EXPECT_GT(on_box_top, 10);
  EXPECT_GT(on_table, 500);
}

TEST(MpcdiBuilder, SamplesThatHitNothingAreNaN) {
  UnitCalibration unit = DownwardUnit();
  // Looking horizontally along +y from 0.1 m above the table: the upper half sees nothing.
  Eigen::Matrix3d level;
  level << 1, 0, 0,  //
      0, 0, 1,       //
      0, -1, 0;
  unit.table_from_projector = Rigid3d(level, Eigen::Vector3d(0.0, -0.9, 0.1));
  Expected<std::unique_ptr<RayCaster>> caster = RayCaster::Create(TableAndBox());
  ASSERT_TRUE(caster.ok());
  const Expected<MpcdiWarp> warp =
      ComputeMpcdiWarp(unit.projector, *unit.table_from_projector, **caster, 32);
  ASSERT_TRUE(warp.ok()) << warp.status().ToString();
  int misses = 0, hits = 0;
  for (const Eigen::Vector3f& s : warp->samples) {
    if (std::isnan(s.x())) {
      EXPECT_TRUE(std::isnan(s.y()) && std::isnan(s.z()));
      ++misses;
    } else {
      EXPECT_LE(DistanceToScene_m(s.cast<double>()), kOnSurfaceTolerance_m);
      ++hits;
    }
  }
  EXPECT_GT(misses, 0);
  EXPECT_GT(hits, 0);
  // Top row misses (above the horizon), bottom row hits the table.
  EXPECT_TRUE(std::isnan(warp->samples.front().x()));
  EXPECT_FALSE(std::isnan(warp->samples.back().x()));
}

TEST(MpcdiBuilder, BuiltSiteWritesAndReadsBack) {
  std::vector<MpcdiUnit> units(2);
  units[0].calibration = DownwardUnit();
  units[1].calibration = DownwardUnit();
  units[1].calibration.unit_id = 8;
  units[1].calibration.table_from_projector->translation.x() += 0.2;
  units[1].region_id = "left-projector";
  MpcdiBuildOptions options;
  options.date = "2026-12-02 12:00:00";
  const Expected<MpcdiSite> site = BuildMpcdiSite(units, TableAndBox(), options);
  ASSERT_TRUE(site.ok()) << site.status().ToString();
  ASSERT_EQ(site->regions.size(), 2u);
  EXPECT_EQ(site->profile, "sl");
  EXPECT_EQ(site->regions[0].id, "unit-7");
  EXPECT_EQ(site->regions[1].id, "left-projector");
  EXPECT_EQ(site->buffer_x_resolution_px, 640);
  const MpcdiRegion& region = site->regions[0];
  EXPECT_EQ(region.x_resolution_px, 640);
  EXPECT_EQ(region.coordinate_frame->position,
            units[0].calibration.table_from_projector->translation);
  ASSERT_TRUE(region.alpha);
  EXPECT_EQ(region.alpha->width_px, 640);
  EXPECT_EQ(region.alpha->height_px, 400);
  EXPECT_TRUE(std::all_of(region.alpha->values.begin(), region.alpha->values.end(),
                          [](uint8_t v) { return v == 255; }));

  const std::string path = (std::filesystem::temp_directory_path() /
                            ("sandtable_mpcdi_builder_" + std::to_string(::getpid()) + ".mpcdi"))
                               .string();
  ASSERT_TRUE(WriteMpcdi(path, *site).ok());
  const Expected<MpcdiSite> read = ReadMpcdi(path);
  std::filesystem::remove(path);
  ASSERT_TRUE(read.ok()) << read.status().ToString();
  ASSERT_EQ(read->regions.size(), 2u);
  for (size_t r = 0; r < 2; ++r) {
    const MpcdiRegion& a = site->regions[r];
    const MpcdiRegion& b = read->regions[r];
    EXPECT_EQ(b.warp->samples, a.warp->samples);  // all finite here
    EXPECT_EQ(b.alpha->values, a.alpha->values);
    const Eigen::Matrix3d ra = MpcdiWorldFromViewer(*a.frustum, a.coordinate_frame);
    const Eigen::Matrix3d rb = MpcdiWorldFromViewer(*b.frustum, b.coordinate_frame);
    EXPECT_NEAR((ra - rb).norm(), 0.0, kRotationTolerance);
    EXPECT_NEAR((rb - units[r].calibration.table_from_projector->RotationMatrix()).norm(), 0.0,
                kRotationTolerance);
  }
}

TEST(MpcdiBuilder, RefusesAnUnregisteredUnit) {
  std::vector<MpcdiUnit> units(1);
  units[0].calibration = DownwardUnit();
  units[0].calibration.table_from_projector.reset();
  const Expected<MpcdiSite> site = BuildMpcdiSite(units, TableAndBox());
  ASSERT_FALSE(site.ok());
  EXPECT_EQ(site.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(site.status().message().find("unit_id 7"), std::string::npos);
  EXPECT_NE(site.status().message().find("table_from_projector"), std::string::npos);
  MpcdiBuildOptions options;
  options.warp_step_px = 0;
  units[0].calibration = DownwardUnit();
  EXPECT_EQ(BuildMpcdiSite(units, TableAndBox(), options).status().code(),
            StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace sandtable
