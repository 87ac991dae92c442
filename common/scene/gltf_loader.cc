#include "common/scene/gltf_loader.h"

#include <cmath>
#include <cstring>
#include <functional>
#include <optional>
#include <sstream>

#include <tiny_gltf.h>

namespace sandtable {

namespace {

using tinygltf::Accessor;
using tinygltf::Model;

std::string BaseName(const std::string& path) {
  const size_t slash = path.find_last_of('/');
  return slash == std::string::npos ? path : path.substr(slash + 1);
}

bool EndsWith(const std::string& s, const std::string& suffix) {
  if (s.size() < suffix.size()) return false;
  for (size_t i = 0; i < suffix.size(); ++i) {
    if (std::tolower(static_cast<unsigned char>(s[s.size() - suffix.size() + i])) != suffix[i]) {
      return false;
    }
  }
  return true;
}

// A validated view of an accessor's elements: element i starts at data + i * stride.
struct AccessorView {
  const uint8_t* data = nullptr;
  size_t stride = 0;
  size_t count = 0;
  int component_type = 0;
  int num_components = 0;
  bool normalized = false;
};

// Checks every index the spec leaves to the reader: accessor -> buffer view -> buffer, offsets,
// stride and count against the byte lengths, in 64-bit arithmetic (no overflow for counts that
// fit the file).
Expected<AccessorView> ViewAccessor(const Model& model, int accessor_index,
                                    const std::string& what) {
  if (accessor_index < 0 || accessor_index >= static_cast<int>(model.accessors.size())) {
    return ParseError(what + ": accessor " + std::to_string(accessor_index) + " out of range (" +
                      std::to_string(model.accessors.size()) + " accessors)");
  }
  const Accessor& accessor = model.accessors[accessor_index];
  const std::string name = what + " (accessor " + std::to_string(accessor_index) + ")";
  if (accessor.sparse.isSparse) return ParseError(name + ": sparse accessors are not supported");
  if (accessor.bufferView < 0 ||
      accessor.bufferView >= static_cast<int>(model.bufferViews.size())) {
    return ParseError(name + ": bufferView " + std::to_string(accessor.bufferView) +
                      " out of range (" + std::to_string(model.bufferViews.size()) +
                      " buffer views)");
  }
  const tinygltf::BufferView& view = model.bufferViews[accessor.bufferView];
  if (view.buffer < 0 || view.buffer >= static_cast<int>(model.buffers.size())) {
    return ParseError(name + ": buffer " + std::to_string(view.buffer) + " not found (" +
                      std::to_string(model.buffers.size()) + " buffers)");
  }
  const tinygltf::Buffer& buffer = model.buffers[view.buffer];
  const int component_size = tinygltf::GetComponentSizeInBytes(accessor.componentType);
  const int num_components = tinygltf::GetNumComponentsInType(accessor.type);
  if (component_size <= 0 || num_components <= 0) {
    return ParseError(name + ": unknown componentType " + std::to_string(accessor.componentType) +
                      " or type " + std::to_string(accessor.type));
  }
  const uint64_t element_size = static_cast<uint64_t>(component_size) * num_components;
  const uint64_t stride = view.byteStride > 0 ? view.byteStride : element_size;
  if (stride < element_size) {
    return ParseError(name + ": byteStride " + std::to_string(stride) + " < element size " +
                      std::to_string(element_size));
  }
  const uint64_t view_end = static_cast<uint64_t>(view.byteOffset) + view.byteLength;
  if (view_end > buffer.data.size()) {
    return ParseError(name + ": bufferView " + std::to_string(accessor.bufferView) +
                      " ends at byte " + std::to_string(view_end) + " past its buffer of " +
                      std::to_string(buffer.data.size()) + " bytes");
  }
  if (accessor.count > 0) {
    const uint64_t needed = static_cast<uint64_t>(accessor.byteOffset) +
                            stride * (static_cast<uint64_t>(accessor.count) - 1) + element_size;
    if (needed > view.byteLength) {
      return ParseError(name + ": " + std::to_string(accessor.count) + " elements need " +
                        std::to_string(needed) + " bytes, bufferView has " +
                        std::to_string(view.byteLength));
    }
  }
  AccessorView out;
  out.data = buffer.data.data() + view.byteOffset + accessor.byteOffset;
  out.stride = stride;
  out.count = accessor.count;
  out.component_type = accessor.componentType;
  out.num_components = num_components;
  out.normalized = accessor.normalized;
  return out;
}

template <typename T>
T Load(const uint8_t* p) {
  T value;
  std::memcpy(&value, p, sizeof(T));
  return value;
}

// Component `c` of element `i` as a float (normalized integers mapped to [0, 1]).
std::optional<float> ReadFloat(const AccessorView& v, size_t i, int c) {
  const uint8_t* p = v.data + i * v.stride;
  switch (v.component_type) {
    case TINYGLTF_COMPONENT_TYPE_FLOAT:
      return Load<float>(p + 4 * c);
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
      if (!v.normalized) return std::nullopt;
      return Load<uint8_t>(p + c) / 255.0f;
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
      if (!v.normalized) return std::nullopt;
      return Load<uint16_t>(p + 2 * c) / 65535.0f;
    default:
      return std::nullopt;
  }
}

Eigen::Matrix4d NodeMatrix(const tinygltf::Node& node) {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  if (node.matrix.size() == 16) {
    for (int col = 0; col < 4; ++col) {
      for (int row = 0; row < 4; ++row) m(row, col) = node.matrix[col * 4 + row];  // column-major
    }
    return m;
  }
  Eigen::Affine3d t = Eigen::Affine3d::Identity();
  if (node.translation.size() == 3) {
    t.translate(Eigen::Vector3d(node.translation[0], node.translation[1], node.translation[2]));
  }
  if (node.rotation.size() == 4) {  // glTF order x, y, z, w
    Eigen::Quaterniond q(node.rotation[3], node.rotation[0], node.rotation[1], node.rotation[2]);
    if (q.norm() > 0) t.rotate(q.normalized());
  }
  if (node.scale.size() == 3) t.scale(Eigen::Vector3d(node.scale[0], node.scale[1], node.scale[2]));
  return t.matrix();
}

class Loader {
 public:
  Loader(const Model& model, const GltfLoadOptions& options, GltfLoadReport* report)
      : model_(model), options_(options), report_(report) {}

