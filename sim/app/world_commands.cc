#include "sim/app/world_commands.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <sstream>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "cluster/report_lines.h"
#include "common/base/log.h"
#include "common/io/image_file.h"
#include "common/io/json_reader.h"
#include "common/scene/gltf_loader.h"
#include "common/scene/gltf_writer.h"
#include "common/scene/procedural_scene.h"
#include "sim/app/world_server.h"
#include "sim/site/factory_calibration.h"
#include "sim/site/site_json.h"
#include "sim/site/site_presets.h"
#include "sim/transport/world.h"

namespace sandtable::sim {
namespace {

int Usage(std::ostream& err, const std::string& command, const std::string& why) {
  err << "sandtable-world " << command << ": " << why << "\nRun with sandtable-world " << command
      << " --help for more information.\n";
  return kExitUsage;
}

int Failure(std::ostream& err, const std::string& command, const std::string& why) {
  err << "sandtable-world " << command << ": " << why << "\n";
  return kExitFailure;
}

// Loads the site and scene files and makes a World. Bad files are usage errors.
struct Loaded {
  std::unique_ptr<World> world;
  std::string error;
};
Loaded LoadWorld(const std::string& site_path, const std::string& scene_path, int num_threads) {
  Loaded out;
  Expected<Site> site = LoadSiteFile(site_path);
  if (!site.ok()) {
    out.error = "--site: " + site.status().ToString();
    return out;
  }
  Expected<Scene> scene = LoadGltfScene(scene_path);
  if (!scene.ok()) {
    out.error = "--scene: " + scene.status().ToString();
    return out;
  }
  WorldOptions options;
  options.transport.num_threads = num_threads;
  Expected<std::unique_ptr<World>> world =
      World::Create(std::move(*site), std::move(*scene), options);
  if (!world.ok()) {
    out.error = world.status().ToString();
    return out;
  }
  out.world = std::move(*world);
  return out;
}

}  // namespace

int MakeSceneCommand(const MakeSceneArgs& args, std::ostream& out, std::ostream& err) {
  const std::string kName = "make-scene";
  ProceduralSceneOptions options;
  Expected<ScenePreset> preset = ParseScenePreset(args.preset);
  if (!preset.ok()) return Usage(err, kName, "--preset: " + preset.status().message());
  options.preset = *preset;
  options.seed = args.seed;
  options.num_buildings = args.buildings;
  options.remove_buildings = args.remove_buildings;
  for (const std::string& move : args.move_buildings) {
    int index = -1;
    double dx = 0, dy = 0;
    char tail = 0;
    if (std::sscanf(move.c_str(), "%d:%lf:%lf%c", &index, &dx, &dy, &tail) != 3) {
      return Usage(err, kName, "--move-building " + move + ": expected I:DX_M:DY_M");
    }
    options.move_buildings.emplace_back(index, Eigen::Vector2d(dx, dy));
  }
  if (Status valid = options.Check(); !valid.ok()) return Usage(err, kName, valid.message());
  Expected<ProceduralScene> scene = MakeProceduralScene(options);
  if (!scene.ok()) return Usage(err, kName, scene.status().message());
  const std::string& path = args.output;
  if (Status written = WriteGltfScene(scene->scene, path); !written.ok()) {
    return Failure(err, kName, written.ToString());
  }
  out << "wrote " << path << ": preset " << ScenePresetName(options.preset) << ", seed "
      << options.seed << ", " << scene->buildings.size() << " buildings, "
      << scene->scene.NumTriangles() << " triangles\n";
  return kExitOk;
}

int MakeSiteCommand(const MakeSiteArgs& args, std::ostream& out, std::ostream& err) {
  const std::string kName = "make-site";
  Expected<Site> site = MakeSitePreset(args.preset);
  if (!site.ok()) return Usage(err, kName, "--preset: " + site.status().message());
  const std::string& path = args.output;
  if (Status written = WriteSiteFile(*site, path); !written.ok()) {
    return Failure(err, kName, written.ToString());
  }
  out << "wrote " << path << ": " << site->name << ", " << site->units.size() << " units\n";
  if (!args.factory_dir.empty()) {
    // One factory calibration per unit, derived from the truth with the default errors.
    const std::filesystem::path dir = args.factory_dir;
    std::error_code error;
    std::filesystem::create_directories(dir, error);
    if (error) return Failure(err, kName, "cannot create " + dir.string() + ": " + error.message());
    for (const UnitSpec& unit : site->units) {
      Expected<FactoryCalibration> calibration =
          MakeFactoryCalibration(unit, FactoryCalibrationError{}, args.seed);
      if (!calibration.ok()) return Failure(err, kName, calibration.status().ToString());
      const std::filesystem::path file =
          dir / ("unit-" + std::to_string(unit.id) + ".factory.json");
      if (Status written = io::WriteJsonFile(FactoryCalibrationToJson(*calibration), file);
          !written.ok()) {
        return Failure(err, kName, written.ToString());
      }
    }
    out << "wrote " << site->units.size() << " factory calibrations to " << dir.string()
        << " (seed " << args.seed << ")\n";
  }
  return kExitOk;
}

int RenderCommand(const RenderArgs& args, std::ostream& out, std::ostream& err) {
  const std::string kName = "render";
  Loaded loaded = LoadWorld(args.site, args.scene, args.threads);
  if (!loaded.world) return Usage(err, kName, loaded.error);
  World& world = *loaded.world;

  if (args.white) {
    for (const UnitSpec& unit : world.site().units) {
      ST_CHECK(world.SetProjectorUniform(unit.id, 255).ok()) << "site units are valid";
    }
  }
  for (const std::string& assignment : args.frames) {
    const size_t equals = assignment.find('=');
    if (equals == std::string::npos || equals == 0) {
      return Usage(err, kName, "--frame '" + assignment + "' must be ID=FILE.png");
    }
    const std::string id_text = assignment.substr(0, equals);
    char* end = nullptr;
    const unsigned long id = std::strtoul(id_text.c_str(), &end, 10);
    if (*end != '\0' || id > kInvalidNodeId - 1) {
      return Usage(err, kName, "--frame: projector id '" + id_text + "' is not a number");
    }
    const std::string file = assignment.substr(equals + 1);
    Expected<cv::Mat> read = io::ReadImageFile(file, cv::IMREAD_UNCHANGED);
    if (!read.ok()) return Usage(err, kName, "--frame: " + read.status().message());
    cv::Mat image = std::move(*read);
    if (image.depth() != CV_8U) return Usage(err, kName, "--frame: " + file + " is not 8-bit");
    if (image.channels() == 4) cv::cvtColor(image, image, cv::COLOR_BGRA2BGR);
    const Status set = world.SetProjectorFrame(static_cast<NodeId>(id), image);
    if (!set.ok()) return Usage(err, kName, "--frame " + assignment + ": " + set.message());
  }

  // The view: orthographic over the scene's extent, or a unit's camera.
  const std::string& view_name = args.view;
  std::optional<View> view;
  if (view_name == "top") {
    Expected<View> top = View::TopOver(world.scene().Bounds(), args.width_px, args.height_px);
    if (!top.ok()) return Usage(err, kName, "--width/--height: " + top.status().message());
    view = *top;
  } else if (view_name.rfind("camera:", 0) == 0) {
    const std::string id_text = view_name.substr(7);
    char* end = nullptr;
    const unsigned long id = std::strtoul(id_text.c_str(), &end, 10);
    const UnitSpec* unit =
        id_text.empty() || *end != '\0' ? nullptr : world.site().FindUnit(static_cast<NodeId>(id));
    if (!unit || !unit->camera) {
      return Usage(err, kName, "--view " + view_name + ": no camera with that id in the site");
    }
    view = View::Perspective(unit->camera->model, world.site().TableFromCamera(*unit));
    if (Status valid = view->Check(); !valid.ok()) {
      return Usage(err, kName, "--view " + view_name + ": " + valid.message());
    }
  } else {
    return Usage(err, kName, "--view must be top or camera:ID, not '" + view_name + "'");
  }
  Expected<std::vector<float>> luminance = world.RenderLuminance(*view);
  if (!luminance.ok()) return Failure(err, kName, luminance.status().ToString());
  // Tone mapping: unless given, white is the 99th percentile of the lit luminance, so a few
  // bright spots do not darken the whole picture.
  double white = args.white_nits;
  size_t lit = 0;
  std::vector<float> positive;
  for (float l : *luminance) {
    if (l > 0) positive.push_back(l);
  }
  if (white == 0.0) {
    if (!positive.empty()) {
      const size_t k = static_cast<size_t>(0.99 * (positive.size() - 1));
      std::nth_element(positive.begin(), positive.begin() + k, positive.end());
      white = positive[k];
    }
    if (!(white > 0)) white = 1.0;
  }
  const cv::Mat image = LuminanceToImage(*luminance, view->width_px(), view->height_px(), white);
  lit = static_cast<size_t>(cv::countNonZero(image));
  const std::string& path = args.output;
  if (Status written = io::WritePngFile(path, image); !written.ok()) {
    return Failure(err, kName, written.ToString());
  }
  out << "wrote " << path << " " << image.cols << "x" << image.rows << " white_nits=" << white
      << " lit_pixels=" << lit << "\n";
  return kExitOk;
}

int ServeCommand(const ServeArgs& args, const std::atomic<bool>& stop, std::ostream& out,
                 std::ostream& err) {
  const std::string kName = "serve";
  std::optional<net::CurveKeyPair> curve;
  if (!args.curve_keys.empty()) {
    Expected<net::CurveKeyPair> keys = net::ReadCurveKeyFile(args.curve_keys);
    if (!keys.ok()) return Usage(err, kName, "--curve-keys: " + keys.status().message());
    curve = *keys;
  }
  Loaded loaded = LoadWorld(args.site, args.scene, args.threads);
  if (!loaded.world) return Usage(err, kName, loaded.error);
  if (args.prebuild) {
    for (const UnitSpec& unit : loaded.world->site().units) {
      if (!unit.camera) continue;
      Expected<const TransportMap*> map = loaded.world->CameraTransport(unit.id);
      if (!map.ok()) return Failure(err, kName, map.status().ToString());
    }
  }
  WorldServerOptions options;
  std::string bind = args.bind;
  // ":0" asks the OS for a port, as ":*" does.
  if (bind.size() > 2 && bind.compare(bind.size() - 2, 2, ":0") == 0) {
    bind.replace(bind.size() - 1, 1, "*");
  }
  options.bind_endpoint = bind;
  options.noise = !args.no_noise;
  options.noise_seed = args.noise_seed;
  options.frame_log_path = args.frame_log;
  options.curve = curve;
  WorldServer server(std::move(loaded.world), options);
  if (Status started = server.Start(); !started.ok()) {
    return Failure(err, kName, started.ToString());
  }
  report::WriteReportLine(out, report::WorldReady{server.endpoint(), options.curve.has_value()});
  const Status ran = server.Run(stop);
  const WorldServerStats& stats = server.stats();
  ST_LOG(kInfo) << "stopping: frames " << stats.frames_set << ", captures " << stats.captures
                << ", truth queries " << stats.truth_queries << ", bad requests "
                << stats.bad_requests << ", rejected " << stats.rejected << "; messages "
                << server.counters().ToString();
  if (!ran.ok()) return Failure(err, kName, ran.ToString());
  return kExitOk;
}

}  // namespace sandtable::sim
