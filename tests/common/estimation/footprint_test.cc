// TableFootprint: a projector's image border on the table plane.
#include <gtest/gtest.h>

#include "common/estimation/footprint.h"

namespace sandtable {
namespace {

constexpr double kTolM = 1e-9;

// 1000 x 500 projector, f = 1000 px, 2 m above the table looking straight down, its image's
// right along the table's +x and its image's down along -y: the image covers x in [-1, 1],
// y in [-0.5, 0.5].
CameraModel Projector() { return CameraModel(1000, 500, 1000.0, 1000.0, 499.5, 249.5); }
Rigid3d LookingDown() {
  return Rigid3d(Eigen::Vector3d(1.0, -1.0, -1.0).asDiagonal().toDenseMatrix(),
                 Eigen::Vector3d(0.0, 0.0, 2.0));
}

TEST(FootprintTest, IsTheImageBorderOnTheTable) {
  const std::vector<Eigen::Vector2d> footprint = TableFootprint(Projector(), LookingDown(), 4);
  ASSERT_EQ(footprint.size(), 16u);
  const Eigen::Vector2d corners[4] = {{-1.0, 0.5}, {1.0, 0.5}, {1.0, -0.5}, {-1.0, -0.5}};
  for (int side = 0; side < 4; ++side) {  // top left, top right, bottom right, bottom left
    EXPECT_NEAR((footprint[4 * side] - corners[side]).norm(), 0.0, kTolM) << side;
  }
  for (const Eigen::Vector2d& p : footprint) {
    EXPECT_LE(std::abs(p.x()), 1.0 + kTolM);
    EXPECT_LE(std::abs(p.y()), 0.5 + kTolM);
  }
  EXPECT_NEAR(footprint[2].x(), 0.0, kTolM);  // the top edge's midpoint
  EXPECT_NEAR(footprint[2].y(), 0.5, kTolM);
}

TEST(FootprintTest, RaysThatMissTheTableAreLeftOut) {
  // Looking up, away from the table: nothing of it reaches the table.
  const Rigid3d up(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0.0, 0.0, 2.0));
  EXPECT_TRUE(TableFootprint(Projector(), up, 4).empty());
  // Tilted 80 degrees about x: the image's top half looks over the horizon.
  const Rigid3d tilted(
      Eigen::AngleAxisd(M_PI - 80.0 * M_PI / 180.0, Eigen::Vector3d::UnitX()).toRotationMatrix(),
      Eigen::Vector3d(0.0, 0.0, 2.0));
  const std::vector<Eigen::Vector2d> part = TableFootprint(Projector(), tilted, 4);
  EXPECT_GT(part.size(), 0u);
  EXPECT_LT(part.size(), 16u);
}

}  // namespace
}  // namespace sandtable
