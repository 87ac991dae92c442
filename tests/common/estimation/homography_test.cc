#include "common/estimation/homography.h"

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

constexpr double kExact_px = 1e-8;       // transfer error of noise-free recoveries
constexpr double kExactRelative = 1e-9;  // |H - H_true| / |H_true| for noise-free data
constexpr double kRotationTolerance_rad = 1e-9;
constexpr double kTranslationTolerance_m = 1e-9;

// A camera (1280x800, f = 1000 px) looking at the z = 0 plane of a frame "plane" from about
// 1.5 m, tilted 25 degrees; points in a 1 m x 1 m square on the plane.
struct PlaneScene {
  Eigen::Matrix3d k;
  Rigid3d camera_from_plane;
  Eigen::Matrix3d image_from_plane;
  std::vector<Eigen::Vector2d> on_plane_m;
  std::vector<Eigen::Vector2d> in_image_px;
};

PlaneScene MakePlaneScene(int n, uint64_t seed, double tilt_deg = 25.0) {
  PlaneScene s;
  s.k << 1000.0, 0.0, 639.5, 0.0, 1000.0, 399.5, 0.0, 0.0, 1.0;
  const Eigen::Matrix3d r = (Eigen::AngleAxisd(DegToRad(tilt_deg), Eigen::Vector3d::UnitX()) *
                             Eigen::AngleAxisd(DegToRad(10.0), Eigen::Vector3d::UnitY()) *
                             Eigen::AngleAxisd(DegToRad(5.0), Eigen::Vector3d::UnitZ()))
                                .toRotationMatrix();
  s.camera_from_plane = Rigid3d(r, Eigen::Vector3d(0.05, -0.02, 1.5));
  Eigen::Matrix3d rt;
  rt << r.col(0), r.col(1), s.camera_from_plane.translation;
  s.image_from_plane = NormalizeHomography(s.k * rt);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> coord(-0.5, 0.5);
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector2d p(coord(rng), coord(rng));
    s.on_plane_m.push_back(p);
    s.in_image_px.push_back(ApplyHomography(s.image_from_plane, p));
  }
  return s;
}

using test_util::AddNoise;
using test_util::SweepLog;

// RMS over the true points of |H x - H_true x|: the error of the estimate itself, not of the
// fit to noisy data.
double ErrorVsTruth_px(const Eigen::Matrix3d& h, const PlaneScene& s) {
  return HomographyTransferRms(h, s.on_plane_m, s.in_image_px);
}

TEST(HomographyTest, ApplyAndNormalize) {
  Eigen::Matrix3d h;
  h << 2.0, 0.0, 1.0, 0.0, 2.0, -1.0, 0.0, 0.0, -2.0;
  const Eigen::Matrix3d n = NormalizeHomography(h);
  EXPECT_NEAR(n.norm(), 1.0, kExactRelative);
  EXPECT_GT(n(2, 2), 0.0);
  const Eigen::Vector2d y = ApplyHomography(n, Eigen::Vector2d(1.0, 2.0));
  EXPECT_NEAR(y.x(), -1.5, kExact_px);
  EXPECT_NEAR(y.y(), -1.5, kExact_px);
  // H(2,2) = 0: the sign comes from the last row's first non-zero entry.
  Eigen::Matrix3d h0 = Eigen::Matrix3d::Identity();
  h0(2, 2) = 0.0;
  h0(2, 1) = -1.0;
  EXPECT_GT(NormalizeHomography(h0)(2, 1), 0.0);
}

TEST(HomographyTest, ExactRecoveryFromFourAndManyPairs) {
  for (int n : {4, 5, 50, 1000}) {
    const PlaneScene s = MakePlaneScene(n, 7);
    const Expected<Eigen::Matrix3d> h = EstimateHomographyDlt(s.on_plane_m, s.in_image_px);
    ASSERT_TRUE(h.ok()) << h.status().ToString();
    EXPECT_LT((*h - s.image_from_plane).norm(), kExactRelative) << "n = " << n;
    EXPECT_LT(HomographyTransferRms(*h, s.on_plane_m, s.in_image_px), kExact_px);
  }
}

