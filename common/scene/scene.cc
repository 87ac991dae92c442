#include "common/scene/scene.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <numeric>
#include <unordered_map>

namespace sandtable {

double SrgbToLinear(double encoded) {
  return encoded <= 0.04045 ? encoded / 12.92 : std::pow((encoded + 0.055) / 1.055, 2.4);
}

double LinearToSrgb(double linear) {
  return linear <= 0.0031308 ? linear * 12.92 : 1.055 * std::pow(linear, 1.0 / 2.4) - 0.055;
}

Eigen::AlignedBox3d Scene::Bounds() const {
  Eigen::AlignedBox3d box;
  for (const Eigen::Vector3f& p : positions_in_table_m) box.extend(p.cast<double>());
  return box;
}

Eigen::Vector3d Scene::FaceNormal(int triangle) const {
  const Eigen::Vector3i& t = triangles[triangle];
  const Eigen::Vector3d p0 = positions_in_table_m[t[0]].cast<double>();
  const Eigen::Vector3d p1 = positions_in_table_m[t[1]].cast<double>();
  const Eigen::Vector3d p2 = positions_in_table_m[t[2]].cast<double>();
  const Eigen::Vector3d n = (p1 - p0).cross(p2 - p0);
  const double norm = n.norm();
  return norm > 0.0 ? Eigen::Vector3d(n / norm) : Eigen::Vector3d::Zero();
}

std::vector<int> PlanarFaces(const Scene& scene) {
  // Planes quantized to a grid (normal 1e-4, offset 1e-5 m); a plane near a cell's boundary
  // may fall in the next cell, so each triangle is joined with any plane already seen in the 81
  // cells around its own (union-find over triangles).
  constexpr double kNormalStep = 1e-4, kOffsetStep_m = 1e-5;
  using Key = std::array<int64_t, 4>;
  struct KeyHash {
    size_t operator()(const Key& k) const {
      size_t h = 0;
      for (int64_t v : k) h = h * 1000003u ^ std::hash<int64_t>()(v);
      return h;
    }
  };
  const int n = scene.NumTriangles();
  std::vector<int> parent(n);
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&parent](int i) {
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return i;
  };
  std::unordered_map<Key, int, KeyHash> cell;
  std::vector<bool> degenerate(n, false);
  for (int t = 0; t < n; ++t) {
    const Eigen::Vector3d normal = scene.FaceNormal(t);
    if (normal.squaredNorm() == 0) {
      degenerate[t] = true;
      continue;
    }
    const double offset =
        normal.dot(scene.positions_in_table_m[scene.triangles[t][0]].cast<double>());
    const Key key = {std::llround(normal.x() / kNormalStep), std::llround(normal.y() / kNormalStep),
                     std::llround(normal.z() / kNormalStep), std::llround(offset / kOffsetStep_m)};
    for (int k = 0; k < 81; ++k) {
      Key near = key;
      for (int j = 0, r = k; j < 4; ++j, r /= 3) near[j] += r % 3 - 1;
      auto it = cell.find(near);
      if (it == cell.end()) continue;
      const int a = find(it->second), b = find(t);
      if (a != b) parent[std::max(a, b)] = std::min(a, b);
    }
    cell.emplace(key, t);
  }
  // A root is the smallest triangle of its plane (a union keeps the smaller root).
  std::vector<int> face(n, -1);
  for (int t = 0; t < n; ++t) {
    if (!degenerate[t]) face[t] = find(t);
  }
  return face;
}

namespace {

// Texel coordinate after wrapping: REPEAT folds into [0, size), CLAMP_TO_EDGE clamps.
int Wrap(int i, int size, bool repeat) {
  if (repeat) {
    const int m = i % size;
    return m < 0 ? m + size : m;
  }
  return std::clamp(i, 0, size - 1);
}

Eigen::Vector3d TexelLinear(const Texture& tex, int x, int y) {
  const uint8_t* p = &tex.rgba[(static_cast<size_t>(y) * tex.width_px + x) * 4];
  return {SrgbToLinear(p[0] / 255.0), SrgbToLinear(p[1] / 255.0), SrgbToLinear(p[2] / 255.0)};
}

}  // namespace