  Expected<Scene> Run() {
    ST_RETURN_IF_ERROR(LoadMaterials());
    std::vector<int> roots;
    if (!model_.scenes.empty()) {
      int scene_index = model_.defaultScene >= 0 ? model_.defaultScene : 0;
      if (scene_index >= static_cast<int>(model_.scenes.size())) {
        return ParseError("default scene " + std::to_string(scene_index) + " out of range");
      }
      roots = model_.scenes[scene_index].nodes;
    } else {
      std::vector<bool> is_child(model_.nodes.size(), false);
      for (const tinygltf::Node& node : model_.nodes) {
        for (int c : node.children) {
          if (c >= 0 && c < static_cast<int>(is_child.size())) is_child[c] = true;
        }
      }
      for (size_t i = 0; i < model_.nodes.size(); ++i) {
        if (!is_child[i]) roots.push_back(static_cast<int>(i));
      }
    }
    Eigen::Matrix4d table_from_gltf = Eigen::Matrix4d::Identity();
    table_from_gltf.topLeftCorner<3, 3>() = TableFromGltfRotation() * options_.scale_m_per_unit;
    on_path_.assign(model_.nodes.size(), false);
    for (int root : roots) ST_RETURN_IF_ERROR(VisitNode(root, table_from_gltf));
    return std::move(scene_);
  }

