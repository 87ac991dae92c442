// sandtable-world's command line, through the real program: each subcommand's --help lists
// exactly the flags AddWorldCommands registers for it (and the documented ones are among
// them), and a bad value of any flag exits 2 before any file is read, naming the flag.
#include <chrono>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "common/cli/command_line.h"
#include "sim/app/flags.h"
#include "tests/common/cli/help_text.h"
#include "tests/coordinator/membership/child_process.h"

namespace sandtable::sim {
namespace {

using std::chrono::milliseconds;

constexpr milliseconds kExitDeadline{30000};
constexpr int kExitUsage = 2;

int RunWorld(std::vector<std::string> args, std::string* output) {
  return testing::RunProgram(SANDTABLE_WORLD_BIN, std::move(args), kExitDeadline, output);
}

std::set<std::string> Registered(const CLI::App* command) {
  const std::vector<std::string> names = cli::FlagNames(*command);
  return {names.begin(), names.end()};
}

TEST(WorldCommandLineTest, HelpOfEverySubcommandListsItsFlags) {
  CLI::App app("", "sandtable-world");
  cli::Configure(app);
  WorldCommandLine line;
  AddWorldCommands(app, line);
  struct Documented {
    const CLI::App* command;
    std::set<std::string> flags;  // docs/world.md
  };
  const std::vector<Documented> commands = {
      {line.make_scene_command, {"-h", "--help", "--preset", "--seed", "--buildings", "-o"}},
      {line.make_site_command, {"-h", "--help", "--preset", "--seed", "--factory-dir", "-o"}},
      {line.render_command,
       {"-h", "--help", "--site", "--scene", "--white", "--frame", "--view", "--width", "--height",
        "--white-nits", "--threads", "-o"}},
      {line.serve_command,
       {"-h", "--help", "--site", "--scene", "--bind", "--no-noise", "--noise-seed", "--threads",
        "--prebuild"}},
  };
  for (const Documented& d : commands) {
    const std::string name = d.command->get_name();
    std::string output;
    ASSERT_EQ(RunWorld({name, "--help"}, &output), 0) << name << ": " << output;
    const std::set<std::string> registered = Registered(d.command);
    EXPECT_EQ(testing::FlagsInHelp(output), registered) << name << ": " << output;
    for (const std::string& flag : d.flags) {
      EXPECT_TRUE(registered.count(flag)) << name << " " << flag;
    }
  }
  std::string output;
  ASSERT_EQ(RunWorld({"--help"}, &output), 0) << output;
  for (const std::string name : {"make-scene", "make-site", "render", "serve"}) {
    EXPECT_NE(output.find(name), std::string::npos) << "top-level help lists " << name;
  }
}

TEST(WorldCommandLineTest, BadValuesExitTwoNamingTheFlag) {
  // Files need not exist: the command line is checked before anything is read.
  const std::vector<std::string> render = {"render", "--site", "s.json", "--scene", "g.gltf",
                                           "--view", "top",    "-o",     "x.png"};
  const std::vector<std::string> serve = {"serve", "--site", "s.json", "--scene", "g.gltf"};
  auto with = [](std::vector<std::string> base, const std::vector<std::string>& extra) {
    base.insert(base.end(), extra.begin(), extra.end());
    return base;
  };
  struct Case {
    std::vector<std::string> args;
    std::string names;
  };
  const std::vector<Case> cases = {
      {{"make-scene", "--preset", "flat", "--seed", "abc", "-o", "x.gltf"}, "--seed"},
      {{"make-scene", "--preset", "flat", "--seed", "-1", "-o", "x.gltf"}, "--seed"},
      {{"make-scene", "--preset", "flat", "--buildings", "5000", "-o", "x.gltf"}, "--buildings"},
      {{"make-scene", "--preset", "moon", "-o", "x.gltf"}, "--preset"},
      {{"make-scene", "--preset", "flat"}, "--output"},
      {{"make-site", "--seed", "1", "-o", "x.json"}, "--preset"},
      {{"make-site", "--preset", "flat-4", "--seed", "x", "-o", "x.json"}, "--seed"},
      {with(render, {"--width", "8"}), "--width"},
      {with(render, {"--width", "wide"}), "--width"},
      {with(render, {"--height", "100000"}), "--height"},
      {with(render, {"--white-nits", "-1"}), "--white-nits"},
      {with(render, {"--threads", "-2"}), "--threads"},
      {with(render, {"--frame", "zero=f.png"}), "--frame"},
      {with(render, {"--frame", "0=f.png", "--white"}), "--white"},
      {{"render", "--site", "s.json", "--scene", "g.gltf", "--view", "side", "-o", "x.png"},
       "--view"},
      {with(serve, {"--bind", "localhost:5555"}), "--bind"},
      {with(serve, {"--noise-seed", "one"}), "--noise-seed"},
      {with(serve, {"--threads", "2000"}), "--threads"},
      {with(serve, {"--no-noise=maybe"}), "--no-noise"},
      {{"serve", "--scene", "g.gltf"}, "--site"},
  };
  for (const Case& c : cases) {
    std::string output;
    EXPECT_EQ(RunWorld(c.args, &output), kExitUsage)
        << c.args.front() << " " << c.names << ": " << output;
    EXPECT_NE(output.find(c.names), std::string::npos) << "names the flag: " << output;
    EXPECT_EQ(output.rfind("sandtable-world " + c.args.front() + ": ", 0), 0u) << output;
  }
}

}  // namespace
}  // namespace sandtable::sim
