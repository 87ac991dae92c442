#include "common/estimation/resection.h"

#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <random>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include "common/base/units.h"
#include "tests/common/estimation/estimation_test_util.h"

namespace sandtable {
namespace {

constexpr double kExact_px = 1e-6;       // reprojection rms of noise-free recoveries
constexpr double kExactRelative = 1e-7;  // relative error of recovered parameters, no noise
constexpr double kExactRotation_rad = 1e-8;
constexpr double kExactDistortion = 1e-6;  // absolute, dimensionless coefficients

// A realistic camera (1280x800, fx ~ 1600 px, barrel distortion) 1.6 m from the world origin,
// looking at it from `view_deg` off the world +z axis. Points: uniform in a 1 m x 1 m square
// (x, y) with z uniform in [-half_thickness_m, half_thickness_m], kept when they land on the
// image. half_thickness_m = 0 gives a coplanar target.
struct Scene {
  CameraModel camera;
  Rigid3d camera_from_world;
  std::vector<Eigen::Vector3d> world_m;
  std::vector<Eigen::Vector2d> pixels;  // exact projections
};

Scene MakeScene(int n, uint64_t seed, double half_thickness_m, double view_deg = 30.0) {
  Scene s;
  s.camera = CameraModel(1280, 800, 1600.0, 1605.0, 645.0, 398.0,
                         BrownDistortion{-0.12, 0.05, 0.001, -0.0008, 0.0});
  const double a = DegToRad(view_deg);
  const Eigen::Vector3d centre_in_world(1.6 * std::sin(a), 0.1, 1.6 * std::cos(a));
  const Eigen::Vector3d z = (-centre_in_world).normalized();
  const Eigen::Vector3d x = Eigen::Vector3d::UnitY().cross(z).normalized();
  const Eigen::Vector3d y = z.cross(x);
  Eigen::Matrix3d r;
  r.row(0) = x;
  r.row(1) = y;
  r.row(2) = z;
  s.camera_from_world = Rigid3d(r, -r * centre_in_world);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> in_plane(-0.5, 0.5), out_of_plane(-1.0, 1.0);
  while (static_cast<int>(s.world_m.size()) < n) {
    const Eigen::Vector3d p(in_plane(rng), in_plane(rng), half_thickness_m * out_of_plane(rng));
    const std::optional<Eigen::Vector2d> u = s.camera.Project(s.camera_from_world * p);
    if (!u || !s.camera.InImage(*u)) continue;
    s.world_m.push_back(p);
    s.pixels.push_back(*u);
  }
  return s;
}

using test_util::AddNoise;
using test_util::SweepLog;

// Error of the estimated model itself: rms over the points of |u_hat - u_true| in px.
double ModelError_px(const ResectionResult& r, const Scene& s) {
  return ReprojectionRms_px(r.camera, r.camera_from_world, s.world_m, s.pixels);
}

double RelativeFocalError(const ResectionResult& r, const Scene& s) {
  return std::max(std::abs(r.camera.fx_px / s.camera.fx_px - 1.0),
                  std::abs(r.camera.fy_px / s.camera.fy_px - 1.0));
}

double CentreError_m(const ResectionResult& r, const Scene& s) {
  return (r.camera_from_world.Inverse().translation - s.camera_from_world.Inverse().translation)
      .norm();
}

ResectionOptions KnownCamera(const Scene& s) {
  ResectionOptions o;
  o.fix_intrinsics = true;
  o.fix_distortion = true;
  o.initial_camera = s.camera;
  return o;
}

TEST(ResectionTest, ExactRecoveryWithoutNoise) {
  const Scene s = MakeScene(200, 1, 0.3);
  const Expected<ResectionResult> r = EstimateResection(s.world_m, s.pixels, 1280, 800);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->report.initializer, "dlt");
  EXPECT_TRUE(r->report.converged) << r->report.message;
  EXPECT_LT(r->report.final_rms_px, kExact_px);
  EXPECT_LT(RelativeFocalError(*r, s), kExactRelative);
  EXPECT_NEAR(r->camera.cx_px, s.camera.cx_px, kExactRelative * s.camera.fx_px);
  EXPECT_NEAR(r->camera.cy_px, s.camera.cy_px, kExactRelative * s.camera.fx_px);
  const std::array<double, 5> d = r->camera.distortion.ToArray();
  const std::array<double, 5> d_true = s.camera.distortion.ToArray();
  for (int i = 0; i < 5; ++i) EXPECT_NEAR(d[i], d_true[i], kExactDistortion) << "coeff " << i;
  EXPECT_LT(RotationAngleBetween_rad(r->camera_from_world, s.camera_from_world),
            kExactRotation_rad);
  EXPECT_LT(CentreError_m(*r, s), kExactRelative);
  EXPECT_EQ(r->camera.width_px, 1280);
  EXPECT_EQ(r->camera.height_px, 800);
  EXPECT_EQ(r->report.num_points, 200);
  EXPECT_EQ(r->report.num_free_parameters, 15);
}

TEST(ResectionTest, AcceptanceReachesNoiseFloor) {
  // 200 points, 0.5 px per axis: the ML estimate's rms residual is expected at
  // sigma sqrt(2) sqrt(1 - p / (2n)) with p = 15 free parameters.
  constexpr double kSigma_px = 0.5;
  constexpr double kFloorTolerance = 0.10;   // relative
  constexpr double kFocalTolerance = 0.003;  // relative (0.3 %)
  const Scene s = MakeScene(200, 2, 0.3);
  const Expected<ResectionResult> r =
      EstimateResection(s.world_m, AddNoise(s.pixels, kSigma_px, 3), 1280, 800);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  const int p = r->report.num_free_parameters;
  const double floor_px = kSigma_px * std::sqrt(2.0) * std::sqrt(1.0 - p / (2.0 * 200));
  EXPECT_NEAR(r->report.final_rms_px / floor_px, 1.0, kFloorTolerance);
  EXPECT_LT(RelativeFocalError(*r, s), kFocalTolerance);
  EXPECT_LE(r->report.final_rms_px, r->report.initial_rms_px);
  EXPECT_GT(r->report.solve_time.count(), 0.0);
  // The reported uncertainty is consistent with the actual error.
  constexpr double kMaxSigmas = 4.0;
  ASSERT_TRUE(r->report.uncertainty_available);
  EXPECT_GT(r->report.fx_std_px, 0.0);
  EXPECT_LT(std::abs(r->camera.fx_px - s.camera.fx_px), kMaxSigmas * r->report.fx_std_px);
  EXPECT_LT(std::abs(r->camera.cx_px - s.camera.cx_px), kMaxSigmas * r->report.cx_std_px);
  EXPECT_LT(RotationAngleBetween_rad(r->camera_from_world, s.camera_from_world),
            kMaxSigmas * r->report.rotation_std_rad);
  SweepLog(
      "acceptance: final rms %.4f px, floor %.4f px (ratio %.4f), focal error %.4f %%, "
      "fx %.2f +- %.2f px, %d iterations, %.2f ms\n",
      r->report.final_rms_px, floor_px, r->report.final_rms_px / floor_px,
      100.0 * RelativeFocalError(*r, s), r->camera.fx_px, r->report.fx_std_px, r->report.iterations,
      1e3 * r->report.solve_time.count());
}

TEST(ResectionTest, FewPointsAreRefusedOrReportLargeUncertainty) {
  // With all 15 parameters free, 7 points give 14 residuals: refused. From 10 points on the
  // answer comes with an uncertainty that covers the actual error and shrinks with n.
  constexpr double kMaxSigmas = 5.0;
  const Scene few = MakeScene(7, 29, 0.3);
  const Status st = EstimateResection(few.world_m, few.pixels, 1280, 800).status();
  EXPECT_EQ(st.code(), StatusCode::kDegenerate);
  EXPECT_NE(st.message().find("free parameters"), std::string::npos) << st.message();
  double previous_std_px = std::numeric_limits<double>::infinity();
  for (int n : {10, 30, 100, 300}) {
    const Scene s = MakeScene(n, 30, 0.3);
    const Expected<ResectionResult> r =
        EstimateResection(s.world_m, AddNoise(s.pixels, 0.5, 31), 1280, 800);
    ASSERT_TRUE(r.ok()) << n << ": " << r.status().ToString();
    ASSERT_TRUE(r->report.uncertainty_available) << n;
    SweepLog("n %3d: focal error %.3f %%, fx std %.3f %%\n", n, 100.0 * RelativeFocalError(*r, s),
             100.0 * r->report.fx_std_px / s.camera.fx_px);
    EXPECT_LT(std::abs(r->camera.fx_px - s.camera.fx_px), kMaxSigmas * r->report.fx_std_px) << n;
    EXPECT_LT(r->report.fx_std_px, previous_std_px) << n;
    previous_std_px = r->report.fx_std_px;
  }
}

TEST(ResectionTest, CoplanarPointsWithFreeIntrinsicsAreDegenerate) {
  for (double half_thickness_m : {0.0, 1e-3}) {
    const Scene s = MakeScene(100, 4, half_thickness_m);
    const Status st = EstimateResection(s.world_m, s.pixels, 1280, 800).status();
    EXPECT_EQ(st.code(), StatusCode::kDegenerate) << half_thickness_m;
    EXPECT_NE(st.message().find("coplanar"), std::string::npos) << st.message();
    EXPECT_NE(st.message().find("out-of-plane spread"), std::string::npos) << st.message();
  }
}

TEST(ResectionTest, CoplanarPointsWithFixedIntrinsicsUseHomography) {
  constexpr double kRotation_rad = DegToRad(0.1);
  constexpr double kCentre_m = 0.005;
  const Scene s = MakeScene(100, 5, 0.0);
  const Expected<ResectionResult> exact =
      EstimateResection(s.world_m, s.pixels, 1280, 800, KnownCamera(s));
  ASSERT_TRUE(exact.ok()) << exact.status().ToString();
  EXPECT_EQ(exact->report.initializer, "homography");
  EXPECT_LT(exact->report.final_rms_px, kExact_px);
  EXPECT_LT(RotationAngleBetween_rad(exact->camera_from_world, s.camera_from_world),
            kExactRotation_rad);
  EXPECT_LT(CentreError_m(*exact, s), kExactRelative);
  const Expected<ResectionResult> noisy =
      EstimateResection(s.world_m, AddNoise(s.pixels, 0.5, 6), 1280, 800, KnownCamera(s));
  ASSERT_TRUE(noisy.ok()) << noisy.status().ToString();
  EXPECT_LT(RotationAngleBetween_rad(noisy->camera_from_world, s.camera_from_world), kRotation_rad);
  EXPECT_LT(CentreError_m(*noisy, s), kCentre_m);
  EXPECT_EQ(noisy->report.num_free_parameters, 6);
  // Four points suffice with known intrinsics.
  const std::vector<Eigen::Vector3d> w4(s.world_m.begin(), s.world_m.begin() + 4);
  const std::vector<Eigen::Vector2d> p4(s.pixels.begin(), s.pixels.begin() + 4);
  const Expected<ResectionResult> four = EstimateResection(w4, p4, 1280, 800, KnownCamera(s));
  ASSERT_TRUE(four.ok()) << four.status().ToString();
  EXPECT_LT(RotationAngleBetween_rad(four->camera_from_world, s.camera_from_world),
            kExactRotation_rad);
}

TEST(ResectionTest, FourOrFivePointsWithKnownIntrinsics) {
  // Non-coplanar minimal sets start from P3P. (Before P3P was added, the best-fit-plane
  // homography start on 50 noise-free 4-point sets of this cloud gave 5 wrong poses with
  // "converged" reports and 23 refusals.)
  constexpr double kNoisyRotation_rad = DegToRad(2.0);
  for (int n : {4, 5}) {
    for (uint64_t seed = 0; seed < 20; ++seed) {
      const Scene s = MakeScene(n, 300 + seed, 0.3);
      const Expected<ResectionResult> r =
          EstimateResection(s.world_m, s.pixels, 1280, 800, KnownCamera(s));
      ASSERT_TRUE(r.ok()) << n << "/" << seed << ": " << r.status().ToString();
      EXPECT_LT(RotationAngleBetween_rad(r->camera_from_world, s.camera_from_world),
                kExactRotation_rad)
          << n << "/" << seed << " init " << r->report.initializer;
      EXPECT_LT(CentreError_m(*r, s), kExactRelative) << n << "/" << seed;
      const Expected<ResectionResult> noisy =
          EstimateResection(s.world_m, AddNoise(s.pixels, 0.5, seed), 1280, 800, KnownCamera(s));
      ASSERT_TRUE(noisy.ok()) << n << "/" << seed << ": " << noisy.status().ToString();
      EXPECT_LT(RotationAngleBetween_rad(noisy->camera_from_world, s.camera_from_world),
                kNoisyRotation_rad)
          << n << "/" << seed;
    }
  }
}

TEST(ResectionTest, EachGroupHeldFixed) {
  constexpr double kSigma_px = 0.3;
  constexpr double kFocalTolerance = 0.003;
  constexpr double kRotation_rad = DegToRad(0.1);
  constexpr double kModelError_px = 0.3;  // rms |u_hat - u_true| over the points
  const Scene s = MakeScene(200, 7, 0.3);
  const std::vector<Eigen::Vector2d> noisy = AddNoise(s.pixels, kSigma_px, 8);
  // A wrong initial camera: fixed groups must keep these values exactly.
  CameraModel off = s.camera;
  off.fx_px *= 1.01;
  off.distortion.k1 = -0.1;

  {  // Intrinsics fixed (at the true values), distortion and pose free.
    ResectionOptions o;
    o.fix_intrinsics = true;
    CameraModel start = s.camera;
    start.distortion = BrownDistortion{};
    o.initial_camera = start;
    const Expected<ResectionResult> r = EstimateResection(s.world_m, noisy, 1280, 800, o);
    ASSERT_TRUE(r.ok()) << r.status().ToString();
    EXPECT_EQ(r->camera.fx_px, start.fx_px);
    EXPECT_EQ(r->camera.cy_px, start.cy_px);
    // k1..k3 trade off against each other; the distortion they produce is what must match.
    EXPECT_LT(ModelError_px(*r, s), kModelError_px);
    EXPECT_LT(RotationAngleBetween_rad(r->camera_from_world, s.camera_from_world), kRotation_rad);
    EXPECT_EQ(r->report.num_free_parameters, 11);
    EXPECT_EQ(r->report.fx_std_px, 0.0);  // fixed group
    EXPECT_GT(r->report.rotation_std_rad, 0.0);
  }
  {  // Distortion fixed (at a wrong k1): kept, everything else still estimated.
    ResectionOptions o;
    o.fix_distortion = true;
    o.initial_camera = off;
    const Expected<ResectionResult> r = EstimateResection(s.world_m, noisy, 1280, 800, o);
    ASSERT_TRUE(r.ok()) << r.status().ToString();
    EXPECT_EQ(r->camera.distortion.k1, off.distortion.k1);
    EXPECT_EQ(r->camera.distortion.k2, off.distortion.k2);
    EXPECT_NE(r->camera.fx_px, off.fx_px);
    EXPECT_EQ(r->report.num_free_parameters, 10);
  }
  {  // Pose fixed at the truth: intrinsics and distortion recovered.
    ResectionOptions o;
    o.fix_pose = true;
    o.initial_camera_from_world = s.camera_from_world;
    const Expected<ResectionResult> r = EstimateResection(s.world_m, noisy, 1280, 800, o);
    ASSERT_TRUE(r.ok()) << r.status().ToString();
    EXPECT_EQ(r->camera_from_world.translation, s.camera_from_world.translation);
    EXPECT_EQ(r->camera_from_world.rotation.coeffs(), s.camera_from_world.rotation.coeffs());
    EXPECT_LT(RelativeFocalError(*r, s), kFocalTolerance);
    EXPECT_EQ(r->report.initializer, "given_pose");
    EXPECT_EQ(r->report.num_free_parameters, 9);
    EXPECT_EQ(r->report.rotation_std_rad, 0.0);  // fixed group
    EXPECT_GT(r->report.fx_std_px, 0.0);
  }
  {  // Only k3 fixed (at zero, its true value here).
    ResectionOptions o;
    o.fix_k3 = true;
    const Expected<ResectionResult> r = EstimateResection(s.world_m, noisy, 1280, 800, o);
    ASSERT_TRUE(r.ok()) << r.status().ToString();
    EXPECT_EQ(r->camera.distortion.k3, 0.0);
    EXPECT_LT(RelativeFocalError(*r, s), kFocalTolerance);
    EXPECT_EQ(r->report.num_free_parameters, 14);
  }
}

TEST(ResectionTest, InvalidInputsAreNamedErrors) {
  const Scene s = MakeScene(20, 9, 0.3);
  auto code_and_message = [](const Status& st, StatusCode code, const std::string& text) {
    EXPECT_EQ(st.code(), code) << st.ToString();
    EXPECT_NE(st.message().find(text), std::string::npos) << st.message();
  };
  std::vector<Eigen::Vector3d> w = s.world_m;
  std::vector<Eigen::Vector2d> p = s.pixels;
  w[3].x() = std::numeric_limits<double>::quiet_NaN();
  code_and_message(EstimateResection(w, p, 1280, 800).status(), StatusCode::kInvalidArgument,
                   "non-finite");
  w = s.world_m;
  p[2].y() = std::numeric_limits<double>::infinity();
  code_and_message(EstimateResection(w, p, 1280, 800).status(), StatusCode::kInvalidArgument,
                   "non-finite");
  p.pop_back();
  code_and_message(EstimateResection(w, p, 1280, 800).status(), StatusCode::kInvalidArgument,
                   "pixels");
  const std::vector<Eigen::Vector3d> w5(s.world_m.begin(), s.world_m.begin() + 5);
  const std::vector<Eigen::Vector2d> p5(s.pixels.begin(), s.pixels.begin() + 5);
  code_and_message(EstimateResection(w5, p5, 1280, 800).status(), StatusCode::kDegenerate,
                   "at least 6");
  const std::vector<Eigen::Vector3d> w3(s.world_m.begin(), s.world_m.begin() + 3);
  const std::vector<Eigen::Vector2d> p3(s.pixels.begin(), s.pixels.begin() + 3);
  code_and_message(EstimateResection(w3, p3, 1280, 800, KnownCamera(s)).status(),
                   StatusCode::kDegenerate, "at least 4");
  code_and_message(EstimateResection({}, {}, 1280, 800).status(), StatusCode::kDegenerate,
                   "0 points");
  std::vector<Eigen::Vector2d> line = s.pixels;
  for (size_t i = 0; i < line.size(); ++i) line[i] = Eigen::Vector2d(10.0 * i, 5.0 * i + 3.0);
  code_and_message(EstimateResection(s.world_m, line, 1280, 800).status(), StatusCode::kDegenerate,
                   "collinear");

  ResectionOptions o;
  o.fix_intrinsics = true;
  code_and_message(EstimateResection(s.world_m, s.pixels, 1280, 800, o).status(),
                   StatusCode::kInvalidArgument, "initial_camera is required");
  o = ResectionOptions{};
  o.fix_pose = true;
  code_and_message(EstimateResection(s.world_m, s.pixels, 1280, 800, o).status(),
                   StatusCode::kInvalidArgument, "initial_camera_from_world");
  o = KnownCamera(s);
  code_and_message(EstimateResection(s.world_m, s.pixels, 640, 480, o).status(),
                   StatusCode::kInvalidArgument, "image size");
  o.loss = ResectionLoss::kHuber;
  o.loss_scale_px = 0.0;
  code_and_message(EstimateResection(s.world_m, s.pixels, 1280, 800, o).status(),
                   StatusCode::kInvalidArgument, "loss_scale_px");
}

TEST(ResectionTest, MirroredPointsAreNotACamera) {
  // Half the points reflected through the camera centre: they project to the same pixels
  // from behind, so no camera sees all of them in front.
  const Scene s = MakeScene(60, 10, 0.3);
  std::vector<Eigen::Vector3d> w = s.world_m;
  const Eigen::Vector3d centre = s.camera_from_world.Inverse().translation;
  for (size_t i = 0; i < w.size(); i += 2) w[i] = centre - (w[i] - centre);
  const Status st = EstimateResection(w, s.pixels, 1280, 800, KnownCamera(s)).status();
  EXPECT_FALSE(st.ok());
  EXPECT_TRUE(st.code() == StatusCode::kOutOfRange || st.code() == StatusCode::kDegenerate)
      << st.ToString();
}

TEST(ResectionTest, RobustLossResistsOutliers) {
  constexpr double kRotation_rad = DegToRad(0.1);
  constexpr double kFocalTolerance = 0.005;
  const Scene s = MakeScene(200, 11, 0.3);
  std::vector<Eigen::Vector2d> p = AddNoise(s.pixels, 0.3, 12);
  std::mt19937_64 rng(13);
  std::uniform_real_distribution<double> shift(-40.0, 40.0);
  for (size_t i = 0; i < p.size(); i += 10) p[i] += Eigen::Vector2d(shift(rng), shift(rng));
  ResectionOptions o;
  o.loss = ResectionLoss::kCauchy;
  o.loss_scale_px = 1.0;
  const Expected<ResectionResult> r = EstimateResection(s.world_m, p, 1280, 800, o);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_LT(RelativeFocalError(*r, s), kFocalTolerance);
  EXPECT_LT(RotationAngleBetween_rad(r->camera_from_world, s.camera_from_world), kRotation_rad);
}

TEST(ResectionTest, LinearBuildingBlocks) {
  const Scene s = MakeScene(50, 14, 0.3);
  // Distortion-free pixels for the DLT.
  CameraModel pinhole = s.camera;
  pinhole.distortion = BrownDistortion{};
  std::vector<Eigen::Vector2d> px;
  for (const Eigen::Vector3d& x : s.world_m)
    px.push_back(*pinhole.Project(s.camera_from_world * x));
  const auto p = EstimateProjectionMatrixDlt(s.world_m, px);
  ASSERT_TRUE(p.ok()) << p.status().ToString();
  const auto d = DecomposeProjectionMatrix(*p);
  ASSERT_TRUE(d.ok());
  EXPECT_LT((d->k - pinhole.K()).norm() / pinhole.fx_px, kExactRelative);
  EXPECT_NEAR(d->skew_px, 0.0, kExactRelative * pinhole.fx_px);
  EXPECT_LT(RotationAngleBetween_rad(d->camera_from_world, s.camera_from_world),
            kExactRotation_rad);
  // -P is the same camera.
  const auto d_neg = DecomposeProjectionMatrix(-*p);
  ASSERT_TRUE(d_neg.ok());
  EXPECT_LT(RotationAngleBetween_rad(d_neg->camera_from_world, s.camera_from_world),
            kExactRotation_rad);
  EXPECT_EQ(DecomposeProjectionMatrix(Eigen::Matrix<double, 3, 4>::Zero()).status().code(),
            StatusCode::kDegenerate);
  EXPECT_NEAR(OutOfPlaneRatio(MakeScene(50, 15, 0.0).world_m), 0.0, 1e-12);
}

// Stress sweeps (fixed seeds). The observed values quoted are from these seeds.

TEST(ResectionSweepTest, NoiseGrowsErrorLinearly) {
  // Focal error / sigma and model error / sigma stay bounded from 0.1 to 10 px: no breakdown,
  // nothing garbage. Observed: model error 0.29-0.32 sigma (linear); it passes 1 px between
  // sigma = 3 px (0.90) and 4 px (1.21). The focal error grows faster than linearly (0.03 % at
  // 0.5 px, 0.17 % at 2 px, 0.82 % at 5 px, 2.6 % at 10 px) as the free distortion terms
  // absorb more of the noise.
  constexpr double kMaxModelErrorPerSigma = 0.5;    // px of model error per px of noise
  constexpr double kMaxFocalErrorPerSigma = 0.003;  // relative focal error per px of noise
  const Scene s = MakeScene(200, 16, 0.3);
  for (double sigma_px : {0.1, 0.5, 1.0, 2.0, 3.0, 4.0, 5.0, 10.0}) {
    const Expected<ResectionResult> r =
        EstimateResection(s.world_m, AddNoise(s.pixels, sigma_px, 17), 1280, 800);
    ASSERT_TRUE(r.ok()) << sigma_px << ": " << r.status().ToString();
    SweepLog("noise %5.2f px: model error %.3f px, focal error %.4f %%, rms %.3f px, %d it\n",
             sigma_px, ModelError_px(*r, s), 100.0 * RelativeFocalError(*r, s),
             r->report.final_rms_px, r->report.iterations);
    EXPECT_LT(ModelError_px(*r, s) / sigma_px, kMaxModelErrorPerSigma) << sigma_px;
    EXPECT_LT(RelativeFocalError(*r, s) / sigma_px, kMaxFocalErrorPerSigma) << sigma_px;
  }
}

TEST(ResectionSweepTest, WorldScaleDoesNotMatter) {
  // The same scene in world units from 1e-3 to 1e4: intrinsics identical, translation scaled.
  constexpr double kScaleInvariance = 1e-6;  // relative
  const Scene s = MakeScene(100, 18, 0.3);
  const std::vector<Eigen::Vector2d> noisy = AddNoise(s.pixels, 0.5, 19);
  double reference_fx = 0.0;
  for (double scale = 1e-3; scale <= 1e4 * 1.01; scale *= 10.0) {
    std::vector<Eigen::Vector3d> w = s.world_m;
    for (Eigen::Vector3d& x : w) x *= scale;
    const Expected<ResectionResult> r = EstimateResection(w, noisy, 1280, 800);
    ASSERT_TRUE(r.ok()) << scale << ": " << r.status().ToString();
    if (reference_fx == 0.0) reference_fx = r->camera.fx_px;
    SweepLog("scale %8.0e: fx %.9f px, rms %.6f px\n", scale, r->camera.fx_px,
             r->report.final_rms_px);
    EXPECT_NEAR(r->camera.fx_px / reference_fx, 1.0, kScaleInvariance) << scale;
    EXPECT_NEAR(
        r->camera_from_world.translation.norm() / (scale * s.camera_from_world.translation.norm()),
        1.0, 0.01)
        << scale;
  }
}

TEST(ResectionSweepTest, NearCoplanarEitherRefusesOrIsAccurate) {
  // Out-of-plane half-thickness 0 .. 100 mm on a 1 m cloud, 0.5 px noise, all free. Below the
  // default coplanar_ratio_threshold (1e-2, i.e. about 5 mm here) the routine refuses with a
  // named error; above it the focal error is bounded. Observed: ratio 0.02 (10 mm): 1.1 %;
  // 0.06 (30 mm): 1.0 %; 0.2 (100 mm): 0.22 %. (With the gate disabled, ratio 2e-3 converged
  // to fx off by 25 % even without noise in a scratch run: the gate is what prevents silent
  // wrong answers.) With known intrinsics every thickness gives the pose to 0.04 deg.
  constexpr double kFocalToleranceNearGate = 0.03;  // relative, just above the gate
  for (double half_thickness_m : {0.0, 1e-4, 3e-4, 1e-3, 3e-3, 1e-2, 3e-2, 1e-1}) {
    const Scene s = MakeScene(200, 20, half_thickness_m);
    const Expected<ResectionResult> r =
        EstimateResection(s.world_m, AddNoise(s.pixels, 0.5, 21), 1280, 800);
    SweepLog("half-thickness %6.4f m, ratio %.2e: %s\n", half_thickness_m,
             OutOfPlaneRatio(s.world_m),
             r.ok() ? ("focal error " + std::to_string(100.0 * RelativeFocalError(*r, s)) +
                       " %, model error " + std::to_string(ModelError_px(*r, s)) + " px")
                          .c_str()
                    : r.status().ToString().c_str());
    if (OutOfPlaneRatio(s.world_m) < ResectionOptions{}.coplanar_ratio_threshold) {
      ASSERT_FALSE(r.ok()) << half_thickness_m;
      EXPECT_EQ(r.status().code(), StatusCode::kDegenerate);
      EXPECT_NE(r.status().message().find("coplanar"), std::string::npos);
    } else {
      ASSERT_TRUE(r.ok()) << half_thickness_m << ": " << r.status().ToString();
      EXPECT_LT(RelativeFocalError(*r, s), kFocalToleranceNearGate) << half_thickness_m;
    }
    // With known intrinsics every thickness works (homography or DLT-with-K start).
    constexpr double kKnownKRotation_rad = DegToRad(0.1);
    const Scene t = MakeScene(200, 22, half_thickness_m);
    const Expected<ResectionResult> k =
        EstimateResection(t.world_m, AddNoise(t.pixels, 0.5, 23), 1280, 800, KnownCamera(t));
    ASSERT_TRUE(k.ok()) << half_thickness_m << ": " << k.status().ToString();
    SweepLog("  known K: init %s, rotation error %.4f deg, model error %.3f px\n",
             k->report.initializer.c_str(),
             RadToDeg(RotationAngleBetween_rad(k->camera_from_world, t.camera_from_world)),
             ModelError_px(*k, t));
    EXPECT_LT(RotationAngleBetween_rad(k->camera_from_world, t.camera_from_world),
              kKnownKRotation_rad)
        << half_thickness_m;
  }
}

TEST(ResectionSweepTest, GrazingViews) {
  // A plane seen from 0 to 90 degrees off its normal with known intrinsics (the camera sits
  // 1.6 m from the centre of a 1 m square): the pose stays accurate or the call fails with a
  // named error. Observed: model error 0.06-0.11 px at every angle, even at 90 degrees (camera
  // in the plane, image points on a line up to the noise): with known K the pose is still
  // determined (the image line gives the plane's normal, a 1D resection in the plane the
  // rest). Without noise the image points are exactly collinear there and the call refuses.
  constexpr double kModelError_px = 1.0;
  for (double view_deg : {0.0, 45.0, 70.0, 80.0, 85.0, 88.0, 89.0, 89.5, 89.9, 90.0}) {
    const Scene s = MakeScene(200, 24, 0.0, view_deg);
    const Expected<ResectionResult> r =
        EstimateResection(s.world_m, AddNoise(s.pixels, 0.5, 25), 1280, 800, KnownCamera(s));
    if (!r.ok()) {
      SweepLog("plane view %4.1f deg: %s\n", view_deg, r.status().ToString().c_str());
      EXPECT_NE(r.status().code(), StatusCode::kInternal) << view_deg;
      continue;
    }
    SweepLog("plane view %4.1f deg, known K: init %s, model error %.3f px, centre error %.2f mm\n",
             view_deg, r->report.initializer.c_str(), ModelError_px(*r, s),
             MToMm(CentreError_m(*r, s)));
    EXPECT_LT(ModelError_px(*r, s), kModelError_px) << view_deg;
  }
  const Scene edge_on = MakeScene(50, 28, 0.0, 90.0);
  const Status st =
      EstimateResection(edge_on.world_m, edge_on.pixels, 1280, 800, KnownCamera(edge_on)).status();
  EXPECT_EQ(st.code(), StatusCode::kDegenerate) << st.ToString();
  EXPECT_NE(st.message().find("collinear"), std::string::npos) << st.message();
  // Free intrinsics on a 3D cloud from the same directions.
  constexpr double kFocalTolerance = 0.005;
  for (double view_deg : {0.0, 45.0, 70.0, 85.0, 89.0}) {
    const Scene s = MakeScene(200, 26, 0.3, view_deg);
    const Expected<ResectionResult> r =
        EstimateResection(s.world_m, AddNoise(s.pixels, 0.5, 27), 1280, 800);
    ASSERT_TRUE(r.ok()) << view_deg << ": " << r.status().ToString();
    SweepLog("cloud view %4.1f deg, free: focal error %.3f %%, model error %.3f px\n", view_deg,
             100.0 * RelativeFocalError(*r, s), ModelError_px(*r, s));
    EXPECT_LT(RelativeFocalError(*r, s), kFocalTolerance) << view_deg;
  }
}

}  // namespace
}  // namespace sandtable
