#include "common/estimation/resection.h"

#include <chrono>
#include <cmath>
#include <limits>
#include <sstream>
#include <vector>

#include <Eigen/SVD>

#include "common/estimation/homography.h"
#include "common/estimation/homography_hartley.h"
#include "common/estimation/resection_linear.h"
#include "common/estimation/resection_refine.h"

namespace sandtable {
namespace {

// Number of points whose depth in the camera is <= 0.
int CountBehind(const Rigid3d& camera_from_world, std::span<const Eigen::Vector3d> world) {
  int behind = 0;
  for (const Eigen::Vector3d& x : world) behind += !((camera_from_world * x).z() > 0.0);
  return behind;
}

Status BehindError(std::string_view stage, int behind, int n) {
  std::ostringstream s;
  s << "resection: " << behind << " of " << n << " points lie behind the camera " << stage
    << "; the correspondences are not a view of one camera (check for mismatched or mirrored "
       "points)";
  return OutOfRangeError(s.str());
}

// Spread of the cloud for messages: rms extent along the main axis and rms out-of-plane.
std::string SpreadText(std::span<const Eigen::Vector3d> points) {
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& p : points) c += p;
  c /= static_cast<double>(points.size());
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
  for (const Eigen::Vector3d& p : points) scatter += (p - c) * (p - c).transpose();
  const Eigen::Vector3d s = Eigen::JacobiSVD<Eigen::Matrix3d>(scatter).singularValues();
  const double n = static_cast<double>(points.size());
  std::ostringstream out;
  out << "rms out-of-plane spread " << std::sqrt(std::max(0.0, s(2)) / n)
      << " over an rms extent of " << std::sqrt(s(0) / n) << " (world units)";
  return out.str();
}

}  // namespace

Status ResectionOptions::Check() const {
  if ((fix_intrinsics || fix_distortion) && !initial_camera) {
    return InvalidArgumentError(
        "ResectionOptions: initial_camera is required when intrinsics or distortion are fixed");
  }
  if (fix_pose && !initial_camera_from_world) {
    return InvalidArgumentError(
        "ResectionOptions: initial_camera_from_world is required when the pose is fixed");
  }
  if (fix_intrinsics && fix_distortion && fix_pose) {
    return InvalidArgumentError("ResectionOptions: every group is fixed, nothing to estimate");
  }
  if (initial_camera) {
    Status st = initial_camera->Check();
    if (!st.ok()) return st.WithContext("ResectionOptions: initial_camera");
  }
  if (initial_camera_from_world && !initial_camera_from_world->AllFinite()) {
    return InvalidArgumentError("ResectionOptions: initial_camera_from_world is not finite");
  }
  if (!(loss_scale_px > 0.0) || !std::isfinite(loss_scale_px)) {
    return InvalidArgumentError("ResectionOptions: loss_scale_px must be finite and > 0");
  }
  if (max_iterations < 1) return InvalidArgumentError("ResectionOptions: max_iterations < 1");
  if (!(function_tolerance > 0.0) || !(parameter_tolerance > 0.0) || !(gradient_tolerance > 0.0)) {
    return InvalidArgumentError("ResectionOptions: tolerances must be > 0");
  }
  if (!(coplanar_ratio_threshold >= 0.0 && coplanar_ratio_threshold < 1.0) ||
      !(homography_init_ratio >= 0.0 && homography_init_ratio < 1.0)) {
    return InvalidArgumentError(
        "ResectionOptions: coplanar_ratio_threshold and homography_init_ratio must be in [0, 1)");
  }
  return OkStatus();
}

double ReprojectionRms_px(const CameraModel& camera, const Rigid3d& camera_from_world,
                          std::span<const Eigen::Vector3d> points_in_world,
                          std::span<const Eigen::Vector2d> points_in_image_px) {
  ST_CHECK(points_in_world.size() == points_in_image_px.size())
      << "ReprojectionRms_px: 3D and 2D counts differ";
  if (points_in_world.empty()) return 0.0;
  double sum_sq = 0.0;
  for (size_t i = 0; i < points_in_world.size(); ++i) {
    const std::optional<Eigen::Vector2d> u = camera.Project(camera_from_world * points_in_world[i]);
    if (!u) return std::numeric_limits<double>::infinity();
    sum_sq += (*u - points_in_image_px[i]).squaredNorm();
  }
  return std::sqrt(sum_sq / static_cast<double>(points_in_world.size()));
}

