// libFuzzer target over the glTF loader (common/scene/gltf_loader.h), from memory: the bytes
// are a .gltf or a .glb; external URIs are refused, so nothing is read from disk. Seeds in
// tests/fuzz/gltf_corpus/; see deploy/fuzz.sh.
#include <string_view>

#include "common/scene/gltf_loader.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  (void)sandtable::LoadGltfSceneFromBytes(bytes, "fuzz.gltf");
  return 0;
}
