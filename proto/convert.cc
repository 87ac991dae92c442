#include "proto/convert.h"

#include <cmath>
#include <limits>
#include <string>

namespace sandtable::proto {

wire::Vector3 ToWire(const Eigen::Vector3d& v) {
  wire::Vector3 out;
  out.set_x(v.x());
  out.set_y(v.y());
  out.set_z(v.z());
  return out;
}

Expected<Eigen::Vector3d> FromWire(const wire::Vector3& v) {
  const Eigen::Vector3d out(v.x(), v.y(), v.z());
  if (!out.allFinite()) return InvalidArgumentError("Vector3 has a non-finite component");
  return out;
}

wire::Vector2 ToWire(const Eigen::Vector2d& v) {
  wire::Vector2 out;
  out.set_x(v.x());
  out.set_y(v.y());
  return out;
}

Expected<Eigen::Vector2d> FromWire(const wire::Vector2& v) {
  const Eigen::Vector2d out(v.x(), v.y());
  if (!out.allFinite()) return InvalidArgumentError("Vector2 has a non-finite component");
  return out;
}

wire::Rigid3 ToWire(const Rigid3d& target_from_source) {
  wire::Rigid3 out;
  const Eigen::Quaterniond& q = target_from_source.rotation;
  out.mutable_rotation()->set_w(q.w());
  out.mutable_rotation()->set_x(q.x());
  out.mutable_rotation()->set_y(q.y());
  out.mutable_rotation()->set_z(q.z());
  *out.mutable_translation_m() = ToWire(target_from_source.translation);
  return out;
}

Expected<Rigid3d> FromWire(const wire::Rigid3& target_from_source) {
  if (!target_from_source.has_rotation()) {
    return InvalidArgumentError("Rigid3 without rotation (required; identity is w = 1)");
  }
  const wire::Quaternion& r = target_from_source.rotation();
  const Eigen::Quaterniond q(r.w(), r.x(), r.y(), r.z());
  if (!q.coeffs().allFinite()) {
    return InvalidArgumentError("Rigid3 rotation has a non-finite component");
  }
  const double norm = q.norm();
  if (std::abs(norm - 1.0) > kQuaternionNormTolerance) {
    return InvalidArgumentError("Rigid3 rotation quaternion has norm " + std::to_string(norm) +
                                ", must be 1 (within " + std::to_string(kQuaternionNormTolerance) +
                                ")");
  }
  Expected<Eigen::Vector3d> t = FromWire(target_from_source.translation_m());
  if (!t.ok()) return t.status().WithContext("Rigid3 translation_m");
  return Rigid3d(q, *t);
}

wire::CameraModel ToWire(const CameraModel& model) {
  wire::CameraModel out;
  out.set_width_px(static_cast<uint32_t>(model.width_px));
  out.set_height_px(static_cast<uint32_t>(model.height_px));
  out.set_fx_px(model.fx_px);
  out.set_fy_px(model.fy_px);
  out.set_cx_px(model.cx_px);
  out.set_cy_px(model.cy_px);
  out.set_k1(model.distortion.k1);
  out.set_k2(model.distortion.k2);
  out.set_p1(model.distortion.p1);
  out.set_p2(model.distortion.p2);
  out.set_k3(model.distortion.k3);
  return out;
}

Expected<CameraModel> FromWire(const wire::CameraModel& model) {
  constexpr uint32_t kMaxSide_px = static_cast<uint32_t>(std::numeric_limits<int>::max());
  if (model.width_px() > kMaxSide_px || model.height_px() > kMaxSide_px) {
    return InvalidArgumentError("CameraModel size " + std::to_string(model.width_px()) + "x" +
                                std::to_string(model.height_px()) + " px is out of range");
  }
  BrownDistortion distortion;
  distortion.k1 = model.k1();
  distortion.k2 = model.k2();
  distortion.p1 = model.p1();
  distortion.p2 = model.p2();
  distortion.k3 = model.k3();
  CameraModel out(static_cast<int>(model.width_px()), static_cast<int>(model.height_px()),
                  model.fx_px(), model.fy_px(), model.cx_px(), model.cy_px(), distortion);
  ST_RETURN_IF_ERROR(out.Check().WithContext("CameraModel"));
  return out;
}

}  // namespace sandtable::proto
