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

StageClock::StageClock(ClusterSolution* out) : out_(out), start_s_(ThreadCpuSeconds()) {}

void StageClock::Done(const std::string& stage) {
  const double now = ThreadCpuSeconds();
  out_->stage_time_s[stage] += now - start_s_;
  start_s_ = now;
}

namespace {

// One solve of the full path: the bundle from the chained poses (solved again where a unit was
// starved), the table, the model (its placement chosen building by building, its scale, a
// second bundle tied to its surface), the units' calibrations.
class FullSolve {
 public:
  FullSolve(NodeId root, const ClusterObservations& observations, const Scene* model,
            const ClusterSolveOptions& options)
      : root_(root), observations_(observations), model_(model), options_(options) {}

  Expected<ClusterSolution> Run(const std::map<NodeId, LocalGeometry>& local);

 private:
  Status SolveBundle(const std::map<NodeId, Rigid3d>& initial);
  bool Starved(const BundleReport& report) const {
    return !StarvedUnits(report, options_.bundle_starved_share).empty();
  }
  // The solution so far becomes `bundle`'s: its poses, units and points, and its prediction.
  void Adopt(const BundleResult& bundle) {
    projector_from_world_ = bundle.projector_from_world;
    units_ = bundle.units;
    points_ = bundle.points_in_world;
    predicting_ = bundle.report;
    uncertainty_ = bundle.uncertainty;
  }
  // The table plane through points_ (the root projector's centre, the world origin, above it)
  // and points_ in its frame.
  Status FitTableFrame();
  void PlaceModel(const ModelMatcher& matcher);
  Expected<ModelRegistration> ChooseCandidate(const ModelMatcher& matcher,
                                              const std::vector<ModelRegistration>& candidates);
  Status ScaleFromModel(const ModelMatcher& matcher, const ModelRegistration& found,
                        Rigid3d* table_from_model);
  Status RefineWithModel(const ModelMatcher& matcher, Rigid3d* table_from_model);
  void Finish();

