// View: which ray each pixel of a (real or virtual) sensor casts into the table frame.
//   Perspective: a CameraModel (with its distortion) at table_from_camera; pixel centres
//     follow OpenCV (pixel (x, y) centred at (x, y)).
//   Orthographic top view: looking straight down (-z) from above, image x along table +x,
//     image y along table -y (north up), covering `area_in_table_m`; pixel (x, y) centred at
//     area.min + ((x + 0.5) / width, 1 - (y + 0.5) / height) * area.sizes().
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "common/base/status.h"
#include "common/camera/camera_model.h"
#include "common/geometry/rigid3.h"

namespace sandtable::sim {

// The largest raster the world computes (a render, a top view, a camera's transport map): each
// side, px, and the area (16 Mpx; a transport map holds ~30 bytes per pixel plus 32 bytes per
// pixel a projector lights, so a 3-unit site at the limit needs about 2 GB). A view past these is
// refused, naming the limit, before anything is allocated.
inline constexpr int kMaxViewSide_px = 8192;
inline constexpr int64_t kMaxViewPixels = int64_t{4096} * 4096;

class View {
 public:
  static View Perspective(const CameraModel& model, const Rigid3d& table_from_camera);
  static View OrthographicTop(const Eigen::AlignedBox2d& area_in_table_m, int width_px,
                              int height_px, double eye_height_m = 10.0);

  // An orthographic top view over the x-y extent of `bounds` (a scene's), looking down from
  // 10 m above its top. height_px 0: from the extent's aspect (at least 16 px). INVALID_ARGUMENT
  // for an empty, flat or non-finite extent, or a size past kMaxViewSide_px / kMaxViewPixels
  // (a thin scene asking for 1e10 rows is refused here, not allocated).
  static Expected<View> TopOver(const Eigen::AlignedBox3d& bounds, int width_px, int height_px);

  // OK, or INVALID_ARGUMENT naming the limit the size breaks (no pixels, kMaxViewSide_px,
  // kMaxViewPixels).
  Status Check() const;

  int width_px() const { return width_px_; }
  int height_px() const { return height_px_; }
  bool is_perspective() const { return perspective_; }
  const CameraModel& model() const { return model_; }
  const Rigid3d& table_from_camera() const { return table_from_camera_; }

  // The ray of pixel (x, y): false when the pixel has no ray (past the distortion's fold).
  bool Ray(int x, int y, Eigen::Vector3d* origin_in_table_m, Eigen::Vector3d* direction) const;
  // How the ray of pixel (x, y) changes per pixel step along x and y (first order; the
  // perspective case ignores the change of distortion across one pixel). Used for the
  // pixel's footprint on the surface. `direction` is the (unnormalised) one Ray() returned.
  void RayStep(Eigen::Vector3d* origin_step_x, Eigen::Vector3d* direction_step_x,
               Eigen::Vector3d* origin_step_y, Eigen::Vector3d* direction_step_y) const;

 private:
  bool perspective_ = true;
  int width_px_ = 0, height_px_ = 0;
  CameraModel model_;
  Rigid3d table_from_camera_;
  Eigen::AlignedBox2d area_m_;
  double eye_height_m_ = 10.0;
};

}  // namespace sandtable::sim
