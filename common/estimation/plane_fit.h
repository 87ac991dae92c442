// Plane fitting in 3D: least squares (SVD of the centred points) and robust (RANSAC with a
// 3-point minimal sample, then least squares on the inliers).
//
// Units: the points and every length here (threshold, offset, distances) share one unit,
// metres in this project (the names say _m). The fit is equivariant under rotation,
// translation and uniform scale as long as the threshold is scaled with the points.
// Plane: normal . x + offset_m = 0 with |normal| = 1. The sign of a fitted normal is fixed so
// that its largest-magnitude component is positive (the first of equal ones); use
// OrientedToward() to point it at a known side (e.g. the camera above the table).
//
// Failure: INVALID_ARGUMENT for options out of range or any non-finite point (no point is
// silently dropped); DEGENERATE for fewer than 3 points, for points that are all (nearly)
// collinear or coincident (second singular value of the centred points below
// kCollinearRelativeTolerance times the first), and for RANSAC finding no plane with at
// least 3 inliers or with an inlier ratio below options.min_inlier_ratio.
#pragma once

#include <cmath>
#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "common/base/status.h"

namespace sandtable {

// Points whose centred scatter has sigma_2 / sigma_1 below this are called collinear.
inline constexpr double kCollinearRelativeTolerance = 1e-9;

struct Plane {
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  // unit length
  double offset_m = 0.0;                              // normal . x + offset_m = 0

  // Signed distance of a point, positive on the side the normal points to.
  double SignedDistance_m(const Eigen::Vector3d& x_m) const { return normal.dot(x_m) + offset_m; }
  // Orthogonal projection of a point onto the plane.
  Eigen::Vector3d Project(const Eigen::Vector3d& x_m) const {
    return x_m - SignedDistance_m(x_m) * normal;
  }
  // The same plane with the normal flipped, if needed, so that `x_m` is on its positive side
  // (a point on the plane leaves it unchanged).
  Plane OrientedToward(const Eigen::Vector3d& x_m) const;
  bool AllFinite() const;
};

// Least-squares plane through all points (minimises the sum of squared orthogonal
// distances: normal = singular vector of the smallest singular value of the centred points).
Expected<Plane> FitPlaneLeastSquares(std::span<const Eigen::Vector3d> points_m);

struct PlaneFitOptions {
  double inlier_threshold_m = 0.005;  // |distance| <= this is an inlier (> 0)
  double confidence = 0.999;          // RANSAC stopping confidence, in (0, 1)
  int min_iterations = 10;
  int max_iterations = 10000;
  double min_inlier_ratio = 0.0;  // below this the fit fails (DEGENERATE), in [0, 1]
  uint64_t seed = 0;              // deterministic for a given seed
  Status Check() const;
};

struct PlaneFitReport {
  Plane plane;
  std::vector<char> inlier_mask;  // 1 for inliers, one entry per input point
  int num_points = 0;
  int num_inliers = 0;
  double inlier_ratio = 0.0;  // num_inliers / num_points
  double rms_m = 0.0;         // RMS orthogonal distance of the inliers to `plane`
  double max_inlier_distance_m = 0.0;
  int ransac_iterations = 0;
};

// RANSAC on 3-point samples (residual: |orthogonal distance|), then the least-squares plane of
// the inliers, re-scored once. Deterministic for a given options.seed.
Expected<PlaneFitReport> FitPlaneRansac(std::span<const Eigen::Vector3d> points_m,
                                        const PlaneFitOptions& options = {});

}  // namespace sandtable
