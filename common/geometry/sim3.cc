#include "common/geometry/sim3.h"

#include "common/base/check.h"

namespace sandtable {

Eigen::Matrix4d Sim3d::ToMatrix4() const {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.topLeftCorner<3, 3>() = scale * rotation.toRotationMatrix();
  m.topRightCorner<3, 1>() = translation;
  return m;
}

Sim3d Sim3d::Inverse() const {
  ST_CHECK(scale > 0.0) << "Sim3d with non-positive scale " << scale;
  const Eigen::Quaterniond inverse_rotation = rotation.conjugate();
  const double inverse_scale = 1.0 / scale;
  return Sim3d(inverse_scale, inverse_rotation, -inverse_scale * (inverse_rotation * translation));
}

}  // namespace sandtable
