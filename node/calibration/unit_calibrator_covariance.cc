// Covariance of the intrinsics after the joint refinement (ceres::Covariance, DENSE_SVD),
// scaled by the residual variance sigma^2 = 2 cost / (residuals - parameters).
#include <algorithm>
#include <cmath>
#include <string>

#include "node/calibration/unit_calibrator_steps.h"

namespace sandtable::node::unit_calibrator {

void ComputeCovariance(const UnitCalibrationOptions& options, const ceres::Solver::Summary& summary,
                       JointBlocks* b, ceres::Problem* problem, UnitCalibrationReport* report) {
  report->camera_std = report->projector_std =
      ParameterDeviations{{kNaN, kNaN, kNaN, kNaN}, {kNaN, kNaN, kNaN, kNaN, kNaN}};
  if (!options.compute_covariance) return;
  ceres::Covariance::Options cov_options;
  cov_options.algorithm_type = ceres::DENSE_SVD;
  // The parameters span pixels (fx ~ 3e3), metres and dimensionless k3, so J^T J has a
  // reciprocal condition number near 1e-16 from column scale alone (measured on the real
  // data); the SVD of J itself stays accurate to ~eps * cond(J) ~ 1e-8 there.
  cov_options.min_reciprocal_condition_number = 1e-24;
  ceres::Covariance covariance(cov_options);
  std::vector<std::pair<const double*, const double*>> blocks = {
      {b->camera.k.data(), b->camera.k.data()}, {b->projector.k.data(), b->projector.k.data()}};
  const bool camera_d_free = FixedCoefficients(options.camera_distortion).size() < 5;
  const bool projector_d_free = FixedCoefficients(options.projector_distortion).size() < 5;
  if (camera_d_free) blocks.push_back({b->camera.d.data(), b->camera.d.data()});
  if (projector_d_free) blocks.push_back({b->projector.d.data(), b->projector.d.data()});
  const int residuals = summary.num_residuals_reduced;
  const int parameters = summary.num_effective_parameters_reduced;
  const double sigma2 =
      residuals > parameters ? 2.0 * summary.final_cost / (residuals - parameters) : kNaN;
  if (!covariance.Compute(blocks, problem)) {
    report->covariance_message =
        "ceres::Covariance failed: the Jacobian is rank deficient (some parameters are not "
        "determined by these poses)";
    return;
  }
  report->covariance_ok = true;
  auto fill = [&](const double* block, int size, double* out, DistortionModel model,
                  bool distortion) {
    std::vector<double> c(size * size);
    covariance.GetCovarianceBlock(block, block, c.data());
    const std::vector<int> fixed = distortion ? FixedCoefficients(model) : std::vector<int>{};
    for (int i = 0; i < size; ++i) {
      const bool is_fixed = std::find(fixed.begin(), fixed.end(), i) != fixed.end();
      out[i] = is_fixed ? kNaN : std::sqrt(std::max(0.0, c[i * size + i]) * sigma2);
    }
  };
  fill(b->camera.k.data(), 4, report->camera_std.intrinsics_px.data(), options.camera_distortion,
       false);
  fill(b->projector.k.data(), 4, report->projector_std.intrinsics_px.data(),
       options.projector_distortion, false);
  if (camera_d_free) {
    fill(b->camera.d.data(), 5, report->camera_std.distortion.data(), options.camera_distortion,
         true);
  }
  if (projector_d_free) {
    fill(b->projector.d.data(), 5, report->projector_std.distortion.data(),
         options.projector_distortion, true);
  }
  report->covariance_message = "sigma = " + std::to_string(std::sqrt(sigma2)) + " px";
}

}  // namespace sandtable::node::unit_calibrator
