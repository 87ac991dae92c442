// The subcommands of sandtable-world (docs/world.md):
//
//   make-scene --preset sandtable|city|flat [--seed N] [--buildings N] -o scene.gltf|.glb
//   make-site  --preset sandtable-3|grid-N|flat-4 [--seed N] [--factory-dir DIR] -o site.json
//   render     --site S --scene G [--white | --frame ID=FILE.png ...] --view top|camera:ID
//              [--width W] [--height H] [--white-nits L] [--threads N] -o out.png
//   serve      --site S --scene G [--bind tcp://127.0.0.1:0] [--no-noise] [--noise-seed N]
//              [--threads N] [--prebuild]
//
// Each returns the process exit code: 0 success, 1 a failure at run time (an output that
// cannot be written, a socket that cannot bind), 2 a usage error (bad or missing flags, an
// input file that does not load or validate); the message goes to `err`.
#pragma once

#include <atomic>
#include <ostream>
#include <string>
#include <vector>

namespace sandtable::sim {

constexpr int kExitOk = 0;
constexpr int kExitFailure = 1;
constexpr int kExitUsage = 2;

int MakeSceneCommand(const std::vector<std::string>& args, std::ostream& out, std::ostream& err);
int MakeSiteCommand(const std::vector<std::string>& args, std::ostream& out, std::ostream& err);
int RenderCommand(const std::vector<std::string>& args, std::ostream& out, std::ostream& err);
// Prints "sandtable-world world=<endpoint>" on `out` once bound, then serves until `stop`.
int ServeCommand(const std::vector<std::string>& args, const std::atomic<bool>& stop,
                 std::ostream& out, std::ostream& err);

// The usage text of all subcommands.
std::string WorldUsage();

}  // namespace sandtable::sim
