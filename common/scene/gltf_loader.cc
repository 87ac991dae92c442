#include "common/scene/gltf_loader.h"

#include <sys/stat.h>

#include <algorithm>
#include <cmath>
#include <optional>
#include <sstream>
#include <vector>

#include <tiny_gltf.h>

#include "common/base/file_io.h"

namespace sandtable {

namespace {

using tinygltf::Accessor;
using tinygltf::Model;

std::string BaseName(const std::string& path) {
  const size_t slash = path.find_last_of('/');
  return slash == std::string::npos ? path : path.substr(slash + 1);
}

std::string DirName(const std::string& path) {
  const size_t slash = path.find_last_of('/');
  return slash == std::string::npos ? std::string(".") : path.substr(0, slash + 1);
}

std::string Str(uint64_t v) { return std::to_string(v); }

uint64_t SaturatingAdd(uint64_t a, uint64_t b) {
  uint64_t r;
  return __builtin_add_overflow(a, b, &r) ? UINT64_MAX : r;
}
uint64_t SaturatingMul(uint64_t a, uint64_t b) {
  uint64_t r;
  return __builtin_mul_overflow(a, b, &r) ? UINT64_MAX : r;
}

// ---------------------------------------------------------------------------------------------
// Files: every file the loader reads (the scene file and each external URI) goes through here.

// State shared by the tinygltf callbacks of one load.
struct LoadContext {
  bool allow_files = false;  // external URIs (only for LoadGltfScene)
  bool decode_images = true;
  uint64_t bytes_read = 0;
  uint64_t texture_pixels = 0;
  const tinygltf::Model* model = nullptr;  // being filled: buffers and views come before images
  std::string first_error;                 // the first refusal in a callback, for the final message
  void Refuse(const std::string& why) {
    if (first_error.empty()) first_error = why;
  }
};

bool FsFileExists(const std::string& path, void* user) {
  const LoadContext* ctx = static_cast<const LoadContext*>(user);
  if (!ctx->allow_files) return true;  // FsReadWholeFile then refuses it by name
  struct stat st;
  return ::stat(path.c_str(), &st) == 0;  // the type is checked when read
}

std::string FsExpandFilePath(const std::string& path, void*) { return path; }  // no wordexp

bool FsReadWholeFile(std::vector<unsigned char>* out, std::string* err, const std::string& path,
                     void* user) {
  LoadContext* ctx = static_cast<LoadContext*>(user);
  Status status = OkStatus();
  if (!ctx->allow_files) {
    status = ParseError("external URI '" + path + "' not allowed when loading from memory");
  } else {
    const uint64_t left = kMaxGltfTotalBytes - std::min(ctx->bytes_read, kMaxGltfTotalBytes);
    Expected<std::string> bytes = ReadInputFile(path, std::min(kMaxGltfFileBytes, left),
                                                "kMaxGltfFileBytes or kMaxGltfTotalBytes");
    if (bytes.ok()) {
      out->assign(bytes->begin(), bytes->end());
    } else {
      status = bytes.status();
    }
  }
  if (!status.ok()) {
    ctx->Refuse(status.message());
    if (err) *err = status.message();
    return false;
  }
  ctx->bytes_read += out->size();
  return true;
}

bool FsWriteWholeFile(std::string* err, const std::string&, const std::vector<unsigned char>&,
                      void*) {
  if (err) *err = "the loader never writes";
  return false;
}

uint32_t BigEndian32(const uint8_t* p) {
  return (uint32_t{p[0]} << 24) | (uint32_t{p[1]} << 16) | (uint32_t{p[2]} << 8) | p[3];
}

// Width and height from a PNG or JPEG header, without decoding; false if neither.
bool ImageSize(const uint8_t* b, size_t n, uint64_t* width, uint64_t* height) {
  static const uint8_t kPng[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (n >= 24 && std::memcmp(b, kPng, 8) == 0 && std::memcmp(b + 12, "IHDR", 4) == 0) {
    *width = BigEndian32(b + 16);
    *height = BigEndian32(b + 20);
    return true;
  }
  if (n < 4 || b[0] != 0xff || b[1] != 0xd8) return false;
  size_t at = 2;  // JPEG: walk the markers to a SOFn
  while (at + 4 <= n) {
    if (b[at] != 0xff) return false;
    const uint8_t marker = b[at + 1];
    if (marker == 0xff) {  // fill byte
      ++at;
      continue;
    }
    if (marker == 0xd8 || marker == 0x01 || (marker >= 0xd0 && marker <= 0xd7)) {
      at += 2;
      continue;
    }
    const size_t length = (size_t{b[at + 2]} << 8) | b[at + 3];
    const bool sof =
        marker >= 0xc0 && marker <= 0xcf && marker != 0xc4 && marker != 0xc8 && marker != 0xcc;
    if (sof) {
      if (at + 9 > n) return false;
      *height = (uint64_t{b[at + 5]} << 8) | b[at + 6];
      *width = (uint64_t{b[at + 7]} << 8) | b[at + 8];
      return true;
    }
    if (length < 2) return false;
    at += 2 + length;
  }
  return false;
}

// tinygltf's image callback: the size from the header is bounded before stb decodes anything.
bool BoundedImageLoader(tinygltf::Image* image, const int image_index, std::string* err,
                        std::string* warn, int req_width, int req_height,
                        const unsigned char* bytes, int size, void* user) {
  LoadContext* ctx = static_cast<LoadContext*>(user);
  const std::string what = "image " + std::to_string(image_index);
  // tinygltf hands over an image's bufferView without checking it against its buffer.
  if (image->bufferView >= 0 && ctx->model != nullptr) {
    const tinygltf::Model& m = *ctx->model;
    std::string bad;
    if (image->bufferView >= static_cast<int>(m.bufferViews.size())) {
      bad = "bufferView " + std::to_string(image->bufferView) + " out of range";
    } else {
      const tinygltf::BufferView& view = m.bufferViews[image->bufferView];
      const uint64_t buffer_size =
          view.buffer >= 0 && view.buffer < static_cast<int>(m.buffers.size())
              ? m.buffers[view.buffer].data.size()
              : 0;
      if (view.byteOffset > buffer_size || view.byteLength > buffer_size - view.byteOffset ||
          view.byteLength > static_cast<uint64_t>(INT32_MAX)) {
        bad = "bufferView " + std::to_string(image->bufferView) + ": byteOffset " +
              Str(view.byteOffset) + " + byteLength " + Str(view.byteLength) +
              " past its buffer of " + Str(buffer_size) + " bytes";
      }
    }
    if (!bad.empty()) {
      ctx->Refuse(what + ": " + bad);
      if (err) *err += what + ": " + bad + "\n";
      return false;
    }
  }
  if (!ctx->decode_images) return true;  // textures not wanted: leave the image empty
  uint64_t w = 0, h = 0;
  const bool known = size > 0 && ImageSize(bytes, static_cast<size_t>(size), &w, &h);
  std::string why;
  if (!known) {
    why = what + ": not a PNG or JPEG image (the formats glTF 2.0 allows)";
  } else if (w == 0 || h == 0 || w > kMaxTextureSidePx || h > kMaxTextureSidePx) {
    why = what + ": " + Str(w) + "x" + Str(h) + " px, each side must be 1.." +
          std::to_string(kMaxTextureSidePx) + " (kMaxTextureSidePx)";
  } else if (w * h > kMaxTexturePixels) {
    why = what + ": " + Str(w * h) + " px, more than kMaxTexturePixels = " + Str(kMaxTexturePixels);
  } else if (ctx->texture_pixels + w * h > kMaxSceneTexturePixels) {
    why = what +
          ": the images together exceed kMaxSceneTexturePixels = " + Str(kMaxSceneTexturePixels) +
          " px";
  }
  if (!why.empty()) {
    ctx->Refuse(why);
    if (err) *err += why + "\n";
    return false;
  }
  ctx->texture_pixels += w * h;
  return tinygltf::LoadImageData(image, image_index, err, warn, req_width, req_height, bytes, size,
                                 nullptr);
}

// Refuses JSON nested deeper than kMaxGltfJsonDepth: tinygltf converts "extras" and
// "extensions" recursively, so depth would otherwise be stack depth.
Status CheckJsonDepth(const uint8_t* json, size_t n) {
  int depth = 0;
  bool in_string = false;
  for (size_t i = 0; i < n; ++i) {
    const uint8_t c = json[i];
    if (in_string) {
      if (c == '\\') {
        ++i;
      } else if (c == '"') {
        in_string = false;
      }
    } else if (c == '"') {
      in_string = true;
    } else if (c == '[' || c == '{') {
      if (++depth > kMaxGltfJsonDepth) {
        return ParseError("JSON nested deeper than kMaxGltfJsonDepth = " +
                          std::to_string(kMaxGltfJsonDepth) + " at byte " + Str(i));
      }
    } else if (c == ']' || c == '}') {
      --depth;
    }
  }
  return OkStatus();
}

// The .glb header and chunk layout, checked before tinygltf reads it.
Status CheckGlbLayout(const uint8_t* b, size_t n) {
  if (n < 20) return ParseError("binary glTF truncated: " + Str(n) + " bytes, header needs 20");
  uint32_t version, length, json_length, json_type;
  std::memcpy(&version, b + 4, 4);
  std::memcpy(&length, b + 8, 4);
  std::memcpy(&json_length, b + 12, 4);
  std::memcpy(&json_type, b + 16, 4);
  if (version != 2) {
    return ParseError("binary glTF version " + Str(version) + ", only 2 is supported");
  }
  if (length > n) {
    return ParseError("binary glTF truncated: header says " + Str(length) + " bytes, file has " +
                      Str(n));
  }
  if (json_length > kMaxGltfJsonBytes) {
    return ParseError("binary glTF: JSON chunk of " + Str(json_length) +
                      " bytes, more than kMaxGltfJsonBytes = " + Str(kMaxGltfJsonBytes));
  }
  if (json_type != 0x4E4F534Au || uint64_t{json_length} + 20 > length || json_length == 0) {
    return ParseError("binary glTF: first chunk must be JSON within the file's " + Str(length) +
                      " bytes (chunk length " + Str(json_length) + ")");
  }
  return CheckJsonDepth(b + 20, json_length);
}

// ---------------------------------------------------------------------------------------------
// Accessors.

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
// stride and count against the real byte lengths, each sum and product overflow-checked.
Expected<AccessorView> ViewAccessor(const Model& model, int accessor_index,
                                    const std::string& what) {
  if (accessor_index < 0 || accessor_index >= static_cast<int>(model.accessors.size())) {
    return ParseError(what + ": accessor " + std::to_string(accessor_index) + " out of range (" +
                      Str(model.accessors.size()) + " accessors)");
  }
  const Accessor& accessor = model.accessors[accessor_index];
  const std::string name = what + " (accessor " + std::to_string(accessor_index) + ")";
  if (accessor.sparse.isSparse) return ParseError(name + ": sparse accessors are not supported");
  if (accessor.bufferView < 0 ||
      accessor.bufferView >= static_cast<int>(model.bufferViews.size())) {
    return ParseError(name + ": bufferView " + std::to_string(accessor.bufferView) +
                      " out of range (" + Str(model.bufferViews.size()) + " buffer views)");
  }
  const std::string view_name = name + ": bufferView " + std::to_string(accessor.bufferView);
  const tinygltf::BufferView& view = model.bufferViews[accessor.bufferView];
  if (view.buffer < 0 || view.buffer >= static_cast<int>(model.buffers.size())) {
    return ParseError(view_name + ": buffer " + std::to_string(view.buffer) + " not found (" +
                      Str(model.buffers.size()) + " buffers)");
  }
  const uint64_t buffer_size = model.buffers[view.buffer].data.size();
  const int component_size = tinygltf::GetComponentSizeInBytes(accessor.componentType);
  const int num_components = tinygltf::GetNumComponentsInType(accessor.type);
  if (component_size <= 0 || num_components <= 0) {
    return ParseError(name + ": unknown componentType " + std::to_string(accessor.componentType) +
                      " or type " + std::to_string(accessor.type));
  }
  const uint64_t element_size = static_cast<uint64_t>(component_size) * num_components;
  const uint64_t view_offset = view.byteOffset, view_length = view.byteLength;
  if (view_offset > buffer_size || view_length > buffer_size - view_offset) {
    return ParseError(view_name + ": byteOffset " + Str(view_offset) + " + byteLength " +
                      Str(view_length) + " past its buffer of " + Str(buffer_size) + " bytes");
  }
  const uint64_t stride = view.byteStride > 0 ? view.byteStride : element_size;
  if (stride < element_size || (view.byteStride > 0 && view.byteStride > 252)) {
    return ParseError(view_name + ": byteStride " + Str(view.byteStride) +
                      " must be 0 or element size " + Str(element_size) + "..252");
  }
  const uint64_t offset = accessor.byteOffset, count = accessor.count;
  if (offset > view_length) {
    return ParseError(name + ": byteOffset " + Str(offset) + " past its bufferView of " +
                      Str(view_length) + " bytes");
  }
  if (count > 0) {
    // offset + stride * (count - 1) + element_size <= view_length, without wrapping.
    const uint64_t room = view_length - offset;
    uint64_t span = 0;
    if (__builtin_mul_overflow(stride, count - 1, &span) ||
        __builtin_add_overflow(span, element_size, &span) || span > room) {
      return ParseError(name + ": count " + Str(count) + " of " + Str(element_size) +
                        "-byte elements (stride " + Str(stride) + ") does not fit the " +
                        Str(room) + " bytes of bufferView " + std::to_string(accessor.bufferView) +
                        " after byteOffset " + Str(offset));
    }
  }
  AccessorView out;
  out.data = model.buffers[view.buffer].data.data() + view_offset + offset;
  out.stride = stride;
  out.count = count;
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
    if (q.norm() > 0 && std::isfinite(q.norm())) t.rotate(q.normalized());
  }
  if (node.scale.size() == 3) t.scale(Eigen::Vector3d(node.scale[0], node.scale[1], node.scale[2]));
  return t.matrix();
}

bool IsTriangleMode(int mode) {
  return mode == TINYGLTF_MODE_TRIANGLES || mode == TINYGLTF_MODE_TRIANGLE_STRIP ||
         mode == TINYGLTF_MODE_TRIANGLE_FAN;
}

// ---------------------------------------------------------------------------------------------
// The model -> Scene conversion.

class Loader {
 public:
  Loader(const Model& model, const GltfLoadOptions& options, GltfLoadReport* report)
      : model_(model), options_(options), report_(report) {}

