// Writes a Scene (table frame) as glTF 2.0: positions converted back to glTF's +y-up frame
// (glTF (x, y, z) = table (x, z, -y)), one mesh with one indexed (uint32) primitive per
// material, base colour factors as materials. Textures are not written (the procedural scenes
// have none). `.glb` paths give binary glTF, anything else JSON with the buffer embedded as a
// base64 data URI. Round-trips through LoadGltfScene (positions to float precision).
// Failure: IO_ERROR naming the path when the file cannot be written.
#pragma once

#include <string>

#include "common/base/status.h"
#include "common/scene/scene.h"

namespace sandtable {

Status WriteGltfScene(const Scene& scene, const std::string& path);

}  // namespace sandtable
