#include "node/calibration/site_solve.h"

#include <string>
#include <utility>
#include <vector>

namespace sandtable::node {

Status SiteSolveOptions::Check() const {
  ST_RETURN_IF_ERROR(full.Check());
  return planar.Check();
}

std::map<NodeId, LocalGeometry> LocalGeometries(const ClusterObservations& observations) {
  std::map<NodeId, CameraModel> cameras;
  for (const auto& [id, unit] : observations.units) cameras[id] = unit.camera;
  std::map<NodeId, LocalGeometry> local;
  for (const auto& [id, unit] : observations.units) {
    std::vector<Track> own;
    for (const Track& t : observations.tracks) {
      if (t.projector_unit == id) own.push_back(t);
    }
    Expected<LocalGeometry> geometry = EstimateLocalGeometry(unit, cameras, own);
    if (geometry.ok()) local[id] = std::move(*geometry);
  }
  return local;
}

Expected<SiteSolveResult> SolveSite(NodeId root, const ClusterObservations& observations,
                                    const std::map<NodeId, LocalGeometry>& local,
                                    const Scene* model, SitePath path,
                                    const SiteSolveOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  SiteSolveResult out;
  out.path = path;
  if (path == SitePath::kPlanar) {
    Expected<ClusterSolution> planar =
        SolvePlanarCluster(root, observations, model, options.planar);
    if (planar.ok()) {
      out.solution = std::move(*planar);
      return out;
    }
    const std::string why = planar.status().message();
    Expected<ClusterSolution> full = SolveCluster(root, observations, local, model, options.full);
    if (!full.ok()) return full.status();
    full->notes.push_back("planar path failed (" + why + "); full path");
    out.solution = std::move(*full);
    out.path = SitePath::kFull;
    out.fell_back = true;
    return out;
  }
  Expected<ClusterSolution> full = SolveCluster(root, observations, local, model, options.full);
  if (!full.ok()) return full.status();
  out.solution = std::move(*full);
  return out;
}

}  // namespace sandtable::node