Eigen::Vector3d Scene::AlbedoRgbAt(int triangle, double u, double v) const {
  const int material_index = triangle_material.empty() ? -1 : triangle_material[triangle];
  if (material_index < 0 || material_index >= static_cast<int>(materials.size())) {
    return Eigen::Vector3d::Ones();  // glTF default material: white
  }
  const Material& material = materials[material_index];
  Eigen::Vector3d albedo = material.base_color_factor.head<3>();
  if (material.base_color_texture >= 0 && !texcoords.empty()) {
    const Texture& tex = textures[material.base_color_texture];
    if (tex.width_px > 0 && tex.height_px > 0) {
      const Eigen::Vector3i& t = triangles[triangle];
      const Eigen::Vector2d uv = (1.0 - u - v) * texcoords[t[0]].cast<double>() +
                                 u * texcoords[t[1]].cast<double>() +
                                 v * texcoords[t[2]].cast<double>();
      // Texel centres at (i + 0.5) / size, as in OpenGL sampling.
      const double x = uv.x() * tex.width_px - 0.5;
      const double y = uv.y() * tex.height_px - 0.5;
      if (std::isfinite(x) && std::isfinite(y) && std::abs(x) < 1e9 && std::abs(y) < 1e9) {
        const double x0f = std::floor(x), y0f = std::floor(y);
        const double ax = x - x0f, ay = y - y0f;
        const int x0 = static_cast<int>(x0f), y0 = static_cast<int>(y0f);
        const int xa = Wrap(x0, tex.width_px, tex.repeat_s);
        const int xb = Wrap(x0 + 1, tex.width_px, tex.repeat_s);
        const int ya = Wrap(y0, tex.height_px, tex.repeat_t);
        const int yb = Wrap(y0 + 1, tex.height_px, tex.repeat_t);
        const Eigen::Vector3d texel =
            (1 - ay) * ((1 - ax) * TexelLinear(tex, xa, ya) + ax * TexelLinear(tex, xb, ya)) +
            ay * ((1 - ax) * TexelLinear(tex, xa, yb) + ax * TexelLinear(tex, xb, yb));
        albedo = albedo.cwiseProduct(texel);
      }
    }
  }
  return albedo.cwiseMax(0.0).cwiseMin(1.0);
}

double Scene::AlbedoAt(int triangle, double u, double v) const {
  const Eigen::Vector3d rgb = AlbedoRgbAt(triangle, u, v);
  return 0.2126 * rgb.x() + 0.7152 * rgb.y() + 0.0722 * rgb.z();
}

void Scene::Append(const Scene& other) {
  const int vertex_offset = NumVertices();
  const int material_offset = other.materials.empty() ? 0 : static_cast<int>(materials.size());
  const int texture_offset = static_cast<int>(textures.size());
  if (!other.texcoords.empty() || !texcoords.empty()) {
    texcoords.resize(positions_in_table_m.size(), Eigen::Vector2f::Zero());
  }
  positions_in_table_m.insert(positions_in_table_m.end(), other.positions_in_table_m.begin(),
                              other.positions_in_table_m.end());
  if (!texcoords.empty()) {
    if (other.texcoords.empty()) {
      texcoords.resize(positions_in_table_m.size(), Eigen::Vector2f::Zero());
    } else {
      texcoords.insert(texcoords.end(), other.texcoords.begin(), other.texcoords.end());
    }
  }
  for (const Eigen::Vector3i& t : other.triangles) {
    triangles.push_back(t + Eigen::Vector3i::Constant(vertex_offset));
  }
  for (int m : other.triangle_material)
    triangle_material.push_back(m < 0 ? m : m + material_offset);
  for (Material m : other.materials) {
    if (m.base_color_texture >= 0) m.base_color_texture += texture_offset;
    materials.push_back(m);
  }
  textures.insert(textures.end(), other.textures.begin(), other.textures.end());
}

Scene MovedScene(const Scene& scene, const Rigid3d& target_from_scene) {
  Scene moved = scene;
  for (Eigen::Vector3f& v : moved.positions_in_table_m) {
    v = (target_from_scene * v.cast<double>()).cast<float>();
  }
  return moved;
}

}  // namespace sandtable
