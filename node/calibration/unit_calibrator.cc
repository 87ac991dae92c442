#include "node/calibration/unit_calibrator.h"

#include <chrono>
#include <cmath>
#include <limits>
#include <memory>

#include <ceres/ceres.h>
#include <ceres/rotation.h>
#include <opencv2/calib3d.hpp>

#include "common/base/log.h"
#include "common/estimation/homography.h"
#include "node/calibration/procam_model.h"

namespace sandtable::node {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
// The outlier filter fits its homography to at most this many evenly spread samples per pose
// (a pose has ~1e5 decoded samples at stride 2; more adds time, not accuracy).
constexpr size_t kMaxFilterCandidates = 20000;
constexpr int kMinDenseInliers = 50;
constexpr uint64_t kRansacSeed = 7;

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

// Indices (k1 k2 p1 p2 k3 = 0..4) held at zero.
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

// Evenly spread subset of [0, n) of size min(n, max_count).
std::vector<size_t> EvenSubset(size_t n, size_t max_count) {
  std::vector<size_t> out;
  const size_t count = std::min(n, max_count);
  out.reserve(count);
  for (size_t i = 0; i < count; ++i) out.push_back(i * n / count);
  return out;
}

struct Params {
  std::array<double, 4> k{};
  std::array<double, 5> d{};
};

Params ParamsOf(const CameraModel& m) {
  return {{m.fx_px, m.fy_px, m.cx_px, m.cy_px}, m.distortion.ToArray()};
}

CameraModel ModelOf(const Params& p, int width, int height) {
  return CameraModel(width, height, p.k[0], p.k[1], p.k[2], p.k[3],
                     BrownDistortion::FromArray(p.d.data()));
}

std::array<double, 6> PoseParams(const Rigid3d& pose) {
  std::array<double, 6> p{};
  const Eigen::Matrix3d r = pose.RotationMatrix();
  ceres::RotationMatrixToAngleAxis(ceres::ColumnMajorAdapter3x3(r.data()), p.data());
  for (int i = 0; i < 3; ++i) p[3 + i] = pose.translation[i];
  return p;
}

Rigid3d PoseOf(const std::array<double, 6>& p) {
  Eigen::Matrix3d r;
  ceres::AngleAxisToRotationMatrix(p.data(), ceres::ColumnMajorAdapter3x3(r.data()));
  return Rigid3d(r, Eigen::Vector3d(p[3], p[4], p[5]));
}

Rigid3d PoseFromCv(const cv::Mat& rvec, const cv::Mat& tvec) {
  std::array<double, 6> p{};
  for (int i = 0; i < 3; ++i) {
    p[i] = rvec.at<double>(i);
    p[3 + i] = tvec.at<double>(i);
  }
  return PoseOf(p);
}

// Dense samples of `pose` that a board-plane homography (undistorted camera -> projector px)
// explains within `threshold_px`: indices into pose.dense_*, chosen from an even subset of at
// most kMaxFilterCandidates samples.
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

double Rms(double sum_squares, int64_t count) {
  return count > 0 ? std::sqrt(sum_squares / count) : 0.0;
}

// Average of rigid transforms: chordal mean of the rotations (sign-aligned quaternions,
// normalised sum) and the arithmetic mean of the translations.
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

}  // namespace

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

