// The steps of CalibrateUnit (unit_calibrator.h), one file each, and the helpers they share.
// Internal to node/calibration: include only from unit_calibrator*.cc.
//   unit_calibrator_common.cc      parameter blocks, poses, distortion subsets, dense filter
//   unit_calibrator_init.cc        1. camera (Zhang), 2. dense board points, 3. projector
//   unit_calibrator_refine.cc      4. joint Ceres refinement and its unrobustified rms
//   unit_calibrator_covariance.cc  covariance of the intrinsics
//   unit_calibrator_held_out.cc    PredictHeldOutPose
// Pose parameter blocks are angle-axis (rad) + translation (m), target_from_source
// (procam_model.h).
#pragma once

#include <array>
#include <cstdint>
#include <limits>
#include <vector>

#include <ceres/ceres.h>
#include <opencv2/core.hpp>

#include "node/calibration/unit_calibrator.h"

namespace sandtable::node::unit_calibrator {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
// The outlier filter fits its homography to at most this many evenly spread samples per pose
// (a pose has ~1e5 decoded samples at stride 2; more adds time, not accuracy).
constexpr size_t kMaxFilterCandidates = 20000;
constexpr int kMinDenseInliers = 50;
constexpr uint64_t kRansacSeed = 7;

using PoseParams = std::array<double, 6>;

// Intrinsics (fx fy cx cy, px) and Brown coefficients of one device as Ceres blocks.
struct Params {
  std::array<double, 4> k{};
  std::array<double, 5> d{};
};

Params ParamsOf(const CameraModel& m);
CameraModel ModelOf(const Params& p, int width, int height);
PoseParams PoseParamsOf(const Rigid3d& pose);
Rigid3d PoseOf(const PoseParams& p);
Rigid3d PoseFromCv(const cv::Mat& rvec, const cv::Mat& tvec);
// Chordal mean of the rotations (sign-aligned quaternions), mean of the translations.
Rigid3d AverageRigid(const std::vector<Rigid3d>& poses);

int OpenCvFlags(DistortionModel model);
// Indices (k1 k2 p1 p2 k3 = 0..4) held at zero.
std::vector<int> FixedCoefficients(DistortionModel model);
// Evenly spread subset of [0, n) of size min(n, max_count).
std::vector<size_t> EvenSubset(size_t n, size_t max_count);
double Rms(double sum_squares, int64_t count);

// Dense samples of `pose` that a board-plane homography (undistorted camera -> projector px)
// explains within `threshold_px`: indices into pose.dense_*, chosen from an even subset of at
// most kMaxFilterCandidates samples. DEGENERATE below kMinDenseInliers.
Expected<std::vector<size_t>> DenseInliers(const CameraModel& camera, const PoseObservation& pose,
                                           double threshold_px, size_t* candidates);

// 1. Camera intrinsics and camera_from_board per pose from the corners (cv::calibrateCamera).
struct CameraInit {
  CameraModel camera;
  std::vector<PoseParams> camera_from_board;
  double rms_px = 0.0;
};
Expected<CameraInit> InitializeCamera(const std::vector<PoseObservation>& poses,
                                      const UnitCalibrationOptions& options);

// 2. Dense board points: per pose the decoded samples used (indices), their board points and
// projector pixels.
struct DenseBoardPoints {
  std::vector<std::vector<size_t>> used;
  std::vector<std::vector<cv::Point3f>> in_board;
  std::vector<std::vector<cv::Point2f>> in_projector;
  std::vector<int> inliers_per_pose;
};
Expected<DenseBoardPoints> CollectDenseBoardPoints(const std::vector<PoseObservation>& poses,
                                                   const CameraInit& camera,
                                                   const UnitCalibrationOptions& options);

// 3. Projector intrinsics (planar Zhang, pinhole) and projector_from_camera (mean over poses).
struct ProjectorInit {
  Params projector;
  PoseParams projector_from_camera{};
  double rms_px = 0.0;
};
Expected<ProjectorInit> InitializeProjector(const DenseBoardPoints& dense,
                                            const std::vector<PoseParams>& camera_from_board,
                                            const UnitCalibrationOptions& options);

// 4. The joint problem over these blocks (refined in place).
struct JointBlocks {
  Params camera;
  Params projector;
  std::vector<PoseParams> camera_from_board;
  PoseParams projector_from_camera{};
};
// Builds and solves the joint problem into *problem; fills the report's counts, termination,
// iterations and rms. NOT_CONVERGED on a Ceres failure or a corner behind the camera.
Status RefineJointly(const std::vector<PoseObservation>& poses, const DenseBoardPoints& dense,
                     const UnitCalibrationOptions& options, JointBlocks* blocks,
                     ceres::Problem* problem, ceres::Solver::Summary* summary,
                     UnitCalibrationReport* report);

// Standard deviations of the intrinsics from the solved problem (report.camera_std,
// projector_std, covariance_ok, covariance_message); NaN where not computed.
void ComputeCovariance(const UnitCalibrationOptions& options, const ceres::Solver::Summary& summary,
                       JointBlocks* blocks, ceres::Problem* problem, UnitCalibrationReport* report);

}  // namespace sandtable::node::unit_calibrator