 private:
  Status LoadMaterials() {
    for (size_t i = 0; i < model_.materials.size(); ++i) {
      const tinygltf::Material& m = model_.materials[i];
      Material out;
      out.name = m.name;
      const std::vector<double>& f = m.pbrMetallicRoughness.baseColorFactor;
      if (f.size() == 4) out.base_color_factor = Eigen::Vector4d(f[0], f[1], f[2], f[3]);
      if (!out.base_color_factor.allFinite()) {
        return ParseError("material " + std::to_string(i) + ": baseColorFactor not finite");
      }
      const int tex = m.pbrMetallicRoughness.baseColorTexture.index;
      if (options_.load_textures && tex >= 0) {
        Expected<int> texture = LoadTexture(tex, "material " + std::to_string(i));
        if (!texture.ok()) return texture.status();
        out.base_color_texture = *texture;
      }
      scene_.materials.push_back(out);
    }
    return OkStatus();
  }

  Expected<int> LoadTexture(int texture_index, const std::string& what) {
    if (texture_index >= static_cast<int>(model_.textures.size())) {
      return ParseError(what + ": texture " + std::to_string(texture_index) + " out of range");
    }
    const tinygltf::Texture& t = model_.textures[texture_index];
    if (t.source < 0 || t.source >= static_cast<int>(model_.images.size())) {
      return ParseError(what + ": texture " + std::to_string(texture_index) + " has image " +
                        std::to_string(t.source) + " out of range");
    }
    const tinygltf::Image& image = model_.images[t.source];
    Texture out;
    if (t.sampler >= 0 && t.sampler < static_cast<int>(model_.samplers.size())) {
      out.repeat_s = model_.samplers[t.sampler].wrapS != TINYGLTF_TEXTURE_WRAP_CLAMP_TO_EDGE;
      out.repeat_t = model_.samplers[t.sampler].wrapT != TINYGLTF_TEXTURE_WRAP_CLAMP_TO_EDGE;
    }
    const int channels = image.component;
    const int bytes_per_channel = image.bits == 16 ? 2 : 1;
    const uint64_t needed = static_cast<uint64_t>(image.width) * std::max(image.height, 0) *
                            std::max(channels, 0) * bytes_per_channel;
    if (image.width <= 0 || image.height <= 0 || channels < 1 || channels > 4 ||
        needed > image.image.size()) {
      return ParseError(what + ": image " + std::to_string(t.source) + " ('" + image.uri +
                        "') could not be decoded (" + std::to_string(image.width) + "x" +
                        std::to_string(image.height) + "x" + std::to_string(channels) + ")");
    }
    out.width_px = image.width;
    out.height_px = image.height;
    out.rgba.resize(static_cast<size_t>(image.width) * image.height * 4);
    for (size_t p = 0; p < static_cast<size_t>(image.width) * image.height; ++p) {
      uint8_t c[4] = {0, 0, 0, 255};
      for (int k = 0; k < channels; ++k) {
        const size_t at = (p * channels + k) * bytes_per_channel;
        // 16-bit PNG data is stored little-endian by stb; keep the high byte.
        c[k] = bytes_per_channel == 2 ? image.image[at + 1] : image.image[at];
      }
      if (channels == 1 || channels == 2) {  // grey (+ alpha)
        c[3] = channels == 2 ? c[1] : 255;
        c[1] = c[2] = c[0];
      }
      std::memcpy(&out.rgba[p * 4], c, 4);
    }
    scene_.textures.push_back(std::move(out));
    return static_cast<int>(scene_.textures.size()) - 1;
  }

  Status VisitNode(int node_index, const Eigen::Matrix4d& table_from_parent) {
    if (node_index < 0 || node_index >= static_cast<int>(model_.nodes.size())) {
      return ParseError("node " + std::to_string(node_index) + " out of range (" +
                        std::to_string(model_.nodes.size()) + " nodes)");
    }
    if (on_path_[node_index]) {
      return ParseError("node " + std::to_string(node_index) + " is its own ancestor (cycle)");
    }
    const tinygltf::Node& node = model_.nodes[node_index];
    const Eigen::Matrix4d table_from_node = table_from_parent * NodeMatrix(node);
    if (!table_from_node.allFinite()) {
      return ParseError("node " + std::to_string(node_index) + ": transform not finite");
    }
    if (node.mesh >= 0) {
      if (node.mesh >= static_cast<int>(model_.meshes.size())) {
        return ParseError("node " + std::to_string(node_index) + ": mesh " +
                          std::to_string(node.mesh) + " out of range");
      }
      ST_RETURN_IF_ERROR(LoadMesh(node.mesh, table_from_node));
    }
    on_path_[node_index] = true;
    for (int child : node.children) ST_RETURN_IF_ERROR(VisitNode(child, table_from_node));
    on_path_[node_index] = false;
    return OkStatus();
  }

