// Loads a glTF 2.0 file (.gltf with external or data-URI buffers, or binary .glb) into a Scene
// in the table frame.
//
// What is read: the default scene's node hierarchy (or, without scenes, every root node), each
// node's matrix or TRS; mesh primitives of mode TRIANGLES, TRIANGLE_STRIP and TRIANGLE_FAN,
// indexed (uint8/16/32) or not; POSITION (float VEC3), TEXCOORD_0 (float or normalized
// uint8/uint16 VEC2); the material's baseColorFactor and baseColorTexture (decoded image kept
// for albedo lookup). Points and lines are skipped (counted in the report).
// Frames: glTF is +y up in metres (times `options.scale_m_per_unit`); the result is in the
// table frame, table (x, y, z) = glTF (x, -z, y).
// Failure: a malformed file (bad JSON, missing buffer, accessor or buffer view out of range,
// index >= vertex count, non-finite positions, node cycles) returns a PARSE_ERROR or IO_ERROR
// naming the file and the element ("Box.gltf: mesh 0 primitive 0: index 37 >= 24 vertices");
// never aborts. Every accessor is bounds-checked here, independently of tinygltf.
#pragma once

#include <string>

#include "common/base/status.h"
#include "common/scene/scene.h"

namespace sandtable {

struct GltfLoadOptions {
  double scale_m_per_unit = 1.0;  // glTF units to metres
  bool load_textures = true;      // keep base colour images (else only factors)
  Status Check() const;
};

struct GltfLoadReport {
  int num_primitives_loaded = 0;
  int num_primitives_skipped = 0;  // points, lines, or without POSITION
  std::string warnings;            // tinygltf's warnings, if any
};

Expected<Scene> LoadGltfScene(const std::string& path, const GltfLoadOptions& options = {},
                              GltfLoadReport* report = nullptr);

// The fixed rotation between the frames: x_in_table = kTableFromGltf * x_in_gltf.
Eigen::Matrix3d TableFromGltfRotation();

}  // namespace sandtable
