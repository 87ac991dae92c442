// Preset sites (true rigs) for the simulated world.
//
//   sandtable-3: TR09-017. A 5 ft disc table; three 1280x800 projectors, throw ratio 1.27, on
//     legs inclined 20 degrees from vertical, 120 degrees apart. Each projector sits 1.55 m above
//     the table top (inside the 2.58 m-high frame whose table top is 0.74 m above the floor),
//     its optical axis along its leg (20 degrees from vertical) aimed 0.15 m past the table
//     centre, so the three images overlap in a central triangle. A 1024x768 camera (horizontal
//     field of view 50 degrees, mild barrel distortion) on each unit, 0.12 m to the projector's
//     right, toed in towards the projector's aim point.
//   grid-N (1 <= N <= 32): the city table (3.0 m x 2.0 m) under a ceiling grid of N downward
//     projectors, rows x cols with rows = floor(sqrt(N)), cols = ceil(N / rows) (the last row
//     may be partial), at the height where neighbouring footprints overlap by 25 %.
//   flat-4: the flat table (2.0 m x 1.5 m), 2x2 projectors tilted 10 degrees, overlapping 25 %.
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

}  // namespace sandtable::sim
