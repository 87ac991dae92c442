// Camera resection: intrinsics, Brown distortion and pose of one camera (or projector) from
// n 3D-2D correspondences.
//
// Frames and units: points_in_world are 3D points in any frame "world" and any length unit;
// the returned camera_from_world maps x_in_world to x_in_camera (OpenCV camera frame, x right,
// y down, z forward), translation in the world's unit. Pixels follow common/camera
// (pixel (0, 0) centred at (0.0, 0.0)). The projection of X is
//   x_c = camera_from_world * X,  (x, y) = (x_c.x / x_c.z, x_c.y / x_c.z),
//   (xd, yd) = ApplyBrownDistortion(k1 k2 p1 p2 k3, x, y),  u = fx xd + cx,  v = fy yd + cy.
//
// RMS, everywhere in this file: rms_px = sqrt( (1/n) sum_i |u_i - u_hat_i|^2 ), where
// u_i - u_hat_i is the 2D pixel residual of point i (both axes), over all n points, with no
// robust loss applied. For an ML estimate with p free parameters under isotropic Gaussian
// pixel noise of sigma px per axis, E[rms_px^2] = 2 sigma^2 (1 - p / (2n)).
//
// Pipeline:
//  1. Validation: sizes, finite values, n >= 6 (n >= 4 when intrinsics are held fixed) and
//     2n >= p (at least as many residuals as free parameters, so n >= 8 with all 15 free),
//     image points not collinear, coplanarity of the 3D points measured by the SVD of the
//     centred cloud: out_of_plane_ratio = s3 / s1 (s1 >= s2 >= s3 its singular values;
//     s3 / sqrt(n) is the rms out-of-plane spread).
//  2. Initial estimate:
//     - intrinsics free: normalized DLT of the 3x4 projection matrix (Hartley normalisation in
//       2D and 3D), RQ decomposition into K (positive focal lengths, skew dropped), R
//       (det +1) and t, sign chosen so the points are in front. Refused (DEGENERATE) when
//       out_of_plane_ratio < options.coplanar_ratio_threshold: a plane does not determine P.
//     - intrinsics fixed: pixels are undistorted with the initial camera and (a) when the
//       cloud is (near-)coplanar (ratio < options.homography_init_ratio), a homography from
//       the fitted plane gives the pose (CameraFromPlaneHomography); (b) when n >= 6 and the
//       ratio is >= coplanar_ratio_threshold, a DLT with known K gives it (R projected onto
//       SO(3)); (c) when n is 4 or 5 and the cloud is not coplanar, P3P on every triple,
//       scored on all points. The candidate with the lowest reprojection rms is refined.
//     - pose fixed: options.initial_camera_from_world is used as given.
//  3. Ceres Levenberg-Marquardt on the reprojection error in px with the options' robust
//     loss; fixed groups are constant parameter blocks. Rotation as angle-axis.
//
// Errors (never aborts on user data):
//   INVALID_ARGUMENT  size mismatch, NaN/Inf, bad options (Check()), image size mismatch with
//                     the initial camera.
//   DEGENERATE        too few points; coplanar or near-coplanar points with free intrinsics
//                     (message gives the measured out-of-plane spread); collinear image
//                     points; rank-deficient DLT.
//   OUT_OF_RANGE      points on both sides of the camera after the initial estimate, or
//                     points behind the camera after refinement.
//   NOT_CONVERGED     Ceres FAILURE or a non-finite result.
// A refinement that stops on max_iterations (Ceres NO_CONVERGENCE) is returned as a result
// with report.converged = false; callers that need a converged answer must check it.
#pragma once

#include <optional>
#include <span>
#include <string>

#include <Eigen/Core>

#include "common/base/status.h"
#include "common/base/units.h"
#include "common/camera/camera_model.h"
#include "common/geometry/rigid3.h"

namespace sandtable {

enum class ResectionLoss {
  kSquared,  // plain least squares (ML under Gaussian noise)
  kHuber,    // quadratic below loss_scale_px, linear above
  kCauchy,   // log(1 + (r / loss_scale_px)^2)
};

struct ResectionOptions {
  // Groups held at their initial values during refinement.
  bool fix_intrinsics = false;  // fx, fy, cx, cy
  bool fix_distortion = false;  // k1, k2, p1, p2, k3
  bool fix_pose = false;        // camera_from_world
  // k3 alone held at its initial value (zero by default) while the other coefficients are
  // free; a single view rarely determines k3 well. Ignored when fix_distortion is set.
  bool fix_k3 = false;
  // Initial intrinsics and distortion; required when fix_intrinsics or fix_distortion is set.
  // Its width_px/height_px must equal the image size passed to EstimateResection. When absent
  // and not required, the intrinsics come from the DLT and the distortion starts at zero.
  std::optional<CameraModel> initial_camera;
  // Initial pose; required when fix_pose is set, otherwise it replaces the linear estimate.
  std::optional<Rigid3d> initial_camera_from_world;

  ResectionLoss loss = ResectionLoss::kSquared;
  double loss_scale_px = 1.0;  // scale of the robust loss (ignored for kSquared)
  int max_iterations = 100;    // Ceres iterations
  double function_tolerance = 1e-12;
  double parameter_tolerance = 1e-12;
  double gradient_tolerance = 1e-14;

