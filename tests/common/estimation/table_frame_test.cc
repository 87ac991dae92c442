#include "common/estimation/table_frame.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numbers>
#include <random>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Geometry>

#include "common/base/units.h"

namespace sandtable {
namespace {

constexpr double kExactRelativeTolerance = 1e-9;  // of the table size

Eigen::Quaterniond RandomRotation(std::mt19937_64& rng) {
  std::normal_distribution<double> g(0.0, 1.0);
  return Eigen::Quaterniond(g(rng), g(rng), g(rng), g(rng)).normalized();
}

struct Table {
  Rigid3d source_from_truth;  // the truth frame: rectangle [0, w] x [0, h] at z = 0
  Plane plane_in_source;
  std::vector<Eigen::Vector3d> points_in_source;
  Eigen::Vector3d hint_in_source;
};

// A w x h rectangle (w > h) of points: its 4 corners plus `interior` random points inside,
// placed in the source frame by a random rigid transform; the hint 1.5 m above its centre.
Table MakeTable(uint64_t seed, double w_m, double h_m, int interior, double scale = 1.0) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  Table t;
  t.source_from_truth = Rigid3d(RandomRotation(rng), scale * Eigen::Vector3d(3.0, -1.0, 2.0));
  std::vector<Eigen::Vector3d> truth = {{0, 0, 0}, {w_m, 0, 0}, {w_m, h_m, 0}, {0, h_m, 0}};
  for (int i = 0; i < interior; ++i) truth.emplace_back(w_m * u(rng), h_m * u(rng), 0.0);
  for (const Eigen::Vector3d& p : truth)
    t.points_in_source.push_back(t.source_from_truth * (scale * p));
  const Eigen::Vector3d n = t.source_from_truth.rotation * Eigen::Vector3d::UnitZ();
  // Give the plane with the normal pointing DOWN: the hint must flip it.
  t.plane_in_source = Plane{-n, n.dot(t.source_from_truth.translation)};
  t.hint_in_source = t.source_from_truth * (scale * Eigen::Vector3d(w_m / 2, h_m / 2, 1.5));
  return t;
}

TEST(BuildTableFrame, RectangleBecomesPositiveQuadrantWithZUp) {
  for (uint64_t seed = 0; seed < 20; ++seed) {
    const Table t = MakeTable(seed, 1.2, 0.8, 30);
    auto frame = BuildTableFrame(t.plane_in_source, t.points_in_source, t.hint_in_source);
    ASSERT_TRUE(frame.ok()) << frame.status().ToString();
    const Rigid3d& table_from_source = frame->table_from_source;
    constexpr double kTolerance_m = kExactRelativeTolerance * 1.2;
    for (const Eigen::Vector3d& p : t.points_in_source) {
      const Eigen::Vector3d q = table_from_source * p;
      EXPECT_NEAR(q.z(), 0.0, kTolerance_m);
      EXPECT_GE(q.x(), -kTolerance_m);
      EXPECT_GE(q.y(), -kTolerance_m);
      EXPECT_LE(q.x(), 1.2 + kTolerance_m);
      EXPECT_LE(q.y(), 0.8 + kTolerance_m);
    }
    EXPECT_GT((table_from_source * t.hint_in_source).z(), 0.0);
    EXPECT_NEAR(frame->extent_x_m, 1.2, kTolerance_m);
    EXPECT_NEAR(frame->extent_y_m, 0.8, kTolerance_m);
    EXPECT_LT(frame->max_abs_height_m, kTolerance_m);
    EXPECT_EQ(frame->num_hull_vertices, 4);
    EXPECT_EQ(frame->num_points, 34);
    // The origin is a corner of the rectangle: one of the 4 corners maps to (0, 0, 0).
    double nearest_corner_m = std::numeric_limits<double>::infinity();
    for (int i = 0; i < 4; ++i) {
      nearest_corner_m =
          std::min(nearest_corner_m, (table_from_source * t.points_in_source[i]).norm());
    }
    EXPECT_LT(nearest_corner_m, kTolerance_m);
    EXPECT_NEAR(table_from_source.RotationMatrix().determinant(), 1.0, kExactRelativeTolerance);
  }
}

TEST(BuildTableFrame, ExactAcrossScales) {
  for (double scale : {1e-3, 1e-1, 1.0, 1e2, 1e4}) {
    const Table t = MakeTable(7, 1.2, 0.8, 50, scale);
    auto frame = BuildTableFrame(t.plane_in_source, t.points_in_source, t.hint_in_source);
    ASSERT_TRUE(frame.ok()) << frame.status().ToString();
    const double tolerance_m = kExactRelativeTolerance * scale;
    EXPECT_NEAR(frame->extent_x_m, 1.2 * scale, tolerance_m);
    EXPECT_NEAR(frame->extent_y_m, 0.8 * scale, tolerance_m);
    for (const Eigen::Vector3d& p : t.points_in_source) {
      const Eigen::Vector3d q = frame->table_from_source * p;
      EXPECT_NEAR(q.z(), 0.0, tolerance_m);
      EXPECT_GE(std::min(q.x(), q.y()), -tolerance_m);
    }
  }
}

TEST(BuildTableFrame, InvariantUnderPointOrder) {
  std::mt19937_64 rng(8);
  for (uint64_t seed = 0; seed < 10; ++seed) {
    Table t = MakeTable(seed, 1.0, 0.7, 40);
    auto reference = BuildTableFrame(t.plane_in_source, t.points_in_source, t.hint_in_source);
    ASSERT_TRUE(reference.ok());
    for (int shuffle = 0; shuffle < 5; ++shuffle) {
      std::shuffle(t.points_in_source.begin(), t.points_in_source.end(), rng);
      auto frame = BuildTableFrame(t.plane_in_source, t.points_in_source, t.hint_in_source);
      ASSERT_TRUE(frame.ok());
      // Bit-identical: the rule uses only order-free quantities.
      EXPECT_EQ(frame->table_from_source.ToMatrix4(), reference->table_from_source.ToMatrix4());
    }
  }
}

TEST(BuildTableFrame, SquareTieBrokenTowardSourceX) {
  // A square rotated 30 deg in the source xy plane: four candidate +x directions (30, 120,
  // 210, 300 deg); the one closest to the source +x is 30 deg.
  const double a = DegToRad(30.0);
  const Eigen::Vector3d ex(std::cos(a), std::sin(a), 0.0), ey(-std::sin(a), std::cos(a), 0.0);
  std::vector<Eigen::Vector3d> points;
  for (int i = 0; i <= 4; ++i) {
    for (int j = 0; j <= 4; ++j) points.push_back(0.25 * i * ex + 0.25 * j * ey);
  }
  const Plane plane{Eigen::Vector3d::UnitZ(), 0.0};
  auto frame = BuildTableFrame(plane, points, Eigen::Vector3d(0.3, 0.3, 2.0));
  ASSERT_TRUE(frame.ok()) << frame.status().ToString();
  const Eigen::Matrix3d r = frame->table_from_source.RotationMatrix();
  EXPECT_LT((r.row(0).transpose() - ex).norm(), kExactRelativeTolerance);
  EXPECT_LT((r.row(2).transpose() - Eigen::Vector3d::UnitZ()).norm(), kExactRelativeTolerance);
  EXPECT_LT((frame->table_from_source * Eigen::Vector3d::Zero()).norm(), kExactRelativeTolerance);

  // The same square seen from below (hint at z < 0): z flips, and +x is still the candidate
  // closest to the source +x.
  auto below = BuildTableFrame(plane, points, Eigen::Vector3d(0.3, 0.3, -2.0));
  ASSERT_TRUE(below.ok());
  const Eigen::Matrix3d rb = below->table_from_source.RotationMatrix();
  EXPECT_LT((rb.row(2).transpose() + Eigen::Vector3d::UnitZ()).norm(), kExactRelativeTolerance);
  EXPECT_LT((rb.row(0).transpose() - ex).norm(), kExactRelativeTolerance);
  for (const Eigen::Vector3d& p : points) {
    const Eigen::Vector3d q = below->table_from_source * p;
    EXPECT_GE(std::min(q.x(), q.y()), -kExactRelativeTolerance);
  }
}

TEST(BuildTableFrame, MinimumAreaAgainstBruteForce) {
  // Random clouds: the rectangle found has an area no larger than the best of 36000 sampled
  // orientations (0.005 deg steps), and every point lies inside it.
  std::mt19937_64 rng(9);
  std::normal_distribution<double> g(0.0, 1.0);
  for (int trial = 0; trial < 20; ++trial) {
    std::vector<Eigen::Vector3d> points;
    const double aspect = 0.2 + 0.8 * std::abs(g(rng)) / 3.0;
    for (int i = 0; i < 60; ++i) points.emplace_back(g(rng), aspect * g(rng), 0.0);
    auto frame =
        BuildTableFrame(Plane{Eigen::Vector3d::UnitZ(), 0.0}, points, Eigen::Vector3d(0, 0, 1));
    ASSERT_TRUE(frame.ok());
    const double area = frame->extent_x_m * frame->extent_y_m;
    double brute_area = std::numeric_limits<double>::infinity();
    for (int k = 0; k < 36000; ++k) {
      const double t = DegToRad(k * 0.005);
      double min_a = 1e300, max_a = -1e300, min_b = 1e300, max_b = -1e300;
      for (const Eigen::Vector3d& p : points) {
        const double pa = std::cos(t) * p.x() + std::sin(t) * p.y();
        const double pb = -std::sin(t) * p.x() + std::cos(t) * p.y();
        min_a = std::min(min_a, pa), max_a = std::max(max_a, pa);
        min_b = std::min(min_b, pb), max_b = std::max(max_b, pb);
      }
      brute_area = std::min(brute_area, (max_a - min_a) * (max_b - min_b));
    }
    EXPECT_LE(area, brute_area * (1.0 + kExactRelativeTolerance));
    EXPECT_GE(frame->extent_x_m, frame->extent_y_m);
    for (const Eigen::Vector3d& p : points) {
      const Eigen::Vector3d q = frame->table_from_source * p;
      constexpr double kTolerance_m = 1e-12;
      EXPECT_GE(q.x(), -kTolerance_m);
      EXPECT_GE(q.y(), -kTolerance_m);
      EXPECT_LE(q.x(), frame->extent_x_m + kTolerance_m);
      EXPECT_LE(q.y(), frame->extent_y_m + kTolerance_m);
    }
  }
}

TEST(BuildTableFrame, NoisyPointsReportHeight) {
  Table t = MakeTable(10, 1.2, 0.8, 100);
  std::mt19937_64 rng(11);
  std::normal_distribution<double> noise(0.0, 1e-3);
  const Eigen::Vector3d n = t.plane_in_source.normal;
  for (Eigen::Vector3d& p : t.points_in_source) p += noise(rng) * n;
  auto frame = BuildTableFrame(t.plane_in_source, t.points_in_source, t.hint_in_source);
  ASSERT_TRUE(frame.ok());
  constexpr double kMinExpectedHeight_m = 1e-3;  // 104 draws of a 1 mm Gaussian: max > 1 sigma
  constexpr double kMaxExpectedHeight_m = 5e-3;
  EXPECT_GT(frame->max_abs_height_m, kMinExpectedHeight_m);
  EXPECT_LT(frame->max_abs_height_m, kMaxExpectedHeight_m);
}

TEST(BuildTableFrame, NearTieStability) {
  // A 1.2 m x (1.2 m - delta) table outline (200 points on its edges) with 1 mm in-plane
  // noise, long side at 20 deg to the source +x. Records how often +x ends up along the short
  // side (a 90 deg flip) and the jitter of the x axis about z otherwise.
  constexpr double kNoise_m = 1e-3;
  constexpr double kLong_m = 1.2;
  const double a = DegToRad(20.0);
  const Eigen::Vector3d ex(std::cos(a), std::sin(a), 0.0), ey(-std::sin(a), std::cos(a), 0.0);
  for (double delta_m : {0.0, 1e-3, 3e-3, 1e-2, 3e-2}) {
    std::mt19937_64 rng(12);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    std::normal_distribution<double> noise(0.0, kNoise_m);
    const double short_m = kLong_m - delta_m;
    int flips = 0;
    double sum_sq_angle_rad = 0.0;
    constexpr int kTrials = 100;
    for (int trial = 0; trial < kTrials; ++trial) {
      std::vector<Eigen::Vector3d> points;
      for (int i = 0; i < 200; ++i) {
        const double s = u(rng);
        const int side = i % 4;
        const double x = side == 0   ? s * kLong_m
                         : side == 1 ? kLong_m
                         : side == 2 ? s * kLong_m
                                     : 0.0;
        const double y = side == 0   ? 0.0
                         : side == 1 ? s * short_m
                         : side == 2 ? short_m
                                     : s * short_m;
        points.push_back((x + noise(rng)) * ex + (y + noise(rng)) * ey);
      }
      auto frame = BuildTableFrame(Plane{Eigen::Vector3d::UnitZ(), 0.0}, points,
                                   Eigen::Vector3d(0.5, 0.5, 1.0));
      ASSERT_TRUE(frame.ok());
      const Eigen::Vector3d x_axis = frame->table_from_source.RotationMatrix().row(0).transpose();
      if (std::abs(x_axis.dot(ex)) < std::abs(x_axis.dot(ey))) {
        ++flips;
      } else {
        const double angle_rad = std::asin(std::abs(x_axis.cross(ex).z()));
        sum_sq_angle_rad += angle_rad * angle_rad;
      }
    }
    const double jitter_deg =
        flips < kTrials ? RadToDeg(std::sqrt(sum_sq_angle_rad / (kTrials - flips))) : 0.0;
    std::printf(
        "[ measured ] sides differ by %.0f mm, 1 mm noise: %d/%d frames with +x along "
        "the short side; x-axis jitter %.3f deg rms otherwise\n",
        MToMm(delta_m), flips, kTrials, jitter_deg);
    constexpr double kClearTie_m = 1e-2;  // 10 noise sigmas
    if (delta_m >= kClearTie_m) {
      EXPECT_EQ(flips, 0) << delta_m;
    }
    constexpr double kMaxJitter_deg = 0.5;
    EXPECT_LT(jitter_deg, kMaxJitter_deg);
  }
}

TEST(BuildTableFrame, RejectsBadInput) {
  const Plane plane{Eigen::Vector3d::UnitZ(), 0.0};
  const Eigen::Vector3d up(0, 0, 1);
  const std::vector<Eigen::Vector3d> good = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  const std::vector<Eigen::Vector3d> empty;
  const std::vector<Eigen::Vector3d> two = {{0, 0, 0}, {1, 0, 0}};
  // Collinear on the plane, and collinear after projection (a vertical wall of points).
  const std::vector<Eigen::Vector3d> collinear = {{0, 0, 0}, {1, 1, 0}, {2, 2, 0}, {3, 3, 0}};
  const std::vector<Eigen::Vector3d> wall = {{0, 0, 0}, {1, 0, 0}, {0, 0, 1}, {1, 0, 1}};
  const std::vector<Eigen::Vector3d> coincident(4, Eigen::Vector3d(1, 1, 0));
  EXPECT_TRUE(BuildTableFrame(plane, good, up).ok());
  EXPECT_EQ(BuildTableFrame(plane, empty, up).status().code(), StatusCode::kDegenerate);
  EXPECT_EQ(BuildTableFrame(plane, two, up).status().code(), StatusCode::kDegenerate);
  EXPECT_EQ(BuildTableFrame(plane, collinear, up).status().code(), StatusCode::kDegenerate);
  EXPECT_EQ(BuildTableFrame(plane, wall, up).status().code(), StatusCode::kDegenerate);
  EXPECT_EQ(BuildTableFrame(plane, coincident, up).status().code(), StatusCode::kDegenerate);
  const auto on_plane = BuildTableFrame(plane, good, Eigen::Vector3d(5, 5, 0));
  EXPECT_EQ(on_plane.status().code(), StatusCode::kDegenerate);
  EXPECT_NE(on_plane.status().message().find("up hint"), std::string::npos);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  auto bad_points = good;
  bad_points[1].x() = nan;
  EXPECT_EQ(BuildTableFrame(plane, bad_points, up).status().code(), StatusCode::kInvalidArgument);
  bad_points[1].x() = inf;
  EXPECT_EQ(BuildTableFrame(plane, bad_points, up).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(BuildTableFrame(plane, good, Eigen::Vector3d(0, 0, inf)).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(BuildTableFrame(Plane{Eigen::Vector3d(0, 0, 2), 0.0}, good, up).status().code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(BuildTableFrame(Plane{Eigen::Vector3d::UnitZ(), nan}, good, up).status().code(),
            StatusCode::kInvalidArgument);
  TableFrameOptions options;
  options.min_hint_height_m = 0.0;
  EXPECT_EQ(BuildTableFrame(plane, good, up, options).status().code(),
            StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace sandtable
