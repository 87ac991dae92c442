// The overlay layer as triangles: annotation strokes and track traces as ribbons with round
// caps and round joints where they turn by more than 20 degrees, the cursor as a ring and track
// heads as discs, built facing the projector and lifted towards it by `lift_m` plus their half
// width (a disc's radius) so that the scene's depth buffer hides them where the model stands in
// front (a building between the projector and the stroke) and shows them on the surface they lie
// on, even where that surface is at a slant to the projector. The lift bounds what the depth test
// gets wrong: within it of an occluding edge (measured along the projector's ray) a stroke may
// still show.
#pragma once

#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "common/base/status.h"
#include "node/render/render_content.h"

namespace sandtable::node {

struct OverlayVertex {
  float position_in_table_m[3];
  float colour[4];  // display RGB, alpha
};

struct OverlayOptions {
  double lift_m = 0.015;
  int round_segments = 12;  // per cap, joint disc and marker
  Status Check() const;
};

// Appends the triangles (3 vertices each) of everything in `content` as seen from a projector
// centred at `projector_centre_in_table_m`.
std::vector<OverlayVertex> BuildOverlay(const RenderContent& content,
                                        const Eigen::Vector3d& projector_centre_in_table_m,
                                        const OverlayOptions& options = {});

}  // namespace sandtable::node