  Expected<Scene> Run() {
    std::vector<int> roots;
    if (!model_.scenes.empty()) {
      const int scene_index = model_.defaultScene >= 0 ? model_.defaultScene : 0;
      if (scene_index >= static_cast<int>(model_.scenes.size())) {
        return ParseError("default scene " + std::to_string(scene_index) + " out of range");
      }
      roots = model_.scenes[scene_index].nodes;
      for (int r : roots) {
        if (r < 0 || r >= static_cast<int>(model_.nodes.size())) {
          return ParseError("scene " + std::to_string(scene_index) + ": node " + std::to_string(r) +
                            " out of range (" + Str(model_.nodes.size()) + " nodes)");
        }
      }
    }
    ST_RETURN_IF_ERROR(CheckMeshes());
    ST_RETURN_IF_ERROR(CheckNodeGraph(!model_.scenes.empty(), &roots));
    ST_RETURN_IF_ERROR(LoadMaterials());
    scene_.positions_in_table_m.reserve(total_vertices_);
    scene_.triangles.reserve(total_triangles_);
    scene_.triangle_material.reserve(total_triangles_);
    Eigen::Matrix4d table_from_gltf = Eigen::Matrix4d::Identity();
    table_from_gltf.topLeftCorner<3, 3>() = TableFromGltfRotation() * options_.scale_m_per_unit;
    ST_RETURN_IF_ERROR(Expand(roots, table_from_gltf));
    if (report_) report_->num_instances = total_instances_;
    return std::move(scene_);
  }

