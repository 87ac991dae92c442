// Hartley normalisation of 2D point sets and the collinearity measure, shared by the
// homography and resection estimators (internal to common/estimation).
#pragma once

#include <cmath>
#include <numbers>
#include <span>

#include <Eigen/Core>
#include <Eigen/Eigenvalues>

namespace sandtable::internal {

// Similarity T = [s 0 -s cx; 0 s -s cy; 0 0 1] that moves the centroid to the origin and makes
// the mean distance from it sqrt(2) (Hartley & Zisserman, sec. 4.4.4). `ok` is false when all
// points coincide (mean distance 0) or a coordinate is not finite.
struct Hartley2d {
  Eigen::Matrix3d t = Eigen::Matrix3d::Identity();
  double scale = 1.0;  // s: normalised length per input length
  Eigen::Vector2d centroid = Eigen::Vector2d::Zero();
  bool ok = false;

  Eigen::Vector2d Apply(const Eigen::Vector2d& x) const { return scale * (x - centroid); }
};

inline Hartley2d ComputeHartley2d(std::span<const Eigen::Vector2d> points) {
  Hartley2d h;
  if (points.empty()) return h;
  Eigen::Vector2d c = Eigen::Vector2d::Zero();
  for (const Eigen::Vector2d& p : points) c += p;
  c /= static_cast<double>(points.size());
  double mean_distance = 0.0;
  for (const Eigen::Vector2d& p : points) mean_distance += (p - c).norm();
  mean_distance /= static_cast<double>(points.size());
  if (!(mean_distance > 0.0) || !std::isfinite(mean_distance)) return h;
  h.centroid = c;
  h.scale = std::numbers::sqrt2 / mean_distance;
  h.t << h.scale, 0.0, -h.scale * c.x(), 0.0, h.scale, -h.scale * c.y(), 0.0, 0.0, 1.0;
  h.ok = true;
  return h;
}

// s_min / s_max of the centred 2 x n point matrix, in [0, 1]; 0 for fewer than 2 distinct
// points. Scale-invariant. Computed from the 2x2 scatter, whose eigenvalues are the squared
// singular values; the ratio is resolved down to about 1e-8 (double rounding of the scatter).
inline double CollinearityRatio(std::span<const Eigen::Vector2d> points) {
  if (points.size() < 2) return 0.0;
  Eigen::Vector2d c = Eigen::Vector2d::Zero();
  for (const Eigen::Vector2d& p : points) c += p;
  c /= static_cast<double>(points.size());
  Eigen::Matrix2d scatter = Eigen::Matrix2d::Zero();
  for (const Eigen::Vector2d& p : points) scatter += (p - c) * (p - c).transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(scatter, Eigen::EigenvaluesOnly);
  const double largest = eig.eigenvalues()(1);
  if (!(largest > 0.0)) return 0.0;
  return std::sqrt(std::max(0.0, eig.eigenvalues()(0)) / largest);
}

}  // namespace sandtable::internal
