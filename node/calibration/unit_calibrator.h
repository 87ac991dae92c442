// Unit (factory) calibration of a projector-camera pair from chessboard poses with their
// structured-light captures (PoseObservation), without local homographies:
//   1. camera intrinsics + camera_from_board per pose from the chessboard corners
//      (cv::calibrateCamera, Zhang);
//   2. dense correspondences: every decoded camera pixel inside the board, its camera ray cut
//      with the board plane -> board point (x, y, 0) with its decoded projector pixel;
//      decode blunders removed per pose by a RANSAC homography from undistorted camera
//      coordinates to projector px (the board plane induces one when the projector lens is
//      pinhole; `dense_outlier_threshold_px` leaves room for moderate projector distortion);
//   3. projector intrinsics + projector_from_board per pose from the board points (planar
//      Zhang, cv::calibrateCamera, distortion fixed at zero) and projector_from_camera as the
//      average of projector_from_board * board_from_camera over the poses;
//   4. one joint Ceres refinement of everything: camera intrinsics + Brown, projector
//      intrinsics + Brown (subset by DistortionModel), the board poses and
//      projector_from_camera; residuals: corners in the camera (px) and subsampled dense points
//      in the projector (px, Huber loss).
// The board's length unit is metres (BoardSpec::square_m), so translations come out in metres.
// Errors: INVALID_ARGUMENT (options, inconsistent camera sizes), DEGENERATE (fewer than 3
// poses, too few dense inliers on a pose), NOT_CONVERGED (Ceres failure, non-finite result).
#pragma once

#include <array>
#include <string>
#include <vector>

#include "common/base/status.h"
#include "common/base/units.h"
#include "node/calibration/board_observation.h"
#include "node/calibration/unit_calibration.h"

namespace sandtable::node {

// Which Brown coefficients are estimated; the others are held at zero.
enum class DistortionModel { kNone, kK1, kK1K2, kRadial3, kFull };
// "none", "k1", "k1k2", "radial3" (k1 k2 k3), "full" (k1 k2 p1 p2 k3).
Expected<DistortionModel> ParseDistortionModel(const std::string& name);
const char* DistortionModelName(DistortionModel model);

struct UnitCalibrationOptions {
  BoardSpec board;
  int projector_width_px = 1024;
  int projector_height_px = 768;
  DistortionModel camera_distortion = DistortionModel::kFull;
  // Five nearly face-on poses cannot pin the full projector distortion down; radial k1 k2
  // predicts held-out poses best on the real data (docs/unit-calibration.md).
  DistortionModel projector_distortion = DistortionModel::kK1K2;
  // Dense points per pose in the joint refinement (evenly subsampled from the inliers).
  int max_dense_points_per_pose = 500;
  // RANSAC homography inlier threshold for the dense outlier filter, projector px.
  double dense_outlier_threshold_px = 3.0;
  // Huber scale of the dense residuals, projector px.
  double projector_loss_scale_px = 1.0;
  // Weight of each dense residual relative to a corner residual (both in px). The dense
  // errors are spatially correlated (Gray-code quantisation), so counting them as independent
  // overweights them against the corners.
  double dense_weight = 1.0;
  int max_iterations = 100;
  bool compute_covariance = true;
  int num_threads = 1;  // Ceres threads
  Status Check() const;
};

// Standard deviations of one device's parameters (NaN for a parameter held fixed or when the
// covariance could not be computed).
struct ParameterDeviations {
  std::array<double, 4> intrinsics_px{};  // fx fy cx cy
  std::array<double, 5> distortion{};     // k1 k2 p1 p2 k3
};

struct UnitCalibrationReport {
  std::string termination;  // Ceres termination type of the joint refinement
  std::string message;
  int iterations = 0;
  int poses = 0;
  int corner_residuals = 0;  // corners (2 residuals each)
  int dense_residuals = 0;   // dense points used in the refinement
  std::vector<int> dense_inliers_per_pose;
  double initial_camera_rms_px = 0.0;     // cv::calibrateCamera on the corners
  double initial_projector_rms_px = 0.0;  // planar Zhang on the dense points, per-pose boards
  double camera_rms_px = 0.0;             // after the joint refinement (no loss applied)
  double projector_rms_px = 0.0;
  // Covariance (ceres::Covariance, DENSE_SVD) scaled by the residual variance
  // sigma^2 = 2 cost / (residuals - parameters) of the joint problem.
  bool covariance_ok = false;
  std::string covariance_message;
  ParameterDeviations camera_std;
  ParameterDeviations projector_std;
  std::vector<Rigid3d> camera_from_board;  // per pose, metres
  Seconds compute_time{0.0};               // whole CalibrateUnit, observation excluded
};

struct UnitCalibrationResult {
  UnitCalibration calibration;
  UnitCalibrationReport report;
};

Expected<UnitCalibrationResult> CalibrateUnit(const std::vector<PoseObservation>& poses,
                                              const UnitCalibrationOptions& options);

// Prediction of a pose the calibration did not use: camera_from_board from the pose's corners
// alone (cv::solvePnP with the calibrated camera), then the dense projector points predicted
// from the camera pixels through the calibration.
struct HeldOutPrediction {
  std::string pose;
  double camera_rms_px = 0.0;         // corners, after the board pose fit (6 dof)
  double projector_rms_px = 0.0;      // dense points passing the outlier filter
  int64_t projector_points = 0;       // inliers used
  int64_t projector_candidates = 0;   // decoded dense samples before the filter
  double projector_rms_all_px = 0.0;  // every decoded dense sample (blunders included)
};

Expected<HeldOutPrediction> PredictHeldOutPose(const UnitCalibration& calibration,
                                               const PoseObservation& pose,
                                               const UnitCalibrationOptions& options);

}  // namespace sandtable::node