 private:
  // Validates the accessors of every primitive that will be loaded (no data read) and counts
  // the triangles and vertices of one instance of each mesh.
  Status CheckMeshes() {
    mesh_triangles_.assign(model_.meshes.size(), 0);
    mesh_vertices_.assign(model_.meshes.size(), 0);
    for (size_t m = 0; m < model_.meshes.size(); ++m) {
      const tinygltf::Mesh& mesh = model_.meshes[m];
      for (size_t p = 0; p < mesh.primitives.size(); ++p) {
        const tinygltf::Primitive& prim = mesh.primitives[p];
        const std::string what = "mesh " + Str(m) + " primitive " + Str(p);
        const int mode = prim.mode < 0 ? TINYGLTF_MODE_TRIANGLES : prim.mode;
        auto position_it = prim.attributes.find("POSITION");
        if (!IsTriangleMode(mode) || position_it == prim.attributes.end()) continue;
        Expected<AccessorView> positions =
            ViewAccessor(model_, position_it->second, what + " POSITION");
        if (!positions.ok()) return positions.status();
        uint64_t n = positions->count;
        if (prim.indices >= 0) {
          Expected<AccessorView> idx = ViewAccessor(model_, prim.indices, what + " indices");
          if (!idx.ok()) return idx.status();
          n = idx->count;
        }
        const uint64_t triangles = mode == TINYGLTF_MODE_TRIANGLES ? n / 3 : (n >= 3 ? n - 2 : 0);
        mesh_triangles_[m] = SaturatingAdd(mesh_triangles_[m], triangles);
        mesh_vertices_[m] = SaturatingAdd(mesh_vertices_[m], positions->count);
      }
    }
    return OkStatus();
  }

