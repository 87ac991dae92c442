// The uncertainty of a solved least-squares problem's parameters with its many small blocks
// (a bundle's points) folded out: the Schur complement of the Gauss-Newton information.
//
// With the whitened Jacobian J = [J_u J_x] at the solution (u: the kept blocks, x: the
// eliminated ones, each residual block touching at most one eliminated block),
//   S = U - sum_x W_x^T V_x^-1 W_x,   U = J_u^T J_u,  V_x = J_x^T J_x,  W_x = J_x^T J_u
// is the information of u alone, and S^-1 its covariance (for residuals whitened by their true
// sigmas; MarginalCovariance scales it by a measured variance factor). Blocks held constant
// have no columns: the covariance is conditional on them (the gauge a held pose fixes).
// Jacobians are Ceres' own (tangent space of a block's manifold, loss function applied).
//
// Failure: INVALID_ARGUMENT when a residual block touches two eliminated blocks, or a free
// block that is neither kept nor eliminated (its uncertainty would silently be taken as zero),
// or a Jacobian cannot be evaluated.
// Cost: one Jacobian evaluation per residual block, plus per eliminated block O(k^2) for the k
// kept columns its residuals touch.
#pragma once

#include <map>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "common/base/status.h"

namespace ceres {
class Problem;
}

namespace sandtable {

struct ReducedInformation {
  Eigen::MatrixXd information;  // P x P, symmetric: S above
  // First column and tangent size of each kept block that has columns (not constant, in the
  // problem); kept blocks without columns are absent.
  std::map<const double*, int> column;
  std::map<const double*, int> size;
  int eliminated_blocks = 0;
  int residual_blocks = 0;
};

Expected<ReducedInformation> ComputeReducedInformation(const ceres::Problem& problem,
                                                       std::span<double* const> kept,
                                                       std::span<double* const> eliminated);

struct MarginalCovariance {
  Eigen::MatrixXd covariance;  // P x P, same columns as the information
  // Directions the data do not determine (null space of the information, scaled by its
  // diagonal: eigenvalues under rank_tolerance x the largest), one unit column each, in the
  // parameters' own units. The covariance above excludes them (a pseudo-inverse).
  std::vector<Eigen::VectorXd> undetermined;
};

// sigma2: the variance factor (1 for residuals whitened by their true sigmas; the measured
// (residual sum of squares) / (redundancy) to take the noise from the data).
MarginalCovariance InvertInformation(const Eigen::MatrixXd& information, double sigma2,
                                     double rank_tolerance = 1e-10);

}  // namespace sandtable
