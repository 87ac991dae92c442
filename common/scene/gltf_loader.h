// Loads a glTF 2.0 file (.gltf with external or data-URI buffers, or binary .glb) into a Scene
// in the table frame.
//
// What is read: the default scene's node hierarchy (or, without scenes, every root node), each
// node's matrix or TRS; mesh primitives of mode TRIANGLES, TRIANGLE_STRIP and TRIANGLE_FAN,
// indexed (uint8/16/32) or not; POSITION (float VEC3), TEXCOORD_0 (float or normalized
// uint8/uint16 VEC2); the material's baseColorFactor and baseColorTexture (PNG or JPEG, decoded
// image kept for albedo lookup). Points and lines are skipped (counted in the report). A node
// listed as the child of several nodes is instanced once per path (bounded, see below).
// Frames: glTF is +y up in metres (times `options.scale_m_per_unit`); the result is in the
// table frame, table (x, y, z) = glTF (x, -z, y).
//
// Failure: the input is untrusted. A malformed or hostile file returns PARSE_ERROR (or IO_ERROR
// for a path that is missing, not a regular file or too large) naming the file and the element
// ("Box.gltf: mesh 0 primitive 0: index 37 >= 24 vertices"); the loader never aborts, never
// throws, never recurses on input structure and never allocates more than the limits below
// allow. Checked here, independently of tinygltf: every file is a regular file of bounded size
// (read through our own file callbacks, so an external buffer or image URI naming /dev/zero, a
// FIFO or a directory is refused too); the JSON nesting depth; the .glb header and chunk
// lengths; every accessor -> buffer view -> buffer offset, stride and count in overflow-safe
// 64-bit arithmetic; index values against vertex counts; the node graph (child indices, cycles,
// depth) and the size of the expanded scene, counted BEFORE anything is expanded; coordinates
// (finite, within kMaxCoordinate_m of the origin after the node transforms); image sizes from
// their PNG/JPEG headers before decoding. Exceptions thrown inside tinygltf are caught and
// returned as PARSE_ERROR. docs/reliability.md ("glTF scenes") lists the limits.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

#include "common/base/status.h"
#include "common/scene/scene.h"

namespace sandtable {

// Limits (documented in docs/reliability.md, "glTF scenes"). Past any of them the load is
// refused with a message naming the limit.
// Bytes of one file read: the .gltf/.glb and each external buffer or image.
inline constexpr uint64_t kMaxGltfFileBytes = uint64_t{512} << 20;
// Bytes of all files one load reads together.
inline constexpr uint64_t kMaxGltfTotalBytes = uint64_t{1} << 30;
// Bytes of JSON: a .gltf file (data URIs included) or the JSON chunk of a .glb.
inline constexpr uint64_t kMaxGltfJsonBytes = uint64_t{64} << 20;
// Nesting of JSON arrays and objects (glTF itself needs about 6).
inline constexpr int kMaxGltfJsonDepth = 128;
// Depth of the node hierarchy (a root node has depth 1).
inline constexpr int kMaxNodeDepth = 1000;
// Node instances of the expanded hierarchy (a node reached by k paths counts k times).
inline constexpr uint64_t kMaxInstances = 1'000'000;
// Triangles and vertices of the expanded scene.
inline constexpr uint64_t kMaxSceneTriangles = 20'000'000;
inline constexpr uint64_t kMaxSceneVertices = 30'000'000;
// Every vertex in the table frame (after the node transforms and the scale): |x|, |y|, |z|.
inline constexpr double kMaxCoordinate_m = kMaxSceneCoordinate_m;  // scene.h
// Images, from their PNG/JPEG headers before decoding: each side, one image, all images.
inline constexpr int kMaxTextureSidePx = 16384;
inline constexpr uint64_t kMaxTexturePixels = uint64_t{64} << 20;
inline constexpr uint64_t kMaxSceneTexturePixels = uint64_t{128} << 20;

struct GltfLoadOptions {
  double scale_m_per_unit = 1.0;  // glTF units to metres
  bool load_textures = true;      // keep base colour images (else only factors; none decoded)
  Status Check() const;
};

struct GltfLoadReport {
  int num_primitives_loaded = 0;
  int num_primitives_skipped = 0;  // points, lines, or without POSITION
  uint64_t num_instances = 0;      // expanded node visits
  std::string warnings;            // tinygltf's warnings, if any
};

// Loads the file at `path` (glTF JSON or binary glTF, told apart by the "glTF" magic). External
// buffers and images are read relative to the file's folder, each through the same checks.
Expected<Scene> LoadGltfScene(const std::string& path, const GltfLoadOptions& options = {},
                              GltfLoadReport* report = nullptr);

// Loads a glTF JSON or binary glTF held in memory; `name` is used in messages. Only embedded
// data (data: URIs, the .glb BIN chunk) is read: an external URI is an error, nothing is read
// from the file system. For the fuzzer and for scenes received over the network.
Expected<Scene> LoadGltfSceneFromBytes(std::string_view bytes, const std::string& name,
                                       const GltfLoadOptions& options = {},
                                       GltfLoadReport* report = nullptr);

// The fixed rotation between the frames: x_in_table = kTableFromGltf * x_in_gltf.
Eigen::Matrix3d TableFromGltfRotation();

}  // namespace sandtable
