// Preset sites (true rigs) for the simulated world.
//
//   sandtable-3: TR09-017. A 5 ft disc table; three 1280x800 projectors, throw ratio 1.27, on
//     legs inclined 20 degrees from vertical, 120 degrees apart. Each projector sits 1.55 m above
//     the table top (inside the 2.58 m-high frame whose table top is 0.74 m above the floor),
//     its optical axis along its leg (20 degrees from vertical) aimed 0.15 m past the table
//     centre, so the three images overlap in a central triangle. A 1024x768 camera (horizontal
//     field of view 50 degrees, mild barrel distortion) on each unit, 0.12 m to the projector's
//     right, toed in towards the projector's aim point.
//   grid-N (1 <= N <= 64): the city table (3.0 m x 2.0 m) under a ceiling grid of N downward
//     projectors, rows x cols with rows = floor(sqrt(N)), cols = ceil(N / rows) (the last row
//     may be partial), at the height where neighbouring footprints overlap by 25 %. The cameras'
//     exposure is 5 ms for throws of 1.6 to 2.6 m and goes as throw^2 outside (the white stays in
//     range: grid-2 at 5.1 m gets 19 ms, grid-64 at 0.64 m 0.8 ms).
//   flat-4: the flat table (2.0 m x 1.5 m), 2x2 projectors tilted 10 degrees, overlapping 25 %.
//   random:SEED: a random site of 3 to 8 mixed units, checked sound (sim/site/random_site.h).
// Every unit has a camera. Ids are 0..N-1. The presets pass Site::Check().
#pragma once

#include <string_view>

#include "common/base/status.h"
#include "sim/site/site.h"

namespace sandtable::sim {

Expected<Site> MakeSitePreset(std::string_view name);

// The default unit hardware, for tests and presets.
ProjectorSpec DefaultProjector();  // 1280x800, throw ratio 1.27, gamma 2.2, small distortion
CameraSpec DefaultCamera();        // 1024x768, HFOV 50 deg, 8 bit, linear

// Every projector and camera of `site` at `factor` times its resolution (0 < factor <= 1; the
// lab's --resolution-scale for large sites on a small machine): width and height rounded, the
// focal lengths scaled by the same ratio as the size, the principal point so that the image's
// edges stay where they were (pixel-centre convention of camera_model.h); the field of view, the
// distortion and the poses unchanged. INVALID_ARGUMENT outside (0, 1] or when a device would
// fall under 32 px.
Status ScaleSiteResolution(double factor, Site* site);

}  // namespace sandtable::sim
