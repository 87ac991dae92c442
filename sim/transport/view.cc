#include "sim/transport/view.h"

#include <cmath>
#include <sstream>
#include <string>

namespace sandtable::sim {

namespace {

std::string SizeText(int64_t width_px, int64_t height_px) {
  return std::to_string(width_px) + "x" + std::to_string(height_px) + " px";
}

Status CheckSize(int64_t width_px, int64_t height_px) {
  if (width_px <= 0 || height_px <= 0) {
    return InvalidArgumentError("view " + SizeText(width_px, height_px) + " has no pixels");
  }
  if (width_px > kMaxViewSide_px || height_px > kMaxViewSide_px) {
    return InvalidArgumentError(
        "view " + SizeText(width_px, height_px) +
        ": a side over kMaxViewSide_px = " + std::to_string(kMaxViewSide_px));
  }
  if (width_px * height_px > kMaxViewPixels) {
    return InvalidArgumentError("view " + SizeText(width_px, height_px) +
                                ": more than kMaxViewPixels = " + std::to_string(kMaxViewPixels));
  }
  return OkStatus();
}

}  // namespace

Status View::Check() const { return CheckSize(width_px_, height_px_); }

Expected<View> View::TopOver(const Eigen::AlignedBox3d& bounds, int width_px, int height_px) {
  if (bounds.isEmpty() || !bounds.min().allFinite() || !bounds.max().allFinite()) {
    return InvalidArgumentError("top view: the scene has no finite extent");
  }
  const Eigen::AlignedBox2d area(bounds.min().head<2>(), bounds.max().head<2>());
  const Eigen::Vector2d size = area.sizes();
  if (!(size.x() > 0) || !(size.y() > 0)) {
    std::ostringstream s;
    s << "top view: the scene's x-y extent " << size.x() << " x " << size.y()
      << " m is flat; a top view needs both sides > 0";
    return InvalidArgumentError(s.str());
  }
  double height = height_px;
  if (height_px <= 0) {
    height = std::max(16.0, std::round(width_px * size.y() / size.x()));  // may be huge
  }
  if (!(height <= static_cast<double>(kMaxViewSide_px))) {
    std::ostringstream s;
    s << "top view: " << width_px << " px wide over the scene's " << size.x() << " x " << size.y()
      << " m needs " << height << " rows, more than kMaxViewSide_px = " << kMaxViewSide_px
      << " (give a height, or a scene less thin)";
    return InvalidArgumentError(s.str());
  }
  const int rows = static_cast<int>(height);
  if (Status valid = CheckSize(width_px, rows); !valid.ok()) {
    return valid.WithContext("top view");
  }
  return OrthographicTop(area, width_px, rows, bounds.max().z() + 10.0);
}

View View::Perspective(const CameraModel& model, const Rigid3d& table_from_camera) {
  View v;
  v.perspective_ = true;
  v.width_px_ = model.width_px;
  v.height_px_ = model.height_px;
  v.model_ = model;
  v.table_from_camera_ = table_from_camera;
  return v;
}

View View::OrthographicTop(const Eigen::AlignedBox2d& area, int width_px, int height_px,
                           double eye_height_m) {
  View v;
  v.perspective_ = false;
  v.width_px_ = width_px;
  v.height_px_ = height_px;
  v.area_m_ = area;
  v.eye_height_m_ = eye_height_m;
  return v;
}

bool View::Ray(int x, int y, Eigen::Vector3d* origin, Eigen::Vector3d* direction) const {
  if (perspective_) {
    Expected<Eigen::Vector3d> ray_in_camera = model_.Unproject(Eigen::Vector2d(x, y));
    if (!ray_in_camera.ok()) return false;
    *origin = table_from_camera_.translation;
    *direction = table_from_camera_.rotation * *ray_in_camera;
    return true;
  }
  const Eigen::Vector2d size = area_m_.sizes();
  *origin =
      Eigen::Vector3d(area_m_.min().x() + (x + 0.5) / width_px_ * size.x(),
                      area_m_.min().y() + (1.0 - (y + 0.5) / height_px_) * size.y(), eye_height_m_);
  *direction = Eigen::Vector3d(0, 0, -1);
  return true;
}

void View::RayStep(Eigen::Vector3d* origin_step_x, Eigen::Vector3d* direction_step_x,
                   Eigen::Vector3d* origin_step_y, Eigen::Vector3d* direction_step_y) const {
  if (perspective_) {
    *origin_step_x = *origin_step_y = Eigen::Vector3d::Zero();
    *direction_step_x = table_from_camera_.rotation * Eigen::Vector3d(1.0 / model_.fx_px, 0, 0);
    *direction_step_y = table_from_camera_.rotation * Eigen::Vector3d(0, 1.0 / model_.fy_px, 0);
    return;
  }
  *direction_step_x = *direction_step_y = Eigen::Vector3d::Zero();
  *origin_step_x = Eigen::Vector3d(area_m_.sizes().x() / width_px_, 0, 0);
  *origin_step_y = Eigen::Vector3d(0, -area_m_.sizes().y() / height_px_, 0);
}

}  // namespace sandtable::sim
