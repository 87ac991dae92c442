#include "tests/testing/self_calibration_sim.h"

#include <algorithm>
#include <cmath>

#include "common/base/thread_cpu_time.h"
#include "sim/transport/world.h"

namespace sandtable::testing {
Status SimCalibrationOptions::Check() const {
  ST_RETURN_IF_ERROR(plan.Check());
  ST_RETURN_IF_ERROR(grid.Check());
  ST_RETURN_IF_ERROR(solve.Check());
  ST_RETURN_IF_ERROR(factory_error.Check());
  ST_RETURN_IF_ERROR(planar.Check());
  if (metric_samples < 1) return InvalidArgumentError("sim calibration: metric_samples >= 1");
  return OkStatus();
}

Expected<SimCalibrationResult> RunSimCalibration(const sim::Site& site, const Scene& scene,
                                                 const SimCalibrationOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  Expected<std::unique_ptr<sim::World>> created = sim::World::Create(site, scene);
  if (!created.ok()) return created.status();
  sim::World& world = **created;
  SimCalibrationResult result;
  node::ClusterObservations observations;
  for (const sim::UnitSpec& unit : site.units) {
    Expected<sim::FactoryCalibration> factory =
        sim::MakeFactoryCalibration(unit, options.factory_error, options.seed);
    if (!factory.ok()) return factory.status();
    observations.units[unit.id] = {unit.id, factory->camera, factory->projector,
                                   factory->projector_from_camera};
  }
  uint64_t capture_index = 0;
  auto capture = [&](NodeId camera) -> Expected<cv::Mat> {
    sim::CaptureNoise noise{.enabled = options.noise,
                            .seed = options.seed * 1000003ull + (capture_index++)};
    Expected<cv::Mat> image = world.Capture(camera, noise);
    if (!image.ok()) return image.status();
    const sim::UnitSpec* unit = site.FindUnit(camera);
    return node::To8Bit(*image, unit->camera->bit_depth).clone();
  };
  // Pre-pass: black reference, then each projector white alone.
  std::map<NodeId, cv::Mat> black;
  for (const sim::UnitSpec& u : site.units) ST_RETURN_IF_ERROR(world.SetProjectorUniform(u.id, 0));
  for (const sim::UnitSpec& u : site.units) {
    Expected<cv::Mat> b = capture(u.id);
    if (!b.ok()) return b.status();
    black[u.id] = *b;
  }
  std::map<NodeId, std::vector<NodeId>> cameras_seeing;  // projector -> cameras
  for (const sim::UnitSpec& p : site.units) {
    ST_RETURN_IF_ERROR(world.SetProjectorUniform(p.id, 255));
    for (const sim::UnitSpec& c : site.units) {
      Expected<cv::Mat> w = capture(c.id);
      if (!w.ok()) return w.status();
      const int lit = node::CountLitPixels(*w, black[c.id], 20);
      if (lit > 500) cameras_seeing[p.id].push_back(c.id);
      if (c.id == p.id && lit > 0) {
        result.projector_px_per_camera_px[p.id] = std::sqrt(
            static_cast<double>(p.projector.model.width_px) * p.projector.model.height_px / lit);
      }
    }
    ST_RETURN_IF_ERROR(world.SetProjectorUniform(p.id, 0));
  }
  // Sequences, one projector at a time (the distributed service runs a colour class at once;
  // the captures are the same).
  for (const sim::UnitSpec& p : site.units) {
    const double ratio = result.projector_px_per_camera_px.count(p.id)
                             ? result.projector_px_per_camera_px[p.id]
                             : 2.0;
    const PatternOptions full = node::PlanPatterns(
        p.projector.model.width_px, p.projector.model.height_px, ratio * 1.4, options.plan);
    const bool cells = options.planar_path && options.planar_gray_cells;
    const PatternOptions patterns = cells ? node::GrayPrefix(full) : full;
    Expected<std::vector<cv::Mat>> frames = GeneratePatterns(patterns);
    if (!frames.ok()) return frames.status();
    result.frames_per_projector[p.id] = static_cast<int>(frames->size());
    std::map<NodeId, std::vector<cv::Mat>> captures;
    for (const cv::Mat& frame : *frames) {
      ST_RETURN_IF_ERROR(world.SetProjectorFrame(p.id, frame));
      for (NodeId c : cameras_seeing[p.id]) {
        Expected<cv::Mat> image = capture(c);
        if (!image.ok()) return image.status();
        captures[c].push_back(*image);
      }
    }
    ST_RETURN_IF_ERROR(world.SetProjectorUniform(p.id, 0));
    ProjectorGridOptions grid = options.grid;
    grid.projector_width_px = p.projector.model.width_px;
    grid.projector_height_px = p.projector.model.height_px;
    std::map<NodeId, std::vector<ProjectorGridPoint>> by_camera;
    for (auto& [c, images] : captures) {
      const double t0 = ThreadCpuSeconds();
      Expected<std::vector<ProjectorGridPoint>> points =
          cells ? node::DecodeToProjectorCells(images, patterns)
                : node::DecodeToProjectorGrid(images, patterns, grid);
      result.decode_cpu_s += ThreadCpuSeconds() - t0;
      if (!points.ok()) return points.status();
      by_camera[c] = std::move(*points);
      if (getenv("SANDTABLE_TRUE_CORRESPONDENCES")) {
        // Diagnostic: each kept node's camera position replaced by the true one (the projector
        // ray of the node to the surface, seen by the true camera unless occluded), so that a
        // solve from these isolates what the decoding's errors do.
        const sim::UnitSpec* cu = site.FindUnit(c);
        const Rigid3d table_from_camera =
            cu->projector.table_from_projector * cu->camera->projector_from_camera;
        const Rigid3d camera_from_table = table_from_camera.Inverse();
        std::vector<ProjectorGridPoint> exact;
        for (ProjectorGridPoint gp : by_camera[c]) {
          Expected<Eigen::Vector3d> ray =
              p.projector.model.Unproject(gp.projector_px.cast<double>());
          if (!ray.ok()) continue;
          Expected<sim::SurfaceTruth> hit =
              world.TruthAlongRay(p.projector.table_from_projector.translation,
                                  p.projector.table_from_projector.rotation * *ray);
          if (!hit.ok()) continue;
          const Eigen::Vector3d in_camera = camera_from_table * hit->point_in_table_m;
          std::optional<Eigen::Vector2d> px = cu->camera->model.Project(in_camera);
          if (!px) continue;
          const Eigen::Vector3d to_point = hit->point_in_table_m - table_from_camera.translation;
          Expected<sim::SurfaceTruth> seen =
              world.TruthAlongRay(table_from_camera.translation, to_point.normalized());
          if (!seen.ok() || (seen->point_in_table_m - hit->point_in_table_m).norm() > 1e-4) {
            continue;
          }
          gp.camera_px = px->cast<float>();
          exact.push_back(gp);
        }
        by_camera[c] = std::move(exact);
      }
      if (getenv("SANDTABLE_CORRESPONDENCE_TRUTH")) {
        // Diagnostic: the true projector pixel of the surface point each camera position sees.
        const sim::UnitSpec* cu = site.FindUnit(c);
        const Rigid3d table_from_camera =
            cu->projector.table_from_projector * cu->camera->projector_from_camera;
        Eigen::Vector2d sum = Eigen::Vector2d::Zero();
        double sum_sq = 0;
        int n = 0;
        for (const ProjectorGridPoint& gp : by_camera[c]) {
          Expected<Eigen::Vector3d> ray = cu->camera->model.Unproject(gp.camera_px.cast<double>());
          if (!ray.ok()) continue;
          Expected<sim::SurfaceTruth> hit =
              world.TruthAlongRay(table_from_camera.translation, table_from_camera.rotation * *ray);
          if (!hit.ok()) continue;
          Expected<sim::ProjectorTruth> truth =
              world.ProjectorTruthAtPoint(p.id, hit->point_in_table_m);
          if (!truth.ok() || !truth->sample.projectable) continue;
          const Eigen::Vector2d d = truth->sample.pixel_px - gp.projector_px.cast<double>();
          if (d.norm() > 3) continue;
          sum += d;
          sum_sq += d.squaredNorm();
          ++n;
        }
        if (n) {
          fprintf(stderr, "projector %u camera %u: %d points, mean (%.4f, %.4f) rms %.4f px\n",
                  p.id, c, n, sum.x() / n, sum.y() / n, std::sqrt(sum_sq / n));
        }
      }
    }
    std::vector<node::Track> tracks = node::BuildTracks(p.id, by_camera);
    result.tracks += static_cast<int>(tracks.size());
    observations.tracks.insert(observations.tracks.end(), tracks.begin(), tracks.end());
  }
  const Scene model = MovedScene(options.model ? *options.model : scene, options.model_from_table);
  const NodeId root = observations.units.begin()->first;
  if (options.observations_out) *options.observations_out = observations;
  const std::map<NodeId, node::LocalGeometry> local = node::LocalGeometries(observations);
  node::SiteSolveOptions site_options;
  site_options.full = options.solve;
  site_options.planar = options.planar;
  Expected<node::SiteSolveResult> solution = node::SolveSite(
      root, observations, local, options.use_model ? &model : nullptr,
      options.planar_path ? node::SitePath::kPlanar : node::SitePath::kFull, site_options);
  if (!solution.ok()) return solution.status();
  result.solution = std::move(solution->solution);
  // Metric.
  std::vector<sim::EstimatedRegistration> estimates;
  for (const auto& [id, c] : result.solution.calibrations) {
    sim::EstimatedRegistration e;
    e.unit_id = id;
    e.projector = c.projector;
    e.table_from_projector = *c.table_from_projector;
    e.table_from_model = c.table_from_model.value_or(options.model_from_table.Inverse());
    estimates.push_back(e);
  }
  if (!result.solution.model) {
    // No placement found (a flat scene whose outline the cameras do not see whole): measured
    // with the TRUE placement expressed in the nodes' table frame, as the lab does.
    Expected<sim::ModelPlacementError> frames =
        sim::MeasureModelPlacement(world, estimates, options.model_from_table.Inverse(),
                                   options.model_from_table * scene.Bounds().center());
    if (frames.ok()) {
      for (sim::EstimatedRegistration& e : estimates) {
        e.table_from_model =
            frames->true_table_from_estimated_table.Inverse() * options.model_from_table.Inverse();
      }
      result.measured_with_true_placement = true;
    }
  }
  sim::RegistrationMetricOptions metric;
  metric.num_samples = options.metric_samples;
  metric.seed = options.seed;
  metric.true_table_from_model = options.model_from_table.Inverse();
  metric.keep_samples = getenv("SANDTABLE_ERROR_BREAKDOWN") != nullptr;
  Expected<sim::RegistrationReport> report = sim::MeasureRegistration(world, estimates, metric);
  if (!report.ok()) return report.status();
  result.metric = *report;
  if (metric.keep_samples) {
    std::map<NodeId, std::vector<Eigen::Vector2d>> errors;
    for (const sim::RegistrationSample& s : report->samples) {
      errors[s.unit_id].push_back(s.estimated_pixel_px - s.true_pixel_px);
    }
    for (const auto& [unit, e] : errors) {
      Eigen::Vector2d mean = Eigen::Vector2d::Zero();
      for (const Eigen::Vector2d& v : e) mean += v;
      mean /= static_cast<double>(e.size());
      double rms = 0, rms_centred = 0;
      for (const Eigen::Vector2d& v : e) {
        rms += v.squaredNorm();
        rms_centred += (v - mean).squaredNorm();
      }
      fprintf(stderr, "unit %u: px error mean (%.3f, %.3f), rms %.3f, rms about the mean %.3f\n",
              unit, mean.x(), mean.y(), std::sqrt(rms / e.size()),
              std::sqrt(rms_centred / e.size()));
    }
  }
  // Model placement against the truth (sim/lab/registration_metric.h).
  if (result.solution.model) {
    Expected<sim::ModelPlacementError> placement =
        sim::MeasureModelPlacement(world, estimates, options.model_from_table.Inverse(),
                                   options.model_from_table * scene.Bounds().center());
    if (!placement.ok()) return placement.status();
    result.model_offset_mm = placement->offset_mm;
    result.model_offset_deg = placement->offset_deg;
    std::vector<sim::EstimatedRegistration> true_model = estimates;
    for (sim::EstimatedRegistration& e : true_model) {
      e.table_from_model =
          placement->true_table_from_estimated_table.Inverse() * options.model_from_table.Inverse();
    }
    Expected<sim::RegistrationReport> own = sim::MeasureRegistration(world, true_model, metric);
    if (own.ok()) result.metric_true_model = *own;
  }
  if (getenv("SANDTABLE_PARAMETER_TRUTH")) {
    Expected<sim::ModelPlacementError> placement =
        sim::MeasureModelPlacement(world, estimates, options.model_from_table.Inverse(),
                                   options.model_from_table * scene.Bounds().center());
    if (!placement.ok()) return placement.status();
    // Diagnostic: each unit's solved parameters against the truth (the pose in the true
    // table frame through the nodes' table frame's best fit to the truth).
    for (const auto& [id, c] : result.solution.calibrations) {
      const sim::UnitSpec* u = site.FindUnit(id);
      const CameraModel& tp = u->projector.model;
      const CameraModel& tc = u->camera->model;
      const Rigid3d pose = placement->true_table_from_estimated_table * *c.table_from_projector;
      const Rigid3d& truth = u->projector.table_from_projector;
      const Rigid3d mount = c.projector_from_camera * u->camera->projector_from_camera.Inverse();
      const Eigen::AngleAxisd turn(truth.rotation.inverse() * pose.rotation);
      const Eigen::Vector3d dp = pose.translation - truth.translation;
      fprintf(stderr,
              "unit %u: projector f %+.4f%% %+.4f%% c (%+.2f, %+.2f) px k1 %+.4f | camera f "
              "%+.4f%% c (%+.2f, %+.2f) px k1 %+.4f | mount %.2f mm %.3f deg | position "
              "(%+.2f, %+.2f, %+.2f) mm turn %.3f deg\n",
              id, 100 * (c.projector.fx_px / tp.fx_px - 1),
              100 * (c.projector.fy_px / tp.fy_px - 1), c.projector.cx_px - tp.cx_px,
              c.projector.cy_px - tp.cy_px, c.projector.distortion.k1 - tp.distortion.k1,
              100 * (c.camera.fx_px / tc.fx_px - 1), c.camera.cx_px - tc.cx_px,
              c.camera.cy_px - tc.cy_px, c.camera.distortion.k1 - tc.distortion.k1,
              1000 * mount.translation.norm(),
              Eigen::AngleAxisd(mount.rotation).angle() * 180 / M_PI, 1000 * dp.x(), 1000 * dp.y(),
              1000 * dp.z(), turn.angle() * 180 / M_PI);
      // The nodes' table plane against the true table: their up directions in this unit's
      // projector frame (independent of how the lab relates the two table frames).
      const Eigen::Vector3d up_est =
          c.table_from_projector->rotation.inverse() * Eigen::Vector3d::UnitZ();
      const Eigen::Vector3d up_true = truth.rotation.inverse() * Eigen::Vector3d::UnitZ();
      fprintf(stderr, "unit %u: table plane tilt against the true table %.3f deg\n", id,
              std::acos(std::clamp(up_est.dot(up_true), -1.0, 1.0)) * 180 / M_PI);
      // Where the model truly stands in the nodes' table frame, through this unit's pose.
      const Rigid3d model_from_estimated =
          options.model_from_table * truth * c.table_from_projector->Inverse();
      const Eigen::Vector3d z_model = model_from_estimated.rotation * Eigen::Vector3d::UnitZ();
      const Eigen::Vector3d x_model = model_from_estimated.rotation * Eigen::Vector3d::UnitX();
      fprintf(stderr,
              "unit %u: model_from_table truly t (%+.3f, %+.3f, %+.3f) m, yaw %.2f deg, tilt "
              "%.3f deg\n",
              id, model_from_estimated.translation.x(), model_from_estimated.translation.y(),
              model_from_estimated.translation.z(),
              std::atan2(x_model.y(), x_model.x()) * 180 / M_PI,
              std::acos(std::clamp(z_model.z(), -1.0, 1.0)) * 180 / M_PI);
    }
    fprintf(stderr, "frame relation: %d pixel pairs, fit rms %.2f mm\n", placement->pairs,
            placement->frame_fit_rms_mm);
  }
  return result;
}

}  // namespace sandtable::testing
