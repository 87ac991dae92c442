// PredictHeldOutPose: how well a calibration predicts a pose it did not use.
#include <opencv2/calib3d.hpp>

#include "node/calibration/procam_model.h"
#include "node/calibration/unit_calibrator_steps.h"

namespace sandtable::node {

using namespace unit_calibrator;  // NOLINT(build/namespaces): this file's own helpers

Expected<HeldOutPrediction> PredictHeldOutPose(const UnitCalibration& calibration,
                                               const PoseObservation& pose,
                                               const UnitCalibrationOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  ST_RETURN_IF_ERROR(calibration.Check());
  const BoardSpec& board = options.board;
  if (static_cast<int>(pose.corners_in_camera_px.size()) != board.corner_count()) {
    return InvalidArgumentError(pose.name + ": corner count differs from the board's");
  }
  std::vector<cv::Point3f> object_points;
  std::vector<cv::Point2f> image_points;
  for (int k = 0; k < board.corner_count(); ++k) {
    const Eigen::Vector3d x = board.CornerInBoard_m(k);
    object_points.emplace_back(x.x(), x.y(), x.z());
    image_points.emplace_back(pose.corners_in_camera_px[k].x(), pose.corners_in_camera_px[k].y());
  }
  const Params camera = ParamsOf(calibration.camera);
  const Params projector = ParamsOf(calibration.projector);
  cv::Mat k =
      (cv::Mat_<double>(3, 3) << camera.k[0], 0, camera.k[2], 0, camera.k[1], camera.k[3], 0, 0, 1);
  cv::Mat d(1, 5, CV_64F);
  for (int i = 0; i < 5; ++i) d.at<double>(i) = camera.d[i];
  cv::Mat rvec, tvec;
  try {
    if (!cv::solvePnP(object_points, image_points, k, d, rvec, tvec, false,
                      cv::SOLVEPNP_ITERATIVE)) {
      return NotConvergedError(pose.name + ": board pose from the corners (solvePnP) failed");
    }
  } catch (const cv::Exception& e) {
    return NotConvergedError(pose.name + ": solvePnP: " + e.what());
  }
  const PoseParams camera_from_board = PoseParamsOf(PoseFromCv(rvec, tvec));
  const PoseParams projector_from_camera = PoseParamsOf(calibration.projector_from_camera);

  HeldOutPrediction out;
  out.pose = pose.name;
  double corner_sq = 0.0;
  for (int c = 0; c < board.corner_count(); ++c) {
    const Eigen::Vector3d x = board.CornerInBoard_m(c);
    double pixel[2];
    if (!CornerPixel(camera.k.data(), camera.d.data(), camera_from_board.data(), x.data(), pixel)) {
      return NotConvergedError(pose.name + ": a corner lies behind the camera");
    }
    corner_sq += (Eigen::Vector2d(pixel[0], pixel[1]) - pose.corners_in_camera_px[c]).squaredNorm();
  }
  out.camera_rms_px = Rms(corner_sq, board.corner_count());

  size_t candidates = 0;
  Expected<std::vector<size_t>> inliers =
      DenseInliers(calibration.camera, pose, options.dense_outlier_threshold_px, &candidates);
  if (!inliers.ok()) return inliers.status();
  std::vector<char> is_inlier(pose.dense_in_camera_px.size(), 0);
  for (size_t i : *inliers) is_inlier[i] = 1;
  double inlier_sq = 0.0, all_sq = 0.0;
  int64_t all_count = 0;
  for (size_t i : EvenSubset(pose.dense_in_camera_px.size(), kMaxFilterCandidates)) {
    double predicted[2];
    if (!DenseProjectorPixel(camera.k.data(), camera.d.data(), camera_from_board.data(),
                             projector_from_camera.data(), projector.k.data(), projector.d.data(),
                             pose.dense_in_camera_px[i].data(), predicted)) {
      continue;
    }
    const double e2 =
        (Eigen::Vector2d(predicted[0], predicted[1]) - pose.dense_in_projector_px[i]).squaredNorm();
    all_sq += e2;
    ++all_count;
    if (is_inlier[i]) {
      inlier_sq += e2;
      ++out.projector_points;
    }
  }
  out.projector_candidates = static_cast<int64_t>(candidates);
  out.projector_rms_px = Rms(inlier_sq, out.projector_points);
  out.projector_rms_all_px = Rms(all_sq, all_count);
  return out;
}

}  // namespace sandtable::node
