// The command line of sandtable-world (CLI11; exit-code policy in common/cli/command_line.h):
//
//   make-scene --preset sandtable|city|flat [--seed N] [--buildings N] [--remove-building I]...
//              [--move-building I:DX_M:DY_M]... -o scene.gltf|.glb
//   make-site  --preset sandtable-3|grid-N|flat-4 [--seed N] [--factory-dir DIR] -o site.json
//   render     --site S --scene G [--white | --frame ID=FILE.png ...] --view top|camera:ID
//              [--width W] [--height H] [--white-nits L] [--threads N] -o out.png
//   serve      --site S --scene G [--bind tcp://127.0.0.1:0] [--no-noise] [--noise-seed N]
//              [--threads N] [--prebuild] [--curve-keys site.key]
//
// AddWorldCommands registers the four subcommands with typed, range-checked values: an unknown
// flag, a missing required flag, a value of the wrong type or out of range is a usage error
// naming the flag (exit 2) before any file is read. `sandtable-world SUBCOMMAND --help` lists
// every flag of the subcommand.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

namespace sandtable::sim {

struct MakeSceneArgs {
  std::string preset;  // sandtable | city | flat (checked while parsing)
  uint64_t seed = 1;
  int buildings = -1;                       // -1: the preset's count
  std::vector<int> remove_buildings;        // indices into the layout
  std::vector<std::string> move_buildings;  // "I:DX_M:DY_M" (checked after parsing)
  std::string output;                       // .gltf or .glb
};

struct MakeSiteArgs {
  std::string preset;       // sandtable-3 | grid-N | flat-4 (checked after parsing)
  uint64_t seed = 1;        // of the factory calibrations' errors
  std::string factory_dir;  // empty: no factory files
  std::string output;
};

struct RenderArgs {
  std::string site, scene;
  bool white = false;               // every projector full white
  std::vector<std::string> frames;  // ID=FILE.png, one per --frame
  std::string view;                 // top | camera:ID
  int width_px = 1024;
  int height_px = 0;        // 0: from the extent's aspect (top view)
  double white_nits = 0.0;  // 0: the 99th percentile of the lit luminance
  int threads = 0;          // 0: all cores
  std::string output;
};

struct ServeArgs {
  std::string site, scene;
  std::string bind = "tcp://127.0.0.1:0";  // port 0 or *: any free port
  bool no_noise = false;
  uint64_t noise_seed = 1;
  int threads = 0;
  bool prebuild = false;   // build every camera's transport map before serving
  std::string curve_keys;  // site CURVE key file: require CURVE from every client
  std::string frame_log;   // every frame set, one JSON line each (world_server.h)
};

// The parsed values, and which subcommand was given (after parsing: exactly one `parsed()`).
struct WorldCommandLine {
  MakeSceneArgs make_scene;
  MakeSiteArgs make_site;
  RenderArgs render;
  ServeArgs serve;
  CLI::App* make_scene_command = nullptr;
  CLI::App* make_site_command = nullptr;
  CLI::App* render_command = nullptr;
  CLI::App* serve_command = nullptr;
};

// Registers the subcommands on `app` (which must be configured with cli::Configure first);
// `line` receives the values and must outlive the parse.
void AddWorldCommands(CLI::App& app, WorldCommandLine& line);

}  // namespace sandtable::sim