Expected<ResectionResult> EstimateResection(std::span<const Eigen::Vector3d> points_in_world,
                                            std::span<const Eigen::Vector2d> points_in_image_px,
                                            int image_width_px, int image_height_px,
                                            const ResectionOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  ST_RETURN_IF_ERROR(options.Check());
  const int n = static_cast<int>(points_in_world.size());
  if (points_in_image_px.size() != points_in_world.size()) {
    std::ostringstream s;
    s << "resection: " << n << " 3D points but " << points_in_image_px.size() << " pixels";
    return InvalidArgumentError(s.str());
  }
  if (image_width_px <= 0 || image_height_px <= 0) {
    return InvalidArgumentError("resection: image size must be positive");
  }
  if (options.initial_camera && (options.initial_camera->width_px != image_width_px ||
                                 options.initial_camera->height_px != image_height_px)) {
    return InvalidArgumentError("resection: initial_camera image size differs from the image");
  }
  for (int i = 0; i < n; ++i) {
    if (!points_in_world[i].allFinite() || !points_in_image_px[i].allFinite()) {
      std::ostringstream s;
      s << "resection: point " << i << " has a non-finite coordinate (NaN or Inf)";
      return InvalidArgumentError(s.str());
    }
  }
  const int min_points = options.fix_intrinsics ? 4 : 6;
  if (n < min_points) {
    std::ostringstream s;
    s << "resection: " << n << " points given, at least " << min_points << " needed"
      << (options.fix_intrinsics ? " with fixed intrinsics" : " (DLT)");
    return DegenerateError(s.str());
  }
  if (const int p = internal::NumFreeResectionParameters(options); 2 * n < p) {
    std::ostringstream s;
    s << "resection: " << n << " points give " << 2 * n << " residuals for " << p
      << " free parameters; at least " << (p + 1) / 2
      << " points needed (or hold distortion or k3 fixed)";
    return DegenerateError(s.str());
  }
  if (internal::CollinearityRatio(points_in_image_px) < kHomographyCollinearRatio) {
    return DegenerateError("resection: the image points are collinear");
  }
  const double ratio = OutOfPlaneRatio(points_in_world);
  const bool coplanar = ratio < options.coplanar_ratio_threshold;
  if (coplanar && !options.fix_intrinsics) {
    std::ostringstream s;
    s << "resection: the 3D points are coplanar or nearly so (out-of-plane ratio " << ratio << " < "
      << options.coplanar_ratio_threshold << "; " << SpreadText(points_in_world)
      << "); one view of a plane does not determine the intrinsics: hold intrinsics fixed or "
         "add off-plane points";
    return DegenerateError(s.str());
  }

  // Pixels with the initial camera's distortion removed (normalised and as pixels of K0).
  std::vector<Eigen::Vector2d> normalized(n);
  std::vector<Eigen::Vector2d> undistorted_px(points_in_image_px.begin(), points_in_image_px.end());
  if (options.initial_camera) {
    const CameraModel& c0 = *options.initial_camera;
    for (int i = 0; i < n; ++i) {
      Expected<Eigen::Vector3d> ray = c0.Unproject(points_in_image_px[i]);
      if (!ray.ok()) {
        std::ostringstream s;
        s << "resection: pixel " << i << " cannot be undistorted with the initial camera";
        return ray.status().WithContext(s.str());
      }
      normalized[i] = ray->head<2>();
      undistorted_px[i] = Eigen::Vector2d(c0.fx_px * normalized[i].x() + c0.cx_px,
                                          c0.fy_px * normalized[i].y() + c0.cy_px);
    }
  }

  ResectionResult result;
  ResectionReport& report = result.report;
  report.num_points = n;
  report.out_of_plane_ratio = ratio;
  report.num_free_parameters = internal::NumFreeResectionParameters(options);
  CameraModel camera(image_width_px, image_height_px, 1.0, 1.0, 0.0, 0.0);
  if (options.initial_camera) camera = *options.initial_camera;
  Rigid3d camera_from_world;

  if (options.fix_intrinsics) {
    // Known K: the pose from the given pose, or the better of the linear candidates.
    if (options.initial_camera_from_world) {
      camera_from_world = *options.initial_camera_from_world;
      report.initializer = "given_pose";
    } else {
      double best_rms = std::numeric_limits<double>::infinity();
      Status last_error = DegenerateError("resection: no initial pose could be computed");
      auto consider = [&](Expected<Rigid3d> pose, const char* name) {
        if (!pose.ok()) {
          last_error = pose.status().WithContext("resection");
          return;
        }
        if (const int behind = CountBehind(*pose, points_in_world); behind > 0) {
          last_error =
              BehindError(std::string("after the initial estimate (") + name + ")", behind, n);
          return;
        }
        const double rms = ReprojectionRms_px(camera, *pose, points_in_world, points_in_image_px);
        if (rms < best_rms) {
          best_rms = rms;
          camera_from_world = *pose;
          report.initializer = name;
        }
      };
      if (n >= 6 && !coplanar) {
        consider(internal::CameraFromWorldDltKnownK(points_in_world, normalized),
                 "dlt_known_intrinsics");
      }
      if (ratio < options.homography_init_ratio) {
        consider(internal::CameraFromWorldPlanar(points_in_world, normalized), "homography");
      }
      if (n < 6 && !coplanar) {
        consider(internal::CameraFromWorldP3p(points_in_world, normalized), "p3p");
      }
      if (report.initializer.empty()) {
        // Every candidate failed or left points behind the camera.
        return last_error;
      }
    }
  } else {
    // Free intrinsics: K from the DLT of the undistorted pixels.
    Expected<Eigen::Matrix<double, 3, 4>> p = EstimateProjectionMatrixDlt(
        points_in_world, undistorted_px, options.coplanar_ratio_threshold);
    if (!p.ok()) return p.status().WithContext("resection");
    Expected<DecomposedProjection> d = DecomposeProjectionMatrix(*p);
    if (!d.ok()) return d.status().WithContext("resection");
    camera.fx_px = d->k(0, 0);
    camera.fy_px = d->k(1, 1);
    camera.cx_px = d->k(0, 2);
    camera.cy_px = d->k(1, 2);
    camera_from_world = d->camera_from_world;
    report.initializer = "dlt";
    if (options.initial_camera_from_world) {
      camera_from_world = *options.initial_camera_from_world;
      report.initializer = "given_pose";
    }
  }
  if (const int behind = CountBehind(camera_from_world, points_in_world); behind > 0) {
    return BehindError("after the initial estimate (" + report.initializer + ")", behind, n);
  }
  report.initial_rms_px =
      ReprojectionRms_px(camera, camera_from_world, points_in_world, points_in_image_px);

  Expected<internal::ResectionRefineOutput> refined = internal::RefineResection(
      points_in_world, points_in_image_px, camera, camera_from_world, options);
  if (!refined.ok()) return refined.status();
  result.camera = refined->camera;
  result.camera_from_world = refined->camera_from_world;
  report.converged = refined->converged;
  report.termination = refined->termination;
  report.message = refined->message;
  report.iterations = refined->iterations;
  report.uncertainty_available = refined->uncertainty_available;
  report.fx_std_px = refined->fx_std_px;
  report.fy_std_px = refined->fy_std_px;
  report.cx_std_px = refined->cx_std_px;
  report.cy_std_px = refined->cy_std_px;
  report.rotation_std_rad = refined->rotation_std_rad;
  report.translation_std = refined->translation_std;
  if (const int behind = CountBehind(result.camera_from_world, points_in_world); behind > 0) {
    return BehindError("after refinement", behind, n);
  }
  report.final_rms_px = ReprojectionRms_px(result.camera, result.camera_from_world, points_in_world,
                                           points_in_image_px);
  report.solve_time = std::chrono::steady_clock::now() - start;
  return result;
}

}  // namespace sandtable
