// ProjectorView: what the renderer needs of a calibrated projector, prepared off the render
// thread (the distortion map costs ~0.1 s at 1280x800) and swapped in between frames.
//
// - clip_from_table: GL projection (intrinsics with the principal point, common/camera/
//   gl_projection.h) times the view (projector_from_table), with near and far fitted to the
//   scene: the distances along the optical axis of the scene's bounding box corners, widened by
//   kDepthMargin and clamped to [kMinNear_m, ...].
// - The lens-distortion pre-warp. The scene is drawn with the pinhole matrix into an image of
//   the projector's size (the "ideal" image); output pixel u (OpenCV, distorted) must show the
//   ideal image at K * Undistort(K^-1 u). source_px holds that ideal pixel for every output
//   pixel (CV_32FC2, OpenCV pixel coordinates; NaN where the distortion has no inverse).
//   max_displacement_px is the largest |source - u| over the image: below kSkipDistortion_px
//   (0.1 px) the pre-warp pass is skipped and source_px is left empty.
// Errors: INVALID_ARGUMENT for a calibration without table_from_projector or an invalid model.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "common/base/status.h"
#include "common/camera/camera_model.h"
#include "common/geometry/rigid3.h"

namespace sandtable::node {

inline constexpr double kSkipDistortion_px = 0.1;
inline constexpr double kMinNear_m = 0.01;
inline constexpr double kDepthMargin = 0.05;  // near *= (1 - m), far *= (1 + m)

struct ProjectorView {
  CameraModel projector;
  Rigid3d projector_from_table;
  Eigen::Vector3d centre_in_table_m = Eigen::Vector3d::Zero();
  double near_m = 0.1, far_m = 10.0;
  Eigen::Matrix4d clip_from_table = Eigen::Matrix4d::Identity();
  double max_displacement_px = 0.0;
  cv::Mat source_px;  // CV_32FC2 (empty: no pre-warp)
  bool needs_prewarp() const { return !source_px.empty(); }
  // For the pre-warp folded into the vertex shader (renderer.h): the squared normalized radius
  // up to which the Brown model is monotonic (CameraModel::InDistortionDomain; capped at 100).
  double distortion_domain_r2 = 100.0;
  // ... and the largest second derivative of the distorted pixel against the ideal pixel over
  // the image (px per px^2), which sets how finely the model is tessellated.
  double max_curvature_per_px = 0.0;
};

// `scene_bounds` in the table frame (the model as placed, and the table); near and far are
// fitted to it. An empty box gives near kMinNear_m, far 100 m.
Expected<ProjectorView> PrepareProjectorView(const CameraModel& projector,
                                             const Rigid3d& projector_from_table,
                                             const Eigen::AlignedBox3d& scene_bounds);

}  // namespace sandtable::node