TEST(HomographyTest, HartleyNormalizationAcrossScales) {
  // The same configuration expressed in units from 1e-3 to 1e4 (both images scaled): the
  // recovered H, brought back to unit scale, must agree, and the relative transfer error with
  // proportional noise must not depend on the scale.
  constexpr double kScaleInvariance = 1e-6;  // relative spread of the rms across scales
  const PlaneScene s = MakePlaneScene(100, 11);
  const std::vector<Eigen::Vector2d> noisy = AddNoise(s.in_image_px, 0.5, 12);
  double reference_relative_rms = -1.0;
  for (double scale = 1e-3; scale <= 1e4 * 1.01; scale *= 10.0) {
    std::vector<Eigen::Vector2d> from, to, to_exact;
    for (size_t i = 0; i < s.on_plane_m.size(); ++i) {
      from.push_back(scale * s.on_plane_m[i]);
      to.push_back(scale * noisy[i]);
      to_exact.push_back(scale * s.in_image_px[i]);
    }
    const Expected<Eigen::Matrix3d> exact = EstimateHomographyDlt(from, to_exact);
    ASSERT_TRUE(exact.ok()) << "scale " << scale << ": " << exact.status().ToString();
    EXPECT_LT(HomographyTransferRms(*exact, from, to_exact) / scale, kExact_px / 1000.0)
        << "scale " << scale;
    const Expected<Eigen::Matrix3d> h = EstimateHomographyDlt(from, to);
    ASSERT_TRUE(h.ok()) << "scale " << scale << ": " << h.status().ToString();
    const double relative_rms = HomographyTransferRms(*h, from, to) / scale;
    if (reference_relative_rms < 0.0) reference_relative_rms = relative_rms;
    EXPECT_NEAR(relative_rms / reference_relative_rms, 1.0, kScaleInvariance) << "scale " << scale;
  }
}

TEST(HomographyTest, InvalidInputsAreErrors) {
  const PlaneScene s = MakePlaneScene(10, 3);
  std::vector<Eigen::Vector2d> empty;
  EXPECT_EQ(EstimateHomographyDlt(empty, empty).status().code(), StatusCode::kDegenerate);
  std::vector<Eigen::Vector2d> three(s.on_plane_m.begin(), s.on_plane_m.begin() + 3);
  std::vector<Eigen::Vector2d> three_to(s.in_image_px.begin(), s.in_image_px.begin() + 3);
  const Status few = EstimateHomographyDlt(three, three_to).status();
  EXPECT_EQ(few.code(), StatusCode::kDegenerate);
  EXPECT_NE(few.message().find("at least 4"), std::string::npos) << few.message();
  std::vector<Eigen::Vector2d> shorter(s.in_image_px.begin(), s.in_image_px.end() - 1);
  EXPECT_EQ(EstimateHomographyDlt(s.on_plane_m, shorter).status().code(),
            StatusCode::kInvalidArgument);
  for (double bad :
       {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity()}) {
    std::vector<Eigen::Vector2d> to = s.in_image_px;
    to[4].y() = bad;
    const Status st = EstimateHomographyDlt(s.on_plane_m, to).status();
    EXPECT_EQ(st.code(), StatusCode::kInvalidArgument);
    EXPECT_NE(st.message().find("non-finite"), std::string::npos) << st.message();
    EXPECT_EQ(EstimateHomographyRansac(s.on_plane_m, to).status().code(),
              StatusCode::kInvalidArgument);
    EXPECT_EQ(RefineHomography(s.on_plane_m, to, s.image_from_plane).status().code(),
              StatusCode::kInvalidArgument);
  }
  EXPECT_EQ(RefineHomography(s.on_plane_m, s.in_image_px,
                             Eigen::Matrix3d::Constant(std::numeric_limits<double>::quiet_NaN()))
                .status()
                .code(),
            StatusCode::kInvalidArgument);
}

