#include "common/scene/gltf_writer.h"

#include <cstring>
#include <limits>
#include <sstream>

#include <tiny_gltf.h>

#include "common/base/file_io.h"
#include "common/scene/gltf_loader.h"

namespace sandtable {

namespace {

template <typename T>
void AppendBytes(std::vector<unsigned char>* buffer, const T& value) {
  const size_t at = buffer->size();
  buffer->resize(at + sizeof(T));
  std::memcpy(buffer->data() + at, &value, sizeof(T));
}

}  // namespace

Status WriteGltfScene(const Scene& scene, const std::string& path) {
  tinygltf::Model model;
  model.asset.version = "2.0";
  model.asset.generator = "sandtable-world";
  tinygltf::Buffer buffer;

  // Positions, converted to glTF's frame, with the min/max the spec requires.
  const Eigen::Matrix3d gltf_from_table = TableFromGltfRotation().transpose();
  Eigen::Vector3f min_p = Eigen::Vector3f::Constant(std::numeric_limits<float>::max());
  Eigen::Vector3f max_p = -min_p;
  for (const Eigen::Vector3f& p : scene.positions_in_table_m) {
    const Eigen::Vector3f q = (gltf_from_table * p.cast<double>()).cast<float>();
    for (int k = 0; k < 3; ++k) AppendBytes(&buffer.data, q[k]);
    min_p = min_p.cwiseMin(q);
    max_p = max_p.cwiseMax(q);
  }
  tinygltf::BufferView positions_view;
  positions_view.buffer = 0;
  positions_view.byteOffset = 0;
  positions_view.byteLength = buffer.data.size();
  positions_view.target = TINYGLTF_TARGET_ARRAY_BUFFER;
  model.bufferViews.push_back(positions_view);
  tinygltf::Accessor positions;
  positions.bufferView = 0;
  positions.componentType = TINYGLTF_COMPONENT_TYPE_FLOAT;
  positions.type = TINYGLTF_TYPE_VEC3;
  positions.count = scene.positions_in_table_m.size();
  positions.minValues = {min_p.x(), min_p.y(), min_p.z()};
  positions.maxValues = {max_p.x(), max_p.y(), max_p.z()};
  model.accessors.push_back(positions);

  for (const Material& m : scene.materials) {
    tinygltf::Material out;
    out.name = m.name;
    out.pbrMetallicRoughness.baseColorFactor = {m.base_color_factor[0], m.base_color_factor[1],
                                                m.base_color_factor[2], m.base_color_factor[3]};
    out.pbrMetallicRoughness.metallicFactor = 0.0;
    out.pbrMetallicRoughness.roughnessFactor = 1.0;
    out.doubleSided = false;
    model.materials.push_back(out);
  }

  // One primitive per material id (-1 = default material).
  tinygltf::Mesh mesh;
  std::vector<int> material_ids;
  for (int m : scene.triangle_material) {
    if (std::find(material_ids.begin(), material_ids.end(), m) == material_ids.end()) {
      material_ids.push_back(m);
    }
  }
  if (scene.triangle_material.empty() && !scene.triangles.empty()) material_ids.push_back(-1);
  for (int material : material_ids) {
    const size_t offset = buffer.data.size();
    size_t count = 0;
    for (int t = 0; t < scene.NumTriangles(); ++t) {
      const int tm = scene.triangle_material.empty() ? -1 : scene.triangle_material[t];
      if (tm != material) continue;
      for (int k = 0; k < 3; ++k)
        AppendBytes(&buffer.data, static_cast<uint32_t>(scene.triangles[t][k]));
      count += 3;
    }
    tinygltf::BufferView view;
    view.buffer = 0;
    view.byteOffset = offset;
    view.byteLength = buffer.data.size() - offset;
    view.target = TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER;
    model.bufferViews.push_back(view);
    tinygltf::Accessor indices;
    indices.bufferView = static_cast<int>(model.bufferViews.size()) - 1;
    indices.componentType = TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT;
    indices.type = TINYGLTF_TYPE_SCALAR;
    indices.count = count;
    model.accessors.push_back(indices);
    tinygltf::Primitive prim;
    prim.attributes["POSITION"] = 0;
    prim.indices = static_cast<int>(model.accessors.size()) - 1;
    prim.material = material;
    prim.mode = TINYGLTF_MODE_TRIANGLES;
    mesh.primitives.push_back(prim);
  }
  model.buffers.push_back(std::move(buffer));
  mesh.name = "scene";
  model.meshes.push_back(mesh);
  tinygltf::Node node;
  node.mesh = 0;
  node.name = "table";
  model.nodes.push_back(node);
  tinygltf::Scene gltf_scene;
  gltf_scene.nodes = {0};
  model.scenes.push_back(gltf_scene);
  model.defaultScene = 0;

  const bool binary = path.size() >= 4 && path.compare(path.size() - 4, 4, ".glb") == 0;
  tinygltf::TinyGLTF gltf;
  // Serialised in memory (buffers and images embedded), then written all or nothing: a full
  // disk leaves the previous file and an error, never a cut or empty scene.
  std::ostringstream bytes;
  bool ok = false;
  try {
    ok = gltf.WriteGltfSceneToStream(&model, bytes, /*prettyPrint=*/!binary,
                                     /*writeBinary=*/binary);
  } catch (const std::exception& e) {
    return IoError(path + ": " + e.what());
  }
  if (!ok || !bytes) return IoError(path + ": could not serialise glTF");
  return WriteFileAtomically(path, bytes.view());
}

}  // namespace sandtable
