// Run time against error of the cluster self-calibration (docs/calibration.md): the whole
// node-side pipeline in one process against the simulated world (tests/testing/
// self_calibration_sim.h), for a site and scene preset and a set of knobs; one CSV line per
// configuration: frames per projector, modeled projection time, compute time, registration
// error (site, table, buildings), model placement error.
//   self_calibration_sweep --site sandtable-3 --scene sandtable [--quick] [--out FILE.csv]
#include <cmath>
#include <fstream>
#include <iostream>
#include <random>
#include <string>
#include <vector>

#include "common/cli/command_line.h"
#include "common/scene/procedural_scene.h"
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
  cli::Configure(app);
  if (std::optional<int> exit = cli::Parse(app, argc, argv)) return *exit;

  Expected<sim::Site> site = sim::MakeSitePreset(site_name);
  if (!site.ok()) {
    std::cerr << site.status().ToString() << "\n";
    return 2;
  }
  Expected<ScenePreset> preset = ParseScenePreset(scene_name);
  if (!preset.ok()) {
    std::cerr << preset.status().ToString() << "\n";
    return 2;
  }
  ProceduralSceneOptions scene_options;
  scene_options.preset = *preset;
  Expected<ProceduralScene> scene = MakeProceduralScene(scene_options);
  if (!scene.ok()) {
    std::cerr << scene.status().ToString() << "\n";
    return 2;
  }
  // The lab's default: an unknown placement within 5 cm and 10 degrees about z.
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const double yaw = u(rng) * 10.0 * M_PI / 180.0;
  const Rigid3d model_from_table(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix(),
                                 Eigen::Vector3d(u(rng) * 0.035, u(rng) * 0.035, 0.0));
  std::vector<Config> configs;
  Config base;
  base.name = "default";
  base.options.seed = seed;
  base.options.model_from_table = model_from_table;
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
    c.name = "no_model_scale";
    c.options.solve.scale_from_model = false;
    configs.push_back(c);
  }
  std::ofstream csv;
  if (!out_path.empty()) csv.open(out_path);
  const std::string header =
      "config,frames_per_projector,device_time_per_projector_s,decode_cpu_s,solve_cpu_s,"
      "tracks,bundle_rms_px,rms_mm,p99_mm,max_mm,rms_px,table_rms_mm,table_max_mm,"
      "buildings_rms_mm,buildings_max_mm,model_offset_mm,model_offset_deg,scale_correction";
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
                  "%.6f",
                  config.name.c_str(), frames, frames * (kFramePeriod_s + kCaptureLatency_s),
                  r->decode_cpu_s, r->solution.time_s, r->tracks,
                  r->solution.bundle.final_rms_px, m.all.rms_mm, m.all.p99_mm, m.all.max_mm,
                  m.all.rms_px, m.table.rms_mm, m.table.max_mm, m.buildings.rms_mm,
                  m.buildings.max_mm, r->model_offset_mm, r->model_offset_deg,
                  r->solution.scale_correction);
    std::cout << line << std::endl;
    if (csv) csv << line << "\n";
    for (const std::string& note : r->solution.notes) std::cerr << "  note: " << note << "\n";
    std::cerr << "  bundle: " << r->solution.bundle.termination << " "
              << r->solution.bundle.iterations << " it, rms " << r->solution.bundle.initial_rms_px
              << " -> " << r->solution.bundle.final_rms_px << " px, dropped "
              << r->solution.bundle.observations_dropped << "; max height "
              << r->solution.max_height_mm << " mm\n";
  }
  return 0;
}
