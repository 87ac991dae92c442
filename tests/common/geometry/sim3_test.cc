#include "common/geometry/sim3.h"

#include <gtest/gtest.h>

#include <random>

namespace sandtable {
namespace {

constexpr double kTolerance_m = 1e-10;
constexpr unsigned kSeed = 7;

TEST(Sim3dTest, InverseAndCompositionAcrossScales) {
  std::mt19937 rng(kSeed);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> log_scale(-3.0, 3.0);
  for (int i = 0; i < 200; ++i) {
    const Sim3d b_from_a(std::pow(10.0, log_scale(rng)),
                         Eigen::Quaterniond(normal(rng), normal(rng), normal(rng), normal(rng)),
                         Eigen::Vector3d(normal(rng), normal(rng), normal(rng)));
    const Sim3d c_from_b(std::pow(10.0, log_scale(rng)),
                         Eigen::Quaterniond(normal(rng), normal(rng), normal(rng), normal(rng)),
                         Eigen::Vector3d(normal(rng), normal(rng), normal(rng)));
    const Eigen::Vector3d x_in_a(normal(rng), normal(rng), normal(rng));
    const Eigen::Vector3d x_in_c = c_from_b * (b_from_a * x_in_a);
    EXPECT_LT(((c_from_b * b_from_a) * x_in_a - x_in_c).norm(),
              kTolerance_m * x_in_c.norm() + kTolerance_m);
    EXPECT_LT((b_from_a.Inverse() * (b_from_a * x_in_a) - x_in_a).norm(), kTolerance_m);
    const Eigen::Vector4d h = b_from_a.ToMatrix4() * x_in_a.homogeneous();
    EXPECT_LT((h.head<3>() - b_from_a * x_in_a).norm(), kTolerance_m * (1.0 + h.norm()));
  }
}

TEST(Sim3dTest, FromRigidKeepsUnitScale) {
  const Rigid3d r(Eigen::Quaterniond(Eigen::AngleAxisd(1.0, Eigen::Vector3d::UnitX())),
                  Eigen::Vector3d(1, 2, 3));
  const Sim3d s(r);
  const Eigen::Vector3d p(0.5, 0.1, -0.2);
  EXPECT_LT((s * p - r * p).norm(), kTolerance_m);
  EXPECT_DOUBLE_EQ(s.scale, 1.0);
}

}  // namespace
}  // namespace sandtable
