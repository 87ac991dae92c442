#include "common/estimation/homography.h"

// Implementation in progress: functions below return INTERNAL until the next commit.

namespace sandtable {

Eigen::Vector2d ApplyHomography(const Eigen::Matrix3d& h, const Eigen::Vector2d& x) {
  const Eigen::Vector3d y = h * x.homogeneous();
  return y.head<2>() / y.z();
}

Eigen::Matrix3d NormalizeHomography(const Eigen::Matrix3d& h) { return h / h.norm(); }

std::vector<double> HomographyTransferErrors(const Eigen::Matrix3d& h,
                                             std::span<const Eigen::Vector2d> from,
                                             std::span<const Eigen::Vector2d> to) {
  std::vector<double> e(from.size());
  for (size_t i = 0; i < from.size(); ++i) e[i] = (to[i] - ApplyHomography(h, from[i])).norm();
  return e;
}

double HomographyTransferRms(const Eigen::Matrix3d&, std::span<const Eigen::Vector2d>,
                             std::span<const Eigen::Vector2d>) {
  return 0.0;
}

Expected<Eigen::Matrix3d> EstimateHomographyDlt(std::span<const Eigen::Vector2d>,
                                                std::span<const Eigen::Vector2d>) {
  return InternalError("EstimateHomographyDlt: not implemented yet");
}

Status HomographyRefineOptions::Check() const { return OkStatus(); }

Expected<RefinedHomography> RefineHomography(std::span<const Eigen::Vector2d>,
                                             std::span<const Eigen::Vector2d>,
                                             const Eigen::Matrix3d&,
                                             const HomographyRefineOptions&) {
  return InternalError("RefineHomography: not implemented yet");
}

Status HomographyRansacOptions::Check() const { return OkStatus(); }

Expected<HomographyRansacResult> EstimateHomographyRansac(std::span<const Eigen::Vector2d>,
                                                          std::span<const Eigen::Vector2d>,
                                                          const HomographyRansacOptions&) {
  return InternalError("EstimateHomographyRansac: not implemented yet");
}

Expected<Rigid3d> CameraFromPlaneHomography(const Eigen::Matrix3d&, const Eigen::Matrix3d&,
                                            std::span<const Eigen::Vector2d>) {
  return InternalError("CameraFromPlaneHomography: not implemented yet");
}

}  // namespace sandtable
