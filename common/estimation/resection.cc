#include "common/estimation/resection.h"

// Implementation in progress: functions below return INTERNAL until the next commit.

namespace sandtable {

Status ResectionOptions::Check() const { return OkStatus(); }

Expected<ResectionResult> EstimateResection(std::span<const Eigen::Vector3d>,
                                            std::span<const Eigen::Vector2d>, int, int,
                                            const ResectionOptions&) {
  return InternalError("EstimateResection: not implemented yet");
}

Expected<Eigen::Matrix<double, 3, 4>> EstimateProjectionMatrixDlt(std::span<const Eigen::Vector3d>,
                                                                  std::span<const Eigen::Vector2d>,
                                                                  double) {
  return InternalError("EstimateProjectionMatrixDlt: not implemented yet");
}

Expected<DecomposedProjection> DecomposeProjectionMatrix(const Eigen::Matrix<double, 3, 4>&) {
  return InternalError("DecomposeProjectionMatrix: not implemented yet");
}

double ReprojectionRms_px(const CameraModel&, const Rigid3d&, std::span<const Eigen::Vector3d>,
                          std::span<const Eigen::Vector2d>) {
  return 0.0;
}

double OutOfPlaneRatio(std::span<const Eigen::Vector3d>) { return 0.0; }

}  // namespace sandtable
