#include "node/calibration/cluster_solver.h"

#include <algorithm>
#include <cmath>
#include <utility>

#include "common/base/thread_cpu_time.h"
#include "common/estimation/resection.h"
#include "common/estimation/triangulation.h"
#include "node/calibration/cluster_uncertainty.h"

namespace sandtable::node {
namespace {
// The change report judges a model only when it saw at least this many of its buildings.
constexpr int kMinJudgedBuildings = 3;
// A placement that puts this share of the buildings it saw in place is taken without
// judging the next candidates.
constexpr double kConvincingPresent = 0.8;
}  // namespace
namespace {

struct TableFit {
  Rigid3d table_from_world;
  TableFrameReport frame;
  int table_points = 0;
  double rms_mm = 0.0;
};

Expected<TableFit> FitTable(const std::vector<Eigen::Vector3d>& points_in_world,
                            const PlaneFitOptions& options, const Eigen::Vector3d& up_hint) {
  Expected<PlaneFitReport> plane = FitPlaneRansac(points_in_world, options);
  if (!plane.ok()) return plane.status();
  std::vector<Eigen::Vector3d> on_table;
  for (size_t i = 0; i < points_in_world.size(); ++i) {
    if (plane->inlier_mask[i]) on_table.push_back(points_in_world[i]);
  }
  Expected<TableFrameReport> frame = BuildTableFrame(plane->plane, on_table, up_hint);
  if (!frame.ok()) return frame.status();
  TableFit fit;
  fit.table_from_world = frame->table_from_source;
  fit.frame = *frame;
  fit.table_points = plane->num_inliers;
  fit.rms_mm = plane->rms_m * 1e3;
  return fit;
}

}  // namespace

UnitCalibration SolvedUnitCalibration(NodeId id, const UnitModel& unit,
                                      const Rigid3d& table_from_projector,
                                      const ClusterSolution& solution) {
  UnitCalibration c;
  c.unit_id = id;
  c.source = kSourceStructuredLight;
  c.camera = unit.camera;
  c.projector = unit.projector;
  c.projector_from_camera = unit.projector_from_camera;
  c.table_from_projector = table_from_projector;
  if (solution.model) c.table_from_model = solution.model->table_from_model;
  const auto report = solution.bundle.units.find(id);
  if (report != solution.bundle.units.end()) {
    c.camera_rms_px = report->second.camera_rms_px;
    c.projector_rms_px = report->second.projector_rms_px;
  }
  return c;
}

namespace {

// The units with fewer projector observations in `report` than `share` of the median unit's.
std::vector<NodeId> StarvedUnits(const BundleReport& report, double share) {
  std::vector<int> seen;
  for (const auto& [id, u] : report.units) seen.push_back(u.projector_observations);
  std::vector<NodeId> out;
  if (seen.size() < 2) return out;
  std::sort(seen.begin(), seen.end());
  const double bound = share * seen[seen.size() / 2];
  for (const auto& [id, u] : report.units) {
    if (u.projector_observations < bound) out.push_back(id);
  }
  return out;
}

}  // namespace

std::vector<NodeId> ResectStarvedUnits(const ClusterObservations& observations,
                                       const BundleResult& bundle,
                                       const ClusterSolveOptions& options,
                                       std::map<NodeId, Rigid3d>* projector_from_world) {
  constexpr int kMinPoints = 12;
  constexpr double kMaxTriangulationRms_px = 2.0;
  constexpr double kMaxResectionRms_px = 3.0;
  const std::vector<NodeId> starved = StarvedUnits(bundle.report, options.bundle_starved_share);
  std::vector<NodeId> moved;
  TriangulationOptions triangulation;
  triangulation.min_angle_deg = 2.0;
  for (NodeId id : starved) {
    const auto unit = observations.units.find(id);
    if (unit == observations.units.end()) continue;
    std::vector<Eigen::Vector3d> points;
    std::vector<Eigen::Vector2d> pixels;
    for (const Track& track : observations.tracks) {
      if (track.projector_unit != id) continue;
      std::vector<TriangulationView> views;
      for (const CameraObservation& o : track.cameras) {
        if (o.camera_unit == id ||
            std::find(starved.begin(), starved.end(), o.camera_unit) != starved.end()) {
          continue;
        }
        const auto pose = bundle.projector_from_world.find(o.camera_unit);
        const auto model = bundle.units.find(o.camera_unit);
        if (pose == bundle.projector_from_world.end() || model == bundle.units.end()) continue;
        views.push_back({model->second.camera,
                         model->second.projector_from_camera.Inverse() * pose->second,
                         o.camera_px});
      }
      if (views.size() < 2) continue;
      Expected<TriangulationReport> point = TriangulatePoint(views, triangulation);
      if (!point.ok() || point->rms_px > kMaxTriangulationRms_px) continue;
      points.push_back(point->point_in_world);
      pixels.push_back(track.projector_px);
    }
    if (static_cast<int>(points.size()) < kMinPoints) continue;
    ResectionOptions resection;
    resection.fix_intrinsics = resection.fix_distortion = true;
    resection.initial_camera = unit->second.projector;
    resection.loss = ResectionLoss::kHuber;
    resection.loss_scale_px = 2.0;
    resection.estimate_uncertainty = false;
    Expected<ResectionResult> r = EstimateResection(points, pixels, unit->second.projector.width_px,
                                                    unit->second.projector.height_px, resection);
    if (!r.ok() || r->report.final_rms_px > kMaxResectionRms_px) continue;
    (*projector_from_world)[id] = r->camera_from_world;
    moved.push_back(id);
  }
  return moved;
}

Expected<ClusterSolution> SolveCluster(NodeId root, const ClusterObservations& observations,
                                       const std::map<NodeId, LocalGeometry>& local,
                                       const Scene* model, const ClusterSolveOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  const double cpu_start = ThreadCpuSeconds();
  ClusterSolution out;
  const std::map<NodeId, Rigid3d> initial = ChainProjectorPoses(root, observations.units, local);
  for (const auto& [id, unit] : observations.units) {
    if (!initial.count(id)) {
      out.notes.push_back("unit " + std::to_string(id) +
                          ": no pose relative to the cluster (no camera shares enough points "
                          "with it); left out");
    }
  }
  double stage_start = ThreadCpuSeconds();
  auto stage_done = [&](const std::string& name) {
    const double now = ThreadCpuSeconds();
    out.stage_time_s[name] += now - stage_start;
    stage_start = now;
  };
  Expected<BundleResult> bundle = AdjustCluster(observations, initial, root, options.bundle);
  if (!bundle.ok()) return bundle.status();
  // Poses chained pair by pair over a long path (grid-12) can start a unit several pixels off:
  // its tracks fail the triangulation check and the solve sees few of them (grid-12's unit 10:
  // 33 projector observations of thousands decoded, 22 mm rms). When a unit was so starved,
  // solve again from the solved poses while they let markedly more tracks in. (Not otherwise:
  // on sandtable-3, with no unit starved, a second solve took 29 % more tracks, the ones the
  // first poses rejected, and registered 0.142 mm rms against 0.123.)
  auto starved = [&](const BundleReport& report) {
    return !StarvedUnits(report, options.bundle_starved_share).empty();
  };
  for (int pass = 1; pass < options.bundle_passes && starved(bundle->report); ++pass) {
    const int could = TracksThatTriangulate(observations, bundle->projector_from_world);
    if (could < bundle->report.tracks_used * (1.0 + options.bundle_pass_gain)) break;
    Expected<BundleResult> again =
        AdjustCluster(observations, bundle->projector_from_world, root, options.bundle);
    if (!again.ok() || again->report.tracks_used <= bundle->report.tracks_used) break;
    out.notes.push_back(
        "bundle solved again from its own poses: " + std::to_string(bundle->report.tracks_used) +
        " -> " + std::to_string(again->report.tracks_used) + " tracks");
    bundle = std::move(again);
  }
  // A unit whose pose was far off, not a few pixels (grid-32 at half resolution: two units 126
  // and 201 mm off with 43 observations), gains nothing from that. Its projector is resected
  // instead from the points the other units' cameras triangulate on its light, with its factory
  // intrinsics, and the bundle solved again from there if that lets more tracks in.
  if (starved(bundle->report)) {
    std::map<NodeId, Rigid3d> poses = bundle->projector_from_world;
    const std::vector<NodeId> moved = ResectStarvedUnits(observations, *bundle, options, &poses);
    if (!moved.empty()) {
      Expected<BundleResult> again = AdjustCluster(observations, poses, root, options.bundle);
      if (again.ok() && again->report.tracks_used > bundle->report.tracks_used) {
        std::string ids;
        for (NodeId id : moved) ids += (ids.empty() ? "" : ", ") + std::to_string(id);
        out.notes.push_back("unit(s) " + ids + " resected from the others' points; bundle " +
                            std::to_string(bundle->report.tracks_used) + " -> " +
                            std::to_string(again->report.tracks_used) + " tracks");
        bundle = std::move(again);
      }
    }
  }
  stage_done("bundle");
  out.bundle = bundle->report;
  std::map<NodeId, Rigid3d> projector_from_world = bundle->projector_from_world;
  std::map<NodeId, UnitModel> units = bundle->units;
  std::vector<Eigen::Vector3d> points = bundle->points_in_world;
  // The prediction of the bundle whose points and poses the solution keeps.
  BundleReport predicting = bundle->report;
  std::optional<BundleUncertainty> uncertainty = bundle->uncertainty;
  bool scale_from_model = false;

  // The root projector's centre (the world origin) is above the table.
  Expected<TableFit> table = FitTable(points, options.plane, Eigen::Vector3d::Zero());
  if (!table.ok()) return DegenerateError("table plane: " + table.status().message());
  auto to_table = [&](const TableFit& fit) {
    out.points_in_table_m.clear();
    for (const Eigen::Vector3d& p : points)
      out.points_in_table_m.push_back(fit.table_from_world * p);
  };
  to_table(*table);
  stage_done("table");

  std::optional<ModelMatcher> matcher;
  if (model) matcher.emplace(*model, options.model);
  if (matcher) {
    Expected<std::vector<ModelRegistration>> candidates =
        matcher->RegisterCandidates(out.points_in_table_m, options.model_candidates);
    stage_done("model");
    Expected<ModelRegistration> found = candidates.ok()
                                            ? Expected<ModelRegistration>(candidates->front())
                                            : Expected<ModelRegistration>(candidates.status());
    // What each candidate placement shows, building by building (in the model frame, so before
    // its scale is applied: the scan divided by it). Of placements that fit about as well (a
    // city's regular blocks), the one that puts the most buildings in place (present, or within
    // the change report's placement tolerance: a wide site's scan is off by some mm here and
    // there) is taken, the most present first among equals (judged in order, stopping at one
    // that puts 80 % of them in place).
    // If even that one leaves most of the buildings it saw further off or missing, the table
    // matched the table: the model is not what stands there, and neither its placement nor its
    // scale is used.
    if (found.ok()) {
      std::pair<int, int> best_count(-1, -1);  // in place, present
      for (ModelRegistration candidate : *candidates) {
        if (candidate.coarse_only) {
          Expected<ModelRegistration> refined = matcher->Refine(
              out.points_in_table_m, candidate.table_from_model, options.model.estimate_scale);
          if (!refined.ok()) continue;
          refined->coarse_score = candidate.coarse_score;
          refined->candidates_tried = candidate.candidates_tried;
          refined->structure_fraction = candidate.structure_fraction;
          candidate = *refined;
        }
        std::vector<Eigen::Vector3d> in_model_scale = out.points_in_table_m;
        if (candidate.scale > 0) {
          for (Eigen::Vector3d& p : in_model_scale) p /= candidate.scale;
        }
        Expected<ModelChangeReport> changes =
            DetectModelChanges(*model, in_model_scale, candidate.table_from_model, options.changes);
        if (!changes.ok()) {
          out.notes.push_back("change report: " + changes.status().message());
          break;
        }
        const int observed = changes->present + changes->moved + changes->missing;
        const bool convincing = changes->in_place >= kConvincingPresent * observed;
        const std::pair<int, int> count(changes->in_place, changes->present);
        if (count > best_count) {
          best_count = count;
          found = candidate;
          out.changes = std::move(*changes);
        }
        if (convincing) break;  // the next candidates only cost time
      }
      stage_done("changes");
      if (out.changes) {
        const int observed = out.changes->present + out.changes->moved + out.changes->missing;
        if (observed >= kMinJudgedBuildings && 2 * out.changes->in_place < observed) {
          found = NotFoundError(
              "model registration: the model does not match the scanned surface (of " +
              std::to_string(observed) + " buildings seen, " +
              std::to_string(out.changes->in_place) + " stand within " +
              std::to_string(std::lround(options.changes.placement_tolerance_m * 1e3)) +
              " mm of where the best placement puts them, " +
              std::to_string(observed - out.changes->in_place - out.changes->missing) +
              " further off, " + std::to_string(out.changes->missing) + " missing; " +
              std::to_string(out.changes->extras.size()) + " structures not in the model)");
        }
      }
    }
    // A placement that needs the model scaled by more than max_scale_correction is not this
    // model in metres: its buildings would be drawn at the wrong size and place, so neither its
    // placement nor its scale is used.
    if (found.ok() && options.scale_from_model &&
        !(std::abs(found->scale - 1.0) <= options.max_scale_correction)) {
      found = NotFoundError("model registration: the best placement needs the model at scale " +
                            std::to_string(found->scale) + ", more than " +
                            std::to_string(std::lround(options.max_scale_correction * 100)) +
                            " % from 1: not this model in metres; not placed");
    }
    if (!found.ok()) {
      out.notes.push_back(found.status().message());
    } else {
      double scale = found->scale;
      std::optional<Rigid3d> table_from_model = found->table_from_model;
      if (options.scale_from_model) {  // within max_scale_correction: refused above otherwise
        // Lengths / scale: points, projector translations, mount translations.
        const double k = 1.0 / scale;
        for (Eigen::Vector3d& p : points) p *= k;
        for (auto& [id, pose] : projector_from_world) pose.translation *= k;
        for (auto& [id, unit] : units) unit.projector_from_camera.translation *= k;
        out.scale_correction = k;
        scale_from_model = true;
        table = FitTable(points, options.plane, Eigen::Vector3d::Zero());
        if (!table.ok()) return DegenerateError("table plane: " + table.status().message());
        to_table(*table);
        Expected<ModelRegistration> refined =
            matcher->Refine(out.points_in_table_m, found->table_from_model, false);
        if (refined.ok()) table_from_model = refined->table_from_model;
      }
      if (options.refine_with_model && table_from_model) {
        // Second refinement: the points tied to the model's surface.
        const Rigid3d world_from_model = table->table_from_world.Inverse() * *table_from_model;
        const Rigid3d model_from_world = world_from_model.Inverse();
        BundleResult previous;
        previous.units = units;
        previous.projector_from_world = projector_from_world;
        previous.points_in_world = points;
        previous.point_track = bundle->point_track;
        BundleWarmStart warm;
        warm.previous = &previous;
        warm.surface_sigma_m = options.model_surface_sigma_m;
        for (size_t i = 0; i < points.size(); ++i) {
          Eigen::Vector3d q, n;
          if (matcher->SurfacePlaneNear(model_from_world * points[i],
                                        options.model_surface_max_distance_m, &q, &n)) {
            warm.surface.push_back(
                {static_cast<int>(i), world_from_model * q, world_from_model.rotation * n});
          }
        }
        stage_done("model");
        Expected<BundleResult> second =
            AdjustCluster(observations, projector_from_world, root, options.bundle, &warm);
        stage_done("model_bundle");
        if (second.ok()) {
          out.model_bundle = second->report;
          predicting = second->report;
          uncertainty = second->uncertainty;
          units = second->units;
          projector_from_world = second->projector_from_world;
          points = second->points_in_world;
          table = FitTable(points, options.plane, Eigen::Vector3d::Zero());
          if (!table.ok()) return DegenerateError("table plane: " + table.status().message());
          to_table(*table);
          // The model stands where it was, in the refined world frame.
          table_from_model = table->table_from_world * world_from_model;
        } else {
          out.notes.push_back("refinement against the model: " + second.status().message());
        }
      }
      Expected<ModelRegistration> final_fit =
          matcher->Refine(out.points_in_table_m, *table_from_model, false);
      stage_done("model");
      if (final_fit.ok()) {
        final_fit->coarse_score = found->coarse_score;
        final_fit->candidates_tried = found->candidates_tried;
        final_fit->structure_fraction = found->structure_fraction;
        final_fit->by_outline = found->by_outline;
        final_fit->scale = scale;
        final_fit->relief_scale = found->relief_scale;
        out.model = *final_fit;
      } else {
        out.notes.push_back(final_fit.status().message());
        out.model = *found;
      }
    }
  }
  out.table_from_world = table->table_from_world;
  out.frame = table->frame;
  out.table_points = table->table_points;
  out.table_plane_rms_mm = table->rms_mm;
  std::vector<double> heights;
  for (const Eigen::Vector3d& p : out.points_in_table_m) heights.push_back(p.z());
  if (!heights.empty()) {
    const size_t k = std::min(heights.size() - 1, static_cast<size_t>(heights.size() * 0.999));
    std::nth_element(heights.begin(), heights.begin() + static_cast<std::ptrdiff_t>(k),
                     heights.end());
    out.max_height_mm = heights[k] * 1e3;
  }
  out.planar = out.max_height_mm < options.planar_threshold_mm;

  for (const auto& [id, unit] : units) {
    out.calibrations[id] = SolvedUnitCalibration(
        id, unit, out.table_from_world * projector_from_world.at(id).Inverse(), out);
  }
  if (uncertainty) {
    TablePredictionOptions prediction;
    prediction.scale_follows_the_model = scale_from_model;
    PredictOnTable(predicting, *uncertainty, out.points_in_table_m, &out.calibrations, prediction);
  }
  if (!predicting.uncertainty_note.empty()) {
    out.notes.push_back("predicted error: " + predicting.uncertainty_note);
  }
  out.time_s = ThreadCpuSeconds() - cpu_start;
  return out;
}

Status ClusterSolveOptions::Check() const {
  ST_RETURN_IF_ERROR(bundle.Check());
  ST_RETURN_IF_ERROR(plane.Check());
  ST_RETURN_IF_ERROR(model.Check());
  ST_RETURN_IF_ERROR(changes.Check());
  if (bundle_passes < 1 || !(bundle_pass_gain >= 0.0) ||
      !(bundle_starved_share >= 0.0 && bundle_starved_share <= 1.0) || model_candidates < 1 ||
      !(max_scale_correction >= 0.0 && max_scale_correction < 1.0) ||
      !(model_surface_sigma_m > 0.0) || !(model_surface_max_distance_m > 0.0) ||
      !(planar_threshold_mm >= 0.0)) {
    return InvalidArgumentError(
        "cluster solve: bundle_passes, model_candidates >= 1; gain >= 0; starved share in "
        "[0, 1]; max_scale_correction in [0, 1); surface sigma and distance > 0; planar "
        "threshold >= 0");
  }
  return OkStatus();
}

}  // namespace sandtable::node