  // Child indices, cycles (iterative depth-first search over every node), depth, and what the
  // expanded scene would hold (instances of each node = number of paths from the roots to it),
  // all before anything is expanded. Without scenes, `roots` becomes every node no one lists.
  Status CheckNodeGraph(bool have_scene, std::vector<int>* roots) {
    const int n = static_cast<int>(model_.nodes.size());
    std::vector<int> num_parents(n, 0);
    for (int i = 0; i < n; ++i) {
      const tinygltf::Node& node = model_.nodes[i];
      if (node.mesh >= static_cast<int>(model_.meshes.size())) {
        return ParseError("node " + std::to_string(i) + ": mesh " + std::to_string(node.mesh) +
                          " out of range (" + Str(model_.meshes.size()) + " meshes)");
      }
      for (int c : node.children) {
        if (c < 0 || c >= n) {
          return ParseError("node " + std::to_string(i) + ": child " + std::to_string(c) +
                            " out of range (" + std::to_string(n) + " nodes)");
        }
        ++num_parents[c];
      }
    }
    if (!have_scene) {
      for (int i = 0; i < n; ++i) {
        if (num_parents[i] == 0) roots->push_back(i);
      }
    }
    // Depth-first search with an explicit stack; colour 1 = on the current path.
    std::vector<uint8_t> colour(n, 0);
    std::vector<int> postorder;
    postorder.reserve(n);
    std::vector<std::pair<int, size_t>> stack;  // node, next child to visit
    for (int start = 0; start < n; ++start) {
      if (colour[start] != 0) continue;
      stack.emplace_back(start, 0);
      colour[start] = 1;
      while (!stack.empty()) {
        auto& [node, next] = stack.back();
        const std::vector<int>& children = model_.nodes[node].children;
        if (next < children.size()) {
          const int child = children[next++];
          if (colour[child] == 1) {
            return ParseError("node " + std::to_string(node) + " lists node " +
                              std::to_string(child) + " as a child, which is its ancestor (cycle)");
          }
          if (colour[child] == 0) {
            colour[child] = 1;
            stack.emplace_back(child, 0);
          }
        } else {
          colour[node] = 2;
          postorder.push_back(node);
          stack.pop_back();
        }
      }
    }
    // Parents before children: reverse postorder. Instances and depth flow down the edges.
    std::vector<uint64_t> instances(n, 0);
    std::vector<int> depth(n, 0);
    for (int r : *roots) {
      instances[r] = SaturatingAdd(instances[r], 1);
      depth[r] = 1;
    }
    for (auto it = postorder.rbegin(); it != postorder.rend(); ++it) {
      const int node = *it;
      if (instances[node] == 0) continue;  // not reached from the roots
      const std::string name = "node " + std::to_string(node);
      if (depth[node] > kMaxNodeDepth) {
        return ParseError(name + " is at depth " + std::to_string(depth[node]) +
                          ", deeper than kMaxNodeDepth = " + std::to_string(kMaxNodeDepth));
      }
      total_instances_ = SaturatingAdd(total_instances_, instances[node]);
      if (total_instances_ > kMaxInstances) {
        return ParseError(name +
                          ": the expanded node hierarchy would hold more than "
                          "kMaxInstances = " +
                          Str(kMaxInstances) + " node instances (this node alone " +
                          Str(instances[node]) + "; nodes reused by several parents multiply)");
      }
      const int mesh = model_.nodes[node].mesh;
      if (mesh >= 0) {
        total_triangles_ =
            SaturatingAdd(total_triangles_, SaturatingMul(instances[node], mesh_triangles_[mesh]));
        total_vertices_ =
            SaturatingAdd(total_vertices_, SaturatingMul(instances[node], mesh_vertices_[mesh]));
        if (total_triangles_ > kMaxSceneTriangles) {
          return ParseError(name + " (mesh " + std::to_string(mesh) +
                            "): the expanded scene would hold more than kMaxSceneTriangles = " +
                            Str(kMaxSceneTriangles) + " triangles");
        }
        if (total_vertices_ > kMaxSceneVertices) {
          return ParseError(name + " (mesh " + std::to_string(mesh) +
                            "): the expanded scene would hold more than kMaxSceneVertices = " +
                            Str(kMaxSceneVertices) + " vertices");
        }
      }
      for (int c : model_.nodes[node].children) {
        instances[c] = SaturatingAdd(instances[c], instances[node]);
        depth[c] = std::max(depth[c], depth[node] + 1);
      }
    }
    return OkStatus();
  }

