// Nonlinear refinement of a homography (RefineHomography, declared in homography.h).
#include <chrono>
#include <cmath>
#include <sstream>

#include <ceres/ceres.h>
#include <ceres/sphere_manifold.h>

#include "common/estimation/ceres_solver_options.h"
#include "common/estimation/homography.h"
#include "common/estimation/homography_hartley.h"

namespace sandtable {
namespace {

// Residual of one pair in px. With Hartley similarities T_f (source) and T_t (destination,
// scale s_t), H = T_t^-1 Hn T_f, and because T_t is a similarity,
//   x_to - H x_from = (T_t x_to - Hn T_f x_from) / s_t   (inhomogeneous points).
// So the px residual is the normalised-coordinate residual divided by s_t; the parameters are
// the 9 entries of Hn (row-major) on the unit sphere, which fixes the projective scale
// without privileging any entry.
struct TransferCost {
  TransferCost(const Eigen::Vector2d& from_n, const Eigen::Vector2d& to_n, double px_per_unit)
      : from_n(from_n), to_n(to_n), px_per_unit(px_per_unit) {}

  template <typename T>
  bool operator()(const T* h, T* residual) const {
    const T x = T(from_n.x()), y = T(from_n.y());
    const T w = h[6] * x + h[7] * y + h[8];
    const T u = (h[0] * x + h[1] * y + h[2]) / w;
    const T v = (h[3] * x + h[4] * y + h[5]) / w;
    residual[0] = (T(to_n.x()) - u) * T(px_per_unit);
    residual[1] = (T(to_n.y()) - v) * T(px_per_unit);
    return true;
  }

  Eigen::Vector2d from_n, to_n;
  double px_per_unit;
};

}  // namespace

Status HomographyRefineOptions::Check() const {
  if (max_iterations < 1) {
    return InvalidArgumentError("HomographyRefineOptions: max_iterations must be >= 1");
  }
  if (!(function_tolerance > 0.0) || !(parameter_tolerance > 0.0) || !(gradient_tolerance > 0.0)) {
    return InvalidArgumentError("HomographyRefineOptions: tolerances must be > 0");
  }
  return OkStatus();
}

Expected<RefinedHomography> RefineHomography(std::span<const Eigen::Vector2d> points_from,
                                             std::span<const Eigen::Vector2d> points_to,
                                             const Eigen::Matrix3d& initial_to_from_from,
                                             const HomographyRefineOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  ST_RETURN_IF_ERROR(options.Check());
  if (points_from.size() != points_to.size()) {
    return InvalidArgumentError("homography refinement: source and destination sizes differ");
  }
  for (size_t i = 0; i < points_from.size(); ++i) {
    if (!points_from[i].allFinite() || !points_to[i].allFinite()) {
      std::ostringstream s;
      s << "homography refinement: pair " << i << " has a non-finite coordinate";
      return InvalidArgumentError(s.str());
    }
  }
  if (points_from.size() < 4) {
    return DegenerateError("homography refinement: at least 4 point pairs needed");
  }
  if (!initial_to_from_from.allFinite() || !(initial_to_from_from.norm() > 0.0)) {
    return InvalidArgumentError("homography refinement: the initial homography is not finite");
  }
  const internal::Hartley2d nf = internal::ComputeHartley2d(points_from);
  const internal::Hartley2d nt = internal::ComputeHartley2d(points_to);
  if (!nf.ok || !nt.ok) {
    return DegenerateError("homography refinement: all points of one image coincide");
  }

  RefinedHomography out;
  HomographyRefineReport& report = out.report;
  report.num_points = static_cast<int>(points_from.size());
  report.initial_rms_px = HomographyTransferRms(initial_to_from_from, points_from, points_to);

  const Eigen::Matrix3d hn0 = NormalizeHomography(nt.t * initial_to_from_from * nf.t.inverse());
  double h[9];
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) h[3 * r + c] = hn0(r, c);
  }
  ceres::Problem problem;
  const double px_per_unit = 1.0 / nt.scale;
  for (size_t i = 0; i < points_from.size(); ++i) {
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<TransferCost, 2, 9>(new TransferCost(
                                 nf.Apply(points_from[i]), nt.Apply(points_to[i]), px_per_unit)),
                             nullptr, h);
  }
  problem.SetManifold(h, new ceres::SphereManifold<9>());

  const ceres::Solver::Options solver = internal::SmallDenseSolverOptions(options);
  ceres::Solver::Summary summary;
  ceres::Solve(solver, &problem, &summary);

  report.termination = ceres::TerminationTypeToString(summary.termination_type);
  report.message = summary.message;
  report.iterations = summary.num_successful_steps + summary.num_unsuccessful_steps;
  report.converged = summary.termination_type == ceres::CONVERGENCE;
  Eigen::Matrix3d hn;
  hn << h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], h[8];
  out.to_from_from = NormalizeHomography(nt.t.inverse() * hn * nf.t);
  report.final_rms_px = HomographyTransferRms(out.to_from_from, points_from, points_to);
  report.solve_time = std::chrono::steady_clock::now() - start;
  if (summary.termination_type == ceres::FAILURE || !out.to_from_from.allFinite() ||
      !std::isfinite(report.final_rms_px)) {
    return NotConvergedError("homography refinement failed: " + summary.message);
  }
  return out;
}

}  // namespace sandtable