  // Standard deviations of the estimate (report.*_std_*) from the Ceres covariance of the
  // free parameters, scaled by the residual variance sum r^2 / (2n - p). Cost: one dense SVD
  // of a p x p matrix.
  bool estimate_uncertainty = true;

  // Coplanarity gate for the DLT (see the pipeline above): below this out_of_plane_ratio the
  // DLT is refused with free intrinsics, and the DLT-with-known-K candidate is skipped with
  // fixed intrinsics. Measured (200 points, 1 m cloud, 0.5 px noise, all 15 parameters free):
  // focal error ~1 % at ratio 0.02-0.06, 0.2 % at 0.2; with the gate off, a noise-free cloud at
  // ratio 2e-3 converged to fx off by 25 %: the gate prevents such silent wrong answers.
  // Lower it only with fewer free parameters or a better-spread cloud.
  double coplanar_ratio_threshold = 1e-2;
  // With fixed intrinsics, below this ratio the homography candidate is also tried.
  double homography_init_ratio = 5e-2;

  Status Check() const;
};

struct ResectionReport {
  bool converged = false;   // Ceres CONVERGENCE
  std::string termination;  // Ceres termination type ("CONVERGENCE", "NO_CONVERGENCE", ...)
  std::string message;      // Ceres message
  std::string initializer;  // "dlt", "dlt_known_intrinsics", "homography", "p3p", "given_pose"
  int num_points = 0;
  int iterations = 0;               // Ceres iterations
  int num_free_parameters = 0;      // p in the noise-floor formula at the top of the file
  double out_of_plane_ratio = 0.0;  // s3 / s1 of the centred 3D cloud (see pipeline step 1)
  double initial_rms_px = 0.0;      // rms (definition at the top) of the initial estimate
  double final_rms_px = 0.0;        // rms after refinement
  Seconds solve_time{0.0};          // whole call, validation to result

  // One-sigma uncertainty of the result (options.estimate_uncertainty), under the assumption
  // of independent pixel noise of the size the residuals show. Zero for fixed groups.
  // uncertainty_available is false when not requested, when 2n - p < 5 (too few residual
  // degrees of freedom to estimate the noise), or when the Jacobi-scaled normal equations have
  // a reciprocal condition below 1e-12 (the data do not determine the free parameters: treat
  // the result as unreliable). Measured (1 m cloud, 0.5 px, 20 seeds per n): the focal error
  // stayed within 2.5 reported sigmas for n >= 10 (4 for n = 12, where 2n - p = 9). A large value
  // (e.g. fx_std_px above 1 % of fx) flags a poorly conditioned input even when the rms looks good.
  bool uncertainty_available = false;
  double fx_std_px = 0.0, fy_std_px = 0.0, cx_std_px = 0.0, cy_std_px = 0.0;
  double rotation_std_rad = 0.0;  // largest axis of the rotation (angle-axis) covariance
  double translation_std = 0.0;   // largest axis of the translation covariance, world unit
};

struct ResectionResult {
  CameraModel camera;         // image size as given; skew dropped
  Rigid3d camera_from_world;  // x_in_camera = camera_from_world * x_in_world
  ResectionReport report;
};

// The full pipeline described at the top of the file.
Expected<ResectionResult> EstimateResection(std::span<const Eigen::Vector3d> points_in_world,
                                            std::span<const Eigen::Vector2d> points_in_image_px,
                                            int image_width_px, int image_height_px,
                                            const ResectionOptions& options = {});

// Building blocks, exposed for benchmarks and for callers with their own pipeline.

// Normalized DLT of the 3x4 projection matrix P with [u; 1] ~ P [X; 1] from n >= 6
// non-coplanar points (no distortion model). Returned with Frobenius norm 1 and the sign that
// puts the majority of the points in front (P.row(2) . [X; 1] > 0).
// Errors: INVALID_ARGUMENT (sizes, non-finite), DEGENERATE (n < 6, coplanar by
// coplanar_ratio_threshold, collinear image points, rank-deficient system).
Expected<Eigen::Matrix<double, 3, 4>> EstimateProjectionMatrixDlt(
    std::span<const Eigen::Vector3d> points_in_world,
    std::span<const Eigen::Vector2d> points_in_image_px, double coplanar_ratio_threshold = 1e-2);

struct DecomposedProjection {
  Eigen::Matrix3d k;          // upper triangular, k(2,2) = 1, fx, fy > 0
  double skew_px = 0.0;       // k(0,1) as estimated (CameraModel drops it)
  Rigid3d camera_from_world;  // det R = +1
};
// RQ decomposition P ~ K [R | t]. Errors: INVALID_ARGUMENT (non-finite), DEGENERATE (the left
// 3x3 block is singular: the camera centre is at infinity).
Expected<DecomposedProjection> DecomposeProjectionMatrix(const Eigen::Matrix<double, 3, 4>& p);

// rms_px (definition at the top of the file) of the projection of points_in_world through
// camera and camera_from_world; +inf if a point does not project (z <= 0).
double ReprojectionRms_px(const CameraModel& camera, const Rigid3d& camera_from_world,
                          std::span<const Eigen::Vector3d> points_in_world,
                          std::span<const Eigen::Vector2d> points_in_image_px);

// s3 / s1 of the centred cloud (0 for fewer than 3 points or a single point); see step 1.
double OutOfPlaneRatio(std::span<const Eigen::Vector3d> points);

}  // namespace sandtable
