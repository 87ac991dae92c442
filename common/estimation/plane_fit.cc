#include "common/estimation/plane_fit.h"

#include <algorithm>
#include <cmath>
#include <optional>
#include <sstream>

#include <Eigen/Geometry>
#include <Eigen/SVD>

#include "common/estimation/ransac.h"

namespace sandtable {
namespace {

// Flips the normal so that its largest-magnitude component is positive (the first of equal
// ones): a fitted plane then does not depend on the sign the SVD happened to return.
Plane Canonical(const Eigen::Vector3d& normal, const Eigen::Vector3d& point_on_plane) {
  int largest = 0;
  for (int i = 1; i < 3; ++i) {
    if (std::abs(normal[i]) > std::abs(normal[largest])) largest = i;
  }
  const Eigen::Vector3d n = normal[largest] < 0.0 ? Eigen::Vector3d(-normal) : normal;
  return Plane{n, -n.dot(point_on_plane)};
}

Status CheckFinite(std::span<const Eigen::Vector3d> points_m) {
  for (size_t i = 0; i < points_m.size(); ++i) {
    if (!points_m[i].allFinite()) {
      std::ostringstream m;
      m << "plane fit: point " << i << " is not finite (" << points_m[i].transpose() << ")";
      return InvalidArgumentError(m.str());
    }
  }
  return OkStatus();
}

// Least-squares plane of the points selected by `indices` (all when empty is not allowed:
// the caller passes them). Assumes finite points.
template <typename GetPoint>
Expected<Plane> LeastSquares(int count, const GetPoint& point) {
  if (count < 3) {
    std::ostringstream m;
    m << "plane fit: " << count << " points given, at least 3 needed";
    return DegenerateError(m.str());
  }
  // Two passes: the centroid first, so that points far from the origin (1e4 m) lose no
  // precision in the scatter.
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (int i = 0; i < count; ++i) centroid += point(i);
  centroid /= static_cast<double>(count);
  Eigen::MatrixX3d centred(count, 3);
  for (int i = 0; i < count; ++i) centred.row(i) = (point(i) - centroid).transpose();
  // SVD of the centred points (not eigenvectors of their scatter matrix, which squares the
  // condition number): the normal is the right singular vector of the smallest singular value.
  Eigen::JacobiSVD<Eigen::MatrixX3d> svd(centred, Eigen::ComputeFullV);
  const Eigen::Vector3d s = svd.singularValues();
  if (!(s[0] > 0.0) || s[1] < kCollinearRelativeTolerance * s[0]) {
    std::ostringstream m;
    m << "plane fit: the " << count << " points are "
      << (s[0] > 0.0 ? "collinear" : "all coincident") << " (singular values " << s[0] << ", "
      << s[1] << ", " << s[2] << "); a plane through them is undetermined";
    return DegenerateError(m.str());
  }
  return Canonical(svd.matrixV().col(2).normalized(), centroid);
}

class PlaneEstimator {
 public:
  using Model = Plane;
  static constexpr int kMinSamples = 3;

  explicit PlaneEstimator(std::span<const Eigen::Vector3d> points_m) : points_m_(points_m) {}

  int NumData() const { return static_cast<int>(points_m_.size()); }

  std::vector<Plane> FitMinimal(std::span<const int> sample) const {
    const Eigen::Vector3d& a = points_m_[sample[0]];
    const Eigen::Vector3d ab = points_m_[sample[1]] - a;
    const Eigen::Vector3d ac = points_m_[sample[2]] - a;
    const Eigen::Vector3d cross = ab.cross(ac);
    // |ab x ac| = |ab| |ac| sin(angle): refuse samples within ~1e-6 rad of collinear, whose
    // normal would be noise.
    const double norm = cross.norm();
    if (!(norm > 1e-6 * ab.norm() * ac.norm())) return {};
    const Eigen::Vector3d n = cross / norm;
    return {Plane{n, -n.dot(a)}};
  }

  double Residual(const Plane& plane, int index) const {
    return std::abs(plane.SignedDistance_m(points_m_[index]));
  }

  std::optional<Plane> FitInliers(std::span<const int> inliers) const {
    Expected<Plane> plane =
        LeastSquares(static_cast<int>(inliers.size()),
                     [&](int i) -> const Eigen::Vector3d& { return points_m_[inliers[i]]; });
    if (!plane.ok()) return std::nullopt;
    return *plane;
  }

