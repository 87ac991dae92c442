#include "node/blend/projector_rays.h"

#include <algorithm>
#include <optional>

namespace sandtable::node::blend_internal {
namespace {

// The physical surface's albedo at a hit: the material's base colour factor as Rec. 709
// luminance (textures are imagery to show, not the white models' paint); 1 without material.
double SurfaceAlbedo(const Scene& scene, int triangle) {
  if (triangle < 0 || triangle >= static_cast<int>(scene.triangle_material.size())) return 1.0;
  const int m = scene.triangle_material[triangle];
  if (m < 0 || m >= static_cast<int>(scene.materials.size())) return 1.0;
  const Eigen::Vector4d& c = scene.materials[m].base_color_factor;
  return std::clamp(0.2126 * c.x() + 0.7152 * c.y() + 0.0722 * c.z(), 0.0, 1.0);
}

}  // namespace

RayTable::RayTable(const CameraModel& model, int step) : step_(step) {
  cols_ = (model.width_px + step - 1) / step + 1;
  rows_ = (model.height_px + step - 1) / step + 1;
  xy_.resize(static_cast<size_t>(cols_) * rows_);
  for (int r = 0; r < rows_; ++r) {
    for (int c = 0; c < cols_; ++c) {
      const Eigen::Vector2d pixel(c * step, r * step);
      Expected<Eigen::Vector3d> ray = model.Unproject(pixel);
      // Past the fold (none inside an image the calibration accepted): the pinhole ray.
      const Eigen::Vector2d n =
          ray.ok() ? Eigen::Vector2d(ray->x(), ray->y()) : model.NormalizedFromPixel(pixel);
      xy_[static_cast<size_t>(r) * cols_ + c] = n;
    }
  }
}

Eigen::Vector3d RayTable::At(double x_px, double y_px) const {
  const double gx = std::clamp(x_px / step_, 0.0, cols_ - 1.0);
  const double gy = std::clamp(y_px / step_, 0.0, rows_ - 1.0);
  const int c = std::min(static_cast<int>(gx), cols_ - 2);
  const int r = std::min(static_cast<int>(gy), rows_ - 2);
  const double fx = gx - c, fy = gy - r;
  auto at = [&](int cc, int rr) { return xy_[static_cast<size_t>(rr) * cols_ + cc]; };
  const Eigen::Vector2d n = (1 - fy) * ((1 - fx) * at(c, r) + fx * at(c + 1, r)) +
                            fy * ((1 - fx) * at(c, r + 1) + fx * at(c + 1, r + 1));
  return {n.x(), n.y(), 1.0};
}

std::vector<Cast> CastPixels(const std::vector<Eigen::Vector2d>& pixels, const RayTable& rays,
                             const Rigid3d& projector_from_table, const RayCaster& caster,
                             double min_cos) {
  const Rigid3d table_from_projector = projector_from_table.Inverse();
  const Eigen::Vector3d centre = table_from_projector.translation;
  const Eigen::Matrix3d rotation = table_from_projector.RotationMatrix();
  std::vector<Ray> batch(pixels.size());
  for (size_t i = 0; i < pixels.size(); ++i) {
    batch[i].origin_in_table_m = centre;
    batch[i].direction_in_table = rotation * rays.At(pixels[i].x(), pixels[i].y());
  }
  std::vector<std::optional<RayHit>> hits;
  caster.IntersectBatch(batch, &hits, /*coherent=*/true);
  std::vector<Cast> out(pixels.size());
  for (size_t i = 0; i < pixels.size(); ++i) {
    out[i].surface = hits[i].has_value();
    if (!hits[i] || !hits[i]->front_face) continue;
    const Eigen::Vector3d dir = batch[i].direction_in_table.normalized();
    // normal_in_table faces the ray's origin: cos = -dir . n.
    const double cos_incidence = -dir.dot(hits[i]->normal_in_table);
    if (cos_incidence < min_cos) continue;
    out[i].point = hits[i]->point_in_table_m;
    out[i].normal = hits[i]->normal_in_table;
    out[i].range_m = hits[i]->distance_m;
    out[i].cos_incidence = cos_incidence;
    out[i].albedo = SurfaceAlbedo(caster.scene(), hits[i]->triangle);
    out[i].triangle = hits[i]->triangle;
  }
  return out;
}

}  // namespace sandtable::node::blend_internal
