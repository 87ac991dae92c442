// Plane-to-plane homographies: normalized DLT, nonlinear refinement, RANSAC, and the
// decomposition of a plane-induced homography into a camera pose.
//
// Convention: a homography is named to_from_from (e.g. `image_from_plane`) and maps a point
// x_from (2D, any unit) to x_to by
//   [x_to; 1] ~ H * [x_from; 1],  x_to = (H x)_{0,1} / (H x)_2.
// Every H returned here is normalised to Frobenius norm 1 with H(2,2) >= 0 (when H(2,2) == 0,
// the first non-zero entry of the last row is positive). H(2,2) = 1 is NOT used as the
// normalisation because it is zero for homographies that send the origin to infinity.
//
// Errors (never aborts on user data):
//   INVALID_ARGUMENT  size mismatch, non-finite coordinates, bad options.
//   DEGENERATE        fewer than 4 pairs; all points (near-)collinear in either image; three of
//                     four points of a minimal set collinear; a rank-deficient linear system;
//                     a singular homography. The message names which.
//   NOT_CONVERGED     refinement failed (NaN, no usable step); the report says why.
// Thread safety: all functions are pure (no shared state).
#pragma once

#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "common/base/status.h"
#include "common/base/units.h"
#include "common/geometry/rigid3.h"

