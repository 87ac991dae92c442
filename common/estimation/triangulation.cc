#include "common/estimation/triangulation.h"

namespace sandtable {

Status TriangulationOptions::Check() const { return OkStatus(); }
Expected<WorldRay> RayThroughPixel(const CameraModel&, const Rigid3d&, const Eigen::Vector2d&,
                                   const UndistortOptions&) {
  return InternalError("not implemented yet");
}
Expected<Eigen::Vector3d> MidpointOfRays(std::span<const WorldRay>) {
  return InternalError("not implemented yet");
}
double MaxRayAngle_deg(std::span<const WorldRay>) { return 0.0; }
Expected<TriangulationReport> TriangulatePoint(std::span<const TriangulationView>,
                                               const TriangulationOptions&) {
  return InternalError("not implemented yet");
}

}  // namespace sandtable
