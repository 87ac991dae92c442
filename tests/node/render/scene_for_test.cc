// RenderLoop::SceneFor without a model placement: the table plane holds the projector's
// footprint, wherever the projector stands (a site wider than 3 m: grid-12's outer projectors
// used to light nothing, and their blend masks were black).
#include <gtest/gtest.h>

#include "common/scene/ray_caster.h"
#include "node/render/render_loop.h"

namespace sandtable::node {
namespace {

UnitCalibration LookingDownFrom(const Eigen::Vector3d& centre) {
  UnitCalibration c;
  c.projector = CameraModel::FromThrowRatio(1280, 800, 1.27);
  // Optical axis (+z) straight down: 180 degrees about x.
  c.table_from_projector = Rigid3d(Eigen::Quaterniond(0.0, 1.0, 0.0, 0.0), centre);
  return c;
}

TEST(SceneForTest, TheTablePlaneHoldsTheProjectorsFootprint) {
  for (const Eigen::Vector3d& centre :
       {Eigen::Vector3d(0.0, 0.0, 1.5), Eigen::Vector3d(4.0, -1.0, 1.5),
        Eigen::Vector3d(-6.0, 3.0, 2.5)}) {
    SCOPED_TRACE(centre.transpose());
    const UnitCalibration c = LookingDownFrom(centre);
    auto scene = std::make_shared<const Scene>(RenderLoop::SceneFor(nullptr, c));
    ASSERT_EQ(scene->NumTriangles(), 2);
    // The 3 x 3 m about the origin stays.
    const Eigen::AlignedBox3d b = scene->Bounds();
    EXPECT_LE(b.min().x(), -1.5);
    EXPECT_GE(b.max().y(), 1.5);
    EXPECT_NEAR(b.min().z(), 0.0, 1e-9);
    EXPECT_NEAR(b.max().z(), 0.0, 1e-9);
    // Every pixel's ray meets it: the corners' and the centre's.
    Expected<std::unique_ptr<RayCaster>> caster = RayCaster::Create(scene);
    ASSERT_TRUE(caster.ok()) << caster.status().ToString();
    const Eigen::Matrix3d rotation = c.table_from_projector->RotationMatrix();
    for (const Eigen::Vector2d& pixel :
         {Eigen::Vector2d(-0.5, -0.5), Eigen::Vector2d(1279.5, -0.5), Eigen::Vector2d(-0.5, 799.5),
          Eigen::Vector2d(1279.5, 799.5), Eigen::Vector2d(640, 400)}) {
      Expected<Eigen::Vector3d> ray = c.projector.Unproject(pixel);
      ASSERT_TRUE(ray.ok());
      Ray r;
      r.origin_in_table_m = centre;
      r.direction_in_table = rotation * *ray;
      EXPECT_TRUE((*caster)->Intersect(r).has_value()) << pixel.transpose();
    }
  }
}

}  // namespace
}  // namespace sandtable::node