  // Pre-order walk with an explicit stack (children in file order), bounded by CheckNodeGraph.
  Status Expand(const std::vector<int>& roots, const Eigen::Matrix4d& table_from_gltf) {
    struct Item {
      int node;
      Eigen::Matrix4d table_from_parent;
    };
    std::vector<Item> stack;
    for (auto it = roots.rbegin(); it != roots.rend(); ++it)
      stack.push_back({*it, table_from_gltf});
    while (!stack.empty()) {
      const Item item = stack.back();
      stack.pop_back();
      const tinygltf::Node& node = model_.nodes[item.node];
      for (const auto& [field, values] :
           {std::pair<const char*, const std::vector<double>*>{"matrix", &node.matrix},
            {"translation", &node.translation},
            {"rotation", &node.rotation},
            {"scale", &node.scale}}) {
        for (double v : *values) {
          if (!std::isfinite(v)) {
            return ParseError("node " + std::to_string(item.node) + ": " + field + " not finite");
          }
        }
      }
      const Eigen::Matrix4d table_from_node = item.table_from_parent * NodeMatrix(node);
      if (!table_from_node.allFinite()) {
        return ParseError("node " + std::to_string(item.node) + ": transform not finite");
      }
      if (node.mesh >= 0) ST_RETURN_IF_ERROR(LoadMesh(node.mesh, item.node, table_from_node));
      for (auto c = node.children.rbegin(); c != node.children.rend(); ++c) {
        stack.push_back({*c, table_from_node});
      }
    }
    return OkStatus();
  }

