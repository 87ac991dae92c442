// sandtable-coordinator's command line, through the real program: --help lists every flag it
// registers (and nothing else), and a bad value of any flag exits 2 before anything starts,
// with a message naming the flag.
#include <chrono>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "tests/common/cli/help_text.h"
#include "tests/coordinator/membership/child_process.h"

namespace sandtable {
namespace {

using std::chrono::milliseconds;

constexpr milliseconds kExitDeadline{30000};
constexpr int kExitUsage = 2;

int RunCoordinator(std::vector<std::string> args, std::string* output) {
  return testing::RunProgram(SANDTABLE_COORDINATOR_BIN, std::move(args), kExitDeadline, output);
}

// Every flag main.cc registers (docs/coordinator.md).
const std::set<std::string> kFlags = {"-h",
                                      "--help",
                                      "--requests",
                                      "--events",
                                      "--curve-keys",
                                      "--insecure",
                                      "--beacon",
                                      "--site-name",
                                      "--enroll",
                                      "--site-config",
                                      "--generate-curve-keys",
                                      "--heartbeat-ms",
                                      "--misses",
                                      "--annotations",
                                      "--annotation-sync",
                                      "--annotations-accept-loss",
                                      "--export-session",
                                      "--import-session",
                                      "--timeline",
                                      "--status",
                                      "--status-token-file",
                                      "--max-members",
                                      "--tracker-replay",
                                      "--table-from-tracker",
                                      "--virtual-wand",
                                      "--scene"};

TEST(CoordinatorCommandLineTest, HelpListsEveryFlag) {
  std::string output;
  ASSERT_EQ(RunCoordinator({"--help"}, &output), 0) << output;
  EXPECT_EQ(testing::FlagsInHelp(output), kFlags) << output;
  std::string short_help;
  ASSERT_EQ(RunCoordinator({"-h"}, &short_help), 0);
  EXPECT_EQ(short_help, output);
}

TEST(CoordinatorCommandLineTest, BadValuesExitTwoNamingTheFlag) {
  struct Case {
    std::vector<std::string> args;
    std::string names;  // what the message must contain
  };
  const std::vector<Case> cases = {
      {{"--heartbeat-ms", "abc"}, "--heartbeat-ms"},
      {{"--heartbeat-ms", "0"}, "--heartbeat-ms"},
      {{"--heartbeat-ms", "100ms"}, "--heartbeat-ms"},
      {{"--heartbeat-ms"}, "--heartbeat-ms"},
      {{"--misses", "-1"}, "--misses"},
      {{"--misses", "2.5"}, "--misses"},
      {{"--annotation-sync", "sometimes"}, "--annotation-sync"},
      {{"--status", "99999"}, "--status"},
      {{"--status", "localhost:80"}, "--status"},
      {{"--status", "0.0.0.0:0"}, "--status-token-file"},  // beyond loopback without a token
      {{"--status", "0", "--status-token-file", "/nonexistent/token"}, "--status-token-file"},
      {{"--max-members", "0"}, "--max-members"},
      {{"--max-members", "100000"}, "--max-members"},
      {{"--requests", "localhost"}, "--requests"},
      {{"--events", "tcp://"}, "--events"},
      {{"--colour", "red"}, "--colour"},
      {{"--table-from-tracker", "t.json"}, "--table-from-tracker"},
      {{"--virtual-wand", "w.txt", "--tracker-replay", "r.traj"}, "--virtual-wand"},
      {{"--export-session", "a.jsonl", "--import-session", "b.jsonl"}, "--export-session"},
  };
  for (const Case& c : cases) {
    std::string output;
    EXPECT_EQ(RunCoordinator(c.args, &output), kExitUsage) << c.args.front() << ": " << output;
    EXPECT_NE(output.find(c.names), std::string::npos) << "names the flag: " << output;
    EXPECT_EQ(output.rfind("sandtable-coordinator: ", 0), 0u) << output;
    EXPECT_EQ(output.find("{\"ready\""), std::string::npos) << "never started: " << output;
  }
}

}  // namespace
}  // namespace sandtable
