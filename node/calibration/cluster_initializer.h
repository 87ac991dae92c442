// First estimates of a cluster self-calibration, from factory knowledge alone.
//
// EstimateLocalGeometry runs on each projecting node i: it triangulates the tracks of its
// projector that its own camera saw (its camera + projector are a calibrated stereo pair,
// baseline projector_from_camera), in projector i's frame, and then, for every other camera j
// that saw at least min_shared_points of those points, estimates camera_j_from_projector_i by
// resection with camera j's factory intrinsics held fixed (Huber loss: a few wrong decodes do
// not move it). That is the node's pose relative to its neighbours, from the points they share.
//
// ChainProjectorPoses runs on the node that solves the cluster: projector_j_from_projector_i =
// projector_from_camera_j * camera_j_from_projector_i for every estimated pair, then a
// breadth-first walk from the root unit (lowest id first, deterministic) gives
// projector_from_world for every unit reachable from the root, world = the root projector's
// frame. Units not reached are left out (the caller reports them).
// Errors: DEGENERATE when the own camera triangulates fewer than min_shared_points points.
#pragma once

#include <map>
#include <string>
#include <vector>

#include "common/base/status.h"
#include "node/calibration/cluster_problem.h"

namespace sandtable::node {

struct LocalGeometryOptions {
  int min_shared_points = 30;
  double min_triangulation_angle_deg = 1.0;
  // Initialization only: with factory errors the two-view residual is a few px (measured up
  // to ~5 px on sandtable-3), the bundle adjustment then takes it to ~0.02 px.
  double max_triangulation_rms_px = 10.0;
  double resection_loss_scale_px = 1.0;
  Status Check() const;
};

struct RelativePose {
  Rigid3d camera_from_projector;  // camera of unit `camera_unit` from this node's projector
  int points = 0;
  double rms_px = 0.0;
};

struct LocalGeometry {
  NodeId unit = kInvalidNodeId;
  int tracks = 0;                             // tracks of this projector
  int triangulated = 0;                       // with the own camera
  std::map<NodeId, RelativePose> neighbours;  // by camera unit (not the own one)
  std::vector<std::string> notes;             // cameras skipped, and why
};

Expected<LocalGeometry> EstimateLocalGeometry(const UnitModel& self,
                                              const std::map<NodeId, CameraModel>& cameras,
                                              const std::vector<Track>& tracks_of_self,
                                              const LocalGeometryOptions& options = {});

// projector_from_world per reachable unit (world = root's projector frame).
std::map<NodeId, Rigid3d> ChainProjectorPoses(NodeId root, const std::map<NodeId, UnitModel>& units,
                                              const std::map<NodeId, LocalGeometry>& local);

}  // namespace sandtable::node