TEST(HomographyTest, CollinearPointsAreDegenerate) {
  std::vector<Eigen::Vector2d> line, image;
  for (int i = 0; i < 20; ++i) {
    line.emplace_back(0.1 * i, 0.05 * i + 1.0);
    image.emplace_back(13.0 * i + 2.0, 7.0 * (i % 5));  // image side in general position
  }
  Status st = EstimateHomographyDlt(line, image).status();
  EXPECT_EQ(st.code(), StatusCode::kDegenerate);
  EXPECT_NE(st.message().find("source points are collinear"), std::string::npos) << st.message();
  st = EstimateHomographyDlt(image, line).status();
  EXPECT_NE(st.message().find("destination points are collinear"), std::string::npos)
      << st.message();

  // Minimal set with three collinear points.
  const std::vector<Eigen::Vector2d> from = {{0, 0}, {1, 1}, {2, 2}, {0, 1}};
  const std::vector<Eigen::Vector2d> to = {{0, 0}, {10, 0}, {10, 10}, {0, 10}};
  st = EstimateHomographyDlt(from, to).status();
  EXPECT_EQ(st.code(), StatusCode::kDegenerate);
  EXPECT_NE(st.message().find("three of the four"), std::string::npos) << st.message();
  EXPECT_EQ(EstimateHomographyRansac(from, to).status().code(), StatusCode::kDegenerate);
}

TEST(HomographyTest, RefinementReachesNoiseFloor) {
  // Noise on the destination only: refinement is the ML estimate, whose rms residual has the
  // expectation sigma sqrt(2) sqrt(1 - 8 / (2n)) (8 dof).
  constexpr double kSigma_px = 0.5;
  constexpr double kFloorTolerance = 0.1;  // relative
  const int n = 200;
  const PlaneScene s = MakePlaneScene(n, 21);
  const std::vector<Eigen::Vector2d> noisy = AddNoise(s.in_image_px, kSigma_px, 22);
  const Expected<Eigen::Matrix3d> dlt = EstimateHomographyDlt(s.on_plane_m, noisy);
  ASSERT_TRUE(dlt.ok());
  const Expected<RefinedHomography> refined = RefineHomography(s.on_plane_m, noisy, *dlt);
  ASSERT_TRUE(refined.ok()) << refined.status().ToString();
  const HomographyRefineReport& r = refined->report;
  EXPECT_TRUE(r.converged) << r.termination << ": " << r.message;
  EXPECT_EQ(r.num_points, n);
  EXPECT_LE(r.final_rms_px, r.initial_rms_px);
  const double floor_px = kSigma_px * std::sqrt(2.0) * std::sqrt(1.0 - 8.0 / (2.0 * n));
  EXPECT_NEAR(r.final_rms_px / floor_px, 1.0, kFloorTolerance);
  EXPECT_NEAR(HomographyTransferRms(refined->to_from_from, s.on_plane_m, noisy), r.final_rms_px,
              kExact_px);
  // The estimate itself is within the noise of the truth (about sigma sqrt(8/n)).
  EXPECT_LT(ErrorVsTruth_px(refined->to_from_from, s), kSigma_px);
  EXPECT_LE(ErrorVsTruth_px(refined->to_from_from, s), ErrorVsTruth_px(*dlt, s) * 1.05);
}

TEST(HomographyTest, RefinementHandlesZeroCornerEntry) {
  // H(2,2) = 0 (the source origin maps to infinity): the sphere parameterisation copes.
  Eigen::Matrix3d h;
  h << 1.0, 0.2, 0.0, 0.1, 1.0, 0.3, 0.5, 0.4, 0.0;
  std::vector<Eigen::Vector2d> from, to;
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> coord(1.0, 3.0);
  for (int i = 0; i < 30; ++i) {
    from.emplace_back(coord(rng), coord(rng));
    to.push_back(ApplyHomography(h, from.back()));
  }
  Eigen::Matrix3d start = h;
  start(0, 1) += 0.05;
  const Expected<RefinedHomography> r = RefineHomography(from, to, start);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_LT(r->report.final_rms_px, kExact_px);
  EXPECT_LT((r->to_from_from - NormalizeHomography(h)).norm(), kExactRelative * 1e3);
}

