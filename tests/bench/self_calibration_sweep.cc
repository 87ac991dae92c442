// Run time against error of the cluster self-calibration (docs/calibration.md): the whole
// node-side pipeline in one process against the simulated world (tests/testing/
// self_calibration_sim.h), for a site and scene preset and a set of knobs; one CSV line per
// configuration: frames per projector, modeled projection time, compute time, registration
// error (site, table, buildings), model placement error.
//   self_calibration_sweep --site sandtable-3 --scene sandtable [--quick] [--out FILE.csv]
//   self_calibration_sweep --site grid-2 --scene city --resolution-scale 0.5 --quick
//   self_calibration_sweep --site random:4 --scene random:4 --seed 4 --quick
// Diagnostics on stderr (environment): SANDTABLE_CORRESPONDENCE_TRUTH=1 prints, per projector
// and camera, the grid correspondences against the world's truth (mean and rms, px);
// SANDTABLE_ERROR_BREAKDOWN=1 the registration error per unit split into its mean and the rest.
#include <cmath>
#include <fstream>
#include <iostream>
#include <random>
#include <string>
#include <vector>

#include "common/cli/command_line.h"
#include "common/scene/procedural_scene.h"
#include "common/scene/random_scene.h"
#include "sim/site/site_presets.h"
#include "tests/testing/self_calibration_sim.h"

namespace {

using namespace sandtable;

struct Config {
  std::string name;
  testing::SimCalibrationOptions options;
};

constexpr double kFramePeriod_s = 1.0 / 60.0;
constexpr double kCaptureLatency_s = 0.002;

}  // namespace