 private:
  std::span<const Eigen::Vector3d> points_m_;
};

}  // namespace

Plane Plane::OrientedToward(const Eigen::Vector3d& x_m) const {
  if (SignedDistance_m(x_m) >= 0.0) return *this;
  return Plane{-normal, -offset_m};
}

bool Plane::AllFinite() const { return normal.allFinite() && std::isfinite(offset_m); }

Status PlaneFitOptions::Check() const {
  if (!(inlier_threshold_m > 0.0) || !std::isfinite(inlier_threshold_m)) {
    return InvalidArgumentError("PlaneFitOptions: inlier_threshold_m must be finite and > 0");
  }
  RansacOptions ransac;
  ransac.max_error = inlier_threshold_m;
  ransac.confidence = confidence;
  ransac.min_iterations = min_iterations;
  ransac.max_iterations = max_iterations;
  ransac.min_inlier_ratio = min_inlier_ratio;
  return ransac.Check();
}

Expected<Plane> FitPlaneLeastSquares(std::span<const Eigen::Vector3d> points_m) {
  ST_RETURN_IF_ERROR(CheckFinite(points_m));
  return LeastSquares(static_cast<int>(points_m.size()),
                      [&](int i) -> const Eigen::Vector3d& { return points_m[i]; });
}

Expected<PlaneFitReport> FitPlaneRansac(std::span<const Eigen::Vector3d> points_m,
                                        const PlaneFitOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  ST_RETURN_IF_ERROR(CheckFinite(points_m));
  const int n = static_cast<int>(points_m.size());
  if (n < 3) {
    std::ostringstream m;
    m << "plane fit: " << n << " points given, at least 3 needed";
    return DegenerateError(m.str());
  }
  // All points collinear (or coincident): no sample would ever give a plane; say why.
  if (Expected<Plane> all = FitPlaneLeastSquares(points_m); !all.ok()) return all.status();

  PlaneEstimator estimator(points_m);
  RansacOptions ransac;
  ransac.max_error = options.inlier_threshold_m;
  ransac.confidence = options.confidence;
  ransac.min_iterations = options.min_iterations;
  ransac.max_iterations = options.max_iterations;
  ransac.min_inlier_ratio = 0.0;  // checked below, after the final refit
  ransac.seed = options.seed;
  auto result = Ransac(estimator, ransac);
  if (!result.ok()) return result.status().WithContext("plane fit");

  // Local optimisation: the least-squares plane of the inliers, re-scored, until the inlier
  // set stops changing (at most kMaxRefits times). The reported plane is always a
  // least-squares plane, never the 3-point sample plane.
  constexpr int kMaxRefits = 5;
  std::vector<char> mask = result->inlier_mask;
  Plane plane = result->model;
  for (int refit = 0; refit < kMaxRefits; ++refit) {
    std::vector<int> inliers;
    for (int i = 0; i < n; ++i) {
      if (mask[i]) inliers.push_back(i);
    }
    std::optional<Plane> refined = estimator.FitInliers(inliers);
    if (!refined) break;  // inliers collinear: keep the sample plane
    plane = *refined;
    std::vector<char> new_mask(n);
    for (int i = 0; i < n; ++i) {
      new_mask[i] = estimator.Residual(plane, i) <= options.inlier_threshold_m ? 1 : 0;
    }
    const bool same = new_mask == mask;
    mask = std::move(new_mask);
    if (same) break;
  }

  PlaneFitReport report;
  report.plane = plane;
  report.inlier_mask = std::move(mask);
  report.num_points = n;
  report.ransac_iterations = result->iterations;
  double sum_sq = 0.0;
  for (int i = 0; i < n; ++i) {
    if (!report.inlier_mask[i]) continue;
    const double r = estimator.Residual(plane, i);
    ++report.num_inliers;
    sum_sq += r * r;
    report.max_inlier_distance_m = std::max(report.max_inlier_distance_m, r);
  }
  report.inlier_ratio = static_cast<double>(report.num_inliers) / n;
  report.rms_m = report.num_inliers > 0 ? std::sqrt(sum_sq / report.num_inliers) : 0.0;
  if (report.num_inliers < 3 || report.inlier_ratio < options.min_inlier_ratio) {
    std::ostringstream m;
    m << "plane fit: " << report.num_inliers << " of " << n << " points (ratio "
      << report.inlier_ratio << ") lie within " << options.inlier_threshold_m
      << " m of the best plane; at least " << options.min_inlier_ratio
      << " required: raise inlier_threshold_m or remove clutter";
    return DegenerateError(m.str());
  }
  return report;
}

}  // namespace sandtable
