// sandtable-world: the simulated site (scenes, rigs, renders, and the world server).
// Subcommands and flags: sim/app/flags.h (`sandtable-world SUBCOMMAND --help`) and
// docs/world.md. Exit codes: 0 ok, 1 failure at run time, 2 usage error (bad flags or input
// files). serve prints {"ready":"sandtable-world","world":"tcp://..."} once bound and stops
// cleanly on SIGINT/SIGTERM.
#include <csignal>
#include <iostream>

#include "common/base/log.h"
#include "common/base/main_guard.h"
#include "common/cli/command_line.h"
#include "sim/app/flags.h"
#include "sim/app/world_commands.h"

namespace {

std::atomic<bool> g_stop{false};
void OnSignal(int) { g_stop = true; }

}  // namespace

static int Run(int argc, char** argv) {
  using namespace sandtable::sim;
  sandtable::SetLogTag("world");
  CLI::App app("The simulated site: scenes, sites, renders, and the world server.",
               "sandtable-world");
  sandtable::cli::Configure(app);
  WorldCommandLine line;
  AddWorldCommands(app, line);
  if (std::optional<int> exit = sandtable::cli::Parse(app, argc, argv)) return *exit;
  if (line.make_scene_command->parsed()) {
    return MakeSceneCommand(line.make_scene, std::cout, std::cerr);
  }
  if (line.make_site_command->parsed())
    return MakeSiteCommand(line.make_site, std::cout, std::cerr);
  if (line.render_command->parsed()) return RenderCommand(line.render, std::cout, std::cerr);
  struct sigaction action {};
  action.sa_handler = OnSignal;
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);
  return ServeCommand(line.serve, g_stop, std::cout, std::cerr);
}

int main(int argc, char** argv) {
  return sandtable::GuardedMain(argc, argv, "sandtable-world", Run);
}
