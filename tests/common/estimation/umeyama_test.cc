#include "common/estimation/umeyama.h"

#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <vector>

#include <gtest/gtest.h>

namespace sandtable {
namespace {

constexpr double kExactRotationTolerance_rad = 1e-9;
constexpr double kExactRelativeTolerance = 1e-9;  // of the point-set size

Eigen::Quaterniond RandomRotation(std::mt19937_64& rng) {
  std::normal_distribution<double> g(0.0, 1.0);
  return Eigen::Quaterniond(g(rng), g(rng), g(rng), g(rng)).normalized();
}

std::vector<Eigen::Vector3d> RandomPoints(std::mt19937_64& rng, int n, double extent_m) {
  std::uniform_real_distribution<double> u(-extent_m, extent_m);
  std::vector<Eigen::Vector3d> points(n);
  for (Eigen::Vector3d& p : points) p = Eigen::Vector3d(u(rng), u(rng), u(rng));
  return points;
}

std::vector<Eigen::Vector3d> Apply(const Sim3d& b_from_a, const std::vector<Eigen::Vector3d>& a) {
  std::vector<Eigen::Vector3d> b;
  for (const Eigen::Vector3d& p : a) b.push_back(b_from_a * p);
  return b;
}

TEST(FitRigidUmeyama, RecoversExactTransformAcrossScales) {
  std::mt19937_64 rng(1);
  for (double extent_m : {1e-3, 1e-2, 1.0, 1e2, 1e4}) {
    for (int trial = 0; trial < 20; ++trial) {
      const Rigid3d truth(RandomRotation(rng), extent_m * Eigen::Vector3d::Random());
      const auto source = RandomPoints(rng, 16, extent_m);
      const auto target = Apply(Sim3d(truth), source);
      auto fit = FitRigidUmeyama(source, target);
      ASSERT_TRUE(fit.ok()) << fit.status().ToString();
      EXPECT_LT(RotationAngleBetween_rad(fit->target_from_source, truth),
                kExactRotationTolerance_rad);
      EXPECT_LT((fit->target_from_source.translation - truth.translation).norm(),
                kExactRelativeTolerance * extent_m);
      EXPECT_LT(fit->rms_m, kExactRelativeTolerance * extent_m);
      ASSERT_EQ(fit->residuals_m.size(), source.size());
      EXPECT_EQ(fit->num_points, 16);
    }
  }
}

TEST(FitSimilarityUmeyama, RecoversScaleRotationTranslation) {
  std::mt19937_64 rng(2);
  for (double scale : {1e-3, 0.0254, 1.0, 39.37, 1e3}) {
    const Sim3d truth(scale, RandomRotation(rng), Eigen::Vector3d(0.3, -1.2, 2.0));
    const auto source = RandomPoints(rng, 16, 1.0);
    auto fit = FitSimilarityUmeyama(source, Apply(truth, source));
    ASSERT_TRUE(fit.ok()) << fit.status().ToString();
    EXPECT_NEAR(fit->target_from_source.scale / scale, 1.0, kExactRelativeTolerance);
    EXPECT_LT(RotationAngleBetween_rad(fit->target_from_source.ToRigid(), truth.ToRigid()),
              kExactRotationTolerance_rad);
    EXPECT_LT((fit->target_from_source.translation - truth.translation).norm(),
              kExactRelativeTolerance * (1.0 + scale));
  }
}

TEST(FitRigidUmeyama, PlanarPointsGiveProperRotation) {
  // Coplanar points: the cross-covariance has rank 2 and the unfixed SVD solution can be a
  // reflection; the fix must return det R = +1 and the true rotation.
  std::mt19937_64 rng(3);
  for (int trial = 0; trial < 50; ++trial) {
    auto source = RandomPoints(rng, 8, 1.0);
    for (Eigen::Vector3d& p : source) p.z() = 0.0;
    const Rigid3d truth(RandomRotation(rng), Eigen::Vector3d::Random());
    auto fit = FitRigidUmeyama(source, Apply(Sim3d(truth), source));
    ASSERT_TRUE(fit.ok()) << fit.status().ToString();
    EXPECT_NEAR(fit->target_from_source.RotationMatrix().determinant(), 1.0,
                kExactRelativeTolerance);
    EXPECT_LT(RotationAngleBetween_rad(fit->target_from_source, truth),
              kExactRotationTolerance_rad);
  }
}

TEST(FitRigidUmeyama, MirroredTargetStillGivesRotation) {
  // A mirrored target has no rigid fit; the result must still be a proper rotation (the
  // reflection fix), with large residuals reported rather than hidden.
  std::mt19937_64 rng(4);
  const auto source = RandomPoints(rng, 10, 1.0);
  std::vector<Eigen::Vector3d> target = source;
  for (Eigen::Vector3d& p : target) p.x() = -p.x();
  auto fit = FitRigidUmeyama(source, target);
  ASSERT_TRUE(fit.ok()) << fit.status().ToString();
  EXPECT_NEAR(fit->target_from_source.RotationMatrix().determinant(), 1.0, kExactRelativeTolerance);
  constexpr double kClearlyNotFitting_m = 0.05;
  EXPECT_GT(fit->rms_m, kClearlyNotFitting_m);
}

TEST(FitRigidUmeyama, InverseOfSwappedFit) {
  std::mt19937_64 rng(5);
  const auto source = RandomPoints(rng, 12, 1.0);
  auto target = Apply(Sim3d(Rigid3d(RandomRotation(rng), Eigen::Vector3d(1, 2, 3))), source);
  std::normal_distribution<double> noise(0.0, 1e-3);
  for (Eigen::Vector3d& p : target) p += Eigen::Vector3d(noise(rng), noise(rng), noise(rng));
  auto forward = FitRigidUmeyama(source, target);
  auto backward = FitRigidUmeyama(target, source);
  ASSERT_TRUE(forward.ok() && backward.ok());
  const Rigid3d round_trip = backward->target_from_source * forward->target_from_source;
  // Least squares is symmetric for rigid fits: the two fits are exact inverses.
  EXPECT_LT(RotationAngleBetween_rad(round_trip, Rigid3d::Identity()), kExactRotationTolerance_rad);
  EXPECT_LT(round_trip.translation.norm(), kExactRelativeTolerance);
  EXPECT_NEAR(forward->rms_m, backward->rms_m, kExactRelativeTolerance);
}

TEST(FitRigidUmeyama, NoiseSweepTrackerCalibration) {
  // Tracker calibration: 16 points over a 1.2 m table, tracker noise sigma per axis. The
  // residual RMS estimates sigma * sqrt(3 (n - 2) / n) (6 of 3n degrees of freedom are fitted),
  // and the translation error at the centroid is about sigma * sqrt(3 / n).
  std::mt19937_64 rng(6);
  for (double sigma_m : {1e-5, 1e-4, 1e-3, 5e-3}) {
    double sum_rms_m = 0.0, sum_rotation_rad = 0.0;
    constexpr int kTrials = 200;
    for (int trial = 0; trial < kTrials; ++trial) {
      auto source = RandomPoints(rng, 16, 0.6);
      const Rigid3d truth(RandomRotation(rng), Eigen::Vector3d(0.5, 0.2, -1.0));
      auto target = Apply(Sim3d(truth), source);
      std::normal_distribution<double> noise(0.0, sigma_m);
      for (Eigen::Vector3d& p : target) p += Eigen::Vector3d(noise(rng), noise(rng), noise(rng));
      auto fit = FitRigidUmeyama(source, target);
      ASSERT_TRUE(fit.ok());
      sum_rms_m += fit->rms_m;
      sum_rotation_rad += RotationAngleBetween_rad(fit->target_from_source, truth);
    }
    const double mean_rms_m = sum_rms_m / kTrials;
    const double expected_rms_m = sigma_m * std::sqrt(3.0 * 14.0 / 16.0);
    constexpr double kStatisticalTolerance = 0.1;  // relative, 200 trials of 16 points
    EXPECT_NEAR(mean_rms_m / expected_rms_m, 1.0, kStatisticalTolerance) << sigma_m;
    // Rotation error ~ sigma / (point spread ~0.6 m / sqrt(3) per axis * sqrt(n)).
    const double mean_rotation_rad = sum_rotation_rad / kTrials;
    const double rotation_bound_rad = 3.0 * sigma_m / (0.35 * std::sqrt(16.0));
    EXPECT_LT(mean_rotation_rad, rotation_bound_rad) << sigma_m;
    std::printf(
        "[ measured ] sigma %.0e m, 16 points: mean rms %.3e m (model %.3e m), mean "
        "rotation error %.2e rad\n",
        sigma_m, mean_rms_m, expected_rms_m, mean_rotation_rad);
  }
}

TEST(FitRigidUmeyama, NearlyCollinearStillSolvedAboveTolerance) {
  // Points on a line with a 1e-6 relative off-line spread are above the 1e-9 tolerance and
  // must still come out exact at zero noise.
  std::mt19937_64 rng(7);
  std::vector<Eigen::Vector3d> source;
  for (int i = 0; i < 10; ++i) {
    source.emplace_back(0.1 * i, 1e-7 * ((i * 7) % 3), 1e-7 * ((i * 5) % 4));
  }
  const Rigid3d truth(RandomRotation(rng), Eigen::Vector3d(1, 0, 0));
  auto fit = FitRigidUmeyama(source, Apply(Sim3d(truth), source));
  ASSERT_TRUE(fit.ok()) << fit.status().ToString();
  constexpr double kNearlyCollinearTolerance_m = 1e-12;
  EXPECT_LT(fit->rms_m, kNearlyCollinearTolerance_m);
}

TEST(FitRigidUmeyama, NearlyCollinearBreakdownWithNoise) {
  // 16 points along a 1.2 m line with an off-line spread of ratio * 1.2 m, 0.5 mm noise: the
  // rotation about the line is determined by the off-line spread only, so the error it causes
  // at a point 0.5 m off the line grows as 1 / ratio. Records where it passes 1 mm; below the
  // 1e-9 tolerance the fit is refused.
  constexpr double kNoise_m = 5e-4;
  constexpr double kLever_m = 0.5;
  for (double ratio : {1.0, 3e-1, 1e-1, 3e-2, 1e-2, 1e-3, 1e-6, 1e-11}) {
    std::mt19937_64 rng(8);
    std::uniform_real_distribution<double> u(-0.5, 0.5);
    std::normal_distribution<double> noise(0.0, kNoise_m);
    double sum_sq_m = 0.0;
    int num_ok = 0, num_refused = 0;
    constexpr int kTrials = 50;
    for (int trial = 0; trial < kTrials; ++trial) {
      std::vector<Eigen::Vector3d> source;
      for (int i = 0; i < 16; ++i) {
        source.emplace_back(1.2 * u(rng), ratio * 1.2 * u(rng), ratio * 1.2 * u(rng));
      }
      const Rigid3d truth(RandomRotation(rng), Eigen::Vector3d(0.1, 0.2, 0.3));
      auto target = Apply(Sim3d(truth), source);
      if (ratio > 1e-9) {
        for (Eigen::Vector3d& p : target) p += Eigen::Vector3d(noise(rng), noise(rng), noise(rng));
      }
      auto fit = FitRigidUmeyama(source, target);
      if (!fit.ok()) {
        EXPECT_EQ(fit.status().code(), StatusCode::kDegenerate);
        ++num_refused;
        continue;
      }
      ++num_ok;
      // Sampling: sigma_2 is the larger of the two off-line spreads of 16 uniform points.
      constexpr double kSpreadRatioFactor = 3.0;
      if (ratio <= 1e-1) {
        EXPECT_LT(fit->source_spread_ratio, kSpreadRatioFactor * ratio);
        EXPECT_GT(fit->source_spread_ratio, ratio / kSpreadRatioFactor);
      }
      const Eigen::Vector3d probe(0.0, kLever_m, 0.0);
      sum_sq_m += (fit->target_from_source * probe - truth * probe).squaredNorm();
    }
    const double rms_probe_mm = num_ok > 0 ? 1e3 * std::sqrt(sum_sq_m / num_ok) : 0.0;
    std::printf(
        "[ measured ] off-line ratio %.0e, 0.5 mm noise: error 0.5 m off the line "
        "%.3f mm rms over %d fits, %d refused\n",
        ratio, rms_probe_mm, num_ok, num_refused);
    if (ratio < 1e-9) {
      EXPECT_EQ(num_refused, kTrials);
    } else {
      EXPECT_EQ(num_ok, kTrials);
    }
    constexpr double kWellConditionedMax_mm = 1.0;
    if (ratio >= 3e-1) {
      EXPECT_LT(rms_probe_mm, kWellConditionedMax_mm);
    }
  }
}

TEST(FitRigidUmeyama, RejectsBadInput) {
  const std::vector<Eigen::Vector3d> three = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  const std::vector<Eigen::Vector3d> two = {{0, 0, 0}, {1, 0, 0}};
  const std::vector<Eigen::Vector3d> empty;
  EXPECT_EQ(FitRigidUmeyama(three, two).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(FitRigidUmeyama(two, two).status().code(), StatusCode::kDegenerate);
  EXPECT_EQ(FitRigidUmeyama(empty, empty).status().code(), StatusCode::kDegenerate);
  EXPECT_EQ(FitSimilarityUmeyama(empty, empty).status().code(), StatusCode::kDegenerate);
  for (double bad :
       {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity(),
        -std::numeric_limits<double>::infinity()}) {
    auto with_bad = three;
    with_bad[1].y() = bad;
    EXPECT_EQ(FitRigidUmeyama(with_bad, three).status().code(), StatusCode::kInvalidArgument);
    EXPECT_EQ(FitSimilarityUmeyama(three, with_bad).status().code(), StatusCode::kInvalidArgument);
  }
  const std::vector<Eigen::Vector3d> collinear = {{0, 0, 0}, {1, 1, 1}, {2, 2, 2}, {5, 5, 5}};
  const std::vector<Eigen::Vector3d> coincident(4, Eigen::Vector3d(1, 2, 3));
  const std::vector<Eigen::Vector3d> good = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  auto s = FitRigidUmeyama(collinear, good).status();
  EXPECT_EQ(s.code(), StatusCode::kDegenerate);
  EXPECT_NE(s.message().find("collinear"), std::string::npos) << s.message();
  EXPECT_EQ(FitRigidUmeyama(good, collinear).status().code(), StatusCode::kDegenerate);
  EXPECT_EQ(FitSimilarityUmeyama(coincident, good).status().code(), StatusCode::kDegenerate);
  UmeyamaOptions bad_options;
  bad_options.degenerate_relative_tolerance = 0.0;
  EXPECT_EQ(FitRigidUmeyama(good, good, bad_options).status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace sandtable
