// sandtable-world: the simulated site (scenes, rigs, renders, and the world server).
// Subcommands and flags: sim/app/world_commands.h and docs/world.md. Exit codes: 0 ok,
// 1 failure at run time, 2 usage error (bad flags or input files). serve stops cleanly on
// SIGINT/SIGTERM.
#include <csignal>
#include <iostream>
#include <string>
#include <vector>

#include "common/base/log.h"
#include "sim/app/world_commands.h"

namespace {

std::atomic<bool> g_stop{false};
void OnSignal(int) { g_stop = true; }

}  // namespace

int main(int argc, char** argv) {
  using namespace sandtable::sim;
  sandtable::SetLogTag("world");
  if (argc < 2) {
    std::cerr << "sandtable-world: missing subcommand\n" << WorldUsage();
    return kExitUsage;
  }
  const std::string command = argv[1];
  const std::vector<std::string> args(argv + 2, argv + argc);
  if (command == "make-scene") return MakeSceneCommand(args, std::cout, std::cerr);
  if (command == "make-site") return MakeSiteCommand(args, std::cout, std::cerr);
  if (command == "render") return RenderCommand(args, std::cout, std::cerr);
  if (command == "serve") {
    struct sigaction action {};
    action.sa_handler = OnSignal;
    sigaction(SIGINT, &action, nullptr);
    sigaction(SIGTERM, &action, nullptr);
    return ServeCommand(args, g_stop, std::cout, std::cerr);
  }
  if (command == "--help" || command == "-h" || command == "help") {
    std::cout << WorldUsage();
    return kExitOk;
  }
  std::cerr << "sandtable-world: unknown subcommand '" << command << "'\n" << WorldUsage();
  return kExitUsage;
}
