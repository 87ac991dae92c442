#include "common/camera/gl_projection.h"

#include <cmath>
#include <sstream>

namespace sandtable {

Eigen::Matrix4d GlEyeFromCamera() { return Eigen::Vector4d(1.0, -1.0, -1.0, 1.0).asDiagonal(); }

Eigen::Matrix4d GlEyeFromTable(const Rigid3d& camera_from_table) {
  return GlEyeFromCamera() * camera_from_table.ToMatrix4();
}

Expected<Eigen::Matrix4d> GlProjectionFromCamera(const CameraModel& camera, double near_m,
                                                 double far_m) {
  Status camera_status = camera.Check();
  if (!camera_status.ok()) return camera_status.WithContext("GL projection");
  if (!std::isfinite(near_m) || !(near_m > 0.0)) {
    std::ostringstream s;
    s << "GL projection: near_m = " << near_m << " must be finite and > 0";
    return InvalidArgumentError(s.str());
  }
  if (!std::isfinite(far_m) || !(far_m > near_m)) {
    std::ostringstream s;
    s << "GL projection: far_m = " << far_m << " must be finite and > near_m = " << near_m;
    return InvalidArgumentError(s.str());
  }
  const double w = camera.width_px, h = camera.height_px;
  // Derivation. A point in the camera frame (x, y, z), z > 0, is at pixel
  //   u = fx x / z + cx,  v = fy y / z + cy      (CameraModel, zero distortion).
  // We want w_clip = z (so the perspective divide is the division by z), i.e. w_clip = -z_eye
  // with (x_eye, y_eye, z_eye) = (x, -y, -z), and x_clip / w_clip = x_ndc, where
  //   x_ndc = 2 (u + 0.5) / W - 1,  y_ndc = 1 - 2 (v + 0.5) / H   (header: viewport mapping).
  // Multiplying by z:
  //   x_clip = (2 fx / W) x + (2 (cx + 0.5) / W - 1) z
  //          = (2 fx / W) x_eye + (1 - 2 (cx + 0.5) / W) z_eye
  //   y_clip = z - (2 fy / H) y - (2 (cy + 0.5) / H) z
  //          = (2 fy / H) y_eye + (2 (cy + 0.5) / H - 1) z_eye
  // Depth row: the usual glFrustum one, z_ndc(-near) = -1, z_ndc(-far) = +1.
  Eigen::Matrix4d p = Eigen::Matrix4d::Zero();
  p(0, 0) = 2.0 * camera.fx_px / w;
  p(0, 2) = 1.0 - 2.0 * (camera.cx_px + 0.5) / w;
  p(1, 1) = 2.0 * camera.fy_px / h;
  p(1, 2) = 2.0 * (camera.cy_px + 0.5) / h - 1.0;
  p(2, 2) = -(far_m + near_m) / (far_m - near_m);
  p(2, 3) = -2.0 * far_m * near_m / (far_m - near_m);
  p(3, 2) = -1.0;
  return p;
}

Eigen::Vector2d PixelFromNdc(const Eigen::Vector2d& ndc, int width_px, int height_px) {
  return {(ndc.x() + 1.0) * 0.5 * width_px - 0.5, (1.0 - ndc.y()) * 0.5 * height_px - 0.5};
}

Eigen::Vector2d NdcFromPixel(const Eigen::Vector2d& pixel, int width_px, int height_px) {
  return {2.0 * (pixel.x() + 0.5) / width_px - 1.0, 1.0 - 2.0 * (pixel.y() + 0.5) / height_px};
}

}  // namespace sandtable