  Status LoadMesh(int mesh_index, const Eigen::Matrix4d& table_from_node) {
    const tinygltf::Mesh& mesh = model_.meshes[mesh_index];
    for (size_t p = 0; p < mesh.primitives.size(); ++p) {
      const tinygltf::Primitive& prim = mesh.primitives[p];
      const std::string what =
          "mesh " + std::to_string(mesh_index) + " primitive " + std::to_string(p);
      const int mode = prim.mode < 0 ? TINYGLTF_MODE_TRIANGLES : prim.mode;
      auto position_it = prim.attributes.find("POSITION");
      if ((mode != TINYGLTF_MODE_TRIANGLES && mode != TINYGLTF_MODE_TRIANGLE_STRIP &&
           mode != TINYGLTF_MODE_TRIANGLE_FAN) ||
          position_it == prim.attributes.end()) {
        if (report_) ++report_->num_primitives_skipped;
        continue;
      }
      Expected<AccessorView> positions =
          ViewAccessor(model_, position_it->second, what + " POSITION");
      if (!positions.ok()) return positions.status();
      if (positions->component_type != TINYGLTF_COMPONENT_TYPE_FLOAT ||
          positions->num_components != 3) {
        return ParseError(what + ": POSITION must be float VEC3");
      }
      const size_t num_vertices = positions->count;
      const int base = scene_.NumVertices();
      if (num_vertices > static_cast<size_t>(INT32_MAX - base)) {
        return ParseError(what + ": too many vertices");
      }
      for (size_t i = 0; i < num_vertices; ++i) {
        const uint8_t* at = positions->data + i * positions->stride;
        const Eigen::Vector4d x(Load<float>(at), Load<float>(at + 4), Load<float>(at + 8), 1.0);
        const Eigen::Vector4d x_in_table = table_from_node * x;
        if (!x_in_table.allFinite()) {
          return ParseError(what + ": vertex " + std::to_string(i) + " is not finite");
        }
        scene_.positions_in_table_m.push_back(x_in_table.head<3>().cast<float>());
      }
      // Texture coordinates: kept for every vertex once any primitive has them.
      auto uv_it = prim.attributes.find("TEXCOORD_0");
      if (uv_it != prim.attributes.end()) {
        Expected<AccessorView> uvs = ViewAccessor(model_, uv_it->second, what + " TEXCOORD_0");
        if (!uvs.ok()) return uvs.status();
        if (uvs->num_components != 2 || uvs->count != num_vertices) {
          return ParseError(what + ": TEXCOORD_0 must be VEC2 with one per vertex");
        }
        scene_.texcoords.resize(base, Eigen::Vector2f::Zero());
        for (size_t i = 0; i < num_vertices; ++i) {
          std::optional<float> s = ReadFloat(*uvs, i, 0), t = ReadFloat(*uvs, i, 1);
          if (!s || !t) return ParseError(what + ": TEXCOORD_0 component type not supported");
          scene_.texcoords.emplace_back(*s, *t);
        }
      } else if (!scene_.texcoords.empty()) {
        scene_.texcoords.resize(scene_.positions_in_table_m.size(), Eigen::Vector2f::Zero());
      }
      // Indices (or 0..n-1), validated against the vertex count.
      std::vector<uint32_t> indices;
      if (prim.indices >= 0) {
        Expected<AccessorView> idx = ViewAccessor(model_, prim.indices, what + " indices");
        if (!idx.ok()) return idx.status();
        if (idx->num_components != 1) return ParseError(what + ": indices must be SCALAR");
        indices.resize(idx->count);
        for (size_t i = 0; i < idx->count; ++i) {
          const uint8_t* at = idx->data + i * idx->stride;
          switch (idx->component_type) {
            case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
              indices[i] = Load<uint8_t>(at);
              break;
            case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
              indices[i] = Load<uint16_t>(at);
              break;
            case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT:
              indices[i] = Load<uint32_t>(at);
              break;
            default:
              return ParseError(what + ": index componentType " +
                                std::to_string(idx->component_type) + " is not uint8/16/32");
          }
          if (indices[i] >= num_vertices) {
            return ParseError(what + ": index " + std::to_string(indices[i]) +
                              " >= " + std::to_string(num_vertices) + " vertices");
          }
        }
      } else {
        indices.resize(num_vertices);
        for (size_t i = 0; i < num_vertices; ++i) indices[i] = static_cast<uint32_t>(i);
      }
      int material = prim.material;
      if (material >= static_cast<int>(scene_.materials.size())) {
        return ParseError(what + ": material " + std::to_string(material) + " out of range");
      }
      auto add = [&](uint32_t a, uint32_t b, uint32_t c) {
        scene_.triangles.emplace_back(base + a, base + b, base + c);
        scene_.triangle_material.push_back(material);
      };
      if (mode == TINYGLTF_MODE_TRIANGLES) {
        if (indices.size() % 3 != 0) {
          return ParseError(what + ": " + std::to_string(indices.size()) +
                            " indices is not a multiple of 3");
        }
        for (size_t i = 0; i + 2 < indices.size(); i += 3)
          add(indices[i], indices[i + 1], indices[i + 2]);
      } else if (mode == TINYGLTF_MODE_TRIANGLE_STRIP) {
        for (size_t i = 0; i + 2 < indices.size(); ++i) {
          if (i % 2 == 0)
            add(indices[i], indices[i + 1], indices[i + 2]);
          else
            add(indices[i + 1], indices[i], indices[i + 2]);
        }
      } else {
        for (size_t i = 1; i + 1 < indices.size(); ++i) add(indices[0], indices[i], indices[i + 1]);
      }
      if (report_) ++report_->num_primitives_loaded;
    }
    return OkStatus();
  }

