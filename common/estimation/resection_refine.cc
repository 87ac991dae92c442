#include "common/estimation/resection_refine.h"
#include "common/estimation/ceres_solver_options.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <utility>
#include <vector>

#include <ceres/ceres.h>
#include <ceres/rotation.h>
#include <Eigen/Eigenvalues>

namespace sandtable::internal {
namespace {

// Reprojection residual of one point, in px (observed minus predicted). Parameter blocks:
// intrinsics (fx, fy, cx, cy), distortion (k1 k2 p1 p2 k3, common/camera order), rotation as
// angle-axis (rad), translation (world unit); x_c = R(aa) X + t. The distortion is the very
// ApplyBrownDistortion template the camera model uses, so the refined model projects exactly
// as CameraModel::Project does.
struct ReprojectionCost {
  ReprojectionCost(const Eigen::Vector3d& point_in_world, const Eigen::Vector2d& observed_px)
      : point_in_world(point_in_world), observed_px(observed_px) {}

  template <typename T>
  bool operator()(const T* intrinsics, const T* distortion, const T* rotation_aa,
                  const T* translation, T* residual) const {
    const T x_w[3] = {T(point_in_world.x()), T(point_in_world.y()), T(point_in_world.z())};
    T x_c[3];
    ceres::AngleAxisRotatePoint(rotation_aa, x_w, x_c);
    x_c[0] += translation[0];
    x_c[1] += translation[1];
    x_c[2] += translation[2];
    // A point at or behind the camera has no projection; report the residual as not
    // computable so the step that produced it is rejected.
    if (!(x_c[2] > T(0.0))) return false;
    const T x = x_c[0] / x_c[2];
    const T y = x_c[1] / x_c[2];
    T xd, yd;
    ApplyBrownDistortion(distortion, x, y, &xd, &yd);
    residual[0] = T(observed_px.x()) - (intrinsics[0] * xd + intrinsics[2]);
    residual[1] = T(observed_px.y()) - (intrinsics[1] * yd + intrinsics[3]);
    return true;
  }

  Eigen::Vector3d point_in_world;
  Eigen::Vector2d observed_px;
};

}  // namespace

int NumFreeResectionParameters(const ResectionOptions& options) {
  int p = 0;
  if (!options.fix_intrinsics) p += 4;
  if (!options.fix_distortion) p += options.fix_k3 ? 4 : 5;
  if (!options.fix_pose) p += 6;
  return p;
}

Expected<ResectionRefineOutput> RefineResection(std::span<const Eigen::Vector3d> points_in_world,
                                                std::span<const Eigen::Vector2d> points_in_image_px,
                                                const CameraModel& camera,
                                                const Rigid3d& camera_from_world,
                                                const ResectionOptions& options) {
  double intrinsics[4] = {camera.fx_px, camera.fy_px, camera.cx_px, camera.cy_px};
  std::array<double, 5> distortion = camera.distortion.ToArray();
  double rotation_aa[3];
  const Eigen::Matrix3d r = camera_from_world.RotationMatrix();
  ceres::RotationMatrixToAngleAxis(ceres::ColumnMajorAdapter3x3(r.data()), rotation_aa);
  double translation[3] = {camera_from_world.translation.x(), camera_from_world.translation.y(),
                           camera_from_world.translation.z()};

  ceres::Problem problem;
  for (size_t i = 0; i < points_in_world.size(); ++i) {
    ceres::LossFunction* loss = nullptr;
    switch (options.loss) {
      case ResectionLoss::kSquared:
        break;
      case ResectionLoss::kHuber:
        loss = new ceres::HuberLoss(options.loss_scale_px);
        break;
      case ResectionLoss::kCauchy:
        loss = new ceres::CauchyLoss(options.loss_scale_px);
        break;
    }
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<ReprojectionCost, 2, 4, 5, 3, 3>(
                                 new ReprojectionCost(points_in_world[i], points_in_image_px[i])),
                             loss, intrinsics, distortion.data(), rotation_aa, translation);
  }
  if (options.fix_intrinsics) problem.SetParameterBlockConstant(intrinsics);
  if (options.fix_distortion) {
    problem.SetParameterBlockConstant(distortion.data());
  } else if (options.fix_k3) {
    problem.SetManifold(distortion.data(), new ceres::SubsetManifold(5, {4}));
  }
  if (options.fix_pose) {
    problem.SetParameterBlockConstant(rotation_aa);
    problem.SetParameterBlockConstant(translation);
  }

  const ceres::Solver::Options solver = internal::SmallDenseSolverOptions(options);
  ceres::Solver::Summary summary;
  ceres::Solve(solver, &problem, &summary);

