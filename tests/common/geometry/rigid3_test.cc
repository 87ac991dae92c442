#include "common/geometry/rigid3.h"

#include <gtest/gtest.h>

#include <random>

namespace sandtable {
namespace {

constexpr double kTolerance_m = 1e-12;
constexpr double kAngleTolerance_rad = 1e-12;
constexpr int kTrials = 200;
constexpr unsigned kSeed = 20261122;

Rigid3d RandomRigid(std::mt19937& rng) {
  std::normal_distribution<double> normal(0.0, 1.0);
  Eigen::Quaterniond q(normal(rng), normal(rng), normal(rng), normal(rng));
  return Rigid3d(q.normalized(), Eigen::Vector3d(normal(rng), normal(rng), normal(rng)) * 3.0);
}

TEST(Rigid3dTest, IdentityMapsPointToItself) {
  const Eigen::Vector3d p(1.0, -2.0, 3.0);
  EXPECT_TRUE(((Rigid3d::Identity() * p) - p).norm() < kTolerance_m);
}

TEST(Rigid3dTest, InverseUndoesTransform) {
  std::mt19937 rng(kSeed);
  std::normal_distribution<double> normal(0.0, 1.0);
  for (int i = 0; i < kTrials; ++i) {
    const Rigid3d b_from_a = RandomRigid(rng);
    const Eigen::Vector3d x_in_a(normal(rng), normal(rng), normal(rng));
    const Eigen::Vector3d back = b_from_a.Inverse() * (b_from_a * x_in_a);
    EXPECT_LT((back - x_in_a).norm(), kTolerance_m);
    EXPECT_LT(RotationAngleBetween_rad(b_from_a * b_from_a.Inverse(), Rigid3d::Identity()),
              1e-7);  // acos near 1 loses half the digits: 1e-14 in w is 1.4e-7 rad
  }
}

TEST(Rigid3dTest, CompositionMatchesSequentialApplication) {
  std::mt19937 rng(kSeed + 1);
  std::normal_distribution<double> normal(0.0, 1.0);
  for (int i = 0; i < kTrials; ++i) {
    const Rigid3d b_from_a = RandomRigid(rng);
    const Rigid3d c_from_b = RandomRigid(rng);
    const Rigid3d c_from_a = c_from_b * b_from_a;
    const Eigen::Vector3d x_in_a(normal(rng), normal(rng), normal(rng));
    EXPECT_LT(((c_from_a * x_in_a) - (c_from_b * (b_from_a * x_in_a))).norm(), 1e-11);
    // (c_from_b * b_from_a)^-1 = a_from_b * b_from_c
    const Rigid3d a_from_c = b_from_a.Inverse() * c_from_b.Inverse();
    EXPECT_LT(((a_from_c * (c_from_a * x_in_a)) - x_in_a).norm(), 1e-11);
  }
}

TEST(Rigid3dTest, MatrixRoundTrip) {
  std::mt19937 rng(kSeed + 2);
  for (int i = 0; i < kTrials; ++i) {
    const Rigid3d t = RandomRigid(rng);
    const Rigid3d back = Rigid3d::FromMatrix3x4(t.ToMatrix3x4());
    EXPECT_LT((back.translation - t.translation).norm(), kTolerance_m);
    EXPECT_LT(RotationAngleBetween_rad(back, t), 1e-7);
    const Eigen::Matrix4d m = t.ToMatrix4();
    const Eigen::Vector3d p(0.3, -0.2, 0.9);
    EXPECT_LT(((m * p.homogeneous()).head<3>() - t * p).norm(), kTolerance_m);
  }
}

TEST(Rigid3dTest, RotationAngleOfKnownRotation) {
  const Rigid3d a(Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ())),
                  Eigen::Vector3d::Zero());
  EXPECT_NEAR(RotationAngleBetween_rad(a, Rigid3d::Identity()), 0.3, kAngleTolerance_rad);
  // q and -q are the same rotation.
  Rigid3d neg = a;
  neg.rotation.coeffs() *= -1.0;
  EXPECT_NEAR(RotationAngleBetween_rad(a, neg), 0.0, 1e-7);
}

}  // namespace
}  // namespace sandtable
