// A projector's footprint on the table: its image border cast onto the table plane z = 0.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "common/camera/camera_model.h"
#include "common/geometry/rigid3.h"

namespace sandtable {

inline constexpr int kFootprintPointsPerEdge = 8;

// The projector's image border (its pixel edges, `per_edge` points on each of the four sides,
// clockwise in the image from its top left corner) cast onto the table plane z = 0, table
// frame, metres. A point whose ray does not meet the plane in front of the projector (or whose
// lens distortion cannot be inverted) is left out.
std::vector<Eigen::Vector2d> TableFootprint(const CameraModel& projector,
                                            const Rigid3d& table_from_projector,
                                            int per_edge = kFootprintPointsPerEdge);

}  // namespace sandtable
