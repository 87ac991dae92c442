#include "common/estimation/triangulation.h"

#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include "common/base/units.h"

namespace sandtable {
namespace {

constexpr double kExactRelativeTolerance = 1e-9;  // of the distance to the cameras
constexpr double kExactReprojection_px = 1e-6;

CameraModel TestCamera() {
  BrownDistortion distortion;
  distortion.k1 = -0.12;
  distortion.k2 = 0.03;
  distortion.p1 = 5e-4;
  distortion.p2 = -3e-4;
  return CameraModel(1280, 800, 1100.0, 1100.0, 639.5, 399.5, distortion);
}

// camera_from_world of a camera at `centre` looking at `target` (world +z up; camera x right,
// y down, z forward).
Rigid3d LookAt(const Eigen::Vector3d& centre, const Eigen::Vector3d& target) {
  const Eigen::Vector3d z = (target - centre).normalized();
  Eigen::Vector3d up = Eigen::Vector3d::UnitZ();
  if (std::abs(z.dot(up)) > 0.99) up = Eigen::Vector3d::UnitY();
  const Eigen::Vector3d x = z.cross(up).normalized();
  const Eigen::Vector3d y = z.cross(x);
  Eigen::Matrix3d r;
  r.row(0) = x.transpose();
  r.row(1) = y.transpose();
  r.row(2) = z.transpose();
  return Rigid3d(r, -(r * centre));
}

TriangulationView Observe(const CameraModel& camera, const Rigid3d& camera_from_world,
                          const Eigen::Vector3d& point_in_world) {
  const auto pixel = camera.Project(camera_from_world * point_in_world);
  EXPECT_TRUE(pixel.has_value());
  return {camera, camera_from_world, pixel.value_or(Eigen::Vector2d::Zero())};
}

// Views from cameras on a circle of radius `radius_m` at height `height_m` above the point's
// neighbourhood, spread over `spread_deg` of azimuth, all looking at `look_at`.
std::vector<TriangulationView> Rig(int num_views, double spread_deg, double radius_m,
                                   double height_m, const Eigen::Vector3d& point,
                                   const Eigen::Vector3d& look_at, double scale = 1.0) {
  std::vector<TriangulationView> views;
  const CameraModel camera = TestCamera();
  for (int i = 0; i < num_views; ++i) {
    const double azimuth_rad =
        DegToRad(num_views == 1 ? 0.0 : spread_deg * (i / (num_views - 1.0) - 0.5));
    const Eigen::Vector3d centre =
        scale * Eigen::Vector3d(radius_m * std::sin(azimuth_rad), -radius_m * std::cos(azimuth_rad),
                                height_m);
    views.push_back(Observe(camera, LookAt(centre, scale * look_at), scale * point));
  }
  return views;
}

TEST(TriangulatePoint, ExactAtZeroNoiseForTwoToEightViews) {
  std::mt19937_64 rng(21);
  std::uniform_real_distribution<double> u(-0.3, 0.3);
  for (int num_views = 2; num_views <= 8; ++num_views) {
    for (int trial = 0; trial < 10; ++trial) {
      const Eigen::Vector3d point(u(rng), u(rng), 0.5 * std::abs(u(rng)));
      const auto views = Rig(num_views, 60.0, 1.5, 1.2, point, Eigen::Vector3d::Zero());
      auto report = TriangulatePoint(views);
      ASSERT_TRUE(report.ok()) << report.status().ToString();
      EXPECT_LT((report->point_in_world - point).norm(), kExactRelativeTolerance * 2.0);
      EXPECT_LT(report->rms_px, kExactReprojection_px);
      EXPECT_LT(report->midpoint_rms_px, kExactReprojection_px);
      double angle_deg = 0.0;
      for (const TriangulationView& a : views) {
        for (const TriangulationView& b : views) {
          const Eigen::Vector3d ra = point - a.camera_from_world.Inverse().translation;
          const Eigen::Vector3d rb = point - b.camera_from_world.Inverse().translation;
          angle_deg = std::max(angle_deg, RadToDeg(std::atan2(ra.cross(rb).norm(), ra.dot(rb))));
        }
      }
      constexpr double kAngleTolerance_deg = 1e-6;
      EXPECT_NEAR(report->angle_deg, angle_deg, kAngleTolerance_deg);
      EXPECT_EQ(report->num_views, num_views);
      EXPECT_GT(report->min_depth_m, 0.0);
    }
  }
}

TEST(TriangulatePoint, ScaleInvariant) {
  // The same rig scaled from 1 mm to 10 km gives the same pixels and the scaled point.
  const Eigen::Vector3d point(0.1, -0.05, 0.2);
  for (double scale : {1e-3, 1e-2, 1.0, 1e2, 1e4}) {
    const auto views = Rig(3, 40.0, 1.5, 1.2, point, Eigen::Vector3d::Zero(), scale);
    auto report = TriangulatePoint(views);
    ASSERT_TRUE(report.ok()) << report.status().ToString();
    EXPECT_LT((report->point_in_world - scale * point).norm(), kExactRelativeTolerance * scale)
        << scale;
    EXPECT_LT(report->rms_px, kExactReprojection_px) << scale;
  }
}

TEST(TriangulatePoint, NoiseSweepRefinementNeverWorseThanMidpoint) {
  // Camera + projector stereo pair, 25 deg apart, 1.6 m from the table. Pixel noise sigma.
  std::mt19937_64 rng(22);
  std::uniform_real_distribution<double> u(-0.3, 0.3);
  for (double sigma_px : {0.1, 0.5, 1.0, 2.0}) {
    std::normal_distribution<double> noise(0.0, sigma_px);
    double sum_sq_error_m = 0.0, sum_sq_midpoint_m = 0.0, sum_sq_rms_px = 0.0;
    constexpr int kTrials = 200;
    for (int trial = 0; trial < kTrials; ++trial) {
      const Eigen::Vector3d point(u(rng), u(rng), 0.0);
      auto views = Rig(2, 25.0, 1.5, 0.6, point, Eigen::Vector3d::Zero());
      for (TriangulationView& view : views) {
        view.observed_px += Eigen::Vector2d(noise(rng), noise(rng));
      }
      auto report = TriangulatePoint(views);
      ASSERT_TRUE(report.ok()) << report.status().ToString();
      EXPECT_LE(report->rms_px, report->midpoint_rms_px);
      TriangulationOptions no_refine;
      no_refine.refine = false;
      auto midpoint = TriangulatePoint(views, no_refine);
      ASSERT_TRUE(midpoint.ok());
      EXPECT_EQ(midpoint->iterations, 0);
      EXPECT_FALSE(midpoint->refined);
      sum_sq_error_m += (report->point_in_world - point).squaredNorm();
      sum_sq_midpoint_m += (midpoint->point_in_world - point).squaredNorm();
      sum_sq_rms_px += report->rms_px * report->rms_px;
    }
    const double rms_error_mm = MToMm(std::sqrt(sum_sq_error_m / kTrials));
    const double midpoint_error_mm = MToMm(std::sqrt(sum_sq_midpoint_m / kTrials));
    // Two views, 4 measurements, 3 unknowns: the squared residual sum is sigma^2 chi^2(1), so
    // E[rms_px^2] = sigma^2 / 2 (rms over the 2 views).
    const double mean_rms_px = std::sqrt(sum_sq_rms_px / kTrials);
    constexpr double kStatisticalTolerance = 0.2;  // relative, 200 trials
    EXPECT_NEAR(mean_rms_px / (sigma_px / std::sqrt(2.0)), 1.0, kStatisticalTolerance);
    // Depth error ~ sigma_px / f * distance / sin(angle) (~1.6 m, 25 deg, f = 1100 px).
    const double model_mm = MToMm(sigma_px / 1100.0 * 1.6 / std::sin(DegToRad(25.0)));
    constexpr double kModelFactor = 2.0;
    EXPECT_LT(rms_error_mm, kModelFactor * model_mm) << sigma_px;
    std::printf(
        "[ measured ] sigma %.1f px: 3D rms %.3f mm refined, %.3f mm midpoint "
        "(model %.3f mm), reprojection rms %.3f px\n",
        sigma_px, rms_error_mm, midpoint_error_mm, model_mm, mean_rms_px);
  }
}

TEST(TriangulatePoint, AngleCheckRefusesNarrowRays) {
  // Two cameras 1.5 m from the point, the baseline shrinking so the rays meet at 0.01 .. 10
  // deg. With min_angle_deg = 1 the check refuses below 1 deg and names the angle.
  const Eigen::Vector3d point(0.0, 0.0, 0.0);
  TriangulationOptions options;
  options.min_angle_deg = 1.0;
  for (double angle_deg : {0.01, 0.1, 0.5, 0.99, 1.01, 2.0, 5.0, 10.0}) {
    const auto views = Rig(2, angle_deg, 1.5, 0.0, point, point);
    auto report = TriangulatePoint(views, options);
    if (angle_deg < options.min_angle_deg) {
      ASSERT_FALSE(report.ok()) << angle_deg;
      EXPECT_EQ(report.status().code(), StatusCode::kDegenerate);
      EXPECT_NE(report.status().message().find("deg"), std::string::npos);
    } else {
      ASSERT_TRUE(report.ok()) << report.status().ToString();
      constexpr double kAngleTolerance_deg = 1e-6;
      EXPECT_NEAR(report->angle_deg, angle_deg, kAngleTolerance_deg);
      EXPECT_LT((report->point_in_world - point).norm(), kExactRelativeTolerance * 1.5);
    }
  }
}

TEST(TriangulatePoint, NarrowAngleErrorGrowthWithoutCheck) {
  // With the check off (min_angle_deg = 0), depth error at 0.5 px noise grows as 1/angle;
  // this records where it passes 1 mm at 1.5 m. Exact (noise-free) data must still be exact
  // down to 0.01 deg: near-parallel rays are solved, not garbage.
  std::mt19937_64 rng(23);
  std::normal_distribution<double> noise(0.0, 0.5);
  const Eigen::Vector3d point(0.0, 0.0, 0.0);
  TriangulationOptions options;
  options.min_angle_deg = 0.0;
  for (double angle_deg : {0.01, 0.1, 1.0, 5.0, 10.0, 20.0, 40.0}) {
    auto exact = TriangulatePoint(Rig(2, angle_deg, 1.5, 0.0, point, point), options);
    ASSERT_TRUE(exact.ok()) << exact.status().ToString();
    constexpr double kNarrowExactTolerance_m = 1e-6;
    EXPECT_LT((exact->point_in_world - point).norm(), kNarrowExactTolerance_m) << angle_deg;
    double sum_sq_m = 0.0;
    int num_ok = 0, num_behind = 0;
    constexpr int kTrials = 100;
    for (int trial = 0; trial < kTrials; ++trial) {
      auto views = Rig(2, angle_deg, 1.5, 0.0, point, point);
      for (TriangulationView& view : views) {
        view.observed_px += Eigen::Vector2d(noise(rng), noise(rng));
      }
      auto report = TriangulatePoint(views, options);
      if (!report.ok()) {
        // Noise can make near-parallel rays diverge (the point comes out behind a camera).
        EXPECT_EQ(report.status().code(), StatusCode::kOutOfRange) << report.status().ToString();
        ++num_behind;
        continue;
      }
      ++num_ok;
      sum_sq_m += (report->point_in_world - point).squaredNorm();
    }
    std::printf(
        "[ measured ] angle %.2f deg, 0.5 px noise at 1.5 m: 3D rms %.3f mm over %d "
        "points, %d refused as behind a camera\n",
        angle_deg, num_ok > 0 ? MToMm(std::sqrt(sum_sq_m / num_ok)) : 0.0, num_ok, num_behind);
  }
}

TEST(TriangulatePoint, PointBehindCameraRejected) {
  // Two cameras side by side looking along +y, each observing a pixel that leans outward:
  // the rays diverge and meet only behind the cameras.
  const CameraModel camera = TestCamera();
  const Rigid3d left = LookAt({-0.5, 0, 0}, {-0.5, 1, 0});
  const Rigid3d right = LookAt({0.5, 0, 0}, {0.5, 1, 0});
  const std::vector<TriangulationView> views = {Observe(camera, left, {-1.0, 1.0, 0.0}),
                                                Observe(camera, right, {1.0, 1.0, 0.0})};
  auto report = TriangulatePoint(views);
  ASSERT_FALSE(report.ok());
  EXPECT_EQ(report.status().code(), StatusCode::kOutOfRange) << report.status().ToString();
}

TEST(TriangulatePoint, RejectsBadInput) {
  const auto good = Rig(2, 30.0, 1.5, 1.0, Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero());
  EXPECT_EQ(TriangulatePoint({}).status().code(), StatusCode::kDegenerate);
  EXPECT_EQ(TriangulatePoint(std::span(good).first(1)).status().code(), StatusCode::kDegenerate);
  for (double bad :
       {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity()}) {
    auto views = good;
    views[1].observed_px.x() = bad;
    EXPECT_EQ(TriangulatePoint(views).status().code(), StatusCode::kInvalidArgument);
    views = good;
    views[0].camera_from_world.translation.y() = bad;
    EXPECT_EQ(TriangulatePoint(views).status().code(), StatusCode::kInvalidArgument);
  }
  auto views = good;
  views[0].camera.fx_px = 0.0;
  EXPECT_EQ(TriangulatePoint(views).status().code(), StatusCode::kInvalidArgument);
  TriangulationOptions options;
  options.min_angle_deg = -1.0;
  EXPECT_EQ(TriangulatePoint(good, options).status().code(), StatusCode::kInvalidArgument);
  options = TriangulationOptions();
  options.max_iterations = 0;
  EXPECT_EQ(TriangulatePoint(good, options).status().code(), StatusCode::kInvalidArgument);
}

TEST(TriangulatePoint, PixelPastTheDistortionFoldIsRefused) {
  // Strong barrel distortion: the corner pixel lies past the fold where the Brown model stops
  // being invertible; the camera refuses the ray and so does the triangulation.
  auto views = Rig(2, 30.0, 1.5, 1.0, Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero());
  views[0].camera.fx_px = views[0].camera.fy_px = 400.0;
  views[0].camera.distortion = BrownDistortion{-0.5, 0.0, 0.0, 0.0, 0.05};
  views[0].observed_px = Eigen::Vector2d(1279.0, 799.0);
  const auto ray = views[0].camera.Unproject(views[0].observed_px);
  ASSERT_FALSE(ray.ok()) << "precondition: this pixel must be past the fold";
  auto report = TriangulatePoint(views);
  ASSERT_FALSE(report.ok());
  EXPECT_EQ(report.status().code(), ray.status().code());
  EXPECT_NE(report.status().message().find("view 0"), std::string::npos);
}

TEST(MidpointOfRays, TwoSkewRaysAndParallelRays) {
  // Rays along x at z = 0 and along y at z = 2: the common perpendicular runs from (0,0,0)
  // to (0,0,2), midpoint (0,0,1).
  const std::vector<WorldRay> skew = {{{-1, 0, 0}, {1, 0, 0}}, {{0, 3, 2}, {0, -2, 0}}};
  auto midpoint = MidpointOfRays(skew);
  ASSERT_TRUE(midpoint.ok());
  EXPECT_LT((*midpoint - Eigen::Vector3d(0, 0, 1)).norm(), kExactRelativeTolerance);
  constexpr double kAngleTolerance_deg = 1e-12;
  EXPECT_NEAR(MaxRayAngle_deg(skew), 90.0, kAngleTolerance_deg);

  const std::vector<WorldRay> parallel = {{{0, 0, 0}, {0, 0, 1}}, {{1, 0, 0}, {0, 0, 2}}};
  EXPECT_EQ(MidpointOfRays(parallel).status().code(), StatusCode::kDegenerate);
  EXPECT_EQ(MaxRayAngle_deg(parallel), 0.0);
  const std::vector<WorldRay> zero = {{{0, 0, 0}, {0, 0, 0}}, {{1, 0, 0}, {0, 0, 1}}};
  EXPECT_EQ(MidpointOfRays(zero).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(MidpointOfRays(std::span(skew).first(1)).status().code(), StatusCode::kDegenerate);
}

TEST(RayThroughPixel, PassesThroughObservedPoint) {
  const CameraModel camera = TestCamera();
  const Rigid3d camera_from_world = LookAt({0.3, -1.5, 1.0}, {0, 0, 0});
  const Eigen::Vector3d point(0.2, 0.1, 0.05);
  const auto pixel = camera.Project(camera_from_world * point);
  ASSERT_TRUE(pixel.has_value());
  auto ray = RayThroughPixel(camera, camera_from_world, *pixel);
  ASSERT_TRUE(ray.ok());
  const Eigen::Vector3d to_point = point - ray->origin_in_world;
  EXPECT_LT(to_point.cross(ray->direction_in_world).norm(), kExactRelativeTolerance);
  EXPECT_GT(to_point.dot(ray->direction_in_world), 0.0);
  EXPECT_NEAR(ray->direction_in_world.norm(), 1.0, kExactRelativeTolerance);
}

}  // namespace
}  // namespace sandtable
