#include "common/geometry/rigid3.h"

#include <algorithm>
#include <cmath>

namespace sandtable {

Rigid3d Rigid3d::FromMatrix3x4(const Eigen::Matrix<double, 3, 4>& target_from_source) {
  return Rigid3d(Eigen::Matrix3d(target_from_source.leftCols<3>()),
                 Eigen::Vector3d(target_from_source.col(3)));
}

Eigen::Matrix<double, 3, 4> Rigid3d::ToMatrix3x4() const {
  Eigen::Matrix<double, 3, 4> m;
  m.leftCols<3>() = RotationMatrix();
  m.col(3) = translation;
  return m;
}

Eigen::Matrix4d Rigid3d::ToMatrix4() const {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.topRows<3>() = ToMatrix3x4();
  return m;
}

Rigid3d Rigid3d::Inverse() const {
  const Eigen::Quaterniond inverse_rotation = rotation.conjugate();
  return Rigid3d(inverse_rotation, -(inverse_rotation * translation));
}

double RotationAngleBetween_rad(const Rigid3d& a, const Rigid3d& b) {
  // |w| of the relative quaternion is cos(angle / 2); the abs handles the q / -q double cover.
  const double w = std::abs((a.rotation.conjugate() * b.rotation).normalized().w());
  return 2.0 * std::acos(std::clamp(w, 0.0, 1.0));
}

}  // namespace sandtable