namespace sandtable {

// Collinearity test, in Hartley-normalised coordinates: a 2D point set whose centred scatter
// has singular values s_min/s_max below this ratio is called collinear (a 1000 px long line
// with 0.1 px perpendicular jitter has a ratio near 1e-4).
constexpr double kHomographyCollinearRatio = 1e-5;
// The linear system is called rank-deficient when its second-smallest singular value is below
// this fraction of its largest (after Hartley normalisation).
constexpr double kHomographyRankDeficientRatio = 1e-9;
// A homography whose smallest singular value is below this fraction of its largest is called
// singular (it collapses the plane onto a line).
constexpr double kHomographySingularRatio = 1e-10;

// Applies H to one point: (H [x;1])_{0,1} / (H [x;1])_2. The result is not finite when the
// point maps to the line at infinity.
Eigen::Vector2d ApplyHomography(const Eigen::Matrix3d& to_from_from, const Eigen::Vector2d& x);

// Brings H to the normalisation described at the top of the file (Frobenius norm 1, sign).
Eigen::Matrix3d NormalizeHomography(const Eigen::Matrix3d& h);

// Transfer error in the destination image: |x_to_i - H x_from_i|, one value per pair, in the
// unit of x_to (px for images). Non-finite when a point maps to infinity.
std::vector<double> HomographyTransferErrors(const Eigen::Matrix3d& to_from_from,
                                             std::span<const Eigen::Vector2d> points_from,
                                             std::span<const Eigen::Vector2d> points_to);
// sqrt(mean_i |x_to_i - H x_from_i|^2) in the unit of x_to; +inf if any error is non-finite.
double HomographyTransferRms(const Eigen::Matrix3d& to_from_from,
                             std::span<const Eigen::Vector2d> points_from,
                             std::span<const Eigen::Vector2d> points_to);

// Normalized DLT (Hartley & Zisserman, Alg. 4.2) from n >= 4 pairs: each point set is moved
// to its centroid and scaled to a mean distance of sqrt(2) from it, the 2n x 9 system is
// solved by SVD, and the normalisation is undone. Minimises the algebraic error, not a
// geometric one: follow with RefineHomography for an ML estimate under pixel noise.
// Works for any coordinate scale (tested 1e-3 .. 1e4). Cost O(n).
// Errors: see the top of the file. With exactly 4 pairs, three collinear points in either
// set give DEGENERATE "three of the four points ... are collinear".
// Near-collinear data: measured with 200 source points in a strip of a 1 m square and 0.5 px
// noise, refused below width/length 1e-5; between 1e-5 and 1e-3 the DLT fits the data itself
// badly (3-21 px rms) while RefineHomography brings it to the noise level (0.10 px) at every
// width. Away from the strip H is undetermined (60 px at 1e-3, 6.6 px at 1e-2, 0.7 px at 0.1
// over the whole square): do not extrapolate from near-collinear points.
Expected<Eigen::Matrix3d> EstimateHomographyDlt(std::span<const Eigen::Vector2d> points_from,
                                                std::span<const Eigen::Vector2d> points_to);

struct HomographyRefineOptions {
  int max_iterations = 50;
  // Ceres stopping tolerances (relative change of cost / parameters / gradient).
  double function_tolerance = 1e-12;
  double parameter_tolerance = 1e-12;
  double gradient_tolerance = 1e-14;
  Status Check() const;
};

struct HomographyRefineReport {
  bool converged = false;   // Ceres reported CONVERGENCE (or NO_CONVERGENCE with a usable
                            // decrease after max_iterations: converged = false, result kept)
  std::string termination;  // Ceres termination type, e.g. "CONVERGENCE"
  std::string message;      // Ceres message
  int num_points = 0;
  int iterations = 0;  // Ceres iterations (successful + unsuccessful steps)
  // Transfer error in the destination image, rms_px = sqrt(mean_i |x_to_i - H x_from_i|^2).
  double initial_rms_px = 0.0;
  double final_rms_px = 0.0;
  Seconds solve_time{0.0};
};

struct RefinedHomography {
  Eigen::Matrix3d to_from_from;  // normalised as at the top of the file
  HomographyRefineReport report;
};

// Levenberg-Marquardt (Ceres) on the one-sided transfer error in the destination image:
//   minimise sum_i |x_to_i - H x_from_i|^2   (in the unit of x_to, usually px).
// This is the ML estimate when only the destination points are noisy (e.g. a known planar
// target seen by a camera). H is parameterised on the unit sphere in R^9 (8 dof) in
// Hartley-normalised coordinates, so it works at any coordinate scale and for H(2,2) ~ 0.
// Needs n >= 4 pairs. Errors: INVALID_ARGUMENT (sizes, non-finite, bad options, non-finite
// `initial`), DEGENERATE (n < 4), NOT_CONVERGED (Ceres FAILURE, or a non-finite result). When
// Ceres stops on max_iterations the result is returned with report.converged = false.
Expected<RefinedHomography> RefineHomography(std::span<const Eigen::Vector2d> points_from,
                                             std::span<const Eigen::Vector2d> points_to,
                                             const Eigen::Matrix3d& initial_to_from_from,
                                             const HomographyRefineOptions& options = {});

struct HomographyRansacOptions {
  // Inlier threshold on the transfer error in the destination image (unit of x_to, px).
  double max_transfer_error_px = 2.0;
  double confidence = 0.999;
  int min_iterations = 10;
  int max_iterations = 10000;
  double min_inlier_ratio = 0.0;  // DEGENERATE when the best inlier ratio is below this
  uint64_t seed = 0;              // deterministic for a fixed seed
  // After RANSAC (which already refits the DLT on all inliers), run RefineHomography on the
  // final inliers.
  bool refine = true;
  HomographyRefineOptions refine_options;
  Status Check() const;
};

struct HomographyRansacResult {
  Eigen::Matrix3d to_from_from;   // normalised as at the top of the file
  std::vector<char> inlier_mask;  // 1 = inlier, one entry per pair
  int num_inliers = 0;
  double inlier_ratio = 0.0;   // num_inliers / n
  int iterations = 0;          // RANSAC samples drawn
  double inlier_rms_px = 0.0;  // transfer rms over the final inliers
  bool refined = false;        // RefineHomography ran and was kept
};

// RANSAC (common/estimation/ransac.h) over minimal 4-point DLT samples; minimal samples with
// three collinear points (in either image) are rejected before fitting. The consensus set is
// refit with the normalized DLT, then (options.refine) refined by RefineHomography, then
// re-scored. Errors: those of EstimateHomographyDlt on the inputs (sizes, non-finite, < 4),
// DEGENERATE when no sample yields a model with >= 4 inliers or the ratio is below
// min_inlier_ratio. Breakdown (200 pairs, 0.3 px noise, 1.5 px threshold, 20 seeds): correct up
// to 85 % outliers with max_iterations = 10000; at 90 % it needs max_iterations ~ 1e5. Past
// that it returns the best (wrong) model with a low inlier_ratio: set min_inlier_ratio to
// turn that into an error. Cost ~27 us per sample at n = 200.
Expected<HomographyRansacResult> EstimateHomographyRansac(
    std::span<const Eigen::Vector2d> points_from, std::span<const Eigen::Vector2d> points_to,
    const HomographyRansacOptions& options = {});

// Decomposes a plane-induced homography H ~ K [r1 r2 t], which maps a point (x, y) on the
// z = 0 plane of a frame "plane" (any length unit) to its undistorted pixel, into the pose
// camera_from_plane (translation in the plane's length unit). `k` is the 3x3 intrinsic
// matrix (use the identity when H maps to normalised image coordinates).
// The scale is fixed by the mean norm of K^-1 h1 and K^-1 h2; R = [r1 r2 r1 x r2] is brought
// to the nearest rotation by SVD (det R = +1). The sign is chosen so that `points_on_plane`
// (plane coordinates (x, y)) lie in front of the camera (z > 0); with no points given, so that
// the plane origin does (t_z > 0).
// Errors: INVALID_ARGUMENT (non-finite H or K, K not invertible), DEGENERATE (K^-1 H has rank
// < 2, so no pose), OUT_OF_RANGE (the given points lie on both sides of the camera plane).
Expected<Rigid3d> CameraFromPlaneHomography(const Eigen::Matrix3d& image_from_plane,
                                            const Eigen::Matrix3d& k,
                                            std::span<const Eigen::Vector2d> points_on_plane = {});

}  // namespace sandtable
