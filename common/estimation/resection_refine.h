// Ceres refinement step of the resection pipeline (internal to common/estimation; the public
// entry point is EstimateResection in resection.h).
#pragma once

#include <span>
#include <string>

#include <Eigen/Core>

#include "common/base/status.h"
#include "common/camera/camera_model.h"
#include "common/estimation/resection.h"
#include "common/geometry/rigid3.h"

namespace sandtable::internal {

struct ResectionRefineOutput {
  CameraModel camera;
  Rigid3d camera_from_world;
  bool converged = false;
  std::string termination;
  std::string message;
  int iterations = 0;
  // Filled when options.estimate_uncertainty (see ResectionReport).
  bool uncertainty_available = false;
  double fx_std_px = 0.0, fy_std_px = 0.0, cx_std_px = 0.0, cy_std_px = 0.0;
  double rotation_std_rad = 0.0;
  double translation_std = 0.0;
};

// Levenberg-Marquardt on the pixel reprojection error (model in resection.h) from `camera` and
// `camera_from_world`, with the groups that `options` fixes held constant and its robust loss.
// Inputs are assumed validated (sizes equal, finite). NOT_CONVERGED on Ceres FAILURE or a
// non-finite result.
Expected<ResectionRefineOutput> RefineResection(std::span<const Eigen::Vector3d> points_in_world,
                                                std::span<const Eigen::Vector2d> points_in_image_px,
                                                const CameraModel& camera,
                                                const Rigid3d& camera_from_world,
                                                const ResectionOptions& options);

// Number of parameters `options` leaves free (4 intrinsics, 5 or 4 distortion, 6 pose).
int NumFreeResectionParameters(const ResectionOptions& options);

}  // namespace sandtable::internal