  const Model& model_;
  const GltfLoadOptions& options_;
  GltfLoadReport* report_;
  Scene scene_;
  std::vector<bool> on_path_;
};

}  // namespace

Status GltfLoadOptions::Check() const {
  if (!(scale_m_per_unit > 0.0) || !std::isfinite(scale_m_per_unit)) {
    return InvalidArgumentError("GltfLoadOptions: scale_m_per_unit = " +
                                std::to_string(scale_m_per_unit) + " must be finite and > 0");
  }
  return OkStatus();
}

Eigen::Matrix3d TableFromGltfRotation() {
  // table (x, y, z) = glTF (x, -z, y)
  Eigen::Matrix3d r;
  r << 1, 0, 0, 0, 0, -1, 0, 1, 0;
  return r;
}

Expected<Scene> LoadGltfScene(const std::string& path, const GltfLoadOptions& options,
                              GltfLoadReport* report) {
  ST_RETURN_IF_ERROR(options.Check());
  const std::string file = BaseName(path);
  tinygltf::Model model;
  tinygltf::TinyGLTF gltf;
  std::string err, warn;
  bool ok = false;
  try {
    ok = EndsWith(path, ".glb") ? gltf.LoadBinaryFromFile(&model, &err, &warn, path)
                                : gltf.LoadASCIIFromFile(&model, &err, &warn, path);
  } catch (const std::exception& e) {  // nlohmann::json inside tinygltf may throw
    return ParseError(file + ": " + e.what());
  }
  if (report) report->warnings = warn;
  if (!ok) {
    while (!err.empty() && (err.back() == '\n' || err.back() == ' ')) err.pop_back();
    return ParseError(file + ": " + (err.empty() ? std::string("could not be loaded") : err));
  }
  Loader loader(model, options, report);
  Expected<Scene> scene = loader.Run();
  if (!scene.ok()) return scene.status().WithContext(file);
  return scene;
}

}  // namespace sandtable
