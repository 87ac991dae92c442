// Scene: triangle meshes in the table frame, with the albedo the world's light transport uses.
//
// Frame: table frame (origin on the table surface, +z up, metres). The glTF loader converts
// from glTF's +y-up frame with table (x, y, z) = glTF (x, -z, y).
// Albedo: linear RGB in [0, 1] = base colour factor (linear) x base colour texture (sRGB-encoded
// 8-bit, decoded to linear here), as glTF 2.0 defines baseColor. The world is monochrome: its
// light transport uses AlbedoAt(), the Rec. 709 luminance of that RGB albedo.
// Triangles are stored unshared per primitive (the loader does not merge vertices), so vertex
// counts equal the sum of the primitives' POSITION counts.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "common/geometry/rigid3.h"

namespace sandtable {

// The range of every vertex a scene may hold, table frame: finite and |x|, |y|, |z| <= this
// (10 km; Embree's float BVH asserts on coordinates near 1e19). The glTF loader refuses vertices
// outside it while loading, the ray caster refuses a scene holding one before building.
inline constexpr double kMaxSceneCoordinate_m = 1e4;

// An 8-bit RGBA image (sRGB-encoded colour, linear alpha), row-major, top row first.
struct Texture {
  int width_px = 0;
  int height_px = 0;
  std::vector<uint8_t> rgba;  // width_px * height_px * 4
  bool repeat_s = true;       // glTF sampler wrapS == REPEAT (else clamp to edge)
  bool repeat_t = true;
};

struct Material {
  std::string name;
  Eigen::Vector4d base_color_factor{1.0, 1.0, 1.0, 1.0};  // linear RGBA
  int base_color_texture = -1;                            // index into Scene::textures or -1
};

struct Scene {
  std::vector<Eigen::Vector3f> positions_in_table_m;
  // Empty, or one TEXCOORD_0 per vertex (glTF convention: (0, 0) is the image's top-left).
  std::vector<Eigen::Vector2f> texcoords;
  std::vector<Eigen::Vector3i> triangles;  // vertex indices, counter-clockwise = front
  std::vector<int> triangle_material;      // one per triangle, index into materials
  std::vector<Material> materials;
  std::vector<Texture> textures;

  int NumVertices() const { return static_cast<int>(positions_in_table_m.size()); }
  int NumTriangles() const { return static_cast<int>(triangles.size()); }

  // Axis-aligned bounds of all vertices (empty box for an empty scene).
  Eigen::AlignedBox3d Bounds() const;

  // Unit geometric normal of a triangle from its counter-clockwise winding (zero vector for a
  // degenerate triangle).
  Eigen::Vector3d FaceNormal(int triangle) const;

  // Linear RGB albedo at barycentric (u, v) of a triangle (point = (1-u-v) p0 + u p1 + v p2,
  // Embree's convention). Bilinear texture lookup with the sampler's wrap mode.
  Eigen::Vector3d AlbedoRgbAt(int triangle, double u, double v) const;
  // Rec. 709 luminance of AlbedoRgbAt, in [0, 1].
  double AlbedoAt(int triangle, double u, double v) const;

  // Appends `other`. Vertex indices are shifted; material ids are shifted past this scene's
  // materials when `other` carries materials of its own, else kept (they then refer to this
  // scene's materials, as for the procedural building blocks).
  void Append(const Scene& other);
};

// The scene moved rigidly: every vertex x becomes target_from_scene * x (a rigid map keeps the
// windings, so normals follow). For a model placed on the table: MovedScene(model,
// table_from_model).
Scene MovedScene(const Scene& scene, const Rigid3d& target_from_scene);

// The plane of each triangle, as an id shared by every triangle of the scene lying in the same
// plane (the same unit normal within ~2e-4 and offset along it within ~20 um), connected or
// not: two buildings' walls in one plane, or two coincident faces (a wall where two boxes
// touch) are one. The id is the smallest index of a triangle in that plane, so the same model
// gives the same ids wherever it is loaded; -1 for a degenerate triangle. Computed on the model
// in its own frame (not as placed), every node of a site finds the same planes.
std::vector<int> PlanarFaces(const Scene& scene);

// sRGB transfer function, 8-bit code -> linear [0, 1].
double SrgbToLinear(double encoded);
double LinearToSrgb(double linear);

}  // namespace sandtable
