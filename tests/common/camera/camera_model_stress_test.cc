// Stress and property tests of CameraModel: round trips over the whole image with no, mild and
// strong Brown distortion; refusal (never a wrong ray) past the fold of extreme distortion;
// non-finite input. Fixed seeds. docs/numerics.md reports the fold radii measured here.
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include "common/camera/camera_model.h"

namespace sandtable {
namespace {

// Undistort stops at |Distort(x) - x_d| < 1e-10 (normalized), i.e. 1e-7 px at fx = 1000 px;
// worst round trip measured with the strong wide lens below: 1.0e-7 px.
constexpr double kRoundTrip_px = 1e-6;
constexpr double kRayAngle_rad = 1e-9;
// Distorted radii this far inside / outside the fold's image must be accepted / refused.
constexpr double kFoldMargin = 1e-3;  // relative
// With p1 = p2 = 1e-3 the fold curve is no longer a circle: the first refusal moved by up to
// 0.3% of the radial fold's distorted radius (measured 0.478 vs 0.4792).
constexpr double kFoldMarginTangential = 1e-2;
constexpr double kNormalizedResidual = 1e-9;

struct Lens {
  const char* name;
  BrownDistortion distortion;
};

// 1280x800 at fx = 1000 px: corner half-diagonal 0.755 normalized, ~90 degrees diagonal field of
// view once the barrel distortion is undone ("wide").
CameraModel WideCamera(const BrownDistortion& d) {
  return CameraModel(1280, 800, 1000.0, 1001.0, 641.3, 398.2, d);
}

const Lens kLenses[] = {
    {"none", {}},
    {"mild", {-0.05, 0.01, 1e-4, -2e-4, 0.0}},
    {"strong", {-0.4, 0.2, 1e-3, -1.2e-3, -0.05}},
};

// Smallest radius where the radial map stops increasing, by bisection on its derivative
// (independent of CameraModel::InDistortionDomain); infinity if none below r_limit.
double FoldRadius(const BrownDistortion& d, double r_limit = 10.0) {
  auto derivative = [&](double r) {
    const double s = r * r;
    return 1.0 + 3.0 * d.k1 * s + 5.0 * d.k2 * s * s + 7.0 * d.k3 * s * s * s;
  };
  double lo = 0.0, hi = -1.0;
  for (double r = 1e-3; r < r_limit; r += 1e-3) {
    if (derivative(r) <= 0.0) {
      hi = r;
      break;
    }
    lo = r;
  }
  if (hi < 0.0) return std::numeric_limits<double>::infinity();
  for (int i = 0; i < 60; ++i) {
    const double mid = 0.5 * (lo + hi);
    (derivative(mid) > 0.0 ? lo : hi) = mid;
  }
  return lo;
}

double RadialMap(const BrownDistortion& d, double r) {
  const double s = r * r;
  return r * (1.0 + s * (d.k1 + s * (d.k2 + s * d.k3)));
}

// Dense pixel grid: every 4 px plus the last row/column and the outer corners of the sensor.
std::vector<Eigen::Vector2d> DenseGrid(const CameraModel& cam) {
  std::vector<double> us, vs;
  for (double u = -0.5; u < cam.width_px - 0.5; u += 4.0) us.push_back(u);
  for (double v = -0.5; v < cam.height_px - 0.5; v += 4.0) vs.push_back(v);
  us.push_back(cam.width_px - 1.0);
  us.push_back(cam.width_px - 0.5);
  vs.push_back(cam.height_px - 1.0);
  vs.push_back(cam.height_px - 0.5);
  std::vector<Eigen::Vector2d> grid;
  for (double v : vs) {
    for (double u : us) grid.emplace_back(u, v);
  }
  return grid;
}

TEST(CameraModelStressTest, PixelRoundTripOverWholeImage) {
  for (const Lens& lens : kLenses) {
    const CameraModel cam = WideCamera(lens.distortion);
    ASSERT_TRUE(cam.Check().ok());
    double worst_px = 0.0;
    for (const Eigen::Vector2d& pixel : DenseGrid(cam)) {
      const Expected<Eigen::Vector3d> ray = cam.Unproject(pixel);
      ASSERT_TRUE(ray.ok()) << lens.name << " " << pixel.transpose() << ": "
                            << ray.status().ToString();
      const auto back = cam.Project(*ray);
      ASSERT_TRUE(back.has_value()) << lens.name << " " << pixel.transpose();
      worst_px = std::max(worst_px, (*back - pixel).norm());
    }
    EXPECT_LT(worst_px, kRoundTrip_px) << lens.name;
    std::printf("%-6s lens: worst pixel round trip %.3g px\n", lens.name, worst_px);
  }
}

TEST(CameraModelStressTest, RayRoundTripForPointsInView) {
  std::mt19937 rng(20240611);
  std::uniform_real_distribution<double> lateral(-1.2, 1.2), depth(0.5, 5.0);
  for (const Lens& lens : kLenses) {
    const CameraModel cam = WideCamera(lens.distortion);
    int in_view = 0;
    for (int i = 0; i < 20000; ++i) {
      const double z_m = depth(rng);
      const Eigen::Vector3d x_in_camera(lateral(rng) * z_m, lateral(rng) * z_m, z_m);
      const auto pixel = cam.Project(x_in_camera);
      if (!pixel.has_value() || !cam.InImage(*pixel)) continue;
      ++in_view;
      const Expected<Eigen::Vector3d> ray = cam.Unproject(*pixel);
      ASSERT_TRUE(ray.ok()) << lens.name << ": " << ray.status().ToString();
      const double angle_rad = std::atan2(ray->cross(x_in_camera).norm(), ray->dot(x_in_camera));
      ASSERT_LT(angle_rad, kRayAngle_rad) << lens.name << " " << x_in_camera.transpose();
    }
    EXPECT_GT(in_view, 3000) << lens.name;  // measured 3553 with the strong lens
  }
}

// Extreme barrel lenses: past the fold Undistort refuses; inside it, it returns the ray on the
// valid branch. A wrong ray (a preimage beyond the fold) is never returned.
TEST(CameraModelStressTest, UndistortRefusesPastTheFoldNeverAWrongRay) {
  const BrownDistortion extreme[] = {
      {-0.5, -0.3, 0.0, 0.0, 0.0},    // fold at r = 0.676, distorted radius 0.479
      {-0.5, -0.1, 0.0, 0.0, 0.0},    // fold at r = 0.749
      {-0.5, 0.0, 0.0, 0.0, 0.05},    // folds, then unfolds (k3 > 0): three preimages
      {-0.5, -0.3, 1e-3, 1e-3, 0.0},  // with tangential terms
  };
  for (const BrownDistortion& d : extreme) {
    const CameraModel cam(1000, 1000, 300.0, 300.0, 499.5, 499.5, d);
    const double r_fold = FoldRadius(d);
    ASSERT_TRUE(std::isfinite(r_fold));
    const double rd_fold = RadialMap(d, r_fold);
    const bool radial_only = d.p1 == 0.0 && d.p2 == 0.0;
    const double margin = radial_only ? kFoldMargin : kFoldMarginTangential;
    int accepted = 0, refused = 0;
    for (int direction = 0; direction < 12; ++direction) {
      const double angle_rad = 0.1 + direction * 0.5;
      const Eigen::Vector2d unit(std::cos(angle_rad), std::sin(angle_rad));
      for (double rd = 0.0; rd < 2.0; rd += 2e-3) {
        const Eigen::Vector2d distorted = rd * unit;
        const Expected<Eigen::Vector2d> x = cam.Undistort(distorted);
        if (!x.ok()) {
          EXPECT_EQ(x.status().code(), StatusCode::kNotConverged) << x.status().ToString();
          EXPECT_GT(rd, rd_fold * (1.0 - margin)) << "refused inside the fold";
          ++refused;
          continue;
        }
        ++accepted;
        EXPECT_LT((cam.Distort(*x) - distorted).norm(), kNormalizedResidual);
        EXPECT_LT(x->norm(), r_fold) << "wrong branch for distorted radius " << rd;
        if (radial_only) {
          EXPECT_LT(rd, rd_fold * (1.0 + kFoldMargin)) << "accepted past the fold";
        }
      }
    }
    EXPECT_GT(accepted, 100);
    EXPECT_GT(refused, 100);
  }
}

// A 3D point past the fold would otherwise be drawn on a pixel that belongs to another ray.
TEST(CameraModelStressTest, ProjectRefusesPointsPastTheFold) {
  const BrownDistortion d{-0.5, -0.3, 0.0, 0.0, 0.0};
  const CameraModel cam(1000, 1000, 300.0, 300.0, 499.5, 499.5, d);
  const double r_fold = FoldRadius(d);
  EXPECT_TRUE(cam.Project(Eigen::Vector3d(0.99 * r_fold, 0.0, 1.0)).has_value());
  EXPECT_TRUE(cam.InDistortionDomain({0.0, 0.99 * r_fold}));
  EXPECT_FALSE(cam.InDistortionDomain({0.0, 1.01 * r_fold}));
  // r = 1.33: the radial factor is negative, the pixel would be on the opposite side.
  EXPECT_FALSE(cam.Project(Eigen::Vector3d(1.33, 0.0, 1.0)).has_value());
  EXPECT_FALSE(cam.Project(Eigen::Vector3d(0.0, 1.01 * r_fold, 1.0)).has_value());
  // Without distortion the whole half-space projects.
  const CameraModel pinhole(1000, 1000, 300.0, 300.0, 499.5, 499.5);
  EXPECT_TRUE(pinhole.Project(Eigen::Vector3d(100.0, -50.0, 1.0)).has_value());
}

TEST(CameraModelStressTest, NonFiniteInputsAreErrors) {
  const CameraModel cam = WideCamera(kLenses[2].distortion);
  constexpr double kNan = std::numeric_limits<double>::quiet_NaN();
  constexpr double kInf = std::numeric_limits<double>::infinity();
  for (const Eigen::Vector2d& bad :
       {Eigen::Vector2d(kNan, 0.0), Eigen::Vector2d(0.0, kInf), Eigen::Vector2d(-kInf, kNan)}) {
    EXPECT_EQ(cam.Unproject(bad).status().code(), StatusCode::kInvalidArgument);
    EXPECT_EQ(cam.Undistort(bad).status().code(), StatusCode::kInvalidArgument);
    EXPECT_FALSE(cam.InDistortionDomain(bad));
  }
  EXPECT_FALSE(cam.Project(Eigen::Vector3d(kNan, 0.0, 1.0)).has_value());
  EXPECT_FALSE(cam.Project(Eigen::Vector3d(0.0, 0.0, kInf)).has_value());
  EXPECT_FALSE(cam.Project(Eigen::Vector3d(kInf, 0.0, 1.0)).has_value());
  // Finite but huge: x/z^2 overflows; no Inf pixel comes out.
  const CameraModel pinhole(640, 480, 500.0, 500.0, 319.5, 239.5);
  const auto huge = pinhole.Project(Eigen::Vector3d(1e300, 0.0, 1e-300));
  EXPECT_TRUE(!huge.has_value() || huge->allFinite());
  // A model with a NaN coefficient fails Check() and never returns a ray.
  CameraModel broken = cam;
  broken.distortion.k2 = kNan;
  EXPECT_FALSE(broken.Check().ok());
  EXPECT_FALSE(broken.Unproject({640.0, 400.0}).ok());
}

TEST(CameraModelStressTest, UndistortOptionsAreChecked) {
  UndistortOptions options;
  EXPECT_TRUE(options.Check().ok());
  options.max_iterations = 0;
  EXPECT_FALSE(options.Check().ok());
  options.max_iterations = 30;
  options.tolerance = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(options.Check().ok());
}

}  // namespace
}  // namespace sandtable
