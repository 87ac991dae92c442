// The world's per-projector ground truth keeps "has a true pixel" (projectable) apart from
// "is lit" (visible): outside the image, grazing, self-shadowed and cast-shadowed points are
// not lit but keep their projection; a point behind the projector has none.
#include <gtest/gtest.h>

#include <cmath>
#include <optional>

#include "common/scene/procedural_scene.h"
#include "sim/site/site_presets.h"
#include "sim/transport/transport_map.h"
#include "sim/transport/world.h"

namespace sandtable::sim {
namespace {

// The world projects through the projector pose as a matrix, the test through Rigid3d.
constexpr double kPixelTolerance_px = 1e-6;
// Unproject then project (the model's iterative undistortion).
constexpr double kRoundTripTolerance_px = 1e-4;

Site OneProjectorSite(const Eigen::Vector3d& eye, const Eigen::Vector3d& target) {
  Site site;
  site.name = "truth";
  site.table.is_disc = false;
  site.table.size_m = {6.0, 6.0};
  UnitSpec unit;
  unit.id = 3;
  unit.projector = DefaultProjector();
  unit.projector.table_from_projector =
      *TableFromDeviceLookAt(eye, target, Eigen::Vector3d::UnitY());
  site.units.push_back(unit);
  return site;
}

// A 6 m table with one box x in [0.25, 0.375], y in [-0.0625, 0.0625], z in [0, 0.125], and a
// lone vertical wall (no top, no back) in the plane x = -0.25: y in [-0.25, 0.25], z in
// [0, 0.25]. Dyadic corners: the float vertices hold them exactly.
Scene TableBoxAndWall() {
  Scene scene = MakeRectangleMesh({6.0, 6.0}, 0);
  scene.materials = {Material{"white", {0.8, 0.8, 0.8, 1.0}, -1}};
  scene.Append(MakeBoxMesh({0.3125, 0.0, 0.0}, {0.125, 0.125, 0.125}, 0.0, 0));
  const int base = scene.NumVertices();
  scene.positions_in_table_m.push_back({-0.25f, -0.25f, 0.0f});
  scene.positions_in_table_m.push_back({-0.25f, 0.25f, 0.0f});
  scene.positions_in_table_m.push_back({-0.25f, 0.25f, 0.25f});
  scene.positions_in_table_m.push_back({-0.25f, -0.25f, 0.25f});
  scene.triangles.push_back({base, base + 1, base + 2});
  scene.triangles.push_back({base, base + 2, base + 3});
  scene.triangle_material.push_back(0);
  scene.triangle_material.push_back(0);
  return scene;
}

class ProjectorTruthTest : public ::testing::Test {
 protected:
  void Make(const Eigen::Vector3d& eye, const Eigen::Vector3d& target) {
    Expected<std::unique_ptr<World>> world =
        World::Create(OneProjectorSite(eye, target), TableBoxAndWall());
    ASSERT_TRUE(world.ok()) << world.status().ToString();
    world_ = std::move(*world);
    ASSERT_TRUE(world_->SetProjectorUniform(3, 255).ok());
  }
  const ProjectorSpec& projector() const { return world_->site().units[0].projector; }
  // The test's own projection of a table point (nullopt behind the projector).
  std::optional<Eigen::Vector2d> Projection(const Eigen::Vector3d& point) const {
    return projector().model.Project(projector().table_from_projector.Inverse() * point);
  }
  ProjectorTruth Truth(const Eigen::Vector3d& point) const {
    Expected<ProjectorTruth> truth = world_->ProjectorTruthAtPoint(3, point);
    EXPECT_TRUE(truth.ok()) << truth.status().ToString();
    return truth.ok() ? *truth : ProjectorTruth();
  }
  // Not lit, but with its true pixel.
  void ExpectUnlitWithPixel(const Eigen::Vector3d& point, const char* what) const {
    SCOPED_TRACE(what);
    const std::optional<Eigen::Vector2d> expected = Projection(point);
    ASSERT_TRUE(expected.has_value()) << "test setup: the point must be in front";
    const ProjectorTruth truth = Truth(point);
    EXPECT_EQ(truth.unit, 3u);
    EXPECT_TRUE(truth.sample.projectable);
    EXPECT_FALSE(truth.sample.visible);
    EXPECT_NEAR(truth.sample.pixel_px.x(), expected->x(), kPixelTolerance_px);
    EXPECT_NEAR(truth.sample.pixel_px.y(), expected->y(), kPixelTolerance_px);
    EXPECT_EQ(truth.sample.gain_per_m2, 0.0);
    EXPECT_EQ(truth.luminance_nits, 0.0);
  }
  std::unique_ptr<World> world_;
};

TEST_F(ProjectorTruthTest, LitPointHasItsPixel) {
  ASSERT_NO_FATAL_FAILURE(Make({0.0, 0.0, 1.0}, {0.0, 0.0, 0.0}));
  const Eigen::Vector3d point(0.0625, -0.125, 0.0);
  const std::optional<Eigen::Vector2d> expected = Projection(point);
  ASSERT_TRUE(expected && projector().model.InImage(*expected));
  const ProjectorTruth truth = Truth(point);
  EXPECT_TRUE(truth.sample.projectable);
  EXPECT_TRUE(truth.sample.visible);
  EXPECT_NEAR(truth.sample.pixel_px.x(), expected->x(), kPixelTolerance_px);
  EXPECT_NEAR(truth.sample.pixel_px.y(), expected->y(), kPixelTolerance_px);
  EXPECT_GT(truth.sample.gain_per_m2, 0.0);
  EXPECT_GT(truth.luminance_nits, 0.0);
}

TEST_F(ProjectorTruthTest, OutsideTheImageKeepsItsPixel) {
  ASSERT_NO_FATAL_FAILURE(Make({0.0, 0.0, 1.0}, {0.0, 0.0, 0.0}));
  // The table point that the pixel 40 px below the image's bottom edge would light (clear of
  // the box and the wall).
  const CameraModel& model = projector().model;
  const Eigen::Vector2d outside(0.5 * model.width_px, model.height_px + 40.0);
  Expected<Eigen::Vector3d> ray = model.Unproject(outside);
  ASSERT_TRUE(ray.ok()) << ray.status().ToString();
  const Rigid3d& table_from_projector = projector().table_from_projector;
  const Eigen::Vector3d direction = table_from_projector.rotation * *ray;
  const Eigen::Vector3d centre = table_from_projector.translation;
  const Eigen::Vector3d point = centre - centre.z() / direction.z() * direction;
  ASSERT_FALSE(model.InImage(*Projection(point)));
  ExpectUnlitWithPixel(point, "outside the image");
  EXPECT_NEAR(Truth(point).sample.pixel_px.y(), outside.y(), kRoundTripTolerance_px);
}

TEST_F(ProjectorTruthTest, GrazingPointKeepsItsPixel) {
  // The projector's centre lies in the wall's plane x = -0.25: its rays run along the wall.
  ASSERT_NO_FATAL_FAILURE(Make({-0.25, 0.0, 1.0}, {-0.25, 0.0, 0.0}));
  ExpectUnlitWithPixel({-0.25, 0.125, 0.125}, "grazing the wall");
}

TEST_F(ProjectorTruthTest, SelfShadowedPointKeepsItsPixel) {
  ASSERT_NO_FATAL_FAILURE(Make({0.0, 0.0, 1.0}, {0.0, 0.0, 0.0}));
  // The box's far face (x = 0.375, facing +x, away from the projector): its own box hides it.
  ExpectUnlitWithPixel({0.375, 0.0, 0.0625}, "the box's far face");
  // The wall's near side is lit ...
  EXPECT_TRUE(Truth({-0.25, 0.0, 0.125}).sample.visible);
  // ... and the table behind the wall is in its cast shadow.
  ExpectUnlitWithPixel({-0.3125, 0.0, 0.0}, "the table in the wall's shadow");
  // The table just beyond the box, in its cast shadow.
  ExpectUnlitWithPixel({0.40625, 0.0, 0.0}, "the table in the box's shadow");
}

TEST_F(ProjectorTruthTest, BehindTheProjectorHasNoPixel) {
  // Looking sideways and down, towards +x: the table at x < 0 is behind the projector.
  ASSERT_NO_FATAL_FAILURE(Make({0.0, 0.0, 1.0}, {2.0, 0.0, 0.0}));
  for (const Eigen::Vector3d& point :
       {Eigen::Vector3d(-1.0, 0.0, 0.0), Eigen::Vector3d(0.0, 0.0, 2.0)}) {  // table; in the air
    ASSERT_FALSE(Projection(point).has_value()) << "test setup: the point must be behind";
    const ProjectorTruth truth = Truth(point);
    EXPECT_FALSE(truth.sample.projectable) << point.transpose();
    EXPECT_FALSE(truth.sample.visible) << point.transpose();
    EXPECT_EQ(truth.luminance_nits, 0.0);
  }
}

TEST_F(ProjectorTruthTest, SampleProjectorFillsThePixelOfAnySideOrAngle) {
  ASSERT_NO_FATAL_FAILURE(Make({0.0, 0.0, 1.0}, {0.0, 0.0, 0.0}));
  const Eigen::Vector3d point(0.0, 0.0, 0.0);  // straight below the projector's centre
  const std::optional<Eigen::Vector2d> expected = Projection(point);
  ASSERT_TRUE(expected.has_value());
  struct Case {
    Eigen::Vector3d normal;
    bool lit;
    const char* what;
  };
  const Case cases[] = {{{0, 0, 1}, true, "facing"},
                        {{0, 0, -1}, false, "facing away"},
                        {{1, 0, 0}, false, "grazing"}};  // exactly perpendicular to the ray
  for (const Case& c : cases) {
    const ProjectorSample s = SampleProjector(projector(), world_->caster(), point, c.normal);
    EXPECT_EQ(s.visible, c.lit) << c.what;
    EXPECT_TRUE(s.projectable) << c.what;
    EXPECT_NEAR(s.pixel_px.x(), expected->x(), kPixelTolerance_px) << c.what;
    EXPECT_NEAR(s.pixel_px.y(), expected->y(), kPixelTolerance_px) << c.what;
    EXPECT_EQ(s.gain_per_m2 > 0.0, c.lit) << c.what;
  }
  const ProjectorSample projected = ProjectPoint(projector(), point);
  EXPECT_TRUE(projected.projectable);
  EXPECT_FALSE(projected.visible);
  EXPECT_NEAR(projected.pixel_px.x(), expected->x(), kPixelTolerance_px);
}

}  // namespace
}  // namespace sandtable::sim
