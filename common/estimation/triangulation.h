// Triangulation of one 3D point from two or more calibrated views.
//
// Each view is a camera model (pinhole + Brown distortion, common/camera/camera_model.h), the
// pose camera_from_world (Rigid3d, x_in_camera = R x_in_world + t) and the observed pixel,
// DISTORTED, in that camera's image (OpenCV pixel centres). "World" is whatever frame the
// poses map from (the table frame, or the first camera's frame); the point comes back in that
// frame and in its length unit (metres everywhere in this project).
//
// Method:
//   1. Each pixel is undistorted (CameraModel::Unproject) into a ray in the world frame.
//   2. Midpoint: the point minimising the sum of squared perpendicular distances to all rays
//      (for two rays, the midpoint of their common perpendicular), a 3x3 linear solve.
//   3. Optional refinement: Levenberg-Marquardt on the 3 coordinates minimising the sum of
//      squared reprojection errors in px (distorted projection, the same model as the
//      cameras); kept only if it lowers the cost and every depth stays positive.
//
// Checks, in this order (the first that fails is returned; the message names the cause and
// the numbers):
//   - INVALID_ARGUMENT: an options field out of range, a camera that fails
//     CameraModel::Check(), a pose or pixel that is not finite.
//   - DEGENERATE: fewer than 2 views.
//   - NOT_CONVERGED: a pixel whose distortion cannot be inverted (from Unproject).
//   - DEGENERATE: the triangulation angle (the largest angle between any two of the rays) is
//     below options.min_angle_deg: "triangulation: rays meet at 0.0123 deg, below the 1 deg
//     minimum ...". This is also how near-parallel rays are refused; nothing is returned.
//     With min_angle_deg = 0, rays parallel to ~1e-7 rad still give DEGENERATE (midpoint).
//   - OUT_OF_RANGE: the point lies at or behind some camera (depth <= 0 in that camera).
// A successful result is always finite. The reprojection error is reported, not judged: the
// caller decides which rms_px is acceptable for its data.
//
// Cost: O(N) for the midpoint, O(N^2) for the angle check, a few O(N) iterations to refine.
#pragma once

#include <span>

#include <Eigen/Core>

#include "common/base/status.h"
#include "common/camera/camera_model.h"
#include "common/geometry/rigid3.h"

namespace sandtable {

struct TriangulationView {
  CameraModel camera;
  Rigid3d camera_from_world;
  Eigen::Vector2d observed_px = Eigen::Vector2d::Zero();  // distorted pixel in `camera`
};

struct TriangulationOptions {
  // The largest angle between two of the rays must be at least this (degrees, >= 0).
  double min_angle_deg = 1.0;
  // Run the nonlinear (reprojection error) refinement after the midpoint.
  bool refine = true;
  int max_iterations = 20;  // of the refinement, >= 1
  // The refinement stops when a step moves the point by less than this fraction of its
  // distance to the nearest camera centre (dimensionless, > 0).
  double relative_step_tolerance = 1e-12;
  UndistortOptions undistort;
  Status Check() const;
};

struct TriangulationReport {
  Eigen::Vector3d point_in_world = Eigen::Vector3d::Zero();  // world frame and length unit
  double rms_px = 0.0;           // RMS reprojection error over the views, px
  double max_px = 0.0;           // largest reprojection error of one view, px
  double midpoint_rms_px = 0.0;  // RMS reprojection error of the midpoint estimate, px
  double angle_deg = 0.0;        // triangulation angle: largest angle between two rays
  double min_depth_m = 0.0;  // smallest depth (camera z) of the point over the views, world unit
  int num_views = 0;
  int iterations = 0;    // refinement iterations run (0 when refine is off)
  bool refined = false;  // the refined point replaced the midpoint
};

// A ray x(s) = origin + s * direction, s >= 0, in the world frame. direction need not be unit.
struct WorldRay {
  Eigen::Vector3d origin_in_world = Eigen::Vector3d::Zero();
  Eigen::Vector3d direction_in_world = Eigen::Vector3d::UnitZ();
};

// The ray of a (distorted) pixel of a camera in the world frame: origin at the camera centre,
// direction unit length. Errors as Unproject (INVALID_ARGUMENT for a non-finite pixel,
// NOT_CONVERGED where the distortion cannot be inverted).
Expected<WorldRay> RayThroughPixel(const CameraModel& camera, const Rigid3d& camera_from_world,
                                   const Eigen::Vector2d& pixel,
                                   const UndistortOptions& options = {});

// Least-squares closest point to >= 2 rays (generalised midpoint). No angle or depth checks:
// DEGENERATE when fewer than 2 rays are given or the rays are (numerically) all parallel,
// INVALID_ARGUMENT for a non-finite or zero direction/origin.
Expected<Eigen::Vector3d> MidpointOfRays(std::span<const WorldRay> rays);

// The largest angle between two rays' directions, degrees in [0, 180]. 0 for fewer than 2.
double MaxRayAngle_deg(std::span<const WorldRay> rays);

// The full pipeline described at the top of this file.
Expected<TriangulationReport> TriangulatePoint(std::span<const TriangulationView> views,
                                               const TriangulationOptions& options = {});

}  // namespace sandtable
