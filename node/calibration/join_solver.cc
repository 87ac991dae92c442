#include "node/calibration/join_solver.h"

#include "common/base/thread_cpu_time.h"

namespace sandtable::node {

Expected<ClusterSolution> SolveJoin(const ClusterSolution& site, const ClusterObservations& joining,
                                    const std::map<NodeId, LocalGeometry>& local,
                                    BundleOptions options) {
  const double cpu_start = ThreadCpuSeconds();
  ClusterObservations observations;
  std::map<NodeId, Rigid3d> projector_from_table;
  options.held_units.clear();
  for (const auto& [id, c] : site.calibrations) {
    if (!c.table_from_projector) continue;
    observations.units[id] = UnitModel{id, c.camera, c.projector, c.projector_from_camera};
    projector_from_table[id] = c.table_from_projector->Inverse();
    options.held_units.insert(id);
  }
  if (observations.units.empty()) {
    return DegenerateError("join: the site holds no calibrated unit to join");
  }
  ClusterSolution out = site;
  out.calibrations.clear();
  out.notes.clear();
  out.stage_time_s.clear();
  out.model_bundle.reset();
  for (const auto& [id, unit] : joining.units) {
    if (observations.units.count(id)) continue;  // calibrated already: held
    auto geometry = local.find(id);
    const RelativePose* best = nullptr;
    NodeId best_camera = kInvalidNodeId;
    if (geometry != local.end()) {
      for (const auto& [camera, relative] : geometry->second.neighbours) {
        if (!options.held_units.count(camera)) continue;
        if (!best || relative.points > best->points) {
          best = &relative;
          best_camera = camera;
        }
      }
    }
    if (!best) {
      out.notes.push_back("unit " + std::to_string(id) +
                          ": no calibrated camera shares enough of its points; not joined");
      continue;
    }
    const UnitModel& neighbour = observations.units.at(best_camera);
    const Rigid3d camera_from_table =
        neighbour.projector_from_camera.Inverse() * projector_from_table.at(best_camera);
    observations.units[id] = unit;
    projector_from_table[id] = best->camera_from_projector.Inverse() * camera_from_table;
    out.notes.push_back("unit " + std::to_string(id) + ": first pose from camera " +
                        std::to_string(best_camera) + " (" + std::to_string(best->points) +
                        " shared points)");
  }
  for (const Track& t : joining.tracks) {
    if (observations.units.count(t.projector_unit) && !options.held_units.count(t.projector_unit)) {
      observations.tracks.push_back(t);
    }
  }
  if (observations.units.size() == options.held_units.size()) {
    return DegenerateError("join: no joining unit could be placed against the site");
  }
  const NodeId root = *options.held_units.begin();
  Expected<BundleResult> bundle = AdjustCluster(observations, projector_from_table, root, options);
  if (!bundle.ok()) return bundle.status();
  // The first pose came from one neighbour camera's relative pose (factory models); a track
  // that another camera also sees does not triangulate from it when that camera disagrees by
  // more than the triangulation's gate, and the whole track is left out: the solve then rests
  // on the first neighbour alone. Once more from the refined pose, so that every camera that
  // sees the joining units counts; kept when more tracks triangulate.
  if (bundle->report.tracks_untriangulated > 0) {
    for (const auto& [id, unit] : observations.units) {
      if (!options.held_units.count(id) && bundle->projector_from_world.count(id)) {
        projector_from_table[id] = bundle->projector_from_world.at(id);
      }
    }
    Expected<BundleResult> again = AdjustCluster(observations, projector_from_table, root, options);
    if (again.ok() && again->report.tracks_untriangulated < bundle->report.tracks_untriangulated) {
      out.notes.push_back("joined units posed again from the first solve: " +
                          std::to_string(bundle->report.tracks_untriangulated) + " -> " +
                          std::to_string(again->report.tracks_untriangulated) +
                          " tracks that do not triangulate");
      bundle = std::move(again);
    }
  }
  out.bundle = bundle->report;
  for (const auto& [id, unit] : bundle->units) {
    if (options.held_units.count(id)) continue;
    out.bundle.units[id].free_parameters.push_back("(calibrated units held)");
    out.calibrations[id] =
        SolvedUnitCalibration(id, unit, bundle->projector_from_world.at(id).Inverse(), out);
  }
  out.stage_time_s["join_bundle"] = bundle->report.solve_time_s;
  out.time_s = ThreadCpuSeconds() - cpu_start;
  return out;
}

}  // namespace sandtable::node
