// The site's solve from what its units observed, one function for the elected runner
// (node/app/self_calibration_solve.cc) and the in-process harness (tests/testing/
// self_calibration_sim.h), so that the two cannot drift apart.
#pragma once

#include <map>

#include "common/base/ids.h"
#include "common/base/status.h"
#include "common/scene/scene.h"
#include "node/calibration/cluster_initializer.h"
#include "node/calibration/cluster_solver.h"
#include "node/calibration/planar_solver.h"

namespace sandtable::node {

enum class SitePath {
  kPlanar,  // every unit's footprint is planar: SolvePlanarCluster, the full path if it fails
  kFull,    // SolveCluster from the units' local geometry
};

struct SiteSolveOptions {
  ClusterSolveOptions full;
  PlanarSolveOptions planar;
  Status Check() const;
};

struct SiteSolveResult {
  ClusterSolution solution;
  SitePath path = SitePath::kFull;  // the path that gave the solution
  bool fell_back = false;           // the planar path failed and the full path solved
};

// Each unit's local geometry from the site's observations (its own projector's tracks seen by
// every camera), as every unit estimates its own before it sends its input; a unit whose
// geometry cannot be estimated is left out of the map.
std::map<NodeId, LocalGeometry> LocalGeometries(const ClusterObservations& observations);

// Solves the site rooted at `root` (its projector's frame is the world's) on `path`. A planar
// solve that fails is followed by the full solve, which still has every correspondence; its
// solution notes why. `model` may be null (no model to place).
Expected<SiteSolveResult> SolveSite(NodeId root, const ClusterObservations& observations,
                                    const std::map<NodeId, LocalGeometry>& local,
                                    const Scene* model, SitePath path,
                                    const SiteSolveOptions& options);

}  // namespace sandtable::node