TEST(HomographyTest, RansacOutlierSweep) {
  // 200 pairs, 0.3 px noise, a growing fraction replaced by uniform outliers over the image.
  // Observed over 20 seeds per level (this scene, 1.5 px threshold): 20/20 correct up to 85 %
  // outliers with the default max_iterations = 10000; at 90 % only 9/20 with 10000 (0.999
  // confidence needs ~69000 samples) and 20/20 with 100000 (~83000 drawn, ~2 s); at 95 % 1/20.
  constexpr double kSigma_px = 0.3;
  constexpr double kMaxError_px = 0.5;  // error of the estimate vs truth
  const PlaneScene s = MakePlaneScene(200, 31);
  for (int percent = 0; percent <= 90; percent += 10) {
    std::vector<Eigen::Vector2d> to = AddNoise(s.in_image_px, kSigma_px, 32 + percent);
    std::mt19937_64 rng(100 + percent);
    std::uniform_real_distribution<double> u(0.0, 1279.0), v(0.0, 799.0);
    const int num_outliers = static_cast<int>(s.on_plane_m.size()) * percent / 100;
    for (int i = 0; i < num_outliers; ++i) to[i] = Eigen::Vector2d(u(rng), v(rng));
    HomographyRansacOptions options;
    options.max_transfer_error_px = 1.5;
    options.seed = 1;
    if (percent >= 90) options.max_iterations = 100000;
    const Expected<HomographyRansacResult> r = EstimateHomographyRansac(s.on_plane_m, to, options);
    ASSERT_TRUE(r.ok()) << percent << "% outliers: " << r.status().ToString();
    SweepLog("outliers %d %%: error vs truth %.4f px, inliers %d, iterations %d\n", percent,
             ErrorVsTruth_px(r->to_from_from, s), r->num_inliers, r->iterations);
    EXPECT_LT(ErrorVsTruth_px(r->to_from_from, s), kMaxError_px) << percent << "% outliers";
    // Almost all true inliers found; a few outliers can fall within the threshold by chance.
    const int true_inliers = static_cast<int>(s.on_plane_m.size()) - num_outliers;
    EXPECT_GE(r->num_inliers, true_inliers * 95 / 100) << percent << "% outliers";
    EXPECT_LE(r->num_inliers, true_inliers + num_outliers / 20 + 1) << percent << "% outliers";
    EXPECT_EQ(r->inlier_mask.size(), s.on_plane_m.size());
    EXPECT_NEAR(r->inlier_ratio, static_cast<double>(r->num_inliers) / s.on_plane_m.size(), 1e-12);
    EXPECT_TRUE(r->refined);
    EXPECT_LT(r->inlier_rms_px, options.max_transfer_error_px);
  }
}

TEST(HomographyTest, RansacDeterministicAndRespectsMinInlierRatio) {
  const PlaneScene s = MakePlaneScene(100, 41);
  std::vector<Eigen::Vector2d> to = AddNoise(s.in_image_px, 0.3, 42);
  std::mt19937_64 rng(43);
  std::uniform_real_distribution<double> u(0.0, 1279.0);
  for (int i = 0; i < 60; ++i) to[i] = Eigen::Vector2d(u(rng), u(rng) * 0.6);
  HomographyRansacOptions options;
  options.seed = 9;
  const auto a = EstimateHomographyRansac(s.on_plane_m, to, options);
  const auto b = EstimateHomographyRansac(s.on_plane_m, to, options);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(a->to_from_from, b->to_from_from);
  EXPECT_EQ(a->iterations, b->iterations);
  options.min_inlier_ratio = 0.6;
  const Status st = EstimateHomographyRansac(s.on_plane_m, to, options).status();
  EXPECT_EQ(st.code(), StatusCode::kDegenerate);
  EXPECT_NE(st.message().find("inlier ratio"), std::string::npos) << st.message();
  options.max_transfer_error_px = -1.0;
  EXPECT_EQ(EstimateHomographyRansac(s.on_plane_m, to, options).status().code(),
            StatusCode::kInvalidArgument);
}

