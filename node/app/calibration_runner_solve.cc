// The runner's solve (calibration_runner.h): the round's inputs into the cluster solve
// (or the join solve) on a worker, the round's report, and each unit's result.
#include <algorithm>
#include <cmath>
#include <sstream>
#include <string>
#include <vector>

#include "common/base/log.h"
#include "common/base/thread_cpu_time.h"
#include "common/io/json_codec.h"
#include "common/io/mpcdi_builder.h"
#include "common/scene/procedural_scene.h"
#include "node/app/calibration_runner.h"
#include "node/calibration/join_solver.h"
#include "node/calibration/schedule.h"
#include "node/calibration/site_solve.h"
#include "proto/convert.h"
#include "proto/envelope_stamper.h"

namespace sandtable::node {
namespace {

std::string Fixed(double value, int digits) {
  std::ostringstream out;
  out.setf(std::ios::fixed);
  out.precision(digits);
  out << value;
  return out.str();
}

std::vector<double> Mm(const Eigen::VectorXd& v) {
  std::vector<double> out;
  for (int i = 0; i < v.size(); ++i) out.push_back(std::round(v[i] * 1e4) / 10.0);  // 0.1 mm
  return out;
}

// The change report in the runner's report (docs/file-formats.md, self_calibration_report.json):
// positions and sizes in the MODEL frame, mm.
nlohmann::json ModelChangesToJson(const ModelChangeReport& c) {
  nlohmann::json parts = nlohmann::json::array();
  for (const PartChange& p : c.parts) {
    nlohmann::json j = {{"building", p.part},
                        {"state", std::string(PartStateName(p.state))},
                        {"centre_in_model_mm", Mm(p.centre_in_model_m)},
                        {"size_mm", Mm(p.size_m)},
                        {"points", p.points_on_footprint},
                        {"support", p.support}};
    if (p.state == PartState::kPresent || p.state == PartState::kMoved) {
      j["moved_by_mm"] = Mm(p.moved_by_m);
      j["moved_mm"] = p.moved_by_m.norm() * 1e3;
      j["moved_yaw_deg"] = p.moved_yaw_deg;
      j["fit_rms_mm"] = p.fit_rms_mm;
    }
    parts.push_back(j);
  }
  nlohmann::json extras = nlohmann::json::array();
  for (const ExtraStructure& e : c.extras) {
    extras.push_back({{"centre_in_model_mm", Mm(e.centre_in_model_m)},
                      {"size_mm", Mm(e.size_m)},
                      {"height_mm", e.height_m * 1e3},
                      {"points", e.points}});
  }
  return {{"buildings", parts},     {"not_in_model", extras}, {"present", c.present},
          {"moved", c.moved},       {"missing", c.missing},   {"unobserved", c.unobserved},
          {"in_place", c.in_place}, {"compute_s", c.time_s}};
}

// One log line per building that is not where the model has it, and per extra structure.
void LogModelChanges(const ModelChangeReport& c) {
  for (const PartChange& p : c.parts) {
    if (p.state == PartState::kPresent) continue;
    std::ostringstream line;
    line << "self-calibration: model building " << p.part << " at ("
         << Fixed(p.centre_in_model_m.x() * 1e3, 0) << ", "
         << Fixed(p.centre_in_model_m.y() * 1e3, 0) << ") mm (model frame) is "
         << PartStateName(p.state);
    if (p.state == PartState::kMoved) {
      line << " by " << Fixed(p.moved_by_m.norm() * 1e3, 1) << " mm ("
           << Fixed(p.moved_by_m.x() * 1e3, 1) << ", " << Fixed(p.moved_by_m.y() * 1e3, 1)
           << ") and " << Fixed(p.moved_yaw_deg, 2) << " deg";
    }
    if (p.state == PartState::kUnobserved) line << ": no camera saw where it stands";
    ST_LOG(kWarning) << line.str();
  }
  for (const ExtraStructure& e : c.extras) {
    ST_LOG(kWarning) << "self-calibration: structure not in the model at ("
                     << Fixed(e.centre_in_model_m.x() * 1e3, 0) << ", "
                     << Fixed(e.centre_in_model_m.y() * 1e3, 0) << ") mm (model frame), "
                     << Fixed(e.size_m.x() * 1e3, 0) << " x " << Fixed(e.size_m.y() * 1e3, 0)
                     << " mm, " << Fixed(e.height_m * 1e3, 0) << " mm high";
  }
}

// The site as MPCDI: each unit's region, its warp cast on the found model (in the table frame)
// or, without one, on the table plane (a 20 m square at z = 0).
Expected<MpcdiSite> SiteAsMpcdi(const ClusterSolution& solution, const Scene* model) {
  auto scene = std::make_shared<Scene>();
  if (model && solution.model) {
    *scene = MovedScene(*model, solution.model->table_from_model);
  } else {
    scene->Append(MakeRectangleMesh(Eigen::Vector2d(20.0, 20.0), 0));
  }
  std::vector<MpcdiUnit> units;
  for (const auto& [id, c] : solution.calibrations) units.push_back({"", c, std::nullopt});
  return BuildMpcdiSite(units, std::shared_ptr<const Scene>(scene));
}

// The solve's figures in the round's report (docs/calibration.md, "self_calibration_report.json").
void AddSolutionToReport(const ClusterSolution& s, nlohmann::json* report,
                         std::vector<std::string>* notes) {
  for (const std::string& n : s.notes) notes->push_back(n);
  nlohmann::json units = nlohmann::json::object();
  for (const auto& [id, u] : s.bundle.units) {
    units[std::to_string(id)] = {{"projector_rms_px", u.projector_rms_px},
                                 {"camera_rms_px", u.camera_rms_px},
                                 {"projector_observations", u.projector_observations},
                                 {"camera_observations", u.camera_observations},
                                 {"free_parameters", u.free_parameters},
                                 {"termination", s.bundle.termination},
                                 {"iterations", s.bundle.iterations}};
    const auto c = s.calibrations.find(id);
    if (c != s.calibrations.end() && c->second.predicted_error) {
      const PredictedErrorRecord& p = *c->second.predicted_error;
      nlohmann::json& unit = units[std::to_string(id)];
      unit["predicted_rms_px"] = p.rms_px;
      unit["predicted_rms_mm"] = p.rms_mm;
      unit["predicted_samples"] = p.samples;
      unit["weak_direction"] = p.weak_direction;
      unit["weak_share"] = p.weak_share;
    }
  }
  (*report)["bundle"] = {{"termination", s.bundle.termination},
                         {"iterations", s.bundle.iterations},
                         {"tracks", s.bundle.tracks_used},
                         {"tracks_untriangulated", s.bundle.tracks_untriangulated},
                         {"observations_dropped", s.bundle.observations_dropped},
                         {"initial_rms_px", s.bundle.initial_rms_px},
                         {"final_rms_px", s.bundle.final_rms_px},
                         {"solve_time_s", s.bundle.solve_time_s},
                         {"sigma_px", s.bundle.sigma_px},
                         {"undetermined", s.bundle.undetermined},
                         {"units", units}};
  (*report)["table"] = {{"points", s.table_points},         {"plane_rms_mm", s.table_plane_rms_mm},
                        {"max_height_mm", s.max_height_mm}, {"planar", s.planar},
                        {"extent_x_m", s.frame.extent_x_m}, {"extent_y_m", s.frame.extent_y_m}};
  if (s.model) {
    (*report)["model"] = {{"found", true},
                          {"table_from_model", io::RigidToJson(s.model->table_from_model)},
                          {"scale", s.model->scale},
                          {"relief_scale", s.model->relief_scale},
                          {"scale_correction", s.scale_correction},
                          {"rms_mm", s.model->rms_m * 1e3},
                          {"inliers", s.model->inliers},
                          {"points", s.model->points},
                          {"coarse_score", s.model->coarse_score},
                          {"by_outline", s.model->by_outline}};
    if (s.changes) {
      (*report)["model"]["changes"] = ModelChangesToJson(*s.changes);
      LogModelChanges(*s.changes);
    }
  } else {
    (*report)["model"] = {{"found", false}};
    if (s.changes) {  // found, then rejected: what the placement showed
      (*report)["model"]["changes"] = ModelChangesToJson(*s.changes);
    }
  }
}

}  // namespace

void CalibrationRunner::CollectInputs(ClusterObservations* observations_out,
                                      std::map<NodeId, LocalGeometry>* local_out) {
  Round& r = *round_;
  ClusterObservations& observations = *observations_out;
  std::map<NodeId, LocalGeometry>& local = *local_out;
  for (const auto& [id, input] : r.inputs) {
    if (!r.Active(id)) continue;
    Expected<CameraModel> camera = proto::FromWire(input.camera_model());
    Expected<CameraModel> projector = proto::FromWire(input.projector_model());
    Expected<Rigid3d> mount = proto::FromWire(input.projector_from_camera());
    if (!camera.ok() || !projector.ok() || !mount.ok()) {
      r.left_out[id] = "unit " + std::to_string(id) + ": invalid factory models in its input";
      continue;
    }
    observations.units[id] = UnitModel{id, *camera, *projector, *mount};
    LocalGeometry geometry;
    geometry.unit = id;
    geometry.triangulated = static_cast<int>(input.triangulated());
    for (const wire::RelativePose& rp : input.relative_poses()) {
      Expected<Rigid3d> pose = proto::FromWire(rp.camera_from_projector());
      if (!pose.ok()) continue;
      geometry.neighbours[rp.camera_id()] = {*pose, static_cast<int>(rp.points()), rp.rms_px()};
    }
    local[id] = geometry;
    std::map<NodeId, std::vector<ProjectorGridPoint>> by_camera;
    for (const wire::CorrespondenceSet& set : input.correspondences()) {
      std::vector<ProjectorGridPoint> points = GridPointsFromWire(set);
      if (!points.empty()) by_camera[set.camera_id()] = std::move(points);
    }
    const std::vector<Track> tracks = BuildTracks(id, by_camera);
    observations.tracks.insert(observations.tracks.end(), tracks.begin(), tracks.end());
  }
  for (NodeId m : r.projecting) {
    if (r.Active(m) && !observations.units.count(m)) {
      r.left_out[m] = "unit " + std::to_string(m) + ": sent no calibration input";
    }
  }
}

void CalibrationRunner::StartJoinSolve(NodeRuntime& node) {
  Round& r = *round_;
  r.solving = true;
  ReportProgress(r, "solve", {});
  r.path = "join";
  r.path_reason = "units joined a calibrated site; the calibrated units are held";
  ClusterObservations observations;
  std::map<NodeId, LocalGeometry> local;
  CollectInputs(&observations, &local);
  struct Solved {
    std::optional<ClusterSolution> solution;
    Status status = OkStatus();
    double cpu_s = 0.0;
  };
  std::shared_ptr<const ClusterSolution> site = last_solution_;
  // A unit the operator asked to recalibrate is in the held site: it is placed again, not held.
  if (std::any_of(r.projecting.begin(), r.projecting.end(),
                  [&](NodeId p) { return site->calibrations.count(p) > 0; })) {
    auto without = std::make_shared<ClusterSolution>(*site);
    for (NodeId p : r.projecting) without->calibrations.erase(p);
    site = std::move(without);
    r.path_reason = "the operator asked to recalibrate unit(s) of the site; the others are held";
  }
  const BundleOptions bundle = options_.solve.bundle;
  node.workers().Run<Solved>(
      [observations = std::move(observations), local = std::move(local), site, bundle] {
        Solved s;
        const double t0 = ThreadCpuSeconds();
        Expected<ClusterSolution> solved = SolveJoin(*site, observations, local, bundle);
        if (solved.ok()) {
          s.solution = std::move(*solved);
        } else {
          s.status = solved.status();
        }
        s.cpu_s = ThreadCpuSeconds() - t0;
        return s;
      },
      [this, &node](Solved s) {
        if (s.solution && last_solution_) {
          for (const auto& [id, c] : s.solution->calibrations) last_solution_->calibrations[id] = c;
        }
        FinishRound(s.solution ? &*s.solution : nullptr, s.status, s.cpu_s, node);
      });
}

void CalibrationRunner::StartSolve(NodeRuntime& node) {
  Round& r = *round_;
  r.solving = true;
  ReportProgress(r, "solve", {});
  ClusterObservations observations;
  std::map<NodeId, LocalGeometry> local;
  CollectInputs(&observations, &local);
  // The path: planar when every unit's probe found its footprint planar (and the site asks
  // for no full path), else full.
  int planar_units = 0, probed = 0;
  std::string not_planar;
  for (const auto& [id, input] : r.inputs) {
    if (!r.Active(id) || !observations.units.count(id)) continue;
    const wire::PlanarityProbe& probe = input.planarity();
    ++probed;
    if (probe.ok() && probe.planar()) {
      ++planar_units;
    } else if (not_planar.empty()) {
      not_planar = "unit " + std::to_string(id) + ": " +
                   (probe.ok() ? "max height " + std::to_string(probe.max_height_mm()) + " mm, " +
                                     std::to_string(probe.points_over_threshold()) +
                                     " points over " + std::to_string(probe.threshold_mm()) + " mm"
                               : "no probe (" + probe.message() + ")");
    }
  }
  const bool planar =
      options_.path == SelfCalibrationOptions::Path::kAuto && probed > 0 && planar_units == probed;
  r.path = planar ? "planar" : "full";
  r.path_reason = options_.path == SelfCalibrationOptions::Path::kFull
                      ? "the full path was asked for"
                  : planar ? "every unit's footprint is planar"
                           : "relief in a footprint (" + not_planar + ")";
  ST_LOG(kInfo) << "self-calibration: " << r.path << " path: " << r.path_reason;
  const NodeId root = observations.units.count(r.self) || observations.units.empty()
                          ? r.self
                          : observations.units.begin()->first;
  struct Solved {
    std::optional<ClusterSolution> solution;
    Status status = OkStatus();
    double cpu_s = 0.0;
    std::shared_ptr<const MpcdiSite> mpcdi;
    bool fell_back = false;
  };
  std::shared_ptr<const Scene> model = model_;
  SiteSolveOptions site_options;
  site_options.full = options_.solve;
  site_options.planar = options_.planar;
  node.workers().Run<Solved>(
      [observations = std::move(observations), local = std::move(local), root, model, site_options,
       planar] {
        Solved s;
        const double t0 = ThreadCpuSeconds();
        Expected<SiteSolveResult> solved =
            SolveSite(root, observations, local, model.get(),
                      planar ? SitePath::kPlanar : SitePath::kFull, site_options);
        if (solved.ok()) {
          s.fell_back = solved->fell_back;
          s.solution = std::move(solved->solution);
          Expected<MpcdiSite> site = SiteAsMpcdi(*s.solution, model.get());
          if (site.ok()) {
            s.mpcdi = std::make_shared<const MpcdiSite>(std::move(*site));
          } else {
            s.solution->notes.push_back("MPCDI export: " + site.status().message());
          }
        } else {
          s.status = solved.status();
        }
        s.cpu_s = ThreadCpuSeconds() - t0;
        return s;
      },
      [this, &node](Solved s) {
        if (RoundAgainForReturners(s.solution ? &*s.solution : nullptr, node)) return;
        ledger_->site_mpcdi = s.mpcdi;
        if (s.fell_back) round_->path = "full";
        if (s.solution) last_solution_ = std::make_shared<ClusterSolution>(*s.solution);
        FinishRound(s.solution ? &*s.solution : nullptr, s.status, s.cpu_s, node);
      });
}

bool CalibrationRunner::RoundAgainForReturners(const ClusterSolution* solution, NodeRuntime& node) {
  Round& r = *round_;
  if (solution && solution->calibrations.size() >= 2) return false;
  std::vector<NodeId> back;
  for (NodeId m : r.departed) {
    if (node.peers().count(m)) back.push_back(m);
  }
  if (back.empty()) return false;
  // The round was solved from one unit's view alone (or not at all) because units left it,
  // and they are back: its result would be weak (docs/calibration.md, "A unit that comes
  // back"); nothing is delivered and a new round with everyone starts.
  ST_LOG(kWarning) << "self-calibration: " << back.size() << " unit(s) left round " << r.round
                   << " and came back before its end; "
                   << (solution ? "solved from one unit alone" : "not solved")
                   << ", so not delivered: calibrating all again";
  round_.reset();
  return true;
}

void CalibrationRunner::FinishRound(const ClusterSolution* solution, const Status& status,
                                    double solve_cpu_s, NodeRuntime& node) {
  Round& r = *round_;
  ledger_->compute_s += solve_cpu_s;
  r.compute_s[r.self] += solve_cpu_s;
  const double period = options_.frame_period_s + options_.capture_latency_s;
  nlohmann::json report{
      {"format", "sandtable.self_calibration_report"},
      {"version", 1},
      {"runner", r.self},
      {"round", r.round},
      {"members", r.members},
      {"frame_period_s", options_.frame_period_s},
      {"capture_latency_s", options_.capture_latency_s},
      {"prepass_frames", r.prepass_frames},
      {"site_frames", r.prepass_frames + r.site_frames},
      {"device_time_s", (r.prepass_frames + r.site_frames) * period},
      {"measured_device_time_s", r.measured_site_device_s},
      {"colours", ColourCount(r.colours)},
      {"path", r.path},
      {"path_reason", r.path_reason},
      {"solve_compute_s", solve_cpu_s},
      {"wall_s",
       std::chrono::duration<double>(std::chrono::steady_clock::now() - r.round_started).count()}};
  nlohmann::json per_projector = nlohmann::json::object();
  for (const auto& [p, plan] : r.plans) {
    const int frames = r.frames_per_projector[p];
    std::vector<NodeId> seeing(r.cameras_seeing[p].begin(), r.cameras_seeing[p].end());
    per_projector[std::to_string(p)] = {
        {"colour", r.colours[p]},
        {"cameras", seeing},
        {"frames", frames},
        // its sequence, its pre-pass white and its response frames
        {"device_time_s", (frames + 1 + r.response_frames) * period},
        {"measured_device_time_s", r.measured_device_s.count(p) ? r.measured_device_s.at(p) : 0.0},
        {"gray_lsb_skip", plan.gray_lsb_skip},
        {"phase_steps", plan.phase_steps},
        {"phase_period_px", plan.phase_period_px},
        {"projector_px_per_camera_px", r.resolution[p]},
        {"compute_s", r.compute_s[p]}};
  }
  report["projectors"] = per_projector;
  nlohmann::json response = nlohmann::json::object();
  for (const auto& [id, fitted] : r.response) response[std::to_string(id)] = fitted;
  report["projector_response"] = response;
  nlohmann::json planarity = nlohmann::json::object();
  for (const auto& [id, input] : r.inputs) {
    const wire::PlanarityProbe& p = input.planarity();
    planarity[std::to_string(id)] =
        p.ok() ? nlohmann::json{{"planar", p.planar()},
                                {"max_height_mm", p.max_height_mm()},
                                {"surface_rms_mm", p.surface_rms_mm()},
                                {"points", p.points()},
                                {"points_over_threshold", p.points_over_threshold()},
                                {"threshold_mm", p.threshold_mm()}}
               : nlohmann::json{{"planar", false}, {"error", p.message()}};
  }
  report["planarity"] = planarity;
  if (r.join) {
    nlohmann::json blanked = nlohmann::json::object();
    for (const auto& [id, px] : r.blanked_px) blanked[std::to_string(id)] = px;
    report["joining"] = r.projecting;
    report["neighbours_blanked_px"] = blanked;
  }
  nlohmann::json left = nlohmann::json::object();
  for (const auto& [id, why] : r.left_out) left[std::to_string(id)] = why;
  report["left_out"] = left;
  std::vector<std::string> notes = r.notes;
  if (solution) {
    AddSolutionToReport(*solution, &report, &notes);
    report["ok"] = true;
  } else {
    notes.push_back("cluster solve: " + status.message());
    report["ok"] = false;
    report["error"] = status.message();
  }
  report["notes"] = notes;
  const std::string report_text = report.dump();
  ST_LOG(kInfo) << "self-calibration: round done in " << report["wall_s"].get<double>() << " s; "
                << (solution ? "solved" : status.message());
  SendResults(solution, status, report_text, node);
  r.solving = false;
  r.finished = true;
  // Every unit it was to calibrate placed (or gone): the retries start over.
  bool all_placed = solution != nullptr;
  for (NodeId m : r.projecting) {
    all_placed &=
        r.departed.count(m) > 0 || (r.Active(m) && solution && solution->calibrations.count(m) > 0);
  }
  failed_rounds_ = all_placed ? 0 : failed_rounds_ + 1;
  last_round_ended_ = std::chrono::steady_clock::now();
  if (!all_placed) {
    ST_LOG(kWarning) << "self-calibration: the round left units without a calibration ("
                     << failed_rounds_ << " round(s) in a row)";
  }
}

// Each projecting unit's CalibrationResult: its calibration from `solution`, or why it has
// none; the round's report with it.
void CalibrationRunner::SendResults(const ClusterSolution* solution, const Status& status,
                                    const std::string& report_text, NodeRuntime& node) {
  Round& r = *round_;
  for (NodeId m : r.projecting) {
    wire::Envelope e;
    wire::CalibrationResult* result = e.mutable_calibration_result();
    result->set_round(r.round);
    result->set_projector_id(m);
    result->set_report_json(report_text);
    std::set<NodeId> overlapping;
    for (const auto& [a, b] : r.overlaps) {
      if (a == m) overlapping.insert(b);
      if (b == m) overlapping.insert(a);
    }
    for (const auto& [p, seeing] : r.cameras_seeing) {
      if (p == m) overlapping.insert(seeing.begin(), seeing.end());
      if (seeing.count(m)) overlapping.insert(p);
    }
    overlapping.erase(m);
    for (NodeId u : overlapping) result->add_overlapping_units(u);
    const UnitCalibration* found = nullptr;
    if (solution) {
      auto c = solution->calibrations.find(m);
      if (c != solution->calibrations.end()) found = &c->second;
    }
    if (found && r.Active(m)) {
      const UnitCalibration& u = *found;
      const Rigid3d projector_from_table = u.table_from_projector->Inverse();
      result->set_ok(true);
      *result->mutable_projector_model() = proto::ToWire(u.projector);
      *result->mutable_camera_model() = proto::ToWire(u.camera);
      *result->mutable_projector_from_table() = proto::ToWire(projector_from_table);
      *result->mutable_camera_from_table() =
          proto::ToWire(u.projector_from_camera.Inverse() * projector_from_table);
      if (u.table_from_model)
        *result->mutable_table_from_model() = proto::ToWire(*u.table_from_model);
      result->set_reprojection_rms_px(u.projector_rms_px);
      result->set_camera_rms_px(u.camera_rms_px);
      result->set_compute_time_s(r.compute_s[m]);
      if (u.predicted_error) {
        const PredictedErrorRecord& p = *u.predicted_error;
        wire::PredictedError* w = result->mutable_predicted_error();
        w->set_rms_px(p.rms_px);
        w->set_rms_mm(p.rms_mm);
        w->set_samples(static_cast<uint32_t>(p.samples));
        w->set_sigma_px(p.sigma_px);
        w->set_weak_direction(p.weak_direction);
        w->set_weak_share(p.weak_share);
        w->set_undetermined(p.undetermined);
      }
    } else {
      result->set_ok(false);
      std::string why = r.left_out.count(m) ? r.left_out[m]
                        : solution
                            ? "unit " + std::to_string(m) + ": not reached by the cluster solve"
                            : status.message();
      result->set_message(why);
    }
    link_->Send(m, std::move(e), node);
  }
}

}  // namespace sandtable::node