Expected<UnitCalibrationResult> CalibrateUnit(const std::vector<PoseObservation>& poses,
                                              const UnitCalibrationOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  ST_RETURN_IF_ERROR(options.Check());
  const int n_poses = static_cast<int>(poses.size());
  if (n_poses < 3) {
    return DegenerateError("unit calibration: " + std::to_string(n_poses) +
                           " poses given, at least 3 needed (Zhang)");
  }
  const BoardSpec& board = options.board;
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
  UnitCalibrationResult result;
  UnitCalibrationReport& report = result.report;
  report.poses = n_poses;

  // 1. Camera (Zhang, OpenCV).
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
  cv::Mat camera_k, camera_d;
  std::vector<cv::Mat> rvecs, tvecs;
  try {
    report.initial_camera_rms_px =
        cv::calibrateCamera(object_points, image_points, camera_size, camera_k, camera_d, rvecs,
                            tvecs, OpenCvFlags(options.camera_distortion));
  } catch (const cv::Exception& e) {
    return NotConvergedError(std::string("camera calibration (cv::calibrateCamera): ") + e.what());
  }
  Eigen::Matrix3d k_eigen;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) k_eigen(r, c) = camera_k.at<double>(r, c);
  std::array<double, 5> d_array{};
  for (int i = 0; i < 5; ++i) d_array[i] = camera_d.at<double>(i);
  const CameraModel camera0 = CameraModel::FromK(camera_size.width, camera_size.height, k_eigen,
                                                 BrownDistortion::FromArray(d_array.data()));
  std::vector<std::array<double, 6>> camera_from_board(n_poses);
  for (int p = 0; p < n_poses; ++p)
    camera_from_board[p] = PoseParams(PoseFromCv(rvecs[p], tvecs[p]));

  // 2. Dense board points with their projector pixels.
  Params camera_params = ParamsOf(camera0);
  std::vector<std::vector<size_t>> dense_used(n_poses);
  std::vector<std::vector<cv::Point3f>> board_points(n_poses);
  std::vector<std::vector<cv::Point2f>> projector_points(n_poses);
  for (int p = 0; p < n_poses; ++p) {
    Expected<std::vector<size_t>> inliers =
        DenseInliers(camera0, poses[p], options.dense_outlier_threshold_px, nullptr);
    if (!inliers.ok()) return inliers.status();
    report.dense_inliers_per_pose.push_back(static_cast<int>(inliers->size()));
    const Rigid3d board_from_camera = PoseOf(camera_from_board[p]).Inverse();
    for (size_t s : EvenSubset(inliers->size(), options.max_dense_points_per_pose)) {
      const size_t i = (*inliers)[s];
      double x_in_camera[3];
      if (!BoardPointInCamera(camera_params.k.data(), camera_params.d.data(),
                              camera_from_board[p].data(), poses[p].dense_in_camera_px[i].data(),
                              x_in_camera)) {
        continue;
      }
      const Eigen::Vector3d x_in_board =
          board_from_camera * Eigen::Vector3d(x_in_camera[0], x_in_camera[1], x_in_camera[2]);
      dense_used[p].push_back(i);
      board_points[p].emplace_back(x_in_board.x(), x_in_board.y(), 0.0f);
      const Eigen::Vector2d& u = poses[p].dense_in_projector_px[i];
      projector_points[p].emplace_back(u.x(), u.y());
    }
  }

  // 3. Projector (planar Zhang on the dense board points; pinhole first).
  cv::Mat projector_k, projector_d;
  std::vector<cv::Mat> prvecs, ptvecs;
  try {
    report.initial_projector_rms_px = cv::calibrateCamera(
        board_points, projector_points,
        cv::Size(options.projector_width_px, options.projector_height_px), projector_k, projector_d,
        prvecs, ptvecs, OpenCvFlags(DistortionModel::kNone));
  } catch (const cv::Exception& e) {
    return NotConvergedError(std::string("projector initialisation (cv::calibrateCamera): ") +
                             e.what());
  }
  Params projector_params;
  projector_params.k = {projector_k.at<double>(0, 0), projector_k.at<double>(1, 1),
                        projector_k.at<double>(0, 2), projector_k.at<double>(1, 2)};
  std::vector<Rigid3d> projector_from_camera_per_pose;
  for (int p = 0; p < n_poses; ++p) {
    projector_from_camera_per_pose.push_back(PoseFromCv(prvecs[p], ptvecs[p]) *
                                             PoseOf(camera_from_board[p]).Inverse());
  }
  std::array<double, 6> projector_from_camera =
      PoseParams(AverageRigid(projector_from_camera_per_pose));

  // 4. Joint refinement.
  ceres::Problem problem;
  for (int p = 0; p < n_poses; ++p) {
    for (int k = 0; k < board.corner_count(); ++k) {
      problem.AddResidualBlock(
          new ceres::AutoDiffCostFunction<CornerCost, 2, 4, 5, 6>(
              new CornerCost(poses[p].corners_in_camera_px[k], board.CornerInBoard_m(k))),
          nullptr, camera_params.k.data(), camera_params.d.data(), camera_from_board[p].data());
      ++report.corner_residuals;
    }
    for (size_t i : dense_used[p]) {
      problem.AddResidualBlock(
          new ceres::AutoDiffCostFunction<DenseCost, 2, 4, 5, 6, 6, 4, 5>(
              new DenseCost(poses[p].dense_in_camera_px[i], poses[p].dense_in_projector_px[i])),
          new ceres::ScaledLoss(new ceres::HuberLoss(options.projector_loss_scale_px),
                                options.dense_weight * options.dense_weight, ceres::TAKE_OWNERSHIP),
          camera_params.k.data(), camera_params.d.data(), camera_from_board[p].data(),
          projector_from_camera.data(), projector_params.k.data(), projector_params.d.data());
      ++report.dense_residuals;
    }
  }
  SetDistortionFreedom(&problem, camera_params.d.data(), options.camera_distortion);
  SetDistortionFreedom(&problem, projector_params.d.data(), options.projector_distortion);

  ceres::Solver::Options solver;
  solver.linear_solver_type = ceres::DENSE_SCHUR;
  solver.max_num_iterations = options.max_iterations;
  solver.num_threads = options.num_threads;
  solver.function_tolerance = 1e-12;
  solver.parameter_tolerance = 1e-12;
  ceres::Solver::Summary summary;
  ceres::Solve(solver, &problem, &summary);
  report.termination = ceres::TerminationTypeToString(summary.termination_type);
  report.message = summary.message;
  report.iterations = static_cast<int>(summary.iterations.size());
  if (summary.termination_type == ceres::FAILURE || !std::isfinite(summary.final_cost)) {
    return NotConvergedError("unit calibration: joint refinement failed: " + summary.message);
  }

  // Unrobustified RMS.
  double corner_sq = 0.0, dense_sq = 0.0;
  int64_t dense_count = 0;
  for (int p = 0; p < n_poses; ++p) {
    for (int k = 0; k < board.corner_count(); ++k) {
      const Eigen::Vector3d x = board.CornerInBoard_m(k);
      double pixel[2];
      if (!CornerPixel(camera_params.k.data(), camera_params.d.data(), camera_from_board[p].data(),
                       x.data(), pixel)) {
        return NotConvergedError("unit calibration: a corner of " + poses[p].name +
                                 " ends behind the camera");
      }
      corner_sq +=
          (Eigen::Vector2d(pixel[0], pixel[1]) - poses[p].corners_in_camera_px[k]).squaredNorm();
    }
    for (size_t i : dense_used[p]) {
      double predicted[2];
      if (!DenseProjectorPixel(camera_params.k.data(), camera_params.d.data(),
                               camera_from_board[p].data(), projector_from_camera.data(),
                               projector_params.k.data(), projector_params.d.data(),
                               poses[p].dense_in_camera_px[i].data(), predicted)) {
        continue;
      }
      dense_sq += (Eigen::Vector2d(predicted[0], predicted[1]) - poses[p].dense_in_projector_px[i])
                      .squaredNorm();
      ++dense_count;
    }
  }
  report.camera_rms_px = Rms(corner_sq, report.corner_residuals);
  report.projector_rms_px = Rms(dense_sq, dense_count);

  // Covariance of the intrinsics.
  report.camera_std = report.projector_std =
      ParameterDeviations{{kNaN, kNaN, kNaN, kNaN}, {kNaN, kNaN, kNaN, kNaN, kNaN}};
  if (options.compute_covariance) {
    ceres::Covariance::Options cov_options;
    cov_options.algorithm_type = ceres::DENSE_SVD;
    // The parameters span pixels (fx ~ 3e3), metres and dimensionless k3, so J^T J has a
    // reciprocal condition number near 1e-16 from column scale alone (measured on the real
    // data); the SVD of J itself stays accurate to ~eps * cond(J) ~ 1e-8 there.
    cov_options.min_reciprocal_condition_number = 1e-24;
    ceres::Covariance covariance(cov_options);
    std::vector<std::pair<const double*, const double*>> blocks = {
        {camera_params.k.data(), camera_params.k.data()},
        {projector_params.k.data(), projector_params.k.data()}};
    const bool camera_d_free = FixedCoefficients(options.camera_distortion).size() < 5;
    const bool projector_d_free = FixedCoefficients(options.projector_distortion).size() < 5;
    if (camera_d_free) blocks.push_back({camera_params.d.data(), camera_params.d.data()});
    if (projector_d_free) blocks.push_back({projector_params.d.data(), projector_params.d.data()});
    const int residuals = summary.num_residuals_reduced;
    const int parameters = summary.num_effective_parameters_reduced;
    const double sigma2 =
        residuals > parameters ? 2.0 * summary.final_cost / (residuals - parameters) : kNaN;
    if (covariance.Compute(blocks, &problem)) {
      report.covariance_ok = true;
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
      fill(camera_params.k.data(), 4, report.camera_std.intrinsics_px.data(),
           options.camera_distortion, false);
      fill(projector_params.k.data(), 4, report.projector_std.intrinsics_px.data(),
           options.projector_distortion, false);
      if (camera_d_free) {
        fill(camera_params.d.data(), 5, report.camera_std.distortion.data(),
             options.camera_distortion, true);
      }
      if (projector_d_free) {
        fill(projector_params.d.data(), 5, report.projector_std.distortion.data(),
             options.projector_distortion, true);
      }
      report.covariance_message = "sigma = " + std::to_string(std::sqrt(sigma2)) + " px";
    } else {
      report.covariance_message =
          "ceres::Covariance failed: the Jacobian is rank deficient (some parameters are not "
          "determined by these poses)";
    }
  }

  UnitCalibration& calibration = result.calibration;
  calibration.camera = ModelOf(camera_params, camera_size.width, camera_size.height);
  calibration.projector =
      ModelOf(projector_params, options.projector_width_px, options.projector_height_px);
  calibration.projector_from_camera = PoseOf(projector_from_camera);
  calibration.camera_rms_px = report.camera_rms_px;
  calibration.projector_rms_px = report.projector_rms_px;
  calibration.source = kSourceUnitCalibration;
  for (int p = 0; p < n_poses; ++p) {
    calibration.poses_used.push_back(poses[p].name);
    report.camera_from_board.push_back(PoseOf(camera_from_board[p]));
  }
  Status valid = calibration.Check();
  if (!valid.ok()) return NotConvergedError("unit calibration: result invalid: " + valid.message());
  report.compute_time = std::chrono::steady_clock::now() - start;
  return result;
}

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
  const std::array<double, 6> camera_from_board = PoseParams(PoseFromCv(rvec, tvec));
  const std::array<double, 6> projector_from_camera = PoseParams(calibration.projector_from_camera);

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
