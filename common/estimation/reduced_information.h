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

#include <functional>
#include <map>
#include <span>
#include <string>
#include <vector>

#include <ceres/problem.h>
#include <Eigen/Core>

#include "common/base/status.h"

namespace sandtable {

// When the solve's weights are not the noise's (observations known to be exact whitened like
// the others), the estimate's covariance is the sandwich S^-1 N S^-1, with N the covariance of
// the reduced gradient: per eliminated block, K = J_u - J_x V^-1 W over its residuals, and
// N = sum K^T D K, D = the true variance of each whitened residual (1 where the weights are
// right). `true_variance(id)` gives D for a residual block.
struct ReducedInformation {
  Eigen::MatrixXd information;          // P x P, symmetric: S above
  Eigen::MatrixXd gradient_covariance;  // P x P: N above (when true_variance was given)
  // First column and tangent size of each kept block that has columns (not constant, in the
  // problem); kept blocks without columns are absent.
  std::map<const double*, int> column;
  std::map<const double*, int> size;
  int eliminated_blocks = 0;
  int residual_blocks = 0;
};

Expected<ReducedInformation> ComputeReducedInformation(
    const ceres::Problem& problem, std::span<double* const> kept,
    std::span<double* const> eliminated,
    const std::function<double(ceres::ResidualBlockId)>& true_variance = nullptr);

struct MarginalCovariance {
  Eigen::MatrixXd covariance;  // P x P, same columns as the information
  // Directions the data do not determine (null space of the information, scaled by its
  // diagonal: eigenvalues under rank_tolerance x the largest), one unit column each, in the
  // parameters' own units. The covariance above excludes them (a pseudo-inverse).
  std::vector<Eigen::VectorXd> undetermined;
};

// S^+ N S^+ (the pseudo-inverse of InvertInformation with sigma2 = 1, same undetermined
// directions): the covariance of an estimate weighted otherwise than its noise.
MarginalCovariance SandwichCovariance(const ReducedInformation& reduced,
                                      double rank_tolerance = 1e-10);

// sigma2: the variance factor (1 for residuals whitened by their true sigmas; the measured
// (residual sum of squares) / (redundancy) to take the noise from the data).
MarginalCovariance InvertInformation(const Eigen::MatrixXd& information, double sigma2,
                                     double rank_tolerance = 1e-10);

}  // namespace sandtable
