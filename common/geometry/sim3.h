// Sim3d: a similarity transform between two frames, x_in_b = s * R * x_in_a + t.
// Named target_from_source like Rigid3d. Used where a frame's scale is unknown (a tracker in
// unknown units, a reconstruction up to scale).
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "common/geometry/rigid3.h"

namespace sandtable {

struct Sim3d {
  double scale = 1.0;  // > 0, dimensionless (target unit per source unit)
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();

  Sim3d() = default;
  Sim3d(double scale_in, const Eigen::Quaterniond& rotation_in,
        const Eigen::Vector3d& translation_in)
      : scale(scale_in), rotation(rotation_in.normalized()), translation(translation_in) {}
  explicit Sim3d(const Rigid3d& rigid)
      : scale(1.0), rotation(rigid.rotation), translation(rigid.translation) {}

  static Sim3d Identity() { return Sim3d(); }
  Eigen::Matrix4d ToMatrix4() const;
  Sim3d Inverse() const;
  // The rigid part (scale dropped).
  Rigid3d ToRigid() const { return Rigid3d(rotation, translation); }
};

inline Eigen::Vector3d operator*(const Sim3d& b_from_a, const Eigen::Vector3d& x_in_a) {
  return b_from_a.scale * (b_from_a.rotation * x_in_a) + b_from_a.translation;
}

inline Sim3d operator*(const Sim3d& c_from_b, const Sim3d& b_from_a) {
  return Sim3d(c_from_b.scale * b_from_a.scale, c_from_b.rotation * b_from_a.rotation,
               c_from_b.scale * (c_from_b.rotation * b_from_a.translation) + c_from_b.translation);
}

}  // namespace sandtable
