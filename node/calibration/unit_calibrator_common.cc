// Helpers shared by the steps of CalibrateUnit (unit_calibrator_steps.h).
#include <algorithm>
#include <cmath>

#include <ceres/rotation.h>
#include <opencv2/calib3d.hpp>

#include "common/estimation/homography.h"
#include "node/calibration/unit_calibrator_steps.h"

namespace sandtable::node::unit_calibrator {

int OpenCvFlags(DistortionModel model) {
  switch (model) {
    case DistortionModel::kNone:
      return cv::CALIB_FIX_K1 | cv::CALIB_FIX_K2 | cv::CALIB_FIX_K3 | cv::CALIB_ZERO_TANGENT_DIST;
    case DistortionModel::kK1:
      return cv::CALIB_FIX_K2 | cv::CALIB_FIX_K3 | cv::CALIB_ZERO_TANGENT_DIST;
    case DistortionModel::kK1K2:
      return cv::CALIB_FIX_K3 | cv::CALIB_ZERO_TANGENT_DIST;
    case DistortionModel::kRadial3:
      return cv::CALIB_ZERO_TANGENT_DIST;
    case DistortionModel::kFull:
      return 0;
  }
  return 0;
}

std::vector<int> FixedCoefficients(DistortionModel model) {
  switch (model) {
    case DistortionModel::kNone:
      return {0, 1, 2, 3, 4};
    case DistortionModel::kK1:
      return {1, 2, 3, 4};
    case DistortionModel::kK1K2:
      return {2, 3, 4};
    case DistortionModel::kRadial3:
      return {2, 3};
    case DistortionModel::kFull:
      return {};
  }
  return {};
}

std::vector<size_t> EvenSubset(size_t n, size_t max_count) {
  std::vector<size_t> out;
  const size_t count = std::min(n, max_count);
  out.reserve(count);
  for (size_t i = 0; i < count; ++i) out.push_back(i * n / count);
  return out;
}

Params ParamsOf(const CameraModel& m) {
  return {{m.fx_px, m.fy_px, m.cx_px, m.cy_px}, m.distortion.ToArray()};
}

CameraModel ModelOf(const Params& p, int width, int height) {
  return CameraModel(width, height, p.k[0], p.k[1], p.k[2], p.k[3],
                     BrownDistortion::FromArray(p.d.data()));
}

PoseParams PoseParamsOf(const Rigid3d& pose) {
  PoseParams p{};
  const Eigen::Matrix3d r = pose.RotationMatrix();
  ceres::RotationMatrixToAngleAxis(ceres::ColumnMajorAdapter3x3(r.data()), p.data());
  for (int i = 0; i < 3; ++i) p[3 + i] = pose.translation[i];
  return p;
}

Rigid3d PoseOf(const PoseParams& p) {
  Eigen::Matrix3d r;
  ceres::AngleAxisToRotationMatrix(p.data(), ceres::ColumnMajorAdapter3x3(r.data()));
  return Rigid3d(r, Eigen::Vector3d(p[3], p[4], p[5]));
}

Rigid3d PoseFromCv(const cv::Mat& rvec, const cv::Mat& tvec) {
  PoseParams p{};
  for (int i = 0; i < 3; ++i) {
    p[i] = rvec.at<double>(i);
    p[3 + i] = tvec.at<double>(i);
  }
  return PoseOf(p);
}

double Rms(double sum_squares, int64_t count) {
  return count > 0 ? std::sqrt(sum_squares / count) : 0.0;
}

Rigid3d AverageRigid(const std::vector<Rigid3d>& poses) {
  Eigen::Vector4d q_sum = Eigen::Vector4d::Zero();
  Eigen::Vector3d t_sum = Eigen::Vector3d::Zero();
  const Eigen::Vector4d q0 = poses.front().rotation.coeffs();
  for (const Rigid3d& p : poses) {
    Eigen::Vector4d q = p.rotation.coeffs();
    if (q.dot(q0) < 0) q = -q;
    q_sum += q;
    t_sum += p.translation;
  }
  Eigen::Quaterniond q;
  q.coeffs() = q_sum.normalized();
  return Rigid3d(q, t_sum / static_cast<double>(poses.size()));
}

Expected<std::vector<size_t>> DenseInliers(const CameraModel& camera, const PoseObservation& pose,
                                           double threshold_px, size_t* candidates) {
  const std::vector<size_t> subset =
      EvenSubset(pose.dense_in_camera_px.size(), kMaxFilterCandidates);
  std::vector<Eigen::Vector2d> from, to;
  std::vector<size_t> index;
  for (size_t i : subset) {
    Expected<Eigen::Vector3d> ray = camera.Unproject(pose.dense_in_camera_px[i]);
    if (!ray.ok()) continue;
    from.emplace_back(ray->x(), ray->y());
    to.push_back(pose.dense_in_projector_px[i]);
    index.push_back(i);
  }
  if (candidates != nullptr) *candidates = subset.size();
  HomographyRansacOptions ransac;
  ransac.max_transfer_error_px = threshold_px;
  ransac.seed = kRansacSeed;
  ransac.refine = false;
  ransac.max_iterations = 2000;
  Expected<HomographyRansacResult> fit = EstimateHomographyRansac(from, to, ransac);
  if (!fit.ok()) return fit.status().WithContext(pose.name + ": dense outlier filter: ");
  std::vector<size_t> inliers;
  for (size_t j = 0; j < index.size(); ++j) {
    if (fit->inlier_mask[j]) inliers.push_back(index[j]);
  }
  if (static_cast<int>(inliers.size()) < kMinDenseInliers) {
    return DegenerateError(pose.name + ": only " + std::to_string(inliers.size()) +
                           " dense samples agree with a board-plane homography within " +
                           std::to_string(threshold_px) + " px");
  }
  return inliers;
}

}  // namespace sandtable::node::unit_calibrator
