#include "common/camera/gl_projection.h"

#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "common/base/units.h"

namespace sandtable {
namespace {

// Double chain against CameraModel::Project: both are exact formulas, so only rounding is left.
constexpr double kGlVsCameraModel_px = 1e-8;
constexpr double kNdcDepth = 1e-12;
// The renderer's float chain (projection * view * vertex in float) against CameraModel in
// double, table distances 1-5 m, 1280x800 projector: worst difference measured 1.9e-4 px
// (FloatChainAgreesWithDoubleWithinNamedTolerance prints it); bound with 5x margin.
constexpr double kFloatVsDouble_px = 1e-3;

// TR09-017 projector (1280x800, throw ratio 1.27) with lens shift, and an off-centre principal
// point with fx != fy so a swapped or mirrored term cannot cancel out.
CameraModel Projector() { return CameraModel::FromThrowRatio(1280, 800, 1.27, 0.35); }
CameraModel OddCamera() { return CameraModel(1024, 768, 900.0, 880.0, 530.25, 370.75); }

// A point on the ray of `pixel` at depth z_m, in the camera frame.
Eigen::Vector3d PointAtPixel(const CameraModel& cam, const Eigen::Vector2d& pixel, double z_m) {
  const Expected<Eigen::Vector3d> ray = cam.Unproject(pixel);
  EXPECT_TRUE(ray.ok()) << ray.status().ToString();
  return *ray * z_m;
}

Eigen::Vector2d GlPixel(const Eigen::Matrix4d& clip_from_x, const Eigen::Vector3d& x, int w,
                        int h) {
  const Eigen::Vector4d clip = clip_from_x * x.homogeneous();
  return PixelFromNdc(clip.head<2>() / clip.w(), w, h);
}

TEST(GlProjectionTest, ViewportMappingHalfPixelAndFlip) {
  const int w = 1280, h = 800;
  // The image's outer corners: OpenCV (-0.5, -0.5) is the top-left corner = GL NDC (-1, +1).
  EXPECT_NEAR(NdcFromPixel({-0.5, -0.5}, w, h).x(), -1.0, kNdcDepth);
  EXPECT_NEAR(NdcFromPixel({-0.5, -0.5}, w, h).y(), 1.0, kNdcDepth);
  EXPECT_NEAR(NdcFromPixel({w - 0.5, h - 0.5}, w, h).x(), 1.0, kNdcDepth);
  EXPECT_NEAR(NdcFromPixel({w - 0.5, h - 0.5}, w, h).y(), -1.0, kNdcDepth);
  // Centre of OpenCV pixel (0, 0) = centre of GL window pixel (0, h - 1) = window (0.5, h - 0.5).
  const Eigen::Vector2d ndc = NdcFromPixel({0.0, 0.0}, w, h);
  EXPECT_NEAR((ndc.x() + 1.0) * 0.5 * w, 0.5, kGlVsCameraModel_px);
  EXPECT_NEAR((ndc.y() + 1.0) * 0.5 * h, h - 0.5, kGlVsCameraModel_px);
  const Eigen::Vector2d back = PixelFromNdc(ndc, w, h);
  EXPECT_NEAR(back.x(), 0.0, kGlVsCameraModel_px);
  EXPECT_NEAR(back.y(), 0.0, kGlVsCameraModel_px);
}

TEST(GlProjectionTest, EyeFromCameraFlipsYAndZ) {
  const Eigen::Vector4d forward = GlEyeFromCamera() * Eigen::Vector4d(0.1, 0.2, 2.0, 1.0);
  EXPECT_EQ(forward, Eigen::Vector4d(0.1, -0.2, -2.0, 1.0));  // exact: only sign flips
}

// Every pixel centre of a dense grid (corners and outer edges included) through both paths.
TEST(GlProjectionTest, VertexLandsOnCameraModelPixelOverWholeImage) {
  for (const CameraModel& cam : {Projector(), OddCamera()}) {
    const Expected<Eigen::Matrix4d> proj = GlProjectionFromCamera(cam, 0.1, 20.0);
    ASSERT_TRUE(proj.ok()) << proj.status().ToString();
    const Eigen::Matrix4d clip_from_camera = *proj * GlEyeFromCamera();
    double worst_px = 0.0;
    // 17 x 17 points from the outer corner (-0.5, -0.5) to (width - 0.5, height - 0.5).
    for (int j = 0; j <= 16; ++j) {
      for (int i = 0; i <= 16; ++i) {
        const double u = -0.5 + i * cam.width_px / 16.0, v = -0.5 + j * cam.height_px / 16.0;
        for (double z_m : {0.1, 1.0, 3.7, 20.0}) {
          const Eigen::Vector3d x = PointAtPixel(cam, {u, v}, z_m);
          const auto expected = cam.Project(x);
          ASSERT_TRUE(expected.has_value());
          const Eigen::Vector2d gl = GlPixel(clip_from_camera, x, cam.width_px, cam.height_px);
          worst_px = std::max(worst_px, (gl - *expected).norm());
          ASSERT_NEAR(gl.x(), expected->x(), kGlVsCameraModel_px) << cam.ToString();
          ASSERT_NEAR(gl.y(), expected->y(), kGlVsCameraModel_px) << cam.ToString();
        }
      }
    }
    RecordProperty("worst_double_px", std::to_string(worst_px));
  }
}

TEST(GlProjectionTest, ViewMatrixChainMatchesProjectOfTablePoints) {
  const CameraModel cam = Projector();
  // A projector 2 m above the table looking down at 70 degrees from horizontal.
  const Eigen::Matrix3d camera_rot =
      Eigen::AngleAxisd(DegToRad(-160.0), Eigen::Vector3d::UnitX()).toRotationMatrix();
  const Rigid3d camera_from_table(camera_rot, Eigen::Vector3d(0.05, -0.3, 2.2));
  const Expected<Eigen::Matrix4d> proj = GlProjectionFromCamera(cam, 0.5, 10.0);
  ASSERT_TRUE(proj.ok());
  const Eigen::Matrix4d clip_from_table = *proj * GlEyeFromTable(camera_from_table);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> xy(-0.8, 0.8), z(0.0, 0.3);
  int checked = 0;
  for (int i = 0; i < 2000; ++i) {
    const Eigen::Vector3d x_in_table(xy(rng), xy(rng), z(rng));
    const auto expected = cam.Project(camera_from_table * x_in_table);
    if (!expected.has_value()) continue;
    const Eigen::Vector2d gl = GlPixel(clip_from_table, x_in_table, cam.width_px, cam.height_px);
    ASSERT_NEAR(gl.x(), expected->x(), kGlVsCameraModel_px);
    ASSERT_NEAR(gl.y(), expected->y(), kGlVsCameraModel_px);
    ++checked;
  }
  EXPECT_GT(checked, 1000);
}

TEST(GlProjectionTest, DepthMapsNearToMinusOneAndFarToPlusOne) {
  const CameraModel cam = OddCamera();
  const double near_m = 0.25, far_m = 12.0;
  const Expected<Eigen::Matrix4d> proj = GlProjectionFromCamera(cam, near_m, far_m);
  ASSERT_TRUE(proj.ok());
  const Eigen::Matrix4d clip_from_camera = *proj * GlEyeFromCamera();
  auto ndc_depth = [&](double z_m, const Eigen::Vector2d& pixel) {
    const Eigen::Vector4d clip = clip_from_camera * PointAtPixel(cam, pixel, z_m).homogeneous();
    EXPECT_NEAR(clip.w(), z_m, kNdcDepth * z_m);  // w_clip is the depth along the axis
    return clip.z() / clip.w();
  };
  for (const Eigen::Vector2d& pixel :
       {Eigen::Vector2d(0, 0), Eigen::Vector2d(1023, 767), Eigen::Vector2d(cam.cx_px, cam.cy_px)}) {
    EXPECT_NEAR(ndc_depth(near_m, pixel), -1.0, kNdcDepth);
    EXPECT_NEAR(ndc_depth(far_m, pixel), 1.0, kNdcDepth);
    double previous = -1.0;
    for (double z_m = near_m * 1.01; z_m < far_m; z_m *= 1.3) {
      const double d = ndc_depth(z_m, pixel);
      EXPECT_GT(d, previous);  // strictly increasing, inside (-1, 1)
      EXPECT_LT(d, 1.0);
      previous = d;
    }
  }
}

TEST(GlProjectionTest, FloatChainAgreesWithDoubleWithinNamedTolerance) {
  const CameraModel cam = Projector();
  const Eigen::Matrix3d camera_rot =
      Eigen::AngleAxisd(DegToRad(-150.0), Eigen::Vector3d::UnitX()).toRotationMatrix();
  const Expected<Eigen::Matrix4d> proj = GlProjectionFromCamera(cam, 0.1, 100.0);
  ASSERT_TRUE(proj.ok());
  const Eigen::Matrix4f proj_f = proj->cast<float>();
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  double worst_px = 0.0;
  int checked = 0;
  for (double distance_m = 1.0; distance_m <= 5.0; distance_m += 1.0) {
    // Camera centre distance_m from the table origin; the table point is then ~distance_m away.
    const Rigid3d camera_from_table(camera_rot, Eigen::Vector3d(0.0, 0.0, distance_m));
    const Eigen::Matrix4f view_f = GlEyeFromTable(camera_from_table).cast<float>();
    for (int i = 0; i < 4000; ++i) {
      const Eigen::Vector2d pixel(unit(rng) * (cam.width_px - 1), unit(rng) * (cam.height_px - 1));
      const Eigen::Vector3d x_in_table =
          camera_from_table.Inverse() *
          PointAtPixel(cam, pixel, distance_m * (0.8 + 0.4 * unit(rng)));
      const auto expected = cam.Project(camera_from_table * x_in_table);
      ASSERT_TRUE(expected.has_value());
      // What the renderer does: everything in float, including the vertex and the divide.
      const Eigen::Vector4f clip = proj_f * (view_f * x_in_table.cast<float>().homogeneous());
      const Eigen::Vector2f ndc = clip.head<2>() / clip.w();
      const Eigen::Vector2f win((ndc.x() + 1.0f) * 0.5f * cam.width_px,
                                (ndc.y() + 1.0f) * 0.5f * cam.height_px);
      const Eigen::Vector2d gl(win.x() - 0.5, cam.height_px - win.y() - 0.5);
      worst_px = std::max(worst_px, (gl - *expected).norm());
      ++checked;
    }
  }
  std::printf("float vs double GL chain: worst %.3g px over %d vertices at 1-5 m\n", worst_px,
              checked);
  RecordProperty("worst_float_px", std::to_string(worst_px));
  EXPECT_LT(worst_px, kFloatVsDouble_px);
}

TEST(GlProjectionTest, RejectsBadClipPlanesAndCamera) {
  const CameraModel cam = OddCamera();
  EXPECT_EQ(GlProjectionFromCamera(cam, 0.0, 10.0).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(GlProjectionFromCamera(cam, -1.0, 10.0).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(GlProjectionFromCamera(cam, NAN, 10.0).status().code(), StatusCode::kInvalidArgument);
  const Status equal = GlProjectionFromCamera(cam, 2.0, 2.0).status();
  EXPECT_EQ(equal.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(equal.message().find("far_m"), std::string::npos) << equal.message();
  EXPECT_FALSE(GlProjectionFromCamera(cam, 2.0, 1.0).ok());
  EXPECT_FALSE(GlProjectionFromCamera(cam, 0.1, INFINITY).ok());
  CameraModel broken = cam;
  broken.fy_px = 0.0;
  const Status bad_camera = GlProjectionFromCamera(broken, 0.1, 10.0).status();
  EXPECT_EQ(bad_camera.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(bad_camera.message().find("fy_px"), std::string::npos) << bad_camera.message();
  EXPECT_TRUE(GlProjectionFromCamera(cam, 0.1, 10.0).ok());
}

}  // namespace
}  // namespace sandtable
