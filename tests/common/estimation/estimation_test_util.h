// Helpers shared by the estimator tests in this folder.
#pragma once

#include <cstdarg>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <vector>

#include <Eigen/Core>

namespace sandtable::test_util {

// `points` with Gaussian noise of `sigma_px` per axis, deterministic for `seed`.
inline std::vector<Eigen::Vector2d> AddNoise(const std::vector<Eigen::Vector2d>& points,
                                             double sigma_px, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> noise(0.0, 1.0);
  std::vector<Eigen::Vector2d> out = points;
  for (Eigen::Vector2d& p : out) p += sigma_px * Eigen::Vector2d(noise(rng), noise(rng));
  return out;
}

// Sweep tables go to stdout only when SANDTABLE_SWEEP_LOG is set, so that the numbers quoted
// in the tests' comments and docs/numerics.md can be reproduced:
//   SANDTABLE_SWEEP_LOG=1 build/tests/common/estimation/common_estimation_resection_test
inline void SweepLog(const char* format, ...) {
  if (std::getenv("SANDTABLE_SWEEP_LOG") == nullptr) return;
  va_list args;
  va_start(args, format);
  std::vprintf(format, args);
  va_end(args);
}

}  // namespace sandtable::test_util