  ResectionRefineOutput out;
  out.termination = ceres::TerminationTypeToString(summary.termination_type);
  out.message = summary.message;
  out.converged = summary.termination_type == ceres::CONVERGENCE;
  out.iterations = summary.num_successful_steps + summary.num_unsuccessful_steps;
  out.camera =
      CameraModel(camera.width_px, camera.height_px, intrinsics[0], intrinsics[1], intrinsics[2],
                  intrinsics[3], BrownDistortion::FromArray(distortion.data()));
  Eigen::Matrix3d refined_r;
  ceres::AngleAxisToRotationMatrix(rotation_aa, ceres::ColumnMajorAdapter3x3(refined_r.data()));
  // A fixed pose is returned bit for bit (the angle-axis round trip would perturb the last
  // digits of the quaternion).
  out.camera_from_world =
      options.fix_pose
          ? camera_from_world
          : Rigid3d(refined_r, Eigen::Vector3d(translation[0], translation[1], translation[2]));
  const int n = static_cast<int>(points_in_world.size());
  const int p = NumFreeResectionParameters(options);
  // Fewer than kMinDof residual degrees of freedom make sigma^2 itself too noisy to trust.
  constexpr int kMinDof = 5;
  if (options.estimate_uncertainty && summary.termination_type != ceres::FAILURE &&
      2 * n - p >= kMinDof) {
    // Covariance of the free parameters: (J^T J)^-1 sigma^2, J the (robustified) Jacobian at
    // the solution over the free blocks only (columns: intrinsics 4, distortion 5 or 4 in the
    // SubsetManifold tangent, rotation 3, translation 3, minus the fixed groups), and sigma^2
    // estimated from the residuals as sum r^2 / (2n - p) = 2 cost / (2n - p). J^T J is
    // Jacobi-scaled before its condition is judged, so units do not matter; a reciprocal
    // condition below 1e-12 means the data do not determine the free parameters.
    std::vector<double*> free_blocks;
    int rotation_column = -1;
    if (!options.fix_intrinsics) free_blocks.push_back(intrinsics);
    if (!options.fix_distortion) free_blocks.push_back(distortion.data());
    if (!options.fix_pose) {
      rotation_column = p - 6;
      free_blocks.push_back(rotation_aa);
      free_blocks.push_back(translation);
    }
    ceres::Problem::EvaluateOptions evaluate_options;
    evaluate_options.parameter_blocks = free_blocks;
    ceres::CRSMatrix crs;
    double cost = 0.0;
    if (problem.Evaluate(evaluate_options, &cost, nullptr, nullptr, &crs) && crs.num_cols == p) {
      Eigen::MatrixXd j = Eigen::MatrixXd::Zero(crs.num_rows, crs.num_cols);
      for (int row = 0; row < crs.num_rows; ++row) {
        for (int k = crs.rows[row]; k < crs.rows[row + 1]; ++k) j(row, crs.cols[k]) = crs.values[k];
      }
      const Eigen::MatrixXd jtj = j.transpose() * j;
      const Eigen::VectorXd d = jtj.diagonal().cwiseMax(1e-300).cwiseSqrt().cwiseInverse();
      const Eigen::MatrixXd scaled = d.asDiagonal() * jtj * d.asDiagonal();
      const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(scaled);
      const Eigen::VectorXd lambda = eig.eigenvalues();
      if (lambda(0) > 1e-12 * lambda(p - 1)) {
        const double sigma2 = 2.0 * summary.final_cost / (2 * n - p);
        const Eigen::MatrixXd cov = d.asDiagonal() * eig.eigenvectors() *
                                    lambda.cwiseInverse().asDiagonal() *
                                    eig.eigenvectors().transpose() * d.asDiagonal() * sigma2;
        auto largest = [&](int c) {
          const Eigen::Matrix3d block = cov.block<3, 3>(c, c);
          return std::sqrt(std::max(
              0.0, Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(block, Eigen::EigenvaluesOnly)
                       .eigenvalues()(2)));
        };
        out.uncertainty_available = true;
        if (!options.fix_intrinsics) {
          out.fx_std_px = std::sqrt(cov(0, 0));
          out.fy_std_px = std::sqrt(cov(1, 1));
          out.cx_std_px = std::sqrt(cov(2, 2));
          out.cy_std_px = std::sqrt(cov(3, 3));
        }
        if (rotation_column >= 0) {
          out.rotation_std_rad = largest(rotation_column);
          out.translation_std = largest(rotation_column + 3);
        }
      }
    }
  }
  if (summary.termination_type == ceres::FAILURE || !out.camera_from_world.AllFinite() ||
      !out.camera.Check().ok()) {
    return NotConvergedError("resection refinement failed (" + out.termination +
                             "): " + summary.message);
  }
  return out;
}

}  // namespace sandtable::internal