TEST(HomographyTest, NoiseSweepErrorGrowsLinearly) {
  // Error of the refined estimate vs truth divided by sigma stays in a narrow band from 0.1 to
  // 5 px: no breakdown with noise alone at this geometry (200 points, 25 deg tilt).
  constexpr double kMinRatio = 0.05, kMaxRatio = 0.5;  // (error vs truth) / sigma
  const PlaneScene s = MakePlaneScene(200, 51);
  for (double sigma_px : {0.1, 0.5, 1.0, 2.0, 5.0}) {
    const std::vector<Eigen::Vector2d> noisy = AddNoise(s.in_image_px, sigma_px, 52);
    const auto dlt = EstimateHomographyDlt(s.on_plane_m, noisy);
    ASSERT_TRUE(dlt.ok());
    const auto refined = RefineHomography(s.on_plane_m, noisy, *dlt);
    ASSERT_TRUE(refined.ok());
    const double ratio = ErrorVsTruth_px(refined->to_from_from, s) / sigma_px;
    SweepLog("noise %.1f px: DLT error %.4f px, refined error %.4f px (vs truth)\n", sigma_px,
             ErrorVsTruth_px(*dlt, s), ErrorVsTruth_px(refined->to_from_from, s));
    EXPECT_GT(ratio, kMinRatio) << "sigma " << sigma_px;
    EXPECT_LT(ratio, kMaxRatio) << "sigma " << sigma_px;
  }
}

TEST(HomographyTest, NearCollinearSweep) {
  // Source points in a strip of the 1 m square, width/length from 0 to 1, 0.5 px noise on the
  // destination. Either DEGENERATE ("collinear", spread ratio below kHomographyCollinearRatio)
  // or, after refinement, a fit to the data at the noise level. Observed: refused below strip
  // ratio 1e-5; the DLT alone is poor on narrow strips (on-data error 8.9 px at 1e-5, 21 px at
  // 1e-4, 3.0 px at 1e-3, 0.09 px at 1e-2) and refinement brings it to 0.10 px at every width.
  // Away from the strip H is not determined by the data (see the whole-square column of the
  // sweep log): a caller that extrapolates must check the spread of its points.
  constexpr double kSigma_px = 0.5;
  constexpr double kOnDataError_px = 0.3;  // refined, vs truth, at the data points
  const PlaneScene base = MakePlaneScene(4, 81);
  const PlaneScene square = MakePlaneScene(200, 84);  // same camera, points over the square
  for (double width : {0.0, 1e-7, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1, 1.0}) {
    std::mt19937_64 rng(82);
    std::uniform_real_distribution<double> coord(-0.5, 0.5);
    std::vector<Eigen::Vector2d> from, exact;
    for (int i = 0; i < 200; ++i) {
      from.emplace_back(coord(rng), width * coord(rng));
      exact.push_back(ApplyHomography(base.image_from_plane, from.back()));
    }
    const std::vector<Eigen::Vector2d> noisy = AddNoise(exact, kSigma_px, 83);
    const Expected<Eigen::Matrix3d> dlt = EstimateHomographyDlt(from, noisy);
    if (!dlt.ok()) {
      SweepLog("strip %.0e: %s\n", width, dlt.status().ToString().c_str());
      EXPECT_EQ(dlt.status().code(), StatusCode::kDegenerate) << width;
      EXPECT_NE(dlt.status().message().find("collinear"), std::string::npos);
      EXPECT_LT(width, 1e-4) << "refused a strip that is not near-collinear";
      continue;
    }
    const Expected<RefinedHomography> refined = RefineHomography(from, noisy, *dlt);
    ASSERT_TRUE(refined.ok()) << width << ": " << refined.status().ToString();
    const double on_data_px = HomographyTransferRms(refined->to_from_from, from, exact);
    SweepLog("strip %.0e: DLT on-data error %.3f px, refined %.3f px, whole square %.3g px\n",
             width, HomographyTransferRms(*dlt, from, exact), on_data_px,
             HomographyTransferRms(refined->to_from_from, square.on_plane_m, square.in_image_px));
    EXPECT_LT(on_data_px, kOnDataError_px) << width;
  }
}

