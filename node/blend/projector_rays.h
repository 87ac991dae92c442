// Rays through a projector's pixels cast into the model as placed, shared by the blend's
// projector surface (blend_field.cc) and distance field (distance_field.cc). Internal to
// node/blend.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "common/camera/camera_model.h"
#include "common/geometry/rigid3.h"
#include "common/scene/ray_caster.h"

namespace sandtable::node::blend_internal {

// Normalized undistorted ray directions (z = 1) of pixels, from a coarse grid of exact
// undistortions interpolated bilinearly (the Brown model is smooth: on an 8 px grid the
// interpolation error is far below a pixel for the distortions the calibration accepts).
class RayTable {
 public:
  RayTable(const CameraModel& model, int step);
  Eigen::Vector3d At(double x_px, double y_px) const;

 private:
  int step_, cols_, rows_;
  std::vector<Eigen::Vector2d> xy_;
};

struct Cast {
  Eigen::Vector3d point = Eigen::Vector3d::Zero();
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  double range_m = 0.0;  // 0: lights nothing
  bool surface = false;  // the ray meets the model (lit or not): false past its rim
  double cos_incidence = 0.0;
  double albedo = 1.0;
  int triangle = -1;
};

// Casts the rays of `pixels` (x, y) from the projector's centre; a ray that meets a back face,
// or the surface past acos(min_cos), lights nothing (range 0).
std::vector<Cast> CastPixels(const std::vector<Eigen::Vector2d>& pixels, const RayTable& rays,
                             const Rigid3d& projector_from_table, const RayCaster& caster,
                             double min_cos);

}  // namespace sandtable::node::blend_internal
