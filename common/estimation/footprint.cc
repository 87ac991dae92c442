#include "common/estimation/footprint.h"

#include <cmath>

#include "common/estimation/triangulation.h"

namespace sandtable {

std::vector<Eigen::Vector2d> TableFootprint(const CameraModel& projector,
                                            const Rigid3d& table_from_projector, int per_edge) {
  // The image covers [-0.5, width - 0.5] x [-0.5, height - 0.5] (camera_model.h).
  const Eigen::Vector2d lo(-0.5, -0.5), hi(projector.width_px - 0.5, projector.height_px - 0.5);
  const Eigen::Vector2d corners[4] = {lo, {hi.x(), lo.y()}, hi, {lo.x(), hi.y()}};
  std::vector<Eigen::Vector2d> border;
  for (int side = 0; side < 4; ++side) {
    const Eigen::Vector2d& from = corners[side];
    const Eigen::Vector2d& to = corners[(side + 1) % 4];
    for (int i = 0; i < per_edge; ++i) {
      border.push_back(from + (to - from) * (static_cast<double>(i) / per_edge));
    }
  }
  const Rigid3d projector_from_table = table_from_projector.Inverse();
  std::vector<Eigen::Vector2d> out;
  for (const Eigen::Vector2d& pixel : border) {
    Expected<WorldRay> ray = RayThroughPixel(projector, projector_from_table, pixel);
    if (!ray.ok()) continue;
    const double dz = ray->direction_in_world.z();
    if (std::abs(dz) < 1e-12) continue;
    const double s = -ray->origin_in_world.z() / dz;
    if (!(s > 0.0) || !std::isfinite(s)) continue;
    const Eigen::Vector3d hit = ray->origin_in_world + s * ray->direction_in_world;
    out.emplace_back(hit.x(), hit.y());
  }
  return out;
}

}  // namespace sandtable
