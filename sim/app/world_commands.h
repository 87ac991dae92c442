// The subcommands of sandtable-world (docs/world.md), run on command lines already parsed
// and range-checked by AddWorldCommands (sim/app/flags.h).
//
// Each returns the process exit code: 0 success, 1 a failure at run time (an output that
// cannot be written, a socket that cannot bind), 2 a usage error (an input file that does not
// load or validate, a preset or view that does not exist); the message goes to `err`.
#pragma once

#include <atomic>
#include <ostream>

#include "sim/app/flags.h"

namespace sandtable::sim {

constexpr int kExitOk = 0;
constexpr int kExitFailure = 1;
constexpr int kExitUsage = 2;

int MakeSceneCommand(const MakeSceneArgs& args, std::ostream& out, std::ostream& err);
int MakeSiteCommand(const MakeSiteArgs& args, std::ostream& out, std::ostream& err);
int RenderCommand(const RenderArgs& args, std::ostream& out, std::ostream& err);
// Once bound, prints the readiness line {"ready":"sandtable-world","world":"tcp://..."} on
// `out` (cluster/report_lines.h), then serves until `stop`.
int ServeCommand(const ServeArgs& args, const std::atomic<bool>& stop, std::ostream& out,
                 std::ostream& err);

}  // namespace sandtable::sim
