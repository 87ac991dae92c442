// The model's upload (Renderer::UploadGeometry): vertices grouped by material, flat normals, and
// for a folded pre-warp tessellated so that the lens bends no edge.
#include <array>
#include <cstddef>
#include <optional>
#include <vector>

#define GL_GLEXT_PROTOTYPES 1
#include <GL/glcorearb.h>

#include "node/devices/gl_util.h"
#include "node/render/renderer.h"
#include "node/render/renderer_internal.h"

namespace sandtable::node {
namespace {

struct SceneVertex {
  float position[3];
  float normal[3];
  float uv[2];
};

}  // namespace

// The model into the vertex buffer, grouped by material (one draw call each), flat normals.
// With edge_px > 0, every triangle in front of the projector is split at the midpoint of its
// longest edge until no edge spans more than edge_px on the projector's (pinhole) image: the
// folded pre-warp bends edges only at vertices.
Status Renderer::UploadGeometry(unsigned int vao, unsigned int vbo, double edge_px,
                                std::vector<Group>* groups, std::vector<float>* face_normals) {
  const bool tessellate = edge_px > 0.0;
  const Scene& scene = scene_;
  std::vector<std::vector<int>> by_material(std::max<size_t>(scene.materials.size(), 1));
  for (int t = 0; t < scene.NumTriangles(); ++t) {
    int m = t < static_cast<int>(scene.triangle_material.size()) ? scene.triangle_material[t] : 0;
    if (m < 0 || m >= static_cast<int>(by_material.size())) m = 0;
    by_material[m].push_back(t);
  }
  const bool has_uv = scene.texcoords.size() == scene.positions_in_table_m.size();
  const double max_edge2 = edge_px * edge_px;
  const Eigen::Matrix3d rotation = view_.projector_from_table.rotation.toRotationMatrix();
  const Eigen::Vector3d translation = view_.projector_from_table.translation;
  const double fx = view_.projector.fx_px, fy = view_.projector.fy_px;
  // The pinhole pixel of a vertex; nullopt at or behind the near plane.
  auto pixel = [&](const SceneVertex& v) -> std::optional<Eigen::Vector2d> {
    const Eigen::Vector3d c =
        rotation * Eigen::Vector3d(v.position[0], v.position[1], v.position[2]) + translation;
    if (c.z() <= view_.near_m) return std::nullopt;
    return Eigen::Vector2d(fx * c.x() / c.z() + view_.projector.cx_px,
                           fy * c.y() / c.z() + view_.projector.cy_px);
  };
  // Bounds the work a degenerate request could cause: at most this many triangles.
  constexpr size_t kMaxTessellatedTriangles = 4'000'000;
  std::vector<SceneVertex> vertices;
  vertices.reserve(static_cast<size_t>(scene.NumTriangles()) * 3);
  groups->clear();
  std::vector<std::array<SceneVertex, 3>> stack;
  for (size_t m = 0; m < by_material.size(); ++m) {
    if (by_material[m].empty()) continue;
    Group group;
    group.first_vertex = static_cast<int>(vertices.size());
    group.material = static_cast<int>(m);
    for (int t : by_material[m]) {
      const Eigen::Vector3d n = scene.FaceNormal(t);
      std::array<SceneVertex, 3> tri{};
      for (int k = 0; k < 3; ++k) {
        const int v = scene.triangles[t][k];
        const Eigen::Vector3f& p = scene.positions_in_table_m[v];
        for (int i = 0; i < 3; ++i) {
          tri[k].position[i] = p[i];
          tri[k].normal[i] = static_cast<float>(n[i]);
        }
        if (has_uv) {
          tri[k].uv[0] = scene.texcoords[v].x();
          tri[k].uv[1] = scene.texcoords[v].y();
        }
        group.bounds.extend(p.cast<double>());
      }
      stack.push_back(tri);
      while (!stack.empty()) {
        const std::array<SceneVertex, 3> a = stack.back();
        stack.pop_back();
        int longest = -1;
        double longest2 = max_edge2;
        if (tessellate && vertices.size() / 3 + stack.size() < kMaxTessellatedTriangles) {
          const std::optional<Eigen::Vector2d> px[3] = {pixel(a[0]), pixel(a[1]), pixel(a[2])};
          // Off the image (all three corners beyond one of its sides, with a margin of one
          // edge): nothing of it is seen, it is left whole.
          bool off_image = !(px[0] && px[1] && px[2]);
          for (int axis = 0; axis < 2 && !off_image; ++axis) {
            const double size = axis == 0 ? size_.width : size_.height;
            const double lo = -edge_px, hi = size + edge_px;
            off_image = ((*px[0])[axis] < lo && (*px[1])[axis] < lo && (*px[2])[axis] < lo) ||
                        ((*px[0])[axis] > hi && (*px[1])[axis] > hi && (*px[2])[axis] > hi);
          }
          for (int e = 0; e < 3 && !off_image; ++e) {
            const double d2 = (*px[e] - *px[(e + 1) % 3]).squaredNorm();
            if (d2 > longest2) {
              longest2 = d2;
              longest = e;
            }
          }
        }
        if (longest < 0) {
          vertices.insert(vertices.end(), a.begin(), a.end());
          continue;
        }
        // Split edge (longest, longest + 1) at its midpoint.
        const int i0 = longest, i1 = (longest + 1) % 3, i2 = (longest + 2) % 3;
        SceneVertex mid = a[i0];
        for (int i = 0; i < 3; ++i)
          mid.position[i] = 0.5f * (a[i0].position[i] + a[i1].position[i]);
        for (int i = 0; i < 2; ++i) mid.uv[i] = 0.5f * (a[i0].uv[i] + a[i1].uv[i]);
        stack.push_back({a[i0], mid, a[i2]});
        stack.push_back({mid, a[i1], a[i2]});
      }
    }
    group.vertex_count = static_cast<int>(vertices.size()) - group.first_vertex;
    groups->push_back(group);
  }
  if (face_normals) {
    face_normals->clear();
    for (size_t v = 0; v + 2 < vertices.size(); v += 3) {
      face_normals->insert(face_normals->end(), vertices[v].normal, vertices[v].normal + 3);
    }
  }
  glBindVertexArray(vao);
  glBindBuffer(GL_ARRAY_BUFFER, vbo);
  glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(vertices.size() * sizeof(SceneVertex)),
               vertices.data(), GL_STATIC_DRAW);
  glEnableVertexAttribArray(0);
  glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, sizeof(SceneVertex),
                        reinterpret_cast<void*>(offsetof(SceneVertex, position)));
  glEnableVertexAttribArray(1);
  glVertexAttribPointer(1, 3, GL_FLOAT, GL_FALSE, sizeof(SceneVertex),
                        reinterpret_cast<void*>(offsetof(SceneVertex, normal)));
  glEnableVertexAttribArray(2);
  glVertexAttribPointer(2, 2, GL_FLOAT, GL_FALSE, sizeof(SceneVertex),
                        reinterpret_cast<void*>(offsetof(SceneVertex, uv)));
  glBindVertexArray(0);
  return CheckGl("uploading the model");
}

}  // namespace sandtable::node
