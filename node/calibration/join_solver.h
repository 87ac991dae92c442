// A unit that joins a calibrated site (docs/calibration.md, "Live join"): it is calibrated
// against its calibrated neighbours, which are held, so nobody else is recalibrated.
//
// Input: the site's last solution (every calibrated unit's refined models and table pose, the
// model's placement), the joining units' factory models, the tracks of their projectors (seen
// by their own cameras and by the neighbours' cameras) and their local geometry (the pose of
// each neighbour camera that shares their points, cluster_initializer.h).
// Method: the joining projector's first pose in the table frame comes from the neighbour camera
// that shares the most points: projector_from_table = (camera_from_projector)^-1 *
// camera_from_table (the neighbour's, from its calibration). Then the cluster bundle
// (cluster_bundle.h) with every calibrated unit held (BundleOptions::held_units; the table
// frame is their world) and the joining units' parameters free about their factory priors.
// Output: a ClusterSolution that is the site's, with `calibrations` holding the joining units
// only (table_from_model: the site's), the bundle report of the join, and notes.
// Errors: DEGENERATE when no joining unit shares enough points with a calibrated camera;
// the bundle's.
#pragma once

#include <map>

#include "common/base/status.h"
#include "node/calibration/cluster_bundle.h"
#include "node/calibration/cluster_initializer.h"
#include "node/calibration/cluster_solver.h"

namespace sandtable::node {

Expected<ClusterSolution> SolveJoin(const ClusterSolution& site, const ClusterObservations& joining,
                                    const std::map<NodeId, LocalGeometry>& local,
                                    BundleOptions options = {});

}  // namespace sandtable::node
