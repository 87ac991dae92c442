#include "common/estimation/plane_fit.h"

namespace sandtable {

Plane Plane::OrientedToward(const Eigen::Vector3d& x_m) const {
  if (SignedDistance_m(x_m) >= 0.0) return *this;
  return Plane{-normal, -offset_m};
}
bool Plane::AllFinite() const { return normal.allFinite() && std::isfinite(offset_m); }
Status PlaneFitOptions::Check() const { return OkStatus(); }
Expected<Plane> FitPlaneLeastSquares(std::span<const Eigen::Vector3d>) {
  return InternalError("not implemented yet");
}
Expected<PlaneFitReport> FitPlaneRansac(std::span<const Eigen::Vector3d>, const PlaneFitOptions&) {
  return InternalError("not implemented yet");
}

}  // namespace sandtable
