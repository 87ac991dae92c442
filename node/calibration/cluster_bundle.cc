#include "node/calibration/cluster_bundle.h"

#include <cmath>
#include <optional>

#include <ceres/ceres.h>
#include <ceres/rotation.h>

#include "common/base/thread_cpu_time.h"
#include "common/estimation/triangulation.h"
#include "node/calibration/cluster_uncertainty.h"
#include "node/calibration/procam_model.h"

namespace sandtable::node {
namespace {

// x_b = R(pose[0..2]) x_a + pose[3..5]
template <typename T>
void Transform(const T* pose, const T* x, T* out) {
  ceres::AngleAxisRotatePoint(pose, x, out);
  out[0] += pose[3];
  out[1] += pose[4];
  out[2] += pose[5];
}

struct ProjectorCost {
  Eigen::Vector2d observed_px;
  double inverse_sigma;
  template <typename T>
  bool operator()(const T* pose, const T* k, const T* d, const T* x, T* r) const {
    T xp[3], px[2];
    Transform(pose, x, xp);
    if (!ProjectToPixel(k, d, xp, px)) return false;
    r[0] = (px[0] - observed_px.x()) * inverse_sigma;
    r[1] = (px[1] - observed_px.y()) * inverse_sigma;
    return true;
  }
};

struct CameraCost {
  Eigen::Vector2d observed_px;
  double inverse_sigma;
  template <typename T>
  bool operator()(const T* pose, const T* mount, const T* k, const T* d, const T* x, T* r) const {
    T xp[3], xc[3], px[2];
    Transform(pose, x, xp);
    Transform(mount, xp, xc);
    if (!ProjectToPixel(k, d, xc, px)) return false;
    r[0] = (px[0] - observed_px.x()) * inverse_sigma;
    r[1] = (px[1] - observed_px.y()) * inverse_sigma;
    return true;
  }
};

struct PlaneCost {
  Eigen::Vector3d on_plane, normal;
  double inverse_sigma;
  template <typename T>
  bool operator()(const T* x, T* r) const {
    r[0] = ((x[0] - on_plane.x()) * normal.x() + (x[1] - on_plane.y()) * normal.y() +
            (x[2] - on_plane.z()) * normal.z()) *
           inverse_sigma;
    return true;
  }
};

template <int N>
struct PriorCost {
  double mean[N];
  double inverse_sigma[N];
  template <typename T>
  bool operator()(const T* x, T* r) const {
    for (int i = 0; i < N; ++i) r[i] = (x[i] - mean[i]) * inverse_sigma[i];
    return true;
  }
};

void PoseToArray(const Rigid3d& pose, double* out) {
  const Eigen::Matrix3d r = pose.RotationMatrix();
  ceres::RotationMatrixToAngleAxis(ceres::ColumnMajorAdapter3x3(r.data()), out);
  out[3] = pose.translation.x();
  out[4] = pose.translation.y();
  out[5] = pose.translation.z();
}

Rigid3d PoseFromArray(const double* pose) {
  Eigen::Matrix3d r;
  ceres::AngleAxisToRotationMatrix(pose, ceres::ColumnMajorAdapter3x3(r.data()));
  return Rigid3d(r, Eigen::Vector3d(pose[3], pose[4], pose[5]));
}

struct UnitBlocks {
  double pose[6];
  double mount[6];  // camera_from_projector
  double pk[4], pd[5], ck[4], cd[5];
};

void ModelToArrays(const CameraModel& m, double* k, double* d) {
  k[0] = m.fx_px;
  k[1] = m.fy_px;
  k[2] = m.cx_px;
  k[3] = m.cy_px;
  const auto a = m.distortion.ToArray();
  for (int i = 0; i < 5; ++i) d[i] = a[i];
}

CameraModel ModelFromArrays(const CameraModel& like, const double* k, const double* d) {
  CameraModel m = like;
  m.fx_px = k[0];
  m.fy_px = k[1];
  m.cx_px = k[2];
  m.cy_px = k[3];
  m.distortion = BrownDistortion::FromArray(d);
  return m;
}

struct Residual {
  ceres::ResidualBlockId id = nullptr;
  NodeId unit = kInvalidNodeId;
  bool camera = false;
  int point = -1;
};

// A track's point from the units' models and these poses; none when a view is missing or the
// rays miss each other by more than 5 px (rms).
std::optional<Eigen::Vector3d> TriangulateTrack(const ClusterObservations& observations,
                                                const std::map<NodeId, Rigid3d>& poses,
                                                const Track& track) {
  const auto pose = poses.find(track.projector_unit);
  if (pose == poses.end()) return std::nullopt;
  TriangulationOptions triangulation;
  triangulation.min_angle_deg = 1.0;
  std::vector<TriangulationView> views;
  const UnitModel& pu = observations.units.at(track.projector_unit);
  views.push_back({pu.projector, pose->second, track.projector_px});
  for (const CameraObservation& o : track.cameras) {
    const auto camera_pose = poses.find(o.camera_unit);
    if (camera_pose == poses.end()) continue;
    const UnitModel& cu = observations.units.at(o.camera_unit);
    views.push_back(
        {cu.camera, cu.projector_from_camera.Inverse() * camera_pose->second, o.camera_px});
  }
  if (views.size() < 2) return std::nullopt;
  Expected<TriangulationReport> point = TriangulatePoint(views, triangulation);
  if (!point.ok() || point->rms_px > 5.0) return std::nullopt;
  return point->point_in_world;
}

}  // namespace

int TracksThatTriangulate(const ClusterObservations& observations,
                          const std::map<NodeId, Rigid3d>& projector_from_world) {
  int n = 0;
  for (const Track& track : observations.tracks) {
    n += TriangulateTrack(observations, projector_from_world, track).has_value();
  }
  return n;
}

Status BundleOptions::Check() const {
  if (!(observation_sigma_px > 0) || !(huber_whitened >= 0) || !(outlier_px > 0)) {
    return InvalidArgumentError("bundle: sigma, huber and outlier thresholds must be > 0");
  }
  if (!(prior_focal_relative > 0) || !(prior_principal_point_px > 0) || !(prior_k1 > 0) ||
      !(prior_k2 > 0) || !(prior_p > 0) || !(prior_k3 > 0) || !(prior_mount_rotation_deg > 0) ||
      !(prior_mount_translation_m > 0)) {
    return InvalidArgumentError("bundle: every prior sigma must be > 0");
  }
  if (max_iterations < 1 || min_tracks < 1 || rounds < 1) {
    return InvalidArgumentError("bundle: max_iterations, min_tracks and rounds must be >= 1");
  }
  return OkStatus();
}

namespace {

using Points = std::vector<std::array<double, 3>>;

// The parameter blocks each reached unit starts from (a warm start's previous solution where
// there is one) and the factory's, which the priors pull towards.
void InitialBlocks(const ClusterObservations& observations,
                   const std::map<NodeId, Rigid3d>& initial_projector_from_world,
                   const BundleWarmStart* warm, std::map<NodeId, UnitBlocks>* blocks,
                   std::map<NodeId, UnitBlocks>* factory) {
  const bool warm_start = warm && warm->previous;
  for (const auto& [id, unit] : observations.units) {
    auto pose = initial_projector_from_world.find(id);
    if (pose == initial_projector_from_world.end()) continue;  // not reached: left out
    UnitBlocks& b = (*blocks)[id];
    PoseToArray(pose->second, b.pose);
    PoseToArray(unit.projector_from_camera.Inverse(), b.mount);
    ModelToArrays(unit.projector, b.pk, b.pd);
    ModelToArrays(unit.camera, b.ck, b.cd);
    (*factory)[id] = b;
    if (warm_start && warm->previous->units.count(id)) {
      const UnitModel& w = warm->previous->units.at(id);
      PoseToArray(warm->previous->projector_from_world.at(id), b.pose);
      PoseToArray(w.projector_from_camera.Inverse(), b.mount);
      ModelToArrays(w.projector, b.pk, b.pd);
      ModelToArrays(w.camera, b.ck, b.cd);
    }
  }
}

// Every track triangulated from the initial poses (a warm start keeps its previous points).
void InitialPoints(const ClusterObservations& observations,
                   const std::map<NodeId, UnitBlocks>& blocks, const BundleWarmStart* warm,
                   BundleResult* result) {
  if (warm && warm->previous) {
    result->points_in_world = warm->previous->points_in_world;
    result->point_track = warm->previous->point_track;
    return;
  }
  std::map<NodeId, Rigid3d> initial_poses;
  for (const auto& [id, b] : blocks) initial_poses[id] = PoseFromArray(b.pose);
  for (size_t t = 0; t < observations.tracks.size(); ++t) {
    const std::optional<Eigen::Vector3d> point =
        TriangulateTrack(observations, initial_poses, observations.tracks[t]);
    if (!point) {
      ++result->report.tracks_untriangulated;
      continue;
    }
    result->points_in_world.push_back(*point);
    result->point_track.push_back(static_cast<int>(t));
  }
}

// One reprojection residual per observation of each point: its projector's pixel and every
// reached camera's.
std::vector<Residual> AddObservations(const ClusterObservations& observations,
                                      const BundleResult& result, const BundleOptions& options,
                                      std::map<NodeId, UnitBlocks>& blocks, Points& points,
                                      ceres::Problem* problem) {
  const double inverse_sigma = 1.0 / options.observation_sigma_px;
  std::vector<Residual> residuals;
  ceres::LossFunction* loss =
      options.huber_whitened > 0 ? new ceres::HuberLoss(options.huber_whitened) : nullptr;
  for (int i = 0; i < static_cast<int>(points.size()); ++i) {
    const Track& track = observations.tracks[result.point_track[i]];
    UnitBlocks& pb = blocks[track.projector_unit];
    auto* projector_cost = new ceres::AutoDiffCostFunction<ProjectorCost, 2, 6, 4, 5, 3>(
        new ProjectorCost{track.projector_px, inverse_sigma});
    residuals.push_back(
        {problem->AddResidualBlock(projector_cost, loss, pb.pose, pb.pk, pb.pd, points[i].data()),
         track.projector_unit, false, i});
    for (const CameraObservation& o : track.cameras) {
      auto cb = blocks.find(o.camera_unit);
      if (cb == blocks.end()) continue;
      auto* camera_cost = new ceres::AutoDiffCostFunction<CameraCost, 2, 6, 6, 4, 5, 3>(
          new CameraCost{o.camera_px, inverse_sigma});
      residuals.push_back(
          {problem->AddResidualBlock(camera_cost, loss, cb->second.pose, cb->second.mount,
                                     cb->second.ck, cb->second.cd, points[i].data()),
           o.camera_unit, true, i});
    }
  }
  return residuals;
}

// The model's surface (second refinement): points held near the planes they lie on.
void AddSurface(const BundleWarmStart& warm, Points& points, ceres::Problem* problem) {
  auto* surface_loss = new ceres::HuberLoss(2.0);
  for (const SurfaceConstraint& s : warm.surface) {
    if (s.point < 0 || s.point >= static_cast<int>(points.size())) continue;
    auto* cost = new ceres::AutoDiffCostFunction<PlaneCost, 1, 3>(
        new PlaneCost{s.on_plane_in_world, s.normal_in_world, 1.0 / warm.surface_sigma_m});
    problem->AddResidualBlock(cost, surface_loss, points[s.point].data());
  }
}

ceres::CostFunction* IntrinsicsPrior(const double* mean, const BundleOptions& options) {
  auto* p = new PriorCost<4>;
  for (int i = 0; i < 4; ++i) p->mean[i] = mean[i];
  p->inverse_sigma[0] = 1.0 / (options.prior_focal_relative * mean[0]);
  p->inverse_sigma[1] = 1.0 / (options.prior_focal_relative * mean[1]);
  p->inverse_sigma[2] = p->inverse_sigma[3] = 1.0 / options.prior_principal_point_px;
  return new ceres::AutoDiffCostFunction<PriorCost<4>, 4, 4>(p);
}

ceres::CostFunction* DistortionPrior(const double* mean, const BundleOptions& options) {
  auto* p = new PriorCost<5>;
  for (int i = 0; i < 5; ++i) p->mean[i] = mean[i];
  p->inverse_sigma[0] = 1.0 / options.prior_k1;
  p->inverse_sigma[1] = 1.0 / options.prior_k2;
  p->inverse_sigma[2] = p->inverse_sigma[3] = 1.0 / options.prior_p;
  p->inverse_sigma[4] = 1.0 / options.prior_k3;
  return new ceres::AutoDiffCostFunction<PriorCost<5>, 5, 5>(p);
}

ceres::CostFunction* MountPrior(const double* mean, const BundleOptions& options) {
  const double rotation_sigma_rad = options.prior_mount_rotation_deg * M_PI / 180.0;
  auto* p = new PriorCost<6>;
  for (int i = 0; i < 6; ++i) p->mean[i] = mean[i];
  for (int i = 0; i < 3; ++i) p->inverse_sigma[i] = 1.0 / rotation_sigma_rad;
  for (int i = 3; i < 6; ++i) p->inverse_sigma[i] = 1.0 / options.prior_mount_translation_m;
  return new ceres::AutoDiffCostFunction<PriorCost<6>, 6, 6>(p);
}

// One side of a unit (its projector or its camera): intrinsics and distortion free under their
// priors, or held, as the options say; the free ones are listed in the unit's report.
void FreeLens(double* k, double* d, const double* factory_k, const double* factory_d,
              bool free_intrinsics, bool free_distortion, const std::string& side,
              const BundleOptions& options, ceres::Problem* problem, UnitBundleReport* report) {
  if (free_intrinsics) {
    problem->AddResidualBlock(IntrinsicsPrior(factory_k, options), nullptr, k);
    report->free_parameters.push_back(side + " fx fy cx cy");
  } else {
    problem->SetParameterBlockConstant(k);
  }
  if (free_distortion) {
    problem->AddResidualBlock(DistortionPrior(factory_d, options), nullptr, d);
    if (!options.free_k3) problem->SetManifold(d, new ceres::SubsetManifold(5, {4}));
    report->free_parameters.push_back(side +
                                      (options.free_k3 ? " k1 k2 p1 p2 k3" : " k1 k2 p1 p2"));
  } else {
    problem->SetParameterBlockConstant(d);
  }
}

// Priors and held groups: a held unit is constant; the others' lenses and mounts are free under
// priors towards the factory's, and the root's pose fixes the gauge (unless a warm start or
// held units do).
void AddPriors(const std::map<NodeId, UnitBlocks>& factory, NodeId root, bool warm_start,
               const BundleOptions& options, std::map<NodeId, UnitBlocks>& blocks,
               ceres::Problem* problem, BundleReport* report) {
  for (auto& [id, b] : blocks) {
    UnitBundleReport& unit_report = report->units[id];
    if (options.held_units.count(id)) {
      for (double* block : {b.pose, b.mount, b.pk, b.pd, b.ck, b.cd}) {
        if (problem->HasParameterBlock(block)) problem->SetParameterBlockConstant(block);
      }
      unit_report.free_parameters.push_back("none (held)");
      continue;
    }
    const UnitBlocks& f = factory.at(id);
    const bool has = problem->HasParameterBlock(b.pk);
    const bool has_camera = problem->HasParameterBlock(b.ck);
    const bool gauge = id == root && !warm_start && options.held_units.empty();
    if (has) {
      FreeLens(b.pk, b.pd, f.pk, f.pd, options.free_projector_intrinsics,
               options.free_projector_distortion, "projector", options, problem, &unit_report);
      if (gauge) {
        problem->SetParameterBlockConstant(b.pose);
      } else {
        unit_report.free_parameters.push_back("pose");
      }
    }
    if (!has_camera) continue;
    FreeLens(b.ck, b.cd, f.ck, f.cd, options.free_camera_intrinsics, options.free_camera_distortion,
             "camera", options, problem, &unit_report);
    if (options.free_mounts) {
      problem->AddResidualBlock(MountPrior(f.mount, options), nullptr, b.mount);
      unit_report.free_parameters.push_back("mount");
    } else {
      problem->SetParameterBlockConstant(b.mount);
    }
    if (!has && gauge) problem->SetParameterBlockConstant(b.pose);
  }
}

// The reprojection residuals' rms, px (the observations kept).
double RmsPx(ceres::Problem& problem, const std::vector<Residual>& residuals, double sigma_px) {
  double sum = 0.0;
  int n = 0;
  for (const Residual& r : residuals) {
    if (!r.id) continue;
    double cost = 0.0;
    double v[2];
    problem.EvaluateResidualBlock(r.id, /*apply_loss_function=*/false, &cost, v, nullptr);
    sum += (v[0] * v[0] + v[1] * v[1]);
    ++n;
  }
  return n ? std::sqrt(sum / n) * sigma_px : 0.0;
}

// Solves, then drops the observations past outlier_px and solves again, up to options.rounds.
Status SolveRounds(const BundleOptions& options, std::vector<Residual>& residuals,
                   ceres::Problem* problem, BundleReport* report) {
  ceres::Solver::Options solver;
  solver.linear_solver_type = ceres::DENSE_SCHUR;
  solver.max_num_iterations = options.max_iterations;
  solver.num_threads = 1;
  solver.logging_type = ceres::SILENT;
  solver.function_tolerance = options.function_tolerance;
  if (options.log_progress) {
    solver.minimizer_progress_to_stdout = true;
    solver.logging_type = ceres::PER_MINIMIZER_ITERATION;
  }
  solver.parameter_tolerance = 1e-10;
  for (int round = 0; round < options.rounds; ++round) {
    if (round > 0) {
      // Drop observations the model does not explain; when none is dropped the last round's
      // solution stands.
      const int dropped_before = report->observations_dropped;
      for (Residual& r : residuals) {
        if (!r.id) continue;
        double cost = 0.0, v[2];
        problem->EvaluateResidualBlock(r.id, false, &cost, v, nullptr);
        if (std::hypot(v[0], v[1]) * options.observation_sigma_px > options.outlier_px) {
          problem->RemoveResidualBlock(r.id);
          r.id = nullptr;
          ++report->observations_dropped;
        }
      }
      // A handful of dropped observations (under 0.1 %) do not move the solution: the last
      // round stands.
      if (report->observations_dropped - dropped_before <
          std::max<int>(1, static_cast<int>(residuals.size() / 1000))) {
        break;
      }
    }
    ceres::Solver::Summary summary;
    ceres::Solve(solver, problem, &summary);
    report->iterations += static_cast<int>(summary.iterations.size());
    if (options.log_progress) fprintf(stderr, "%s\n", summary.FullReport().c_str());
    report->termination = ceres::TerminationTypeToString(summary.termination_type);
    if (summary.termination_type == ceres::FAILURE || !summary.IsSolutionUsable()) {
      return NotConvergedError("bundle: Ceres " + report->termination + ": " + summary.message);
    }
  }
  return OkStatus();
}

void AddUncertainty(const ClusterObservations& observations, const BundleOptions& options,
                    const std::vector<Residual>& residuals, std::map<NodeId, UnitBlocks>& blocks,
                    Points& points, ceres::Problem& problem, BundleResult* result) {
  std::map<NodeId, UnitParameterBlocks> unit_blocks;
  for (auto& [id, b] : blocks) unit_blocks[id] = {b.pose, b.mount, b.pk, b.pd, b.ck, b.cd};
  std::vector<double*> point_blocks;
  for (auto& p : points) point_blocks.push_back(p.data());
  std::vector<ObservationBlock> observed;
  for (const Residual& r : residuals) {
    if (!r.id) continue;
    const Track& track = observations.tracks[result->point_track[r.point]];
    observed.push_back({r.id, r.unit, r.camera, r.point, track.projector_px});
  }
  Expected<BundleUncertainty> uncertainty =
      EstimateUncertainty(problem, unit_blocks, point_blocks, observed, options, &result->report);
  if (uncertainty.ok()) {
    result->uncertainty = std::move(*uncertainty);
  } else {
    result->report.uncertainty_note = uncertainty.status().message();
  }
}

// Per unit residuals: each unit's projector and camera observations and their rms.
void ReportPerUnit(ceres::Problem& problem, const std::vector<Residual>& residuals, double sigma_px,
                   BundleReport* report) {
  std::map<NodeId, std::pair<double, int>> projector_sum, camera_sum;
  for (const Residual& r : residuals) {
    if (!r.id) continue;
    double cost = 0.0, v[2];
    problem.EvaluateResidualBlock(r.id, false, &cost, v, nullptr);
    auto& s = r.camera ? camera_sum[r.unit] : projector_sum[r.unit];
    s.first += (v[0] * v[0] + v[1] * v[1]) * sigma_px * sigma_px;
    ++s.second;
  }
  for (auto& [id, unit_report] : report->units) {
    if (auto it = projector_sum.find(id); it != projector_sum.end() && it->second.second > 0) {
      unit_report.projector_observations = it->second.second;
      unit_report.projector_rms_px = std::sqrt(it->second.first / it->second.second);
    }
    if (auto it = camera_sum.find(id); it != camera_sum.end() && it->second.second > 0) {
      unit_report.camera_observations = it->second.second;
      unit_report.camera_rms_px = std::sqrt(it->second.first / it->second.second);
    }
  }
}

}  // namespace

Expected<BundleResult> AdjustCluster(const ClusterObservations& observations,
                                     const std::map<NodeId, Rigid3d>& initial_projector_from_world,
                                     NodeId root, const BundleOptions& options,
                                     const BundleWarmStart* warm) {
  ST_RETURN_IF_ERROR(options.Check());
  const double cpu_start = ThreadCpuSeconds();
  std::map<NodeId, UnitBlocks> blocks, factory;
  const bool warm_start = warm && warm->previous;
  InitialBlocks(observations, initial_projector_from_world, warm, &blocks, &factory);
  if (!blocks.count(root)) {
    return InvalidArgumentError("bundle: the root unit " + std::to_string(root) +
                                " has no initial pose");
  }
  BundleResult result;
  InitialPoints(observations, blocks, warm, &result);
  const int n_points = static_cast<int>(result.points_in_world.size());
  if (n_points < options.min_tracks) {
    return DegenerateError("bundle: " + std::to_string(n_points) +
                           " tracks triangulate (at least " + std::to_string(options.min_tracks) +
                           " needed)");
  }
  result.report.tracks_used = n_points;
  Points points(n_points);
  for (int i = 0; i < n_points; ++i) {
    for (int a = 0; a < 3; ++a) points[i][a] = result.points_in_world[i][a];
  }

  ceres::Problem::Options problem_options;
  problem_options.enable_fast_removal = true;
  ceres::Problem problem(problem_options);
  std::vector<Residual> residuals =
      AddObservations(observations, result, options, blocks, points, &problem);
  if (warm_start) AddSurface(*warm, points, &problem);
  AddPriors(factory, root, warm_start, options, blocks, &problem, &result.report);
  result.report.initial_rms_px = RmsPx(problem, residuals, options.observation_sigma_px);
  ST_RETURN_IF_ERROR(SolveRounds(options, residuals, &problem, &result.report));
  result.report.final_rms_px = RmsPx(problem, residuals, options.observation_sigma_px);
  if (options.estimate_uncertainty) {
    AddUncertainty(observations, options, residuals, blocks, points, problem, &result);
  }
  ReportPerUnit(problem, residuals, options.observation_sigma_px, &result.report);
  for (const auto& [id, b] : blocks) {
    const UnitModel& in = observations.units.at(id);
    UnitModel out = in;
    out.projector = ModelFromArrays(in.projector, b.pk, b.pd);
    out.camera = ModelFromArrays(in.camera, b.ck, b.cd);
    out.projector_from_camera = PoseFromArray(b.mount).Inverse();
    result.units[id] = out;
    result.projector_from_world[id] = PoseFromArray(b.pose);
  }
  for (int i = 0; i < n_points; ++i) {
    result.points_in_world[i] = Eigen::Vector3d(points[i][0], points[i][1], points[i][2]);
  }
  result.report.solve_time_s = ThreadCpuSeconds() - cpu_start;
  return result;
}

}  // namespace sandtable::node
