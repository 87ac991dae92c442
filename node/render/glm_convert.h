// The one place where the renderer's GLM (float) meets the project's Eigen (double): named
// conversions, never inline casts (STYLE.md section 1). The precision lost in the float
// conversion of the projection chain is bounded by tests/common/camera/gl_projection_test.cc.
#pragma once

#include <Eigen/Core>
#include <glm/glm.hpp>

namespace sandtable::node {

// Column-major both: glm::mat4[c][r] = m(r, c).
inline glm::mat4 ToGlm(const Eigen::Matrix4d& m) {
  glm::mat4 out(1.0f);
  for (int c = 0; c < 4; ++c) {
    for (int r = 0; r < 4; ++r) out[c][r] = static_cast<float>(m(r, c));
  }
  return out;
}
inline glm::vec3 ToGlm(const Eigen::Vector3d& v) {
  return glm::vec3(static_cast<float>(v.x()), static_cast<float>(v.y()), static_cast<float>(v.z()));
}
inline glm::vec3 ToGlm(const Eigen::Vector3f& v) { return glm::vec3(v.x(), v.y(), v.z()); }
inline glm::vec4 ToGlm(const Eigen::Vector4d& v) {
  return glm::vec4(static_cast<float>(v.x()), static_cast<float>(v.y()), static_cast<float>(v.z()),
                   static_cast<float>(v.w()));
}
inline Eigen::Vector4d ToEigen(const glm::vec4& v) { return {v.x, v.y, v.z, v.w}; }

}  // namespace sandtable::node
