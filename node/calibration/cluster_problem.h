// The data of a cluster self-calibration: what each unit knows of itself (its factory
// calibration) and the structured-light tracks the cluster decoded.
//
// A track is one projector pixel of one unit (a node of the projector grid, common/
// structured_light/projector_grid.h) and the camera pixels where cameras of the cluster (its
// own and its neighbours') saw it: one surface point seen by the projector and by each camera.
// Frames and units: projector and camera px (pixel (0,0) centred at (0.0, 0.0)).
#pragma once

#include <map>
#include <vector>

#include <Eigen/Core>

#include "common/base/ids.h"
#include "common/camera/camera_model.h"
#include "common/geometry/rigid3.h"

namespace sandtable::node {

// A unit's own knowledge: camera, projector, projector_from_camera (factory, or refined).
struct UnitModel {
  NodeId unit = kInvalidNodeId;
  CameraModel camera;
  CameraModel projector;
  Rigid3d projector_from_camera;
};

struct CameraObservation {
  NodeId camera_unit = kInvalidNodeId;
  Eigen::Vector2d camera_px = Eigen::Vector2d::Zero();
};

struct Track {
  NodeId projector_unit = kInvalidNodeId;
  Eigen::Vector2d projector_px = Eigen::Vector2d::Zero();
  std::vector<CameraObservation> cameras;
};

struct ClusterObservations {
  std::map<NodeId, UnitModel> units;  // factory knowledge of every unit taking part
  std::vector<Track> tracks;
};

}  // namespace sandtable::node
