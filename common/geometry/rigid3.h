// Rigid3d: a rigid transform between two frames, x_in_b = R * x_in_a + t.
//
// Naming: every instance is called target_from_source (`table_from_projector`,
// `camera_from_table`); it maps x_in_source to x_in_target. Products cancel inner names:
//   projector_from_table = projector_from_camera * camera_from_table;
// A product whose inner names do not cancel is a bug. Double precision (Eigen); the renderer
// converts to float through the named functions of node/render, never inline.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace sandtable {

struct Rigid3d {
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();  // unit quaternion
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();         // in the target frame's unit

  Rigid3d() = default;
  Rigid3d(const Eigen::Quaterniond& rotation_in, const Eigen::Vector3d& translation_in)
      : rotation(rotation_in.normalized()), translation(translation_in) {}
  Rigid3d(const Eigen::Matrix3d& rotation_matrix, const Eigen::Vector3d& translation_in)
      : rotation(Eigen::Quaterniond(rotation_matrix).normalized()), translation(translation_in) {}

  static Rigid3d Identity() { return Rigid3d(); }
  // From a 3x4 [R | t] (R must be a rotation; it is re-orthonormalised through the quaternion).
  static Rigid3d FromMatrix3x4(const Eigen::Matrix<double, 3, 4>& target_from_source);

  Eigen::Matrix3d RotationMatrix() const { return rotation.toRotationMatrix(); }
  Eigen::Matrix<double, 3, 4> ToMatrix3x4() const;
  Eigen::Matrix4d ToMatrix4() const;

  // source_from_target.
  Rigid3d Inverse() const;

  // Centre of the source frame's origin expressed in the target frame is `translation`; the
  // origin of the target frame in the source frame (e.g. a camera centre in the table frame
  // from camera_from_table) is Inverse().translation.

  bool AllFinite() const { return rotation.coeffs().allFinite() && translation.allFinite(); }
};

// x_in_target = target_from_source * x_in_source.
inline Eigen::Vector3d operator*(const Rigid3d& b_from_a, const Eigen::Vector3d& x_in_a) {
  return b_from_a.rotation * x_in_a + b_from_a.translation;
}

// c_from_a = c_from_b * b_from_a.
inline Rigid3d operator*(const Rigid3d& c_from_b, const Rigid3d& b_from_a) {
  return Rigid3d(c_from_b.rotation * b_from_a.rotation,
                 c_from_b.rotation * b_from_a.translation + c_from_b.translation);
}

// Angle of the relative rotation between two transforms, in radians, in [0, pi].
double RotationAngleBetween_rad(const Rigid3d& a, const Rigid3d& b);

}  // namespace sandtable
