#include "sim/lab/lab_inputs.h"

#include <cmath>
#include <filesystem>
#include <optional>
#include <random>

#include <Eigen/Geometry>

#include "common/io/json_codec.h"
#include "common/io/json_reader.h"
#include "common/scene/gltf_loader.h"
#include "common/scene/gltf_writer.h"
#include "common/scene/procedural_scene.h"
#include "common/scene/random_scene.h"
#include "sim/site/factory_calibration.h"
#include "sim/site/site_json.h"
#include "sim/site/site_presets.h"

namespace sandtable::sim {

namespace {

Status WriteJsonFile(const nlohmann::json& json, const std::filesystem::path& path) {
  return io::WriteJsonFile(json, path.string());  // atomic (common/io/json_reader.h)
}

// A path (then read as a file: a directory, FIFO or device is refused by name) when something
// exists there or the text looks like one ('/' or '.'; preset names have neither); a preset
// name otherwise.
bool IsFile(const std::string& text) {
  std::error_code error;
  return std::filesystem::exists(std::filesystem::symlink_status(text, error)) ||
         text.find_first_of("/.") != std::string::npos;
}

}  // namespace

Expected<LabInputs> PrepareLabInputs(const std::string& site_arg, const std::string& scene_arg,
                                     uint64_t seed, const std::string& out_dir,
                                     const std::string& model_arg, double resolution_scale,
                                     const std::string& device_timing) {
  const std::filesystem::path dir(out_dir);
  LabInputs inputs;
  inputs.site_label = site_arg;
  inputs.scene_label = scene_arg;
  // Everything is read and checked before anything is written: a refused run leaves no folders.
  Expected<Site> site = IsFile(site_arg) ? LoadSiteFile(site_arg) : MakeSitePreset(site_arg);
  if (!site.ok())
    return InvalidArgumentError("--site " + site_arg + ": " + site.status().message());
  inputs.site = std::move(*site);
  if (Status scaled = ScaleSiteResolution(resolution_scale, &inputs.site); !scaled.ok()) {
    return InvalidArgumentError("--resolution-scale: " + scaled.message());
  }
  if (!device_timing.empty()) {
    Expected<DeviceTiming> timing = DeviceTimingPreset(device_timing);
    if (!timing.ok()) return InvalidArgumentError("--device-timing: " + timing.status().message());
    for (UnitSpec& unit : inputs.site.units) unit.timing = *timing;
  }
  std::optional<Scene> scene;  // the scene shown, when the lab makes it
  if (IsFile(scene_arg)) {
    Expected<Scene> loaded = LoadGltfScene(scene_arg);
    if (!loaded.ok()) {
      return InvalidArgumentError("--scene " + scene_arg + ": " + loaded.status().message());
    }
    inputs.scene_path = std::filesystem::absolute(scene_arg).string();
  } else if (std::optional<uint64_t> scene_seed = ParseRandomSeedName(scene_arg)) {
    RandomSceneOptions options;
    options.seed = *scene_seed;
    Expected<RandomScene> made = MakeRandomScene(options);
    if (!made.ok()) return made.status();
    scene = std::move(made->scene.scene);
  } else {
    Expected<ScenePreset> preset = ParseScenePreset(scene_arg);
    if (!preset.ok()) {
      return InvalidArgumentError("--scene " + scene_arg + ": not a file, and " +
                                  preset.status().message());
    }
    ProceduralSceneOptions options;
    options.preset = *preset;
    options.seed = seed;
    Expected<ProceduralScene> made = MakeProceduralScene(options);
    if (!made.ok()) return made.status();
    scene = std::move(made->scene);
  }
  if (!model_arg.empty()) {
    Expected<Scene> model = LoadGltfScene(model_arg);
    if (!model.ok()) {
      return InvalidArgumentError("--model " + model_arg + ": " + model.status().message());
    }
  }

  std::error_code error;
  for (const char* sub : {"", "factory", "truth", "calibration", "logs"}) {
    std::filesystem::create_directories(dir / sub, error);
    if (error) return IoError("cannot create " + (dir / sub).string() + ": " + error.message());
  }
  inputs.site_path = (dir / "site.json").string();
  ST_RETURN_IF_ERROR(WriteSiteFile(inputs.site, inputs.site_path));
  if (scene) {
    inputs.scene_path = (dir / "scene.gltf").string();
    ST_RETURN_IF_ERROR(WriteGltfScene(*scene, inputs.scene_path));
  }

  // The model the nodes must find.
  if (!model_arg.empty()) {
    inputs.model_path = std::filesystem::absolute(model_arg).string();
    inputs.model_from_table = Rigid3d::Identity();
  } else {
    // The scene as the world reads it (its file), which the model moves.
    Expected<Scene> shown = LoadGltfScene(inputs.scene_path);
    if (!shown.ok()) return shown.status();
    // A placement the nodes do not know: uniform in [-max, max] per axis, from the seed.
    std::mt19937_64 rng(seed ^ 0x6d6f64656cULL);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    const double yaw_rad = u(rng) * kMaxModelYaw_deg * 3.14159265358979323846 / 180.0;
    const double x = u(rng) * kMaxModelOffset_m / std::sqrt(2.0);
    const double y = u(rng) * kMaxModelOffset_m / std::sqrt(2.0);
    inputs.model_from_table =
        Rigid3d(Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix(),
                Eigen::Vector3d(x, y, 0.0));
    inputs.model_path = (dir / "model.gltf").string();
    ST_RETURN_IF_ERROR(
        WriteGltfScene(MovedScene(*shown, inputs.model_from_table), inputs.model_path));
  }

  for (const UnitSpec& unit : inputs.site.units) {
    Expected<FactoryCalibration> factory =
        MakeFactoryCalibration(unit, FactoryCalibrationError{}, seed);
    if (!factory.ok()) return factory.status();
    const std::filesystem::path factory_path =
        dir / "factory" / ("unit-" + std::to_string(unit.id) + ".factory.json");
    ST_RETURN_IF_ERROR(WriteJsonFile(FactoryCalibrationToJson(*factory), factory_path));
    inputs.factory_paths[unit.id] = factory_path.string();
    const nlohmann::json true_pose = {
        {"format", "sandtable.true_pose"},
        {"version", 1},
        {"unit_id", unit.id},
        {"table_from_projector", io::RigidToJson(unit.projector.table_from_projector)},
        {"table_from_model", io::RigidToJson(Rigid3d::Identity())}};
    const std::filesystem::path pose_path =
        dir / "truth" / ("unit-" + std::to_string(unit.id) + ".true_pose.json");
    ST_RETURN_IF_ERROR(WriteJsonFile(true_pose, pose_path));
    inputs.true_pose_paths[unit.id] = pose_path.string();
  }
  return inputs;
}

}  // namespace sandtable::sim
