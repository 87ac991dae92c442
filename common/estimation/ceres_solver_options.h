// Ceres solver settings shared by the small dense refinements of common/estimation
// (homography, resection): dense QR, silent, single-threaded (callers parallelise across
// problems, not inside one), stopping rules taken from the routine's own options struct.
#pragma once

#include <ceres/solver.h>

namespace sandtable::internal {

// `Options` has max_iterations, function_tolerance, parameter_tolerance, gradient_tolerance.
template <typename Options>
ceres::Solver::Options SmallDenseSolverOptions(const Options& options) {
  ceres::Solver::Options solver;
  solver.linear_solver_type = ceres::DENSE_QR;
  solver.max_num_iterations = options.max_iterations;
  solver.function_tolerance = options.function_tolerance;
  solver.parameter_tolerance = options.parameter_tolerance;
  solver.gradient_tolerance = options.gradient_tolerance;
  solver.logging_type = ceres::SILENT;
  solver.num_threads = 1;
  return solver;
}

}  // namespace sandtable::internal