TEST(HomographyTest, PlanePoseFromHomography) {
  const PlaneScene s = MakePlaneScene(50, 61);
  for (double sign : {1.0, -1.0}) {  // H is defined up to sign
    const Expected<Rigid3d> pose =
        CameraFromPlaneHomography(sign * s.image_from_plane, s.k, s.on_plane_m);
    ASSERT_TRUE(pose.ok()) << pose.status().ToString();
    EXPECT_LT(RotationAngleBetween_rad(*pose, s.camera_from_plane), kRotationTolerance_rad);
    EXPECT_LT((pose->translation - s.camera_from_plane.translation).norm(),
              kTranslationTolerance_m);
    EXPECT_NEAR(pose->RotationMatrix().determinant(), 1.0, kExactRelative);
    // Without points the plane origin decides the sign (it is in front here).
    const Expected<Rigid3d> by_origin = CameraFromPlaneHomography(sign * s.image_from_plane, s.k);
    ASSERT_TRUE(by_origin.ok());
    EXPECT_LT(RotationAngleBetween_rad(*by_origin, s.camera_from_plane), kRotationTolerance_rad);
  }
  // From a noisy homography: the rotation is still orthonormal and close.
  constexpr double kNoisyRotation_rad = DegToRad(0.5);
  constexpr double kNoisyTranslation_m = 0.01;
  const auto h = EstimateHomographyDlt(s.on_plane_m, AddNoise(s.in_image_px, 0.5, 62));
  ASSERT_TRUE(h.ok());
  const Expected<Rigid3d> noisy = CameraFromPlaneHomography(*h, s.k, s.on_plane_m);
  ASSERT_TRUE(noisy.ok());
  EXPECT_LT(RotationAngleBetween_rad(*noisy, s.camera_from_plane), kNoisyRotation_rad);
  EXPECT_LT((noisy->translation - s.camera_from_plane.translation).norm(), kNoisyTranslation_m);
}

TEST(HomographyTest, PlanePoseErrors) {
  const PlaneScene s = MakePlaneScene(10, 71);
  // Points on both sides of the camera plane: the camera sits above the plane at z = 1.5 m
  // along its axis; points far along the tilt direction fall behind it.
  std::vector<Eigen::Vector2d> straddle = s.on_plane_m;
  const Eigen::Matrix3d r = s.camera_from_plane.RotationMatrix();
  // Plane points with camera depth r.row(2).(x, y, 0) + t_z < 0.
  const Eigen::Vector2d dir(r(2, 0), r(2, 1));
  straddle.push_back(-dir.normalized() * (2.0 * s.camera_from_plane.translation.z() / dir.norm()));
  EXPECT_EQ(CameraFromPlaneHomography(s.image_from_plane, s.k, straddle).status().code(),
            StatusCode::kOutOfRange);
  EXPECT_EQ(CameraFromPlaneHomography(s.image_from_plane, Eigen::Matrix3d::Zero()).status().code(),
            StatusCode::kInvalidArgument);
  Eigen::Matrix3d rank1 = Eigen::Matrix3d::Zero();
  rank1.col(2) = Eigen::Vector3d(1, 2, 3);
  EXPECT_EQ(CameraFromPlaneHomography(rank1, s.k).status().code(), StatusCode::kDegenerate);
}

}  // namespace
}  // namespace sandtable
