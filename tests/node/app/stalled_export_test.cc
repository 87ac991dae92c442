// The network thread never waits for a file (issue: "the network thread never blocks"): the
// node's exports go into a directory whose file system is frozen (fsfreeze on a loop-mounted
// ext4 image: every write there blocks until it is thawed), and meanwhile the node's heartbeats
// and the coordinator's events keep flowing; the `calibrated` line comes once it is thawed.
// Needs root and a loop device (CI runs as root); skips saying so otherwise.
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <variant>
#include <vector>

#include <gtest/gtest.h>

#include "coordinator/membership/coordinator_server.h"
#include "node/app/node_app.h"
#include "tests/node/net/node_site_test_util.h"

namespace sandtable::node {
namespace {

namespace fs = std::filesystem;
using std::chrono::milliseconds;

constexpr milliseconds kHeartbeat{50};
// What the network thread must keep doing while the export is stuck: ~40 heartbeats answered
// and ~10 member lists republished in 2 s; a blocked thread would answer none.
constexpr milliseconds kFrozenFor{2000};
constexpr uint64_t kMinMessagesWhileFrozen = 10;

int Shell(const std::string& command) {
  return std::system((command + " >/dev/null 2>&1").c_str());
}

// A loop-mounted ext4 file system that can be frozen; always thawed and unmounted when it goes.
class FreezableDir {
 public:
  FreezableDir() {
    root_ = fs::temp_directory_path() / ("stalled_export_" + std::to_string(getpid()));
    fs::create_directories(root_ / "mnt");
    image_ = root_ / "fs.img";
    const std::string mnt = (root_ / "mnt").string();
    mounted_ = geteuid() == 0 &&
               Shell("truncate -s 16M " + image_.string() + " && mkfs.ext4 -q -F " +
                     image_.string()) == 0 &&
               Shell("mount -o loop " + image_.string() + " " + mnt) == 0;
  }
  ~FreezableDir() {
    Thaw();
    if (mounted_) Shell("umount " + (root_ / "mnt").string());
    std::error_code ignored;
    fs::remove_all(root_, ignored);
  }
  bool mounted() const { return mounted_; }
  fs::path path() const { return root_ / "mnt"; }
  bool Freeze() {
    frozen_ = Shell("fsfreeze --freeze " + path().string()) == 0;
    return frozen_;
  }
  void Thaw() {
    if (frozen_) Shell("fsfreeze --unfreeze " + path().string());
    frozen_ = false;
  }

 private:
  fs::path root_, image_;
  bool mounted_ = false, frozen_ = false;
};

SelfCalibrationOutcome AnOutcome() {
  SelfCalibrationOutcome outcome;
  outcome.calibration.unit_id = 3;
  outcome.calibration.source = kSourceStructuredLight;
  outcome.calibration.camera = CameraModel(1280, 1024, 1100, 1100, 640, 512);
  outcome.calibration.projector = CameraModel(1920, 1080, 2000, 2000, 960, 1000);
  outcome.calibration.table_from_projector = Rigid3d();
  outcome.calibration.table_from_model = Rigid3d();
  outcome.report = {{"runner", 3}};
  outcome.round = 2;
  return outcome;
}

TEST(StalledExportTest, HeartbeatsAndEventsFlowWhileTheExportDirectoryIsFrozen) {
  coordinator::CoordinatorServer coordinator(
      test_site::SiteCoordinatorOptions(kHeartbeat, /*misses_allowed=*/10));
  ASSERT_TRUE(coordinator.Start().ok());
  NodeRuntime runtime(test_site::SiteNodeOptions(3, coordinator, kHeartbeat, milliseconds(4000)));
  ASSERT_TRUE(runtime.Start().ok());
  ASSERT_TRUE(test_site::StepUntil(
      coordinator, {&runtime}, [&] { return runtime.member_list().has_value(); },
      milliseconds(10000)));
  // Declared after the runtime: thawed (and the stuck worker released) before the runtime goes.
  FreezableDir dir;
  if (!dir.mounted()) GTEST_SKIP() << "needs root and a loop device (mount -o loop)";
  ASSERT_TRUE(dir.Freeze()) << "fsfreeze failed";

  bool blend_started = false;
  std::vector<report::ReportLine> lines;
  ExportAndBlend handoff(
      3, (dir.path() / "calibration").string(), &runtime.workers(),
      [&](const SelfCalibrationOutcome&) { blend_started = true; },
      [](const SelfCalibrationOutcome&) {},
      [&](const report::ReportLine& line) { lines.push_back(line); });
  handoff.OnCalibrated(AnOutcome());
  EXPECT_TRUE(blend_started);  // the blend does not wait for the files

  // The network thread runs on while a worker is stuck in the frozen file system.
  const uint64_t before = runtime.counters().accepted();
  (void)test_site::StepUntil(
      coordinator, {&runtime}, [] { return false; }, kFrozenFor);
  EXPECT_GE(runtime.counters().accepted(), before + kMinMessagesWhileFrozen);
  EXPECT_TRUE(runtime.registered());
  EXPECT_TRUE(lines.empty()) << "the export finished on a frozen file system";

  dir.Thaw();
  ASSERT_TRUE(test_site::StepUntil(
      coordinator, {&runtime}, [&] { return !lines.empty(); }, milliseconds(20000)));
  ASSERT_TRUE(std::holds_alternative<report::Calibrated>(lines[0]));
  const report::Calibrated& calibrated = std::get<report::Calibrated>(lines[0]);
  EXPECT_EQ(calibrated.id, 3u);
  EXPECT_TRUE(fs::exists(calibrated.json)) << calibrated.json;
}

}  // namespace
}  // namespace sandtable::node
