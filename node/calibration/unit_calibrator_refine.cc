// Step 4 of CalibrateUnit: one joint Ceres refinement of both devices, the board poses and
// projector_from_camera; residuals are corners in the camera and dense points in the
// projector (procam_model.h), then the unrobustified rms of both.
#include <cmath>

#include "node/calibration/procam_model.h"
#include "node/calibration/unit_calibrator_steps.h"

namespace sandtable::node::unit_calibrator {

namespace {

struct CornerCost {
  CornerCost(const Eigen::Vector2d& observed_px, const Eigen::Vector3d& x_in_board_m)
      : observed_px(observed_px), x_in_board_m(x_in_board_m) {}
  template <typename T>
  bool operator()(const T* camera_k, const T* camera_d, const T* camera_from_board,
                  T* residual) const {
    const T x[3] = {T(x_in_board_m.x()), T(x_in_board_m.y()), T(x_in_board_m.z())};
    T pixel[2];
    if (!CornerPixel(camera_k, camera_d, camera_from_board, x, pixel)) return false;
    residual[0] = pixel[0] - T(observed_px.x());
    residual[1] = pixel[1] - T(observed_px.y());
    return true;
  }
  Eigen::Vector2d observed_px;
  Eigen::Vector3d x_in_board_m;
};

struct DenseCost {
  DenseCost(const Eigen::Vector2d& camera_px, const Eigen::Vector2d& projector_px)
      : camera_px(camera_px), projector_px(projector_px) {}
  template <typename T>
  bool operator()(const T* camera_k, const T* camera_d, const T* camera_from_board,
                  const T* projector_from_camera, const T* projector_k, const T* projector_d,
                  T* residual) const {
    const T c[2] = {T(camera_px.x()), T(camera_px.y())};
    T predicted[2];
    if (!DenseProjectorPixel(camera_k, camera_d, camera_from_board, projector_from_camera,
                             projector_k, projector_d, c, predicted)) {
      return false;
    }
    residual[0] = predicted[0] - T(projector_px.x());
    residual[1] = predicted[1] - T(projector_px.y());
    return true;
  }
  Eigen::Vector2d camera_px;
  Eigen::Vector2d projector_px;
};

void SetDistortionFreedom(ceres::Problem* problem, double* distortion, DistortionModel model) {
  const std::vector<int> fixed = FixedCoefficients(model);
  if (fixed.size() == 5) {
    problem->SetParameterBlockConstant(distortion);
  } else if (!fixed.empty()) {
    problem->SetManifold(distortion, new ceres::SubsetManifold(5, fixed));
  }
}

}  // namespace

Status RefineJointly(const std::vector<PoseObservation>& poses, const DenseBoardPoints& dense,
                     const UnitCalibrationOptions& options, JointBlocks* b, ceres::Problem* problem,
                     ceres::Solver::Summary* summary, UnitCalibrationReport* report) {
  const BoardSpec& board = options.board;
  const int n_poses = static_cast<int>(poses.size());
  for (int p = 0; p < n_poses; ++p) {
    for (int k = 0; k < board.corner_count(); ++k) {
      problem->AddResidualBlock(
          new ceres::AutoDiffCostFunction<CornerCost, 2, 4, 5, 6>(
              new CornerCost(poses[p].corners_in_camera_px[k], board.CornerInBoard_m(k))),
          nullptr, b->camera.k.data(), b->camera.d.data(), b->camera_from_board[p].data());
      ++report->corner_residuals;
    }
    for (size_t i : dense.used[p]) {
      problem->AddResidualBlock(
          new ceres::AutoDiffCostFunction<DenseCost, 2, 4, 5, 6, 6, 4, 5>(
              new DenseCost(poses[p].dense_in_camera_px[i], poses[p].dense_in_projector_px[i])),
          new ceres::ScaledLoss(new ceres::HuberLoss(options.projector_loss_scale_px),
                                options.dense_weight * options.dense_weight, ceres::TAKE_OWNERSHIP),
          b->camera.k.data(), b->camera.d.data(), b->camera_from_board[p].data(),
          b->projector_from_camera.data(), b->projector.k.data(), b->projector.d.data());
      ++report->dense_residuals;
    }
  }
  SetDistortionFreedom(problem, b->camera.d.data(), options.camera_distortion);
  SetDistortionFreedom(problem, b->projector.d.data(), options.projector_distortion);

  ceres::Solver::Options solver;
  solver.linear_solver_type = ceres::DENSE_SCHUR;
  solver.max_num_iterations = options.max_iterations;
  solver.num_threads = options.num_threads;
  solver.function_tolerance = 1e-12;
  solver.parameter_tolerance = 1e-12;
  ceres::Solve(solver, problem, summary);
  report->termination = ceres::TerminationTypeToString(summary->termination_type);
  report->message = summary->message;
  report->iterations = static_cast<int>(summary->iterations.size());
  if (summary->termination_type == ceres::FAILURE || !std::isfinite(summary->final_cost)) {
    return NotConvergedError("unit calibration: joint refinement failed: " + summary->message);
  }

  // Unrobustified RMS.
  double corner_sq = 0.0, dense_sq = 0.0;
  int64_t dense_count = 0;
  for (int p = 0; p < n_poses; ++p) {
    for (int k = 0; k < board.corner_count(); ++k) {
      const Eigen::Vector3d x = board.CornerInBoard_m(k);
      double pixel[2];
      if (!CornerPixel(b->camera.k.data(), b->camera.d.data(), b->camera_from_board[p].data(),
                       x.data(), pixel)) {
        return NotConvergedError("unit calibration: a corner of " + poses[p].name +
                                 " ends behind the camera");
      }
      corner_sq +=
          (Eigen::Vector2d(pixel[0], pixel[1]) - poses[p].corners_in_camera_px[k]).squaredNorm();
    }
    for (size_t i : dense.used[p]) {
      double predicted[2];
      if (!DenseProjectorPixel(b->camera.k.data(), b->camera.d.data(),
                               b->camera_from_board[p].data(), b->projector_from_camera.data(),
                               b->projector.k.data(), b->projector.d.data(),
                               poses[p].dense_in_camera_px[i].data(), predicted)) {
        continue;
      }
      dense_sq += (Eigen::Vector2d(predicted[0], predicted[1]) - poses[p].dense_in_projector_px[i])
                      .squaredNorm();
      ++dense_count;
    }
  }
  report->camera_rms_px = Rms(corner_sq, report->corner_residuals);
  report->projector_rms_px = Rms(dense_sq, dense_count);
  return OkStatus();
}

}  // namespace sandtable::node::unit_calibrator
