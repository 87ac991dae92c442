// `sandtable-node calibrate-unit`'s command line (node/calibration/calibrate_unit_command.h),
// through the real program: --help lists every flag, and a bad value of any flag exits 2
// before any capture is read, with a message naming the flag.
#include <chrono>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "tests/common/cli/help_text.h"
#include "tests/coordinator/membership/child_process.h"

namespace sandtable {
namespace {

using testing::ChildOutput;
using testing::ChildProcess;

constexpr std::chrono::milliseconds kExitDeadline{30000};
constexpr int kExitUsage = 2;

int RunCalibrateUnit(std::vector<std::string> args, std::string* output) {
  args.insert(args.begin(), {SANDTABLE_NODE_BIN, "calibrate-unit"});
  ChildProcess child(args, ChildOutput::kStdoutAndStderr);
  return testing::RunToEnd(child, kExitDeadline, output);
}

TEST(CalibrateUnitCommandLineTest, HelpListsEveryFlag) {
  std::string output;
  ASSERT_EQ(RunCalibrateUnit({"--help"}, &output), 0) << output;
  const std::set<std::string> flags = {"-h",
                                       "--help",
                                       "--poses",
                                       "-o",
                                       "--output",
                                       "--report",
                                       "--board-cols",
                                       "--board-rows",
                                       "--square-mm",
                                       "--projector-width",
                                       "--projector-height",
                                       "--projector-distortion",
                                       "--camera-distortion",
                                       "--dense-points",
                                       "--dense-weight",
                                       "--no-cross-validation"};
  EXPECT_EQ(testing::FlagsInHelp(output), flags) << output;
}

TEST(CalibrateUnitCommandLineTest, BadValuesExitTwoNamingTheFlag) {
  const std::vector<std::string> base = {"--poses", "missing-dir", "-o", "unit.json"};
  struct Case {
    std::vector<std::string> extra;
    std::string names;
  };
  const std::vector<Case> cases = {
      {{"--board-cols", "abc"}, "--board-cols"},
      {{"--board-rows", "1"}, "--board-rows"},
      {{"--square-mm", "nan"}, "--square-mm"},
      {{"--square-mm", "-75"}, "--square-mm"},
      {{"--projector-width", "1024.5"}, "--projector-width"},
      {{"--projector-height", "010"}, "--projector-height"},
      {{"--projector-distortion", "fisheye"}, "--projector-distortion"},
      {{"--camera-distortion", ""}, "--camera-distortion"},
      {{"--dense-points", "5"}, "--dense-points"},
      {{"--dense-weight", "0"}, "--dense-weight"},
      {{"--colour", "red"}, "--colour"},
  };
  for (const Case& c : cases) {
    std::vector<std::string> args = base;
    args.insert(args.end(), c.extra.begin(), c.extra.end());
    std::string output;
    EXPECT_EQ(RunCalibrateUnit(args, &output), kExitUsage) << c.names << ": " << output;
    EXPECT_NE(output.find(c.names), std::string::npos) << "names the flag: " << output;
    EXPECT_EQ(output.rfind("sandtable-node calibrate-unit: ", 0), 0u) << output;
  }
  std::string output;
  EXPECT_EQ(RunCalibrateUnit({"-o", "unit.json"}, &output), kExitUsage);
  EXPECT_NE(output.find("--poses"), std::string::npos) << "required: " << output;
}

}  // namespace
}  // namespace sandtable
