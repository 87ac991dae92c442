#include "common/camera/camera_model.h"

#include <gtest/gtest.h>

namespace sandtable {
namespace {

constexpr double kTolerance_px = 1e-9;

// OpenCV convention: pixel (0, 0) is centred at (0.0, 0.0). A point on the optical axis lands
// exactly on (cx, cy); a point one focal length off lands one pixel further.
TEST(CameraModelTest, PixelCentreConvention) {
  const CameraModel cam(4, 3, 100.0, 100.0, 0.0, 0.0);
  const auto centre = cam.Project(Eigen::Vector3d(0.0, 0.0, 1.0));
  ASSERT_TRUE(centre.has_value());
  EXPECT_NEAR(centre->x(), 0.0, kTolerance_px);  // centre of the top-left pixel
  EXPECT_NEAR(centre->y(), 0.0, kTolerance_px);
  const auto next = cam.Project(Eigen::Vector3d(0.01, 0.02, 1.0));
  ASSERT_TRUE(next.has_value());
  EXPECT_NEAR(next->x(), 1.0, kTolerance_px);
  EXPECT_NEAR(next->y(), 2.0, kTolerance_px);
  EXPECT_TRUE(cam.InImage({-0.5, -0.5}));
  EXPECT_FALSE(cam.InImage({-0.51, 0.0}));
  EXPECT_TRUE(cam.InImage({3.49, 2.49}));
  EXPECT_FALSE(cam.InImage({3.5, 0.0}));
}

TEST(CameraModelTest, BehindCameraAndNonFiniteDoNotProject) {
  const CameraModel cam(640, 480, 500, 500, 319.5, 239.5);
  EXPECT_FALSE(cam.Project(Eigen::Vector3d(0, 0, -1)).has_value());
  EXPECT_FALSE(cam.Project(Eigen::Vector3d(0, 0, 0)).has_value());
  EXPECT_FALSE(cam.Project(Eigen::Vector3d(NAN, 0, 1)).has_value());
  EXPECT_FALSE(cam.Unproject(Eigen::Vector2d(INFINITY, 0)).ok());
}

TEST(CameraModelTest, CheckNamesTheBrokenField) {
  CameraModel cam(640, 480, -5, 500, 319.5, 239.5);
  const Status s = cam.Check();
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("fx_px"), std::string::npos) << s.message();
  cam.fx_px = 500;
  EXPECT_TRUE(cam.Check().ok());
  cam.distortion.k2 = NAN;
  EXPECT_FALSE(cam.Check().ok());
}

TEST(CameraModelTest, ThrowRatioGivesFocalLength) {
  // TR09-017 projectors: 1280 px wide, throw ratio 1.27.
  const CameraModel proj = CameraModel::FromThrowRatio(1280, 800, 1.27);
  EXPECT_NEAR(proj.fx_px, 1625.6, 1e-9);
  EXPECT_NEAR(proj.cx_px, 639.5, 1e-12);
}

}  // namespace
}  // namespace sandtable
