// Building blocks of the procedural scenes (procedural_scene.cc, random_scene.cc): a portable
// random source and a triangle accumulator that winds every face outward.
//
// Rng: uniform doubles from the 53 high bits of std::mt19937_64, whose sequence the standard
// fixes (std::uniform_real_distribution's algorithm is implementation-defined), so a seed gives
// the same scene on every platform.
// MeshBuilder: each triangle is turned to face away from an interior point of its convex piece,
// so the winding is counter-clockwise seen from outside whatever order the corners come in.
// Frames: table frame, metres.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>
#include <utility>

#include <Eigen/Core>

#include "common/scene/scene.h"

namespace sandtable {

class SceneRng {
 public:
  explicit SceneRng(uint64_t seed) : engine_(seed) {}
  // Uniform in [lo, hi).
  double Uniform(double lo, double hi) {
    return lo + (hi - lo) * static_cast<double>(engine_() >> 11) * 0x1.0p-53;
  }
  // Uniform in {0, ..., n - 1}; n >= 1.
  int Index(int n) { return std::min(n - 1, static_cast<int>(Uniform(0.0, n))); }
  bool Chance(double probability) { return Uniform(0.0, 1.0) < probability; }

 private:
  std::mt19937_64 engine_;
};

class MeshBuilder {
 public:
  explicit MeshBuilder(int material) : material_(material) {}

  void Triangle(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
                const Eigen::Vector3d& interior) {
    const Eigen::Vector3d n = (b - a).cross(c - a);
    const bool flip = n.dot((a + b + c) / 3.0 - interior) < 0.0;
    const int base = scene_.NumVertices();
    scene_.positions_in_table_m.push_back(a.cast<float>());
    scene_.positions_in_table_m.push_back((flip ? c : b).cast<float>());
    scene_.positions_in_table_m.push_back((flip ? b : c).cast<float>());
    scene_.triangles.emplace_back(base, base + 1, base + 2);
    scene_.triangle_material.push_back(material_);
  }
  void Quad(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
            const Eigen::Vector3d& d, const Eigen::Vector3d& interior) {
    Triangle(a, b, c, interior);
    Triangle(a, c, d, interior);
  }
  Scene Take() { return std::move(scene_); }

 private:
  int material_;
  Scene scene_;
};

// A point given in a building's local frame (x, y about `centre`, turned by yaw_rad about +z).
inline Eigen::Vector3d Local(const Eigen::Vector2d& centre, double yaw_rad, double x, double y,
                             double z) {
  const double c = std::cos(yaw_rad), s = std::sin(yaw_rad);
  return {centre.x() + c * x - s * y, centre.y() + s * x + c * y, z};
}

// A box in building-local coordinates: x in [x0, x1], y in [y0, y1], z in [z0, z1]; the
// bottom face only when `bottom` (a building standing on the table needs none).
inline void AddLocalBox(MeshBuilder* mesh, const Eigen::Vector2d& centre, double yaw_rad, double x0,
                        double x1, double y0, double y1, double z0, double z1, bool bottom) {
  auto p = [&](double x, double y, double z) { return Local(centre, yaw_rad, x, y, z); };
  const Eigen::Vector3d interior = p(0.5 * (x0 + x1), 0.5 * (y0 + y1), 0.5 * (z0 + z1));
  mesh->Quad(p(x0, y0, z1), p(x1, y0, z1), p(x1, y1, z1), p(x0, y1, z1), interior);  // top
  if (bottom) mesh->Quad(p(x0, y0, z0), p(x1, y0, z0), p(x1, y1, z0), p(x0, y1, z0), interior);
  mesh->Quad(p(x0, y0, z0), p(x1, y0, z0), p(x1, y0, z1), p(x0, y0, z1), interior);  // -y
  mesh->Quad(p(x0, y1, z0), p(x1, y1, z0), p(x1, y1, z1), p(x0, y1, z1), interior);  // +y
  mesh->Quad(p(x0, y0, z0), p(x0, y1, z0), p(x0, y1, z1), p(x0, y0, z1), interior);  // -x
  mesh->Quad(p(x1, y0, z0), p(x1, y1, z0), p(x1, y1, z1), p(x1, y0, z1), interior);  // +x
}

}  // namespace sandtable
