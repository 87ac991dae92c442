#include "sim/app/flags.h"

#include <cstdlib>
#include <limits>

#include "common/cli/command_line.h"
#include "common/scene/procedural_scene.h"
#include "sim/transport/view.h"

namespace sandtable::sim {
namespace {

// A non-negative integer that fits a NodeId.
bool IsId(const std::string& text) {
  if (text.empty() || text.size() > 9) return false;
  for (char c : text) {
    if (c < '0' || c > '9') return false;
  }
  return true;
}

CLI::Validator ScenePresetName() {
  return CLI::Validator(
      [](std::string& value) {
        Expected<ScenePreset> preset = ParseScenePreset(value);
        return preset.ok() ? std::string() : preset.status().message();
      },
      "sandtable|city|flat", "ScenePreset");
}

CLI::Validator FrameAssignment() {
  return CLI::Validator(
      [](std::string& value) {
        const size_t equals = value.find('=');
        if (equals == std::string::npos || equals + 1 == value.size() ||
            !IsId(value.substr(0, equals))) {
          return "'" + value + "' must be ID=FILE.png (ID: a projector id)";
        }
        return std::string();
      },
      "ID=FILE.png", "FrameAssignment");
}

CLI::Validator ViewName() {
  return CLI::Validator(
      [](std::string& value) {
        if (value == "top" || (value.rfind("camera:", 0) == 0 && IsId(value.substr(7)))) {
          return std::string();
        }
        return "'" + value + "' must be top or camera:ID";
      },
      "top|camera:ID", "View");
}

void AddSiteAndScene(CLI::App* command, std::string* site, std::string* scene) {
  command->add_option("--site", *site, "site file (make-site writes one)")->required();
  command->add_option("--scene", *scene, "glTF scene (.gltf, .glb; make-scene writes one)")
      ->required();
}

}  // namespace

void AddWorldCommands(CLI::App& app, WorldCommandLine& line) {
  app.require_subcommand(1);
  const CLI::Validator kSeed = cli::Integer<uint64_t>(0, std::numeric_limits<uint64_t>::max());

  CLI::App* scene = app.add_subcommand("make-scene", "write a procedural scene as glTF");
  MakeSceneArgs& s = line.make_scene;
  scene->add_option("--preset", s.preset, "scene preset")->required()->check(ScenePresetName());
  scene->add_option("--seed", s.seed, "random seed of the layout")->check(kSeed);
  scene->add_option("--buildings", s.buildings, "number of buildings (-1: the preset's)")
      ->check(cli::Integer(-1, 1000));
  scene
      ->add_option("--remove-building", s.remove_buildings,
                   "leave the layout's building I out (repeatable; to test change reports)")
      ->check(cli::Integer(0, 1000));
  scene->add_option("--move-building", s.move_buildings,
                    "move the layout's building I by DX, DY metres: I:DX:DY (repeatable)");
  scene->add_option("-o,--output", s.output, "output .gltf or .glb")->required();
  line.make_scene_command = scene;

  CLI::App* site = app.add_subcommand("make-site", "write a site preset (and factory files)");
  MakeSiteArgs& m = line.make_site;
  site->add_option("--preset", m.preset,
                   "site preset: sandtable-3, grid-N (N units), flat-4, random:SEED")
      ->required();
  site->add_option("--seed", m.seed, "random seed of the factory calibrations' errors")
      ->check(kSeed);
  site->add_option("--factory-dir", m.factory_dir,
                   "write one factory calibration per unit here (unit-ID.factory.json)");
  site->add_option("-o,--output", m.output, "output site .json")->required();
  line.make_site_command = site;

  CLI::App* render = app.add_subcommand("render", "render the lit site to a PNG");
  RenderArgs& r = line.render;
  AddSiteAndScene(render, &r.site, &r.scene);
  CLI::Option* white = render->add_flag("--white", r.white, "every projector shows full white");
  CLI::Option* frame =
      render->add_option("--frame", r.frames, "projector ID shows FILE.png (repeatable)")
          ->allow_extra_args(false)
          ->check(FrameAssignment());
  white->excludes(frame);
  render->add_option("--view", r.view, "top (orthographic) or camera:ID")
      ->required()
      ->check(ViewName());
  // kMaxViewSide_px per side; the area is bounded by kMaxViewPixels when the view is made.
  render->add_option("--width", r.width_px, "image width, px (at most 8192, 16 Mpx in all)")
      ->check(cli::Integer(16, kMaxViewSide_px));
  render->add_option("--height", r.height_px, "image height, px (default: from the aspect)")
      ->check(cli::Integer(16, kMaxViewSide_px));
  render
      ->add_option("--white-nits", r.white_nits,
                   "luminance shown as white, cd/m^2 (0: the 99th percentile)")
      ->check(cli::Real(0.0, 1e9));
  render->add_option("--threads", r.threads, "render threads (0: all cores)")
      ->check(cli::Integer(0, 1024));
  render->add_option("-o,--output", r.output, "output .png")->required();
  line.render_command = render;

  CLI::App* serve = app.add_subcommand(
      "serve", "serve the world to nodes (prints {\"ready\":\"sandtable-world\",...})");
  ServeArgs& v = line.serve;
  AddSiteAndScene(serve, &v.site, &v.scene);
  serve->add_option("--bind", v.bind, "ROUTER endpoint (port 0 or *: any free port)")
      ->check(cli::Endpoint());
  serve->add_flag("--no-noise", v.no_noise, "noise-free captures");
  serve->add_option("--noise-seed", v.noise_seed, "seed of the capture noise")->check(kSeed);
  serve->add_option("--threads", v.threads, "transport threads (0: all cores)")
      ->check(cli::Integer(0, 1024));
  serve->add_flag("--prebuild", v.prebuild, "build every camera's transport map first");
  serve->add_option("--frame-log", v.frame_log,
                    "append every frame a projector is given to FILE (JSON lines: projector, "
                    "frame_index, hash, time_ms)");
  serve->add_option("--curve-keys", v.curve_keys,
                    "site CURVE key file (sandtable-coordinator --generate-curve-keys): "
                    "serve only clients holding the site key");
  line.serve_command = serve;
}

}  // namespace sandtable::sim
