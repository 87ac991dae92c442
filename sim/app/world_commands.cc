#include "sim/app/world_commands.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "common/base/log.h"
#include "sim/app/flags.h"
#include "sim/app/world_server.h"
#include "common/scene/gltf_loader.h"
#include "common/scene/gltf_writer.h"
#include "common/scene/procedural_scene.h"
#include "sim/site/factory_calibration.h"
#include "sim/site/site_json.h"
#include "sim/site/site_presets.h"
#include "sim/transport/world.h"

namespace sandtable::sim {
namespace {

int Usage(std::ostream& err, const std::string& command, const std::string& why) {
  err << "sandtable-world " << command << ": " << why << "\n" << WorldUsage();
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
Loaded LoadWorld(const Flags& flags, int num_threads) {
  Loaded out;
  Expected<Site> site = LoadSiteFile(flags.Get("--site"));
  if (!site.ok()) {
    out.error = "--site: " + site.status().ToString();
    return out;
  }
  Expected<Scene> scene = LoadGltfScene(flags.Get("--scene"));
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

std::string WorldUsage() {
  return "usage: sandtable-world make-scene --preset sandtable|city|flat [--seed N]\n"
         "                        [--buildings N] -o scene.gltf|scene.glb\n"
         "       sandtable-world make-site --preset sandtable-3|grid-N|flat-4 [--seed N]\n"
         "                        [--factory-dir DIR] -o site.json\n"
         "       sandtable-world render --site S --scene G [--white | --frame ID=FILE.png ...]\n"
         "                        --view top|camera:ID [--width W] [--height H]\n"
         "                        [--white-nits L] [--threads N] -o out.png\n"
         "       sandtable-world serve --site S --scene G [--bind tcp://127.0.0.1:0]\n"
         "                        [--no-noise] [--noise-seed N] [--threads N] [--prebuild]\n";
}

int MakeSceneCommand(const std::vector<std::string>& args, std::ostream& out, std::ostream& err) {
  const std::string kName = "make-scene";
  Expected<Flags> flags = Flags::Parse(args, {.values = {"--preset", "--seed", "--buildings", "-o"},
                                              .required = {"--preset", "-o"}});
  if (!flags.ok()) return Usage(err, kName, flags.status().message());
  ProceduralSceneOptions options;
  Expected<ScenePreset> preset = ParseScenePreset(flags->Get("--preset"));
  if (!preset.ok()) return Usage(err, kName, "--preset: " + preset.status().message());
  options.preset = *preset;
  Expected<int64_t> seed = flags->GetInt("--seed", 1, 0, INT64_MAX);
  if (!seed.ok()) return Usage(err, kName, seed.status().message());
  options.seed = static_cast<uint64_t>(*seed);
  Expected<int64_t> buildings = flags->GetInt("--buildings", -1, -1, 1000);
  if (!buildings.ok()) return Usage(err, kName, buildings.status().message());
  options.num_buildings = static_cast<int>(*buildings);
  if (Status valid = options.Check(); !valid.ok()) return Usage(err, kName, valid.message());
  Expected<ProceduralScene> scene = MakeProceduralScene(options);
  if (!scene.ok()) return Failure(err, kName, scene.status().ToString());
  const std::string path = flags->Get("-o");
  if (Status written = WriteGltfScene(scene->scene, path); !written.ok()) {
    return Failure(err, kName, written.ToString());
  }
  out << "wrote " << path << ": preset " << ScenePresetName(options.preset) << ", seed "
      << options.seed << ", " << scene->buildings.size() << " buildings, "
      << scene->scene.NumTriangles() << " triangles\n";
  return kExitOk;
}

int MakeSiteCommand(const std::vector<std::string>& args, std::ostream& out, std::ostream& err) {
  const std::string kName = "make-site";
  Expected<Flags> flags = Flags::Parse(
      args,
      {.values = {"--preset", "--seed", "--factory-dir", "-o"}, .required = {"--preset", "-o"}});
  if (!flags.ok()) return Usage(err, kName, flags.status().message());
  Expected<int64_t> seed = flags->GetInt("--seed", 1, 0, INT64_MAX);
  if (!seed.ok()) return Usage(err, kName, seed.status().message());
  Expected<Site> site = MakeSitePreset(flags->Get("--preset"));
  if (!site.ok()) return Usage(err, kName, "--preset: " + site.status().message());
  const std::string path = flags->Get("-o");
  if (Status written = WriteSiteFile(*site, path); !written.ok()) {
    return Failure(err, kName, written.ToString());
  }
  out << "wrote " << path << ": " << site->name << ", " << site->units.size() << " units\n";
  if (flags->Has("--factory-dir")) {
    // One factory calibration per unit, derived from the truth with the default errors.
    const std::filesystem::path dir = flags->Get("--factory-dir");
    std::error_code error;
    std::filesystem::create_directories(dir, error);
    if (error) return Failure(err, kName, "cannot create " + dir.string() + ": " + error.message());
    for (const UnitSpec& unit : site->units) {
      Expected<FactoryCalibration> calibration =
          MakeFactoryCalibration(unit, FactoryCalibrationError{}, static_cast<uint64_t>(*seed));
      if (!calibration.ok()) return Failure(err, kName, calibration.status().ToString());
      const std::filesystem::path file =
          dir / ("unit-" + std::to_string(unit.id) + ".factory.json");
      std::ofstream stream(file);
      stream << FactoryCalibrationToJson(*calibration).dump(2) << "\n";
      if (!stream.good()) return Failure(err, kName, "cannot write " + file.string());
    }
    out << "wrote " << site->units.size() << " factory calibrations to " << dir.string()
        << " (seed " << *seed << ")\n";
  }
  return kExitOk;
}

int RenderCommand(const std::vector<std::string>& args, std::ostream& out, std::ostream& err) {
  const std::string kName = "render";
  Expected<Flags> flags =
      Flags::Parse(args, {.values = {"--site", "--scene", "--view", "--width", "--height",
                                     "--white-nits", "--threads", "-o"},
                          .repeated = {"--frame"},
                          .switches = {"--white"},
                          .required = {"--site", "--scene", "--view", "-o"}});
  if (!flags.ok()) return Usage(err, kName, flags.status().message());
  if (flags->Has("--white") && flags->Has("--frame")) {
    return Usage(err, kName, "--white and --frame exclude each other");
  }
  Expected<int64_t> threads = flags->GetInt("--threads", 0, 0, 1024);
  Expected<int64_t> width = flags->GetInt("--width", 1024, 16, 16384);
  Expected<int64_t> height = flags->GetInt("--height", 0, 16, 16384);
  Expected<double> white_nits = flags->GetDouble("--white-nits", 0.0);
  for (const Status& s : {threads.status(), width.status(), height.status(), white_nits.status()}) {
    if (!s.ok()) return Usage(err, kName, s.message());
  }
  if (*white_nits < 0) return Usage(err, kName, "--white-nits must be > 0");
  Loaded loaded = LoadWorld(*flags, static_cast<int>(*threads));
  if (!loaded.world) return Usage(err, kName, loaded.error);
  World& world = *loaded.world;

  if (flags->Has("--white")) {
    for (const UnitSpec& unit : world.site().units) {
      ST_CHECK(world.SetProjectorUniform(unit.id, 255).ok()) << "site units are valid";
    }
  }
  for (const std::string& assignment : flags->GetAll("--frame")) {
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
    cv::Mat image = cv::imread(file, cv::IMREAD_UNCHANGED);
    if (image.empty()) return Usage(err, kName, "--frame: cannot read image " + file);
    if (image.depth() != CV_8U) return Usage(err, kName, "--frame: " + file + " is not 8-bit");
    if (image.channels() == 4) cv::cvtColor(image, image, cv::COLOR_BGRA2BGR);
    const Status set = world.SetProjectorFrame(static_cast<NodeId>(id), image);
    if (!set.ok()) return Usage(err, kName, "--frame " + assignment + ": " + set.message());
  }

  // The view: orthographic over the scene's extent, or a unit's camera.
  const std::string view_name = flags->Get("--view");
  std::optional<View> view;
  if (view_name == "top") {
    const Eigen::AlignedBox3d bounds = world.scene().Bounds();
    const Eigen::AlignedBox2d area(bounds.min().head<2>(), bounds.max().head<2>());
    const Eigen::Vector2d size = area.sizes();
    const int w = static_cast<int>(*width);
    const int h = flags->Has("--height")
                      ? static_cast<int>(*height)
                      : std::max(16, static_cast<int>(std::lround(w * size.y() / size.x())));
    view = View::OrthographicTop(area, w, h, bounds.max().z() + 10.0);
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
  } else {
    return Usage(err, kName, "--view must be top or camera:ID, not '" + view_name + "'");
  }
  Expected<std::vector<float>> luminance = world.RenderLuminance(*view);
  if (!luminance.ok()) return Failure(err, kName, luminance.status().ToString());
  // Tone mapping: unless given, white is the 99th percentile of the lit luminance, so a few
  // bright spots do not darken the whole picture.
  double white = *white_nits;
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
  const std::string path = flags->Get("-o");
  bool written = false;
  try {
    written = cv::imwrite(path, image);
  } catch (const cv::Exception& e) {
    return Failure(err, kName, "cannot write " + path + ": " + e.what());
  }
  if (!written) return Failure(err, kName, "cannot write " + path);
  out << "wrote " << path << " " << image.cols << "x" << image.rows << " white_nits=" << white
      << " lit_pixels=" << lit << "\n";
  return kExitOk;
}

int ServeCommand(const std::vector<std::string>& args, const std::atomic<bool>& stop,
                 std::ostream& out, std::ostream& err) {
  const std::string kName = "serve";
  Expected<Flags> flags =
      Flags::Parse(args, {.values = {"--site", "--scene", "--bind", "--noise-seed", "--threads"},
                          .switches = {"--no-noise", "--prebuild"},
                          .required = {"--site", "--scene"}});
  if (!flags.ok()) return Usage(err, kName, flags.status().message());
  Expected<int64_t> seed = flags->GetInt("--noise-seed", 1, 0, INT64_MAX);
  if (!seed.ok()) return Usage(err, kName, seed.status().message());
  Expected<int64_t> threads = flags->GetInt("--threads", 0, 0, 1024);
  if (!threads.ok()) return Usage(err, kName, threads.status().message());
  Loaded loaded = LoadWorld(*flags, static_cast<int>(*threads));
  if (!loaded.world) return Usage(err, kName, loaded.error);
  if (flags->Has("--prebuild")) {
    for (const UnitSpec& unit : loaded.world->site().units) {
      if (!unit.camera) continue;
      Expected<const TransportMap*> map = loaded.world->CameraTransport(unit.id);
      if (!map.ok()) return Failure(err, kName, map.status().ToString());
    }
  }
  WorldServerOptions options;
  std::string bind = flags->Get("--bind", options.bind_endpoint);
  // ":0" asks the OS for a port, as ":*" does.
  if (bind.size() > 2 && bind.compare(bind.size() - 2, 2, ":0") == 0) {
    bind.replace(bind.size() - 1, 1, "*");
  }
  options.bind_endpoint = bind;
  options.noise = !flags->Has("--no-noise");
  options.noise_seed = static_cast<uint64_t>(*seed);
  WorldServer server(std::move(loaded.world), options);
  if (Status started = server.Start(); !started.ok()) {
    return Failure(err, kName, started.ToString());
  }
  out << "sandtable-world world=" << server.endpoint() << std::endl;
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
