#include "node/calibration/cluster_initializer.h"

#include <deque>
#include <set>

#include "common/estimation/resection.h"
#include "common/estimation/triangulation.h"

namespace sandtable::node {

Expected<LocalGeometry> EstimateLocalGeometry(const UnitModel& self,
                                              const std::map<NodeId, CameraModel>& cameras,
                                              const std::vector<Track>& tracks_of_self,
                                              const LocalGeometryOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  LocalGeometry out;
  out.unit = self.unit;
  out.tracks = static_cast<int>(tracks_of_self.size());
  TriangulationOptions triangulation;
  triangulation.min_angle_deg = options.min_triangulation_angle_deg;
  const Rigid3d camera_from_projector = self.projector_from_camera.Inverse();
  // Points in the projector's frame, per other camera: (point, pixel).
  std::map<NodeId, std::pair<std::vector<Eigen::Vector3d>, std::vector<Eigen::Vector2d>>> shared;
  int with_own = 0;
  std::string first_failure;
  for (const Track& track : tracks_of_self) {
    const CameraObservation* own = nullptr;
    for (const CameraObservation& o : track.cameras) {
      if (o.camera_unit == self.unit) own = &o;
    }
    if (!own) continue;
    ++with_own;
    TriangulationView views[2];
    views[0].camera = self.projector;
    views[0].camera_from_world = Rigid3d::Identity();
    views[0].observed_px = track.projector_px;
    views[1].camera = self.camera;
    views[1].camera_from_world = camera_from_projector;
    views[1].observed_px = own->camera_px;
    Expected<TriangulationReport> point = TriangulatePoint(views, triangulation);
    if (!point.ok() || point->rms_px > options.max_triangulation_rms_px) {
      if (first_failure.empty()) {
        first_failure = point.ok() ? "reprojection " + std::to_string(point->rms_px) + " px"
                                   : point.status().message();
      }
      continue;
    }
    ++out.triangulated;
    for (const CameraObservation& o : track.cameras) {
      if (o.camera_unit == self.unit || !cameras.count(o.camera_unit)) continue;
      auto& [points, pixels] = shared[o.camera_unit];
      points.push_back(point->point_in_world);
      pixels.push_back(o.camera_px);
    }
  }
  if (out.triangulated < options.min_shared_points) {
    return DegenerateError("unit " + std::to_string(self.unit) + ": its own camera triangulated " +
                           std::to_string(out.triangulated) + " of the " +
                           std::to_string(with_own) + " points of its projector it saw (at least " +
                           std::to_string(options.min_shared_points) + " needed)" +
                           (first_failure.empty() ? "" : "; first refused: " + first_failure));
  }
  for (const auto& [camera_unit, data] : shared) {
    const auto& [points, pixels] = data;
    if (static_cast<int>(points.size()) < options.min_shared_points) {
      out.notes.push_back("camera " + std::to_string(camera_unit) + ": " +
                          std::to_string(points.size()) + " shared points, too few for a pose");
      continue;
    }
    const CameraModel& camera = cameras.at(camera_unit);
    ResectionOptions resection;
    resection.fix_intrinsics = true;
    resection.fix_distortion = true;
    resection.initial_camera = camera;
    resection.loss = ResectionLoss::kHuber;
    resection.loss_scale_px = options.resection_loss_scale_px;
    resection.estimate_uncertainty = false;
    Expected<ResectionResult> pose =
        EstimateResection(points, pixels, camera.width_px, camera.height_px, resection);
    if (!pose.ok()) {
      out.notes.push_back("camera " + std::to_string(camera_unit) + ": " + pose.status().message());
      continue;
    }
    RelativePose relative;
    relative.camera_from_projector = pose->camera_from_world;
    relative.points = static_cast<int>(points.size());
    relative.rms_px = pose->report.final_rms_px;
    out.neighbours[camera_unit] = relative;
  }
  return out;
}

std::map<NodeId, Rigid3d> ChainProjectorPoses(NodeId root, const std::map<NodeId, UnitModel>& units,
                                              const std::map<NodeId, LocalGeometry>& local) {
  // Edges i -> j: projector_j_from_projector_i (and the inverse for j -> i).
  std::map<NodeId, std::map<NodeId, Rigid3d>> edges;  // edges[a][b] = projector_b_from_projector_a
  for (const auto& [i, geometry] : local) {
    for (const auto& [j, relative] : geometry.neighbours) {
      auto unit = units.find(j);
      if (unit == units.end()) continue;
      const Rigid3d b_from_a = unit->second.projector_from_camera * relative.camera_from_projector;
      // Keep the first estimate of a pair (lower id projecting first: deterministic).
      if (!edges[i].count(j)) edges[i][j] = b_from_a;
      if (!edges[j].count(i)) edges[j][i] = b_from_a.Inverse();
    }
  }
  std::map<NodeId, Rigid3d> projector_from_world;
  if (!units.count(root)) return projector_from_world;
  projector_from_world[root] = Rigid3d::Identity();
  std::deque<NodeId> queue{root};
  while (!queue.empty()) {
    const NodeId a = queue.front();
    queue.pop_front();
    for (const auto& [b, b_from_a] : edges[a]) {
      if (projector_from_world.count(b)) continue;
      projector_from_world[b] = b_from_a * projector_from_world[a];
      queue.push_back(b);
    }
  }
  return projector_from_world;
}

Status LocalGeometryOptions::Check() const {
  if (min_shared_points < 6 || !(min_triangulation_angle_deg > 0.0) ||
      !(max_triangulation_rms_px > 0.0) || !(resection_loss_scale_px > 0.0)) {
    return InvalidArgumentError(
        "local geometry: min_shared_points >= 6; angle, rms and loss scale > 0");
  }
  return OkStatus();
}

}  // namespace sandtable::node