  Status LoadMaterials() {
    texture_in_scene_.assign(model_.textures.size(), -1);
    for (size_t i = 0; i < model_.materials.size(); ++i) {
      const tinygltf::Material& m = model_.materials[i];
      Material out;
      out.name = m.name;
      const std::vector<double>& f = m.pbrMetallicRoughness.baseColorFactor;
      if (f.size() == 4) out.base_color_factor = Eigen::Vector4d(f[0], f[1], f[2], f[3]);
      if (!out.base_color_factor.allFinite()) {
        return ParseError("material " + Str(i) + ": baseColorFactor not finite");
      }
      const int tex = m.pbrMetallicRoughness.baseColorTexture.index;
      if (options_.load_textures && tex >= 0) {
        Expected<int> texture = LoadTexture(tex, "material " + Str(i));
        if (!texture.ok()) return texture.status();
        out.base_color_texture = *texture;
      }
      scene_.materials.push_back(out);
    }
    return OkStatus();
  }

  // Converts a texture once, however many materials use it.
  Expected<int> LoadTexture(int texture_index, const std::string& what) {
    if (texture_index >= static_cast<int>(model_.textures.size())) {
      return ParseError(what + ": texture " + std::to_string(texture_index) + " out of range");
    }
    if (texture_in_scene_[texture_index] >= 0) return texture_in_scene_[texture_index];
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
    const bool size_ok = image.width > 0 && image.height > 0 && image.width <= kMaxTextureSidePx &&
                         image.height <= kMaxTextureSidePx;
    const uint64_t needed = size_ok ? static_cast<uint64_t>(image.width) * image.height *
                                          std::clamp(channels, 0, 4) * bytes_per_channel
                                    : 0;
    if (!size_ok || channels < 1 || channels > 4 || needed > image.image.size()) {
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
    texture_in_scene_[texture_index] = static_cast<int>(scene_.textures.size()) - 1;
    return texture_in_scene_[texture_index];
  }

  Status LoadMesh(int mesh_index, int node_index, const Eigen::Matrix4d& table_from_node) {
    const tinygltf::Mesh& mesh = model_.meshes[mesh_index];
    for (size_t p = 0; p < mesh.primitives.size(); ++p) {
      const tinygltf::Primitive& prim = mesh.primitives[p];
      const std::string what = "node " + std::to_string(node_index) + " mesh " +
                               std::to_string(mesh_index) + " primitive " + Str(p);
      const int mode = prim.mode < 0 ? TINYGLTF_MODE_TRIANGLES : prim.mode;
      auto position_it = prim.attributes.find("POSITION");
      if (!IsTriangleMode(mode) || position_it == prim.attributes.end()) {
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
      if (num_vertices > static_cast<size_t>(INT32_MAX - base)) {  // kMaxSceneVertices < 2^31
        return ParseError(what + ": too many vertices");
      }
      for (size_t i = 0; i < num_vertices; ++i) {
        const uint8_t* at = positions->data + i * positions->stride;
        const Eigen::Vector3f x_in_file(Load<float>(at), Load<float>(at + 4), Load<float>(at + 8));
        if (!x_in_file.allFinite()) {
          return ParseError(what + ": vertex " + Str(i) + " is not finite");
        }
        const Eigen::Vector4d x_in_table = table_from_node * x_in_file.cast<double>().homogeneous();
        if (!x_in_table.allFinite() ||
            x_in_table.head<3>().cwiseAbs().maxCoeff() > kMaxCoordinate_m) {
          std::ostringstream at_m;
          at_m << x_in_table.x() << ", " << x_in_table.y() << ", " << x_in_table.z();
          return ParseError(what + ": vertex " + Str(i) + " at (" + at_m.str() +
                            ") m in the table frame, outside |x|, |y|, |z| <= kMaxCoordinate_m = " +
                            std::to_string(static_cast<int>(kMaxCoordinate_m)) + " m");
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
          if (!std::isfinite(*s) || !std::isfinite(*t)) {
            return ParseError(what + ": TEXCOORD_0 " + Str(i) + " is not finite");
          }
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
                              " >= " + Str(num_vertices) + " vertices");
          }
        }
      } else {
        indices.resize(num_vertices);
        for (size_t i = 0; i < num_vertices; ++i) indices[i] = static_cast<uint32_t>(i);
      }
      const int material = prim.material;
      if (material >= static_cast<int>(scene_.materials.size())) {
        return ParseError(what + ": material " + std::to_string(material) + " out of range");
      }
      auto add = [&](uint32_t a, uint32_t b, uint32_t c) {
        scene_.triangles.emplace_back(base + a, base + b, base + c);
        scene_.triangle_material.push_back(material);
      };
      if (mode == TINYGLTF_MODE_TRIANGLES) {
        if (indices.size() % 3 != 0) {
          return ParseError(what + ": " + Str(indices.size()) + " indices is not a multiple of 3");
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
  std::vector<uint64_t> mesh_triangles_, mesh_vertices_;
  std::vector<int> texture_in_scene_;
  uint64_t total_instances_ = 0, total_triangles_ = 0, total_vertices_ = 0;
};

// Parses bytes already read and bounded, with our callbacks installed, and converts the model.
Expected<Scene> LoadFromBytes(const uint8_t* bytes, size_t size, const std::string& file,
                              const std::string& base_dir, bool allow_files,
                              const GltfLoadOptions& options, GltfLoadReport* report) {
  if (size > kMaxGltfFileBytes) {
    return IoError(file + ": " + Str(size) +
                   " bytes, more than kMaxGltfFileBytes = " + Str(kMaxGltfFileBytes));
  }
  const bool binary = size >= 4 && std::memcmp(bytes, "glTF", 4) == 0;
  if (!binary && size > kMaxGltfJsonBytes) {
    return ParseError(file + ": " + Str(size) +
                      " bytes of glTF JSON, more than kMaxGltfJsonBytes = " +
                      Str(kMaxGltfJsonBytes) + " (use .glb or an external .bin for large buffers)");
  }
  Status layout = binary ? CheckGlbLayout(bytes, size) : CheckJsonDepth(bytes, size);
  if (!layout.ok()) return layout.WithContext(file);

  LoadContext ctx;
  ctx.allow_files = allow_files;
  ctx.decode_images = options.load_textures;
  ctx.bytes_read = size;
  tinygltf::Model model;
  ctx.model = &model;
  tinygltf::TinyGLTF gltf;
  gltf.SetFsCallbacks(tinygltf::FsCallbacks{&FsFileExists, &FsExpandFilePath, &FsReadWholeFile,
                                            &FsWriteWholeFile, &ctx});
  gltf.SetImageLoader(&BoundedImageLoader, &ctx);
  std::string err, warn;
  bool ok = false;
  try {
    ok = binary
             ? gltf.LoadBinaryFromMemory(&model, &err, &warn, bytes,
                                         static_cast<unsigned int>(size), base_dir)
             : gltf.LoadASCIIFromString(&model, &err, &warn, reinterpret_cast<const char*>(bytes),
                                        static_cast<unsigned int>(size), base_dir);
  } catch (const std::exception& e) {  // nlohmann::json inside tinygltf may throw
    return ParseError(file + ": " + e.what());
  } catch (...) {
    return ParseError(file + ": the glTF parser failed (unknown exception)");
  }
  if (report) report->warnings = warn;
  if (!ok) {
    while (!err.empty() && (err.back() == '\n' || err.back() == ' ')) err.pop_back();
    if (!ctx.first_error.empty() && err.find(ctx.first_error) == std::string::npos) {
      err = ctx.first_error + (err.empty() ? "" : " (" + err + ")");
    }
    return ParseError(file + ": " + (err.empty() ? std::string("could not be loaded") : err));
  }
  try {
    Loader loader(model, options, report);
    Expected<Scene> scene = loader.Run();
    if (!scene.ok()) {
      Status status = scene.status();
      if (!ctx.first_error.empty()) {  // e.g. an image the callback refused
        status = Status(status.code(), status.message() + " (" + ctx.first_error + ")");
      }
      return status.WithContext(file);
    }
    return scene;
  } catch (const std::bad_alloc&) {
    return ParseError(file + ": out of memory while converting the scene");
  }
}

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
  Expected<std::string> bytes = ReadInputFile(path, kMaxGltfFileBytes, "kMaxGltfFileBytes");
  if (!bytes.ok()) return bytes.status();  // the message names the path
  return LoadFromBytes(reinterpret_cast<const uint8_t*>(bytes->data()), bytes->size(), file,
                       DirName(path), /*allow_files=*/true, options, report);
}

Expected<Scene> LoadGltfSceneFromBytes(std::string_view bytes, const std::string& name,
                                       const GltfLoadOptions& options, GltfLoadReport* report) {
  ST_RETURN_IF_ERROR(options.Check());
  return LoadFromBytes(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size(), name, "",
                       /*allow_files=*/false, options, report);
}

}  // namespace sandtable