int main(int argc, char** argv) {
  CLI::App app("self_calibration_sweep: run time against error of the cluster self-calibration",
               "self_calibration_sweep");
  std::string site_name = "sandtable-3", scene_name = "sandtable", out_path;
  bool quick = false;
  uint64_t seed = 1;
  app.add_option("--site", site_name, "site preset");
  app.add_option("--scene", scene_name, "scene preset");
  app.add_option("--out", out_path, "CSV file (default: stdout only)");
  app.add_option("--seed", seed, "seed");
  app.add_flag("--quick", quick, "the default configuration only");
  double resolution_scale = 1.0;
  app.add_option("--resolution-scale", resolution_scale,
                 "every projector and camera at this share of its resolution (the lab's scale)");
  int max_iterations = 0, grid_step = 0;
  double function_tolerance = 0, factory_error_scale = 1.0, prior_scale = 1.0;
  bool no_noise = false, model_refinement = false, log_progress = false;
  app.add_flag("--log-progress", log_progress, "Ceres' iterations and report on stderr");
  app.add_flag("--model-refinement", model_refinement, "add the refinement against the model");
  app.add_option("--factory-error-scale", factory_error_scale, "scale the factory errors");
  app.add_option("--prior-scale", prior_scale, "scale the refinement's prior sigmas");
  app.add_flag("--no-noise", no_noise, "captures without noise");
  bool plan_scale = false;
  app.add_flag("--plan-scale", plan_scale,
               "the model's scale from the plan, the relief free (scale_from_plan)");
  app.add_option("--max-iterations", max_iterations, "override: refinement iterations per round");
  app.add_option("--grid-step", grid_step, "override: projector grid step, px");
  app.add_option("--function-tolerance", function_tolerance, "override: Ceres function tolerance");
  cli::Configure(app);
  if (std::optional<int> exit = cli::Parse(app, argc, argv)) return *exit;

  Expected<sim::Site> site = sim::MakeSitePreset(site_name);
  if (!site.ok()) {
    std::cerr << site.status().ToString() << "\n";
    return 2;
  }
  if (Status scaled = sim::ScaleSiteResolution(resolution_scale, &*site); !scaled.ok()) {
    std::cerr << "--resolution-scale: " << scaled.ToString() << "\n";
    return 2;
  }
  Expected<ProceduralScene> scene = ProceduralScene{};
  if (std::optional<uint64_t> scene_seed = ParseRandomSeedName(scene_name)) {
    RandomSceneOptions random_options;
    random_options.seed = *scene_seed;
    Expected<RandomScene> random = MakeRandomScene(random_options);
    if (!random.ok()) {
      std::cerr << random.status().ToString() << "\n";
      return 2;
    }
    scene = std::move(random->scene);
  } else {
    Expected<ScenePreset> preset = ParseScenePreset(scene_name);
    if (!preset.ok()) {
      std::cerr << preset.status().ToString() << "\n";
      return 2;
    }
    ProceduralSceneOptions scene_options;
    scene_options.preset = *preset;
    scene = MakeProceduralScene(scene_options);
  }
  if (!scene.ok()) {
    std::cerr << scene.status().ToString() << "\n";
    return 2;
  }
  // The lab's default: an unknown placement within 5 cm and 10 degrees about z.
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const double yaw = u(rng) * 10.0 * M_PI / 180.0;
  const Rigid3d model_from_table(
      Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix(),
      Eigen::Vector3d(u(rng) * 0.035, u(rng) * 0.035, 0.0));
  std::vector<Config> configs;
  Config base;
  base.name = "default";
  base.options.seed = seed;
  base.options.model_from_table = model_from_table;
  if (max_iterations > 0) base.options.solve.bundle.max_iterations = max_iterations;
  base.options.noise = !no_noise;
  base.options.solve.bundle.log_progress = log_progress;
  base.options.solve.refine_with_model = model_refinement;
  base.options.solve.model.scale_from_plan = plan_scale;
  {
    auto& e = base.options.factory_error;
    e.focal_relative_sigma *= factory_error_scale;
    e.principal_point_sigma_px *= factory_error_scale;
    e.distortion_sigma *= factory_error_scale;
    e.rotation_sigma_deg *= factory_error_scale;
    e.translation_sigma_m *= factory_error_scale;
    if (factory_error_scale == 0) {
      e.focal_relative_sigma = e.principal_point_sigma_px = e.distortion_sigma = 0;
    }
    auto& b = base.options.solve.bundle;
    b.prior_focal_relative *= prior_scale;
    b.prior_principal_point_px *= prior_scale;
    b.prior_k1 *= prior_scale;
    b.prior_k2 *= prior_scale;
    b.prior_p *= prior_scale;
    b.prior_k3 *= prior_scale;
    b.prior_mount_rotation_deg *= prior_scale;
    b.prior_mount_translation_m *= prior_scale;
  }
  if (function_tolerance > 0) base.options.solve.bundle.function_tolerance = function_tolerance;
  if (grid_step > 0) {
    base.options.grid.step_px = grid_step;
    base.options.grid.offset_px = grid_step / 2.0;
  }
  configs.push_back(base);
  if (!quick) {
    Config c = base;
    c.name = "no_refinement_intrinsics";
    c.options.solve.bundle.free_projector_intrinsics = false;
    c.options.solve.bundle.free_projector_distortion = false;
    c.options.solve.bundle.free_camera_intrinsics = false;
    c.options.solve.bundle.free_camera_distortion = false;
    c.options.solve.bundle.free_mounts = false;
    configs.push_back(c);
    c = base;
    c.name = "grid_step_32";
    c.options.grid.step_px = 32;
    c.options.grid.offset_px = 16;
    configs.push_back(c);
    c = base;
    c.name = "grid_step_8";
    c.options.grid.step_px = 8;
    c.options.grid.offset_px = 4;
    configs.push_back(c);
    c = base;
    c.name = "model_refinement";
    c.options.solve.refine_with_model = true;
    configs.push_back(c);
    c = base;
    c.name = "phase_4_steps";
    c.options.plan.phase_steps = 4;
    configs.push_back(c);
    c = base;
    c.name = "gray_cell_x2";
    c.options.plan.min_gray_cell_camera_px = 8.0;
    configs.push_back(c);
    c = base;
    c.name = "k3_free";
    c.options.solve.bundle.free_k3 = true;
    configs.push_back(c);
    c = base;
    c.name = "scale_from_plan";
    c.options.solve.model.scale_from_plan = true;
    configs.push_back(c);
    c = base;
    c.name = "no_model_scale";
    c.options.solve.scale_from_model = false;
    configs.push_back(c);
  }
  std::ofstream csv;
  if (!out_path.empty()) csv.open(out_path);
  const std::string header =
      "config,frames_per_projector,device_time_per_projector_s,decode_cpu_s,solve_cpu_s,"
      "tracks,bundle_rms_px,rms_mm,p99_mm,max_mm,rms_px,table_rms_mm,table_max_mm,"
      "buildings_rms_mm,buildings_max_mm,model_offset_mm,model_offset_deg,scale_correction,"
      "table_rms_px,buildings_rms_px,true_model_rms_mm,true_model_buildings_rms_mm";
  std::cout << header << "\n";
  if (csv) csv << header << "\n";
  for (const Config& config : configs) {
    Expected<testing::SimCalibrationResult> r =
        testing::RunSimCalibration(*site, scene->scene, config.options);
    if (!r.ok()) {
      std::cout << config.name << ",failed: " << r.status().ToString() << "\n";
      continue;
    }
    int frames = 0;
    for (const auto& [id, f] : r->frames_per_projector) frames = std::max(frames, f);
    const auto& m = r->metric.site;
    char line[1024];
    std::snprintf(line, sizeof(line),
                  "%s,%d,%.3f,%.3f,%.3f,%d,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,"
                  "%.6f,%.4f,%.4f,%.4f,%.4f",
                  config.name.c_str(), frames, frames * (kFramePeriod_s + kCaptureLatency_s),
                  r->decode_cpu_s, r->solution.time_s, r->tracks, r->solution.bundle.final_rms_px,
                  m.all.rms_mm, m.all.p99_mm, m.all.max_mm, m.all.rms_px, m.table.rms_mm,
                  m.table.max_mm, m.buildings.rms_mm, m.buildings.max_mm, r->model_offset_mm,
                  r->model_offset_deg, r->solution.scale_correction, m.table.rms_px,
                  m.buildings.rms_px, r->metric_true_model.site.all.rms_mm,
                  r->metric_true_model.site.buildings.rms_mm);
    std::cout << line << std::endl;
    if (csv) csv << line << "\n";
    for (const auto& [id, c] : r->solution.calibrations) {
      if (!c.predicted_error) continue;
      const PredictedErrorRecord& e = *c.predicted_error;
      std::cerr << "  unit " << id << " predicted " << e.rms_px << " px, " << e.rms_mm
                << " mm (sigma " << e.sigma_px << " px; " << e.weak_direction << ", "
                << e.weak_share << ")\n";
    }
    if (r->solution.model) {
      std::cerr << "  model scale " << r->solution.model->scale << ", relief "
                << r->solution.model->relief_scale << "\n";
    }
    for (const std::string& note : r->solution.notes) std::cerr << "  note: " << note << "\n";
    for (const auto& [stage, s] : r->solution.stage_time_s) {
      std::cerr << "  " << stage << ": " << s << " s\n";
    }
    std::cerr << "  bundle: " << r->solution.bundle.termination << " "
              << r->solution.bundle.iterations << " it, rms " << r->solution.bundle.initial_rms_px
              << " -> " << r->solution.bundle.final_rms_px << " px, dropped "
              << r->solution.bundle.observations_dropped << "; max height "
              << r->solution.max_height_mm << " mm\n";
  }
  return 0;
}
