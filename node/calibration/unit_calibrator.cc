// CalibrateUnit: the four steps of unit_calibrator.h in order, each in its own file
// (unit_calibrator_steps.h); options and distortion model names.
#include "node/calibration/unit_calibrator.h"

#include <chrono>
#include <cmath>

#include "node/calibration/unit_calibrator_steps.h"

namespace sandtable::node {

using namespace unit_calibrator;  // NOLINT(build/namespaces): this file's own helpers

Expected<DistortionModel> ParseDistortionModel(const std::string& name) {
  if (name == "none") return DistortionModel::kNone;
  if (name == "k1") return DistortionModel::kK1;
  if (name == "k1k2") return DistortionModel::kK1K2;
  if (name == "radial3") return DistortionModel::kRadial3;
  if (name == "full") return DistortionModel::kFull;
  return InvalidArgumentError("distortion model \"" + name +
                              "\" unknown; use none, k1, k1k2, radial3 or full");
}

const char* DistortionModelName(DistortionModel model) {
  switch (model) {
    case DistortionModel::kNone:
      return "none";
    case DistortionModel::kK1:
      return "k1";
    case DistortionModel::kK1K2:
      return "k1k2";
    case DistortionModel::kRadial3:
      return "radial3";
    case DistortionModel::kFull:
      return "full";
  }
  return "?";
}

Status UnitCalibrationOptions::Check() const {
  ST_RETURN_IF_ERROR(board.Check());
  if (projector_width_px < 2 || projector_height_px < 2) {
    return InvalidArgumentError("projector size must be at least 2x2 px");
  }
  if (max_dense_points_per_pose < 10) {
    return InvalidArgumentError("max_dense_points_per_pose must be >= 10");
  }
  if (!(dense_outlier_threshold_px > 0.0)) {
    return InvalidArgumentError("dense_outlier_threshold_px must be > 0");
  }
  if (!(projector_loss_scale_px > 0.0)) {
    return InvalidArgumentError("projector_loss_scale_px must be > 0");
  }
  if (!(dense_weight > 0.0) || !std::isfinite(dense_weight)) {
    return InvalidArgumentError("dense_weight must be > 0");
  }
  if (max_iterations < 1) return InvalidArgumentError("max_iterations must be >= 1");
  if (num_threads < 1) return InvalidArgumentError("num_threads must be >= 1");
  return OkStatus();
}

namespace {

Status CheckPoses(const std::vector<PoseObservation>& poses, const BoardSpec& board) {
  const int n_poses = static_cast<int>(poses.size());
  if (n_poses < 3) {
    return DegenerateError("unit calibration: " + std::to_string(n_poses) +
                           " poses given, at least 3 needed (Zhang)");
  }
  const cv::Size camera_size = poses.front().camera_size;
  for (const PoseObservation& pose : poses) {
    if (pose.camera_size != camera_size) {
      return InvalidArgumentError("unit calibration: " + pose.name + " camera size differs from " +
                                  poses.front().name + "'s");
    }
    if (static_cast<int>(pose.corners_in_camera_px.size()) != board.corner_count()) {
      return InvalidArgumentError("unit calibration: " + pose.name + " has " +
                                  std::to_string(pose.corners_in_camera_px.size()) +
                                  " corners, the board " + std::to_string(board.corner_count()));
    }
  }
  return OkStatus();
}

}  // namespace

Expected<UnitCalibrationResult> CalibrateUnit(const std::vector<PoseObservation>& poses,
                                              const UnitCalibrationOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  ST_RETURN_IF_ERROR(options.Check());
  ST_RETURN_IF_ERROR(CheckPoses(poses, options.board));
  const int n_poses = static_cast<int>(poses.size());
  const cv::Size camera_size = poses.front().camera_size;
  UnitCalibrationResult result;
  UnitCalibrationReport& report = result.report;
  report.poses = n_poses;

  // 1. Camera (Zhang, OpenCV).
  Expected<CameraInit> camera = InitializeCamera(poses, options);
  if (!camera.ok()) return camera.status();
  report.initial_camera_rms_px = camera->rms_px;
  // 2. Dense board points with their projector pixels.
  Expected<DenseBoardPoints> dense = CollectDenseBoardPoints(poses, *camera, options);
  if (!dense.ok()) return dense.status();
  report.dense_inliers_per_pose = dense->inliers_per_pose;
  // 3. Projector (planar Zhang on the dense board points; pinhole first).
  Expected<ProjectorInit> projector =
      InitializeProjector(*dense, camera->camera_from_board, options);
  if (!projector.ok()) return projector.status();
  report.initial_projector_rms_px = projector->rms_px;

  // 4. Joint refinement, then the covariance of the intrinsics.
  JointBlocks blocks{ParamsOf(camera->camera), projector->projector, camera->camera_from_board,
                     projector->projector_from_camera};
  ceres::Problem problem;
  ceres::Solver::Summary summary;
  ST_RETURN_IF_ERROR(RefineJointly(poses, *dense, options, &blocks, &problem, &summary, &report));
  ComputeCovariance(options, summary, &blocks, &problem, &report);

  UnitCalibration& calibration = result.calibration;
  calibration.source = kSourceUnitCalibration;
  calibration.camera = ModelOf(blocks.camera, camera_size.width, camera_size.height);
  calibration.projector =
      ModelOf(blocks.projector, options.projector_width_px, options.projector_height_px);
  calibration.projector_from_camera = PoseOf(blocks.projector_from_camera);
  calibration.camera_rms_px = report.camera_rms_px;
  calibration.projector_rms_px = report.projector_rms_px;
  for (int p = 0; p < n_poses; ++p) {
    calibration.poses_used.push_back(poses[p].name);
    report.camera_from_board.push_back(PoseOf(blocks.camera_from_board[p]));
  }
  Status valid = calibration.Check();
  if (!valid.ok()) return NotConvergedError("unit calibration: result invalid: " + valid.message());
  report.compute_time = std::chrono::steady_clock::now() - start;
  return result;
}

}  // namespace sandtable::node
