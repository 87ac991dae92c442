// `sandtable-node render-frame`: one frame of a unit's show written to a PNG, without a site
// (docs/render.md): what the unit would give its projector, for operators and the docs.
//
//   sandtable-node render-frame --calibration unit.json -o frame.png [--model scene.gltf]
//       [--pattern none|id|grid|white|raw-white|bars|black] [--timeline TRACKS.csv] [--media-s T]
//       [--sun on|off] [--sun-start-h H] [--sun-hours-per-s R] [--id N]
//
// The calibration must be a site calibration (table_from_projector; table_from_model places the
// model, else a table plane is drawn). Headless: EGL (llvmpipe without a GPU). Exit 0 when the
// PNG is written, 1 when rendering or writing fails, 2 for bad usage or a bad input file (the
// message names the flag or the file).
#pragma once

#include <string>
#include <vector>

namespace sandtable::node {

// `args` are the arguments after "render-frame".
int RunRenderFrame(const std::vector<std::string>& args);

}  // namespace sandtable::node
