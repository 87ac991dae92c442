// Random sites for the lab (`--site random:SEED`): sites nobody tuned the nodes for, drawn from
// a seed, each checked physically sound before it is used.
//
// What a seed draws (sim/site/random_site.cc has the ranges as named constants):
//   the table: RandomTableForSeed (common/scene/random_scene.h), the same as `--scene random:SEED`;
//   3 to 8 units, their footprints centred on a relaxed (Lloyd) layout over the table;
//   projectors of 1024x768, 1280x800, 1920x1080 or 1920x1200, throw ratio 0.8-1.6, vertical lens
//     shift 0-0.5 of the height, Brown distortion with tangential terms and k3; a pose from
//     straight down to 60 degrees off vertical (the ray through the image centre), any image
//     "up", at least 0.6 m above the table;
//   cameras of 1024x768, 1280x960, 1280x1024 or 1600x1200, 8 to 16 bits, focal length 700-1100 px,
//     barrel distortion up to k1 = -0.25 / k2 = 0.1 with tangential terms, mounted 5-20 cm from
//     the projector in any direction of its image plane, toed in to the image centre's aim
//     point and then turned by up to 8 degrees (yaw and pitch);
//   projector brightness, gamma, black level; camera exposure for the throw, noise.
// Soundness (CheckSiteSoundness): a drawn site that fails it is drawn again from the next
// sub-seed (the result is still a function of the seed alone).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "common/base/status.h"
#include "sim/site/site.h"

namespace sandtable::sim {

// Site::Check(), and on the table plane (z = 0; structures may only add light and shadow):
//   every projector lights at least kMinLitTableShare of its image on the table;
//   every unit's camera sees at least kMinOwnLightSeen of its own projector's light on the table;
//   every unit's footprint overlaps a neighbour's by at least kMinNeighbourOverlap of its own;
//   the units form one connected group through those overlaps.
// OK, or INVALID_ARGUMENT naming the unit and the share found.
inline constexpr double kMinLitTableShare = 0.3;
inline constexpr double kMinOwnLightSeen = 0.25;
inline constexpr double kMinNeighbourOverlap = 0.05;
Status CheckSiteSoundness(const Site& site);

struct RandomSiteReport {
  int draws = 0;                        // sites drawn until one was sound
  std::vector<std::string> rejections;  // why each earlier draw was refused
};

// The sound site of a seed; INTERNAL when 200 draws give none (never seen; the report says why
// each was refused).
Expected<Site> MakeRandomSite(uint64_t seed, RandomSiteReport* report = nullptr);

}  // namespace sandtable::sim
