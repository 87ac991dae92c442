// Steps 1-3 of CalibrateUnit: camera by Zhang, dense board points, projector by planar Zhang.
#include <opencv2/calib3d.hpp>

#include "node/calibration/procam_model.h"
#include "node/calibration/unit_calibrator_steps.h"

namespace sandtable::node::unit_calibrator {

Expected<CameraInit> InitializeCamera(const std::vector<PoseObservation>& poses,
                                      const UnitCalibrationOptions& options) {
  const BoardSpec& board = options.board;
  const int n_poses = static_cast<int>(poses.size());
  const cv::Size camera_size = poses.front().camera_size;
  std::vector<std::vector<cv::Point3f>> object_points(n_poses);
  std::vector<std::vector<cv::Point2f>> image_points(n_poses);
  for (int p = 0; p < n_poses; ++p) {
    for (int k = 0; k < board.corner_count(); ++k) {
      const Eigen::Vector3d x = board.CornerInBoard_m(k);
      object_points[p].emplace_back(x.x(), x.y(), x.z());
      const Eigen::Vector2d& c = poses[p].corners_in_camera_px[k];
      image_points[p].emplace_back(c.x(), c.y());
    }
  }
  CameraInit out;
  cv::Mat camera_k, camera_d;
  std::vector<cv::Mat> rvecs, tvecs;
  try {
    out.rms_px = cv::calibrateCamera(object_points, image_points, camera_size, camera_k, camera_d,
                                     rvecs, tvecs, OpenCvFlags(options.camera_distortion));
  } catch (const cv::Exception& e) {
    return NotConvergedError(std::string("camera calibration (cv::calibrateCamera): ") + e.what());
  }
  Eigen::Matrix3d k_eigen;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) k_eigen(r, c) = camera_k.at<double>(r, c);
  std::array<double, 5> d_array{};
  for (int i = 0; i < 5; ++i) d_array[i] = camera_d.at<double>(i);
  out.camera = CameraModel::FromK(camera_size.width, camera_size.height, k_eigen,
                                  BrownDistortion::FromArray(d_array.data()));
  out.camera_from_board.resize(n_poses);
  for (int p = 0; p < n_poses; ++p) {
    out.camera_from_board[p] = PoseParamsOf(PoseFromCv(rvecs[p], tvecs[p]));
  }
  return out;
}

Expected<DenseBoardPoints> CollectDenseBoardPoints(const std::vector<PoseObservation>& poses,
                                                   const CameraInit& camera,
                                                   const UnitCalibrationOptions& options) {
  const int n_poses = static_cast<int>(poses.size());
  const Params camera_params = ParamsOf(camera.camera);
  DenseBoardPoints out;
  out.used.resize(n_poses);
  out.in_board.resize(n_poses);
  out.in_projector.resize(n_poses);
  for (int p = 0; p < n_poses; ++p) {
    Expected<std::vector<size_t>> inliers =
        DenseInliers(camera.camera, poses[p], options.dense_outlier_threshold_px, nullptr);
    if (!inliers.ok()) return inliers.status();
    out.inliers_per_pose.push_back(static_cast<int>(inliers->size()));
    const Rigid3d board_from_camera = PoseOf(camera.camera_from_board[p]).Inverse();
    for (size_t s : EvenSubset(inliers->size(), options.max_dense_points_per_pose)) {
      const size_t i = (*inliers)[s];
      double x_in_camera[3];
      if (!BoardPointInCamera(camera_params.k.data(), camera_params.d.data(),
                              camera.camera_from_board[p].data(),
                              poses[p].dense_in_camera_px[i].data(), x_in_camera)) {
        continue;
      }
      const Eigen::Vector3d x_in_board =
          board_from_camera * Eigen::Vector3d(x_in_camera[0], x_in_camera[1], x_in_camera[2]);
      out.used[p].push_back(i);
      out.in_board[p].emplace_back(x_in_board.x(), x_in_board.y(), 0.0f);
      const Eigen::Vector2d& u = poses[p].dense_in_projector_px[i];
      out.in_projector[p].emplace_back(u.x(), u.y());
    }
  }
  return out;
}

Expected<ProjectorInit> InitializeProjector(const DenseBoardPoints& dense,
                                            const std::vector<PoseParams>& camera_from_board,
                                            const UnitCalibrationOptions& options) {
  const int n_poses = static_cast<int>(camera_from_board.size());
  ProjectorInit out;
  cv::Mat projector_k, projector_d;
  std::vector<cv::Mat> prvecs, ptvecs;
  try {
    out.rms_px = cv::calibrateCamera(
        dense.in_board, dense.in_projector,
        cv::Size(options.projector_width_px, options.projector_height_px), projector_k, projector_d,
        prvecs, ptvecs, OpenCvFlags(DistortionModel::kNone));
  } catch (const cv::Exception& e) {
    return NotConvergedError(std::string("projector initialisation (cv::calibrateCamera): ") +
                             e.what());
  }
  out.projector.k = {projector_k.at<double>(0, 0), projector_k.at<double>(1, 1),
                     projector_k.at<double>(0, 2), projector_k.at<double>(1, 2)};
  // projector_from_camera = projector_from_board * board_from_camera, per pose, averaged.
  std::vector<Rigid3d> projector_from_camera_per_pose;
  for (int p = 0; p < n_poses; ++p) {
    projector_from_camera_per_pose.push_back(PoseFromCv(prvecs[p], ptvecs[p]) *
                                             PoseOf(camera_from_board[p]).Inverse());
  }
  out.projector_from_camera = PoseParamsOf(AverageRigid(projector_from_camera_per_pose));
  return out;
}

}  // namespace sandtable::node::unit_calibrator
