#include "common/estimation/umeyama.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include <Eigen/SVD>

namespace sandtable {
namespace {

// What both fits share: the centred point sets and Umeyama's rotation and scale.
struct UmeyamaSolution {
  Eigen::Matrix3d rotation;
  double scale = 1.0;
  Eigen::Vector3d mean_source;
  Eigen::Vector3d mean_target;
  double source_spread_ratio = 0.0;
};

Eigen::Vector3d Mean(std::span<const Eigen::Vector3d> points) {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& p : points) sum += p;
  return sum / static_cast<double>(points.size());
}

// Singular values of the centred points (N x 3), largest first. Computed on the points
// themselves rather than on their 3x3 scatter matrix so that a ratio of 1e-9 is resolvable
// (the scatter matrix squares it to 1e-18, below double precision).
Eigen::Vector3d CentredSingularValues(std::span<const Eigen::Vector3d> points,
                                      const Eigen::Vector3d& mean) {
  Eigen::MatrixX3d centred(points.size(), 3);
  for (size_t i = 0; i < points.size(); ++i) centred.row(i) = (points[i] - mean).transpose();
  return Eigen::JacobiSVD<Eigen::MatrixX3d>(centred).singularValues();
}

Status CheckSpread(std::span<const Eigen::Vector3d> points, const Eigen::Vector3d& mean,
                   const char* which, double tolerance, double* spread_ratio) {
  const Eigen::Vector3d s = CentredSingularValues(points, mean);
  *spread_ratio = s[0] > 0.0 ? s[1] / s[0] : 0.0;
  if (!(s[0] > 0.0) || s[1] < tolerance * s[0]) {
    std::ostringstream m;
    m << "umeyama: the " << which << " points are " << (s[0] > 0.0 ? "collinear" : "all coincident")
      << " (singular values " << s[0] << ", " << s[1] << ", " << s[2]
      << "); the rotation about their line is undetermined: add points off the line";
    return DegenerateError(m.str());
  }
  return OkStatus();
}

Expected<UmeyamaSolution> Solve(std::span<const Eigen::Vector3d> source,
                                std::span<const Eigen::Vector3d> target,
                                const UmeyamaOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  if (source.size() != target.size()) {
    std::ostringstream m;
    m << "umeyama: " << source.size() << " source points but " << target.size()
      << " target points; they must be paired";
    return InvalidArgumentError(m.str());
  }
  for (size_t i = 0; i < source.size(); ++i) {
    if (!source[i].allFinite() || !target[i].allFinite()) {
      std::ostringstream m;
      m << "umeyama: pair " << i << " has a non-finite coordinate";
      return InvalidArgumentError(m.str());
    }
  }
  if (source.size() < 3) {
    std::ostringstream m;
    m << "umeyama: " << source.size() << " point pairs given, at least 3 needed";
    return DegenerateError(m.str());
  }
  UmeyamaSolution solution;
  solution.mean_source = Mean(source);
  solution.mean_target = Mean(target);
  double target_spread_ratio = 0.0;
  ST_RETURN_IF_ERROR(CheckSpread(source, solution.mean_source, "source",
                                 options.degenerate_relative_tolerance,
                                 &solution.source_spread_ratio));
  ST_RETURN_IF_ERROR(CheckSpread(target, solution.mean_target, "target",
                                 options.degenerate_relative_tolerance, &target_spread_ratio));

  // Umeyama (1991), eqs. 38-42: with the cross-covariance
  //   Sigma = 1/n sum (y_i - mu_y)(x_i - mu_x)^T = U D V^T,
  // R = U S V^T with S = diag(1, 1, det(U) det(V)) (the reflection fix: a proper rotation
  // even when the best orthogonal matrix is a reflection), c = tr(D S) / sigma_x^2 and
  // t = mu_y - c R mu_x.
  const double n = static_cast<double>(source.size());
  Eigen::Matrix3d sigma = Eigen::Matrix3d::Zero();
  double variance_source = 0.0;
  for (size_t i = 0; i < source.size(); ++i) {
    const Eigen::Vector3d xs = source[i] - solution.mean_source;
    const Eigen::Vector3d xt = target[i] - solution.mean_target;
    sigma += xt * xs.transpose();
    variance_source += xs.squaredNorm();
  }
  sigma /= n;
  variance_source /= n;
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(sigma, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Vector3d s_diag(1.0, 1.0, 1.0);
  if (svd.matrixU().determinant() * svd.matrixV().determinant() < 0.0) s_diag[2] = -1.0;
  solution.rotation = svd.matrixU() * s_diag.asDiagonal() * svd.matrixV().transpose();
  solution.scale = svd.singularValues().dot(s_diag) / variance_source;
  if (!(solution.scale > 0.0) || !std::isfinite(solution.scale)) {
    std::ostringstream m;
    m << "umeyama: the fitted scale is " << solution.scale
      << "; the pairing does not describe a similarity (check the point order)";
    return DegenerateError(m.str());
  }
  return solution;
}

template <typename Transform>
void FillResiduals(const Transform& target_from_source, std::span<const Eigen::Vector3d> source,
                   std::span<const Eigen::Vector3d> target, std::vector<double>* residuals_m,
                   double* rms_m, double* max_m) {
  residuals_m->resize(source.size());
  double sum_sq = 0.0;
  *max_m = 0.0;
  for (size_t i = 0; i < source.size(); ++i) {
    const double r = (target[i] - target_from_source * source[i]).norm();
    (*residuals_m)[i] = r;
    sum_sq += r * r;
    *max_m = std::max(*max_m, r);
  }
  *rms_m = std::sqrt(sum_sq / static_cast<double>(source.size()));
}

}  // namespace

Status UmeyamaOptions::Check() const {
  if (!(degenerate_relative_tolerance > 0.0 && degenerate_relative_tolerance < 1.0)) {
    return InvalidArgumentError("UmeyamaOptions: degenerate_relative_tolerance must be in (0, 1)");
  }
  return OkStatus();
}

Expected<RigidFitReport> FitRigidUmeyama(std::span<const Eigen::Vector3d> points_in_source,
                                         std::span<const Eigen::Vector3d> points_in_target,
                                         const UmeyamaOptions& options) {
  Expected<UmeyamaSolution> solution = Solve(points_in_source, points_in_target, options);
  if (!solution.ok()) return solution.status();
  // The rigid fit is the similarity fit with c = 1 (Umeyama's R does not depend on c).
  RigidFitReport report;
  report.target_from_source = Rigid3d(
      solution->rotation, solution->mean_target - solution->rotation * solution->mean_source);
  report.num_points = static_cast<int>(points_in_source.size());
  report.source_spread_ratio = solution->source_spread_ratio;
  FillResiduals(report.target_from_source, points_in_source, points_in_target, &report.residuals_m,
                &report.rms_m, &report.max_m);
  return report;
}

Expected<SimilarityFitReport> FitSimilarityUmeyama(
    std::span<const Eigen::Vector3d> points_in_source,
    std::span<const Eigen::Vector3d> points_in_target, const UmeyamaOptions& options) {
  Expected<UmeyamaSolution> solution = Solve(points_in_source, points_in_target, options);
  if (!solution.ok()) return solution.status();
  SimilarityFitReport report;
  const Eigen::Quaterniond rotation(solution->rotation);
  report.target_from_source =
      Sim3d(solution->scale, rotation,
            solution->mean_target - solution->scale * (solution->rotation * solution->mean_source));
  report.num_points = static_cast<int>(points_in_source.size());
  report.source_spread_ratio = solution->source_spread_ratio;
  FillResiduals(report.target_from_source, points_in_source, points_in_target, &report.residuals_m,
                &report.rms_m, &report.max_m);
  return report;
}

}  // namespace sandtable
