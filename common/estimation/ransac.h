// Generic RANSAC (Fischler & Bolles) with an adaptive iteration count.
//
// An Estimator provides:
//   using Model = ...;
//   static constexpr int kMinSamples;                          // minimal sample size
//   int NumData() const;
//   // Models fitted to the data at `sample` (kMinSamples indices); empty if degenerate.
//   std::vector<Model> FitMinimal(std::span<const int> sample) const;
//   // Residual of datum `index` under `model`, in the unit of RansacOptions::max_error.
//   double Residual(const Model& model, int index) const;
//   // Optional refit on all inliers (least squares); return nullopt to keep the sample model.
//   std::optional<Model> FitInliers(std::span<const int> inliers) const;
// Residuals are compared with max_error directly (not squared). The iteration count adapts to
// the best inlier ratio seen: N = log(1 - confidence) / log(1 - w^k), clamped to
// [min_iterations, max_iterations]. Deterministic for a given seed.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numeric>
#include <optional>
#include <random>
#include <span>
#include <sstream>
#include <vector>

#include "common/base/status.h"

namespace sandtable {

struct RansacOptions {
  double max_error = 1.0;     // inlier threshold, in the estimator's residual unit (e.g. px)
  double confidence = 0.999;  // probability that one all-inlier sample was drawn
  int min_iterations = 10;
  int max_iterations = 10000;
  double min_inlier_ratio = 0.0;  // fail (DEGENERATE) when the best ratio is below this
  // When the search stops at max_iterations, the probability that at least one all-inlier
  // sample was drawn, 1 - (1 - w^k)^N with w the best inlier ratio, must reach this, else
  // NOT_CONVERGED: below 0.5 it is more likely than not that no clean sample was ever drawn
  // and the "best" model is noise (seen at 90 % outliers: 5 inliers of 500, a 976 px error).
  double min_achieved_confidence = 0.5;
  uint64_t seed = 0;
  Status Check() const {
    if (!(max_error > 0.0) || !std::isfinite(max_error)) {
      return InvalidArgumentError("RansacOptions: max_error must be finite and > 0");
    }
    if (!(confidence > 0.0 && confidence < 1.0)) {
      return InvalidArgumentError("RansacOptions: confidence must be in (0, 1)");
    }
    if (min_iterations < 1 || max_iterations < min_iterations) {
      return InvalidArgumentError("RansacOptions: need 1 <= min_iterations <= max_iterations");
    }
    if (!(min_inlier_ratio >= 0.0 && min_inlier_ratio <= 1.0)) {
      return InvalidArgumentError("RansacOptions: min_inlier_ratio must be in [0, 1]");
    }
    if (!(min_achieved_confidence >= 0.0 && min_achieved_confidence < 1.0)) {
      return InvalidArgumentError("RansacOptions: min_achieved_confidence must be in [0, 1)");
    }
    return OkStatus();
  }
};

template <typename Model>
struct RansacResult {
  Model model;
  std::vector<char> inlier_mask;  // 1 for inliers, size NumData()
  int num_inliers = 0;
  double inlier_ratio = 0.0;  // num_inliers / NumData()
  int iterations = 0;
  // 1 - (1 - w^k)^iterations for the final inlier ratio w: the probability that at least one
  // all-inlier minimal sample was drawn if w is the true ratio.
  double achieved_confidence = 0.0;
  bool refined = false;  // FitInliers produced the final model
};

template <typename Estimator>
Expected<RansacResult<typename Estimator::Model>> Ransac(const Estimator& estimator,
                                                         const RansacOptions& options) {
  using Model = typename Estimator::Model;
  ST_RETURN_IF_ERROR(options.Check());
  const int n = estimator.NumData();
  constexpr int k = Estimator::kMinSamples;
  if (n < k) {
    std::ostringstream s;
    s << "RANSAC: " << n << " data given, at least " << k << " needed";
    return DegenerateError(s.str());
  }

  std::mt19937_64 rng(options.seed);
  std::vector<int> indices(n);
  std::iota(indices.begin(), indices.end(), 0);
  std::vector<int> sample(k);

  auto count_inliers = [&](const Model& model, std::vector<char>* mask) {
    int count = 0;
    for (int i = 0; i < n; ++i) {
      const double r = estimator.Residual(model, i);
      const bool inlier = std::isfinite(r) && r <= options.max_error;
      (*mask)[i] = inlier ? 1 : 0;
      count += inlier;
    }
    return count;
  };

  std::optional<RansacResult<Model>> best;
  std::vector<char> mask(n);
  int required = options.max_iterations;
  int iteration = 0;
  for (; iteration < std::max(options.min_iterations, std::min(required, options.max_iterations));
       ++iteration) {
    // Partial Fisher-Yates shuffle: the first k entries become a uniform random sample.
    for (int j = 0; j < k; ++j) {
      std::uniform_int_distribution<int> pick(j, n - 1);
      std::swap(indices[j], indices[pick(rng)]);
      sample[j] = indices[j];
    }
    for (const Model& model : estimator.FitMinimal(std::span<const int>(sample))) {
      const int count = count_inliers(model, &mask);
      if (!best || count > best->num_inliers) {
        best = RansacResult<Model>{model, mask, count, static_cast<double>(count) / n, 0, false};
        const double w = best->inlier_ratio;
        const double p_good = std::pow(w, k);
        if (p_good >= 1.0 - 1e-12) {
          required = options.min_iterations;
        } else if (p_good > 0.0) {
          // log1p: for p_good below ~1e-16, log(1 - p_good) is exactly 0 and the quotient
          // -inf, whose cast to int is undefined (in practice INT_MIN: the loop stopped at
          // min_iterations on large data sets with a poor first model).
          const double needed = std::log(1.0 - options.confidence) / std::log1p(-p_good);
          required = needed < options.max_iterations ? static_cast<int>(std::ceil(needed))
                                                     : options.max_iterations;
        }
      }
    }
  }
  if (!best || best->num_inliers < k) {
    return DegenerateError("RANSAC: no model with at least a minimal sample of inliers");
  }
  best->iterations = iteration;

  // Refit on the inliers, then re-score once with the refined model.
  std::vector<int> inliers;
  for (int i = 0; i < n; ++i) {
    if (best->inlier_mask[i]) inliers.push_back(i);
  }
  if (std::optional<Model> refined = estimator.FitInliers(std::span<const int>(inliers))) {
    const int count = count_inliers(*refined, &mask);
    if (count >= best->num_inliers) {
      best->model = *refined;
      best->inlier_mask = mask;
      best->num_inliers = count;
      best->inlier_ratio = static_cast<double>(count) / n;
      best->refined = true;
    }
  }
  if (best->inlier_ratio < options.min_inlier_ratio) {
    std::ostringstream s;
    s << "RANSAC: best inlier ratio " << best->inlier_ratio << " is below the required "
      << options.min_inlier_ratio;
    return DegenerateError(s.str());
  }
  // log1p/expm1 keep the tiny probabilities of low inlier ratios exact.
  const double p_good = std::pow(best->inlier_ratio, k);
  best->achieved_confidence =
      p_good >= 1.0 ? 1.0 : -std::expm1(best->iterations * std::log1p(-p_good));
  if (best->iterations >= options.max_iterations &&
      best->achieved_confidence < options.min_achieved_confidence) {
    std::ostringstream s;
    s << "RANSAC: stopped at max_iterations = " << options.max_iterations
      << " with best inlier ratio " << best->inlier_ratio << " (" << best->num_inliers << " of "
      << n << "); the chance that any clean sample was drawn is only " << best->achieved_confidence
      << ": too many outliers for this budget, raise "
      << "max_iterations or clean the data";
    return NotConvergedError(s.str());
  }
  return *std::move(best);
}

}  // namespace sandtable