  const NodeId root_;
  const ClusterObservations& observations_;
  const Scene* model_;
  const ClusterSolveOptions& options_;
  ClusterSolution out_;
  StageClock clock_{&out_};
  Status placing_ = OkStatus();  // a failure while the model was placed that ends the solve
  // The solution so far: poses, units, points, and the bundle whose prediction it keeps.
  std::map<NodeId, Rigid3d> projector_from_world_;
  std::map<NodeId, UnitModel> units_;
  std::vector<Eigen::Vector3d> points_;
  std::vector<int> point_track_;
  BundleReport predicting_;
  std::optional<BundleUncertainty> uncertainty_;
  bool scale_from_model_ = false;
  TableFit table_;
};

Expected<ClusterSolution> FullSolve::Run(const std::map<NodeId, LocalGeometry>& local) {
  const double cpu_start = ThreadCpuSeconds();
  const std::map<NodeId, Rigid3d> initial = ChainProjectorPoses(root_, observations_.units, local);
  for (const auto& [id, unit] : observations_.units) {
    if (!initial.count(id)) {
      out_.notes.push_back("unit " + std::to_string(id) +
                           ": no pose relative to the cluster (no camera shares enough points "
                           "with it); left out");
    }
  }
  clock_ = StageClock(&out_);
  ST_RETURN_IF_ERROR(SolveBundle(initial));
  ST_RETURN_IF_ERROR(FitTableFrame());
  clock_.Done("table");
  if (model_) {
    const ModelMatcher matcher(*model_, options_.model);
    PlaceModel(matcher);
    ST_RETURN_IF_ERROR(placing_);
  }
  Finish();
  out_.time_s = ThreadCpuSeconds() - cpu_start;
  return std::move(out_);
}

Status FullSolve::SolveBundle(const std::map<NodeId, Rigid3d>& initial) {
  Expected<BundleResult> bundle = AdjustCluster(observations_, initial, root_, options_.bundle);
  if (!bundle.ok()) return bundle.status();
  // Poses chained pair by pair over a long path can start a unit several pixels off: its tracks
  // fail the triangulation check and the solve sees few of them. When a unit was so starved,
  // solve again from the solved poses while they let markedly more tracks in (not otherwise: a
  // second solve with no unit starved takes in the tracks the first poses rejected, and
  // registers worse).
  for (int pass = 1; pass < options_.bundle_passes && Starved(bundle->report); ++pass) {
    const int could = TracksThatTriangulate(observations_, bundle->projector_from_world);
    if (could < bundle->report.tracks_used * (1.0 + options_.bundle_pass_gain)) break;
    Expected<BundleResult> again =
        AdjustCluster(observations_, bundle->projector_from_world, root_, options_.bundle);
    if (!again.ok() || again->report.tracks_used <= bundle->report.tracks_used) break;
    out_.notes.push_back(
        "bundle solved again from its own poses: " + std::to_string(bundle->report.tracks_used) +
        " -> " + std::to_string(again->report.tracks_used) + " tracks");
    bundle = std::move(again);
  }
  // A unit whose pose was far off, not a few pixels, gains nothing from that. Its projector is
  // resected instead from the points the other units' cameras triangulate on its light, with
  // its factory intrinsics, and the bundle solved again from there if that lets more tracks in.
  if (Starved(bundle->report)) {
    std::map<NodeId, Rigid3d> poses = bundle->projector_from_world;
    const std::vector<NodeId> moved = ResectStarvedUnits(observations_, *bundle, options_, &poses);
    if (!moved.empty()) {
      Expected<BundleResult> again = AdjustCluster(observations_, poses, root_, options_.bundle);
      if (again.ok() && again->report.tracks_used > bundle->report.tracks_used) {
        std::string ids;
        for (NodeId id : moved) ids += (ids.empty() ? "" : ", ") + std::to_string(id);
        out_.notes.push_back("unit(s) " + ids + " resected from the others' points; bundle " +
                             std::to_string(bundle->report.tracks_used) + " -> " +
                             std::to_string(again->report.tracks_used) + " tracks");
        bundle = std::move(again);
      }
    }
  }
  clock_.Done("bundle");
  out_.bundle = bundle->report;
  point_track_ = bundle->point_track;
  Adopt(*bundle);
  return OkStatus();
}

Status FullSolve::FitTableFrame() {
  Expected<TableFit> table = FitTable(points_, options_.plane, Eigen::Vector3d::Zero());
  if (!table.ok()) return DegenerateError("table plane: " + table.status().message());
  table_ = *table;
  out_.points_in_table_m.clear();
  for (const Eigen::Vector3d& p : points_)
    out_.points_in_table_m.push_back(table_.table_from_world * p);
  return OkStatus();
}

// What each candidate placement shows, building by building (in the model frame, so before its
// scale is applied: the scan divided by it). Of placements that fit about as well (a city's
// regular blocks), the one that puts the most buildings in place (present, or within the change
// report's placement tolerance: a wide site's scan is off by some mm here and there) is taken,
// the most present first among equals (judged in order, stopping at one that puts 80 % of them
// in place). If even that one leaves most of the buildings it saw further off or missing, the
// table matched the table: the model is not what stands there, and neither its placement nor
// its scale is used.
Expected<ModelRegistration> FullSolve::ChooseCandidate(
    const ModelMatcher& matcher, const std::vector<ModelRegistration>& candidates) {
  Expected<ModelRegistration> found = candidates.front();
  std::pair<int, int> best_count(-1, -1);  // in place, present
  for (ModelRegistration candidate : candidates) {
    if (candidate.coarse_only) {
      Expected<ModelRegistration> refined = matcher.Refine(
          out_.points_in_table_m, candidate.table_from_model, options_.model.estimate_scale);
      if (!refined.ok()) continue;
      refined->coarse_score = candidate.coarse_score;
      refined->candidates_tried = candidate.candidates_tried;
      refined->structure_fraction = candidate.structure_fraction;
      candidate = *refined;
    }
    std::vector<Eigen::Vector3d> in_model_scale = out_.points_in_table_m;
    if (candidate.scale > 0) {
      for (Eigen::Vector3d& p : in_model_scale) p /= candidate.scale;
    }
    Expected<ModelChangeReport> changes =
        DetectModelChanges(*model_, in_model_scale, candidate.table_from_model, options_.changes);
    if (!changes.ok()) {
      out_.notes.push_back("change report: " + changes.status().message());
      break;
    }
    const int observed = changes->present + changes->moved + changes->missing;
    const bool convincing = changes->in_place >= kConvincingPresent * observed;
    const std::pair<int, int> count(changes->in_place, changes->present);
    if (count > best_count) {
      best_count = count;
      found = candidate;
      out_.changes = std::move(*changes);
    }
    if (convincing) break;  // the next candidates only cost time
  }
  clock_.Done("changes");
  if (!out_.changes) return found;
  const ModelChangeReport& c = *out_.changes;
  const int observed = c.present + c.moved + c.missing;
  if (observed >= kMinJudgedBuildings && 2 * c.in_place < observed) {
    return NotFoundError("model registration: the model does not match the scanned surface (of " +
                         std::to_string(observed) + " buildings seen, " +
                         std::to_string(c.in_place) + " stand within " +
                         std::to_string(std::lround(options_.changes.placement_tolerance_m * 1e3)) +
                         " mm of where the best placement puts them, " +
                         std::to_string(observed - c.in_place - c.missing) + " further off, " +
                         std::to_string(c.missing) + " missing; " +
                         std::to_string(c.extras.size()) + " structures not in the model)");
  }
  return found;
}

// Lengths / scale (within max_scale_correction): points, projector translations, mount
// translations; the table fitted again and the placement refined at the new scale.
Status FullSolve::ScaleFromModel(const ModelMatcher& matcher, const ModelRegistration& found,
                                 Rigid3d* table_from_model) {
  const double k = 1.0 / found.scale;
  for (Eigen::Vector3d& p : points_) p *= k;
  for (auto& [id, pose] : projector_from_world_) pose.translation *= k;
  for (auto& [id, unit] : units_) unit.projector_from_camera.translation *= k;
  out_.scale_correction = k;
  scale_from_model_ = true;
  ST_RETURN_IF_ERROR(FitTableFrame());
  Expected<ModelRegistration> refined =
      matcher.Refine(out_.points_in_table_m, found.table_from_model, false);
  if (refined.ok()) *table_from_model = refined->table_from_model;
  return OkStatus();
}

// Second refinement: the points tied to the model's surface.
Status FullSolve::RefineWithModel(const ModelMatcher& matcher, Rigid3d* table_from_model) {
  const Rigid3d world_from_model = table_.table_from_world.Inverse() * *table_from_model;
  const Rigid3d model_from_world = world_from_model.Inverse();
  BundleResult previous;
  previous.units = units_;
  previous.projector_from_world = projector_from_world_;
  previous.points_in_world = points_;
  previous.point_track = point_track_;
  BundleWarmStart warm;
  warm.previous = &previous;
  warm.surface_sigma_m = options_.model_surface_sigma_m;
  for (size_t i = 0; i < points_.size(); ++i) {
    Eigen::Vector3d q, n;
    if (matcher.SurfacePlaneNear(model_from_world * points_[i],
                                 options_.model_surface_max_distance_m, &q, &n)) {
      warm.surface.push_back(
          {static_cast<int>(i), world_from_model * q, world_from_model.rotation * n});
    }
  }
  clock_.Done("model");
  Expected<BundleResult> second =
      AdjustCluster(observations_, projector_from_world_, root_, options_.bundle, &warm);
  clock_.Done("model_bundle");
  if (!second.ok()) {
    out_.notes.push_back("refinement against the model: " + second.status().message());
    return OkStatus();
  }
  out_.model_bundle = second->report;
  Adopt(*second);
  ST_RETURN_IF_ERROR(FitTableFrame());
  // The model stands where it was, in the refined world frame.
  *table_from_model = table_.table_from_world * world_from_model;
  return OkStatus();
}

void FullSolve::PlaceModel(const ModelMatcher& matcher) {
  Expected<std::vector<ModelRegistration>> candidates =
      matcher.RegisterCandidates(out_.points_in_table_m, options_.model_candidates);
  clock_.Done("model");
  Expected<ModelRegistration> found = candidates.ok()
                                          ? ChooseCandidate(matcher, *candidates)
                                          : Expected<ModelRegistration>(candidates.status());
  // A placement that needs the model scaled by more than max_scale_correction is not this
  // model in metres: its buildings would be drawn at the wrong size and place, so neither its
  // placement nor its scale is used.
  if (found.ok() && options_.scale_from_model &&
      !(std::abs(found->scale - 1.0) <= options_.max_scale_correction)) {
    found = NotFoundError("model registration: the best placement needs the model at scale " +
                          std::to_string(found->scale) + ", more than " +
                          std::to_string(std::lround(options_.max_scale_correction * 100)) +
                          " % from 1: not this model in metres; not placed");
  }
  if (!found.ok()) {
    out_.notes.push_back(found.status().message());
    return;
  }
  Rigid3d table_from_model = found->table_from_model;
  if (options_.scale_from_model) {
    placing_ = ScaleFromModel(matcher, *found, &table_from_model);
    if (!placing_.ok()) return;
  }
  if (options_.refine_with_model) {
    placing_ = RefineWithModel(matcher, &table_from_model);
    if (!placing_.ok()) return;
  }
  Expected<ModelRegistration> final_fit =
      matcher.Refine(out_.points_in_table_m, table_from_model, false);
  clock_.Done("model");
  if (!final_fit.ok()) {
    out_.notes.push_back(final_fit.status().message());
    out_.model = *found;
    return;
  }
  final_fit->coarse_score = found->coarse_score;
  final_fit->candidates_tried = found->candidates_tried;
  final_fit->structure_fraction = found->structure_fraction;
  final_fit->by_outline = found->by_outline;
  final_fit->scale = found->scale;
  final_fit->relief_scale = found->relief_scale;
  out_.model = *final_fit;
}

// The table frame's report, the scan's height, each unit's calibration on the table and its
// predicted error.
void FullSolve::Finish() {
  out_.table_from_world = table_.table_from_world;
  out_.frame = table_.frame;
  out_.table_points = table_.table_points;
  out_.table_plane_rms_mm = table_.rms_mm;
  std::vector<double> heights;
  for (const Eigen::Vector3d& p : out_.points_in_table_m) heights.push_back(p.z());
  if (!heights.empty()) {
    const size_t k = std::min(heights.size() - 1, static_cast<size_t>(heights.size() * 0.999));
    std::nth_element(heights.begin(), heights.begin() + static_cast<std::ptrdiff_t>(k),
                     heights.end());
    out_.max_height_mm = heights[k] * 1e3;
  }
  out_.planar = out_.max_height_mm < options_.planar_threshold_mm;
  for (const auto& [id, unit] : units_) {
    out_.calibrations[id] = SolvedUnitCalibration(
        id, unit, out_.table_from_world * projector_from_world_.at(id).Inverse(), out_);
  }
  if (uncertainty_) {
    TablePredictionOptions prediction;
    prediction.scale_follows_the_model = scale_from_model_;
    PredictOnTable(predicting_, *uncertainty_, out_.points_in_table_m, &out_.calibrations,
                   prediction);
  }
  if (!predicting_.uncertainty_note.empty()) {
    out_.notes.push_back("predicted error: " + predicting_.uncertainty_note);
  }
}

}  // namespace

Expected<ClusterSolution> SolveCluster(NodeId root, const ClusterObservations& observations,
                                       const std::map<NodeId, LocalGeometry>& local,
                                       const Scene* model, const ClusterSolveOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  return FullSolve(root, observations, model, options).Run(local);
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
