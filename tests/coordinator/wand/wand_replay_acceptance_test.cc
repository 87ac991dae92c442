// Acceptance (issue 6): a FASTRAK trajectory drives the cursor through the real program.
//
// Starts sandtable-coordinator --tracker-replay user1_cup0.traj --table-from-tracker FILE.json
// and subscribes to its PUB. Every tracker_pose received must equal the trajectory sample of
// its time transformed by table_from_tracker (position within 1e-6 m, rotation within 1e-6
// rad), every cursor's tip the same position, and the events must arrive at about 100 Hz
// (generous bounds: CI is loaded). The subscriber may join after the first samples went out
// (PUB drops what nobody receives): the received poses are placed on the 10 ms grid by their
// sample times and aligned to the trajectory as a whole. Waits with deadlines only; the end of
// the replay is recognised by 2 s without events.
#include <gtest/gtest.h>

#include <csignal>
#include <filesystem>
#include <fstream>
#include <map>

#include "common/base/units.h"
#include "coordinator/tracker/replay_source.h"
#include "net/channel.h"
#include "proto/convert.h"
#include "tests/coordinator/membership/child_process.h"
#include "tests/net/test_wait.h"

namespace sandtable {
namespace {

namespace fs = std::filesystem;
using std::chrono::milliseconds;
using testing::ChildProcess;
using testing::ReadReadyLine;
using testing::ReadyString;

constexpr milliseconds kStartDeadline{15000};
constexpr milliseconds kEventDeadline{5000};
constexpr milliseconds kQuietDeadline{2000};  // no event for this long: the replay has ended
constexpr double kGridTolerance = 1e-3;       // of a sample period
constexpr double kPosition_m = 1e-6;
constexpr double kRotation_rad = 1e-6;
constexpr double kMinRate_hz = 50.0, kMaxRate_hz = 200.0;
constexpr double kSamplePeriod_ns = 1e9 / coordinator::kFastrakTrajRate_hz;
constexpr size_t kMinPoses = 100;  // of 290 samples (the subscriber may miss the first ones)
const char* kTraj = "../shared/data/polhemus-hand/pick_and_place/user1_cup0.traj";

double AngleBetween_rad(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b) {
  return a.angularDistance(b);
}

TEST(WandReplayAcceptanceTest, TrajectoryDrivesPosesAndCursorAtTrackerRate) {
  Expected<std::vector<coordinator::TrackerSample>> traj = coordinator::LoadFastrakTraj(kTraj);
  ASSERT_TRUE(traj.ok()) << traj.status().ToString();
  const fs::path json =
      fs::temp_directory_path() / ("sandtable_wand_replay_" + std::to_string(::getpid()) + ".json");
  const Eigen::Quaterniond rotation(
      Eigen::AngleAxisd(DegToRad(30.0), Eigen::Vector3d(0.2, -0.3, 1.0).normalized()));
  const Rigid3d table_from_tracker(rotation, Eigen::Vector3d(0.4, -0.25, 0.8));
  {
    std::ofstream out(json);
    out.precision(17);
    out << "{\"rotation_wxyz\": [" << rotation.w() << ", " << rotation.x() << ", " << rotation.y()
        << ", " << rotation.z() << "], \"translation_m\": [0.4, -0.25, 0.8]}\n";
  }
  std::vector<Rigid3d> expected;
  for (const coordinator::TrackerSample& s : *traj) {
    expected.push_back(table_from_tracker * s.tracker_from_sensor);
  }

  ChildProcess coordinator({SANDTABLE_COORDINATOR_BIN, "--tracker-replay", kTraj,
                            "--table-from-tracker", json.string()});
  std::string error;
  const std::optional<nlohmann::json> ready =
      ReadReadyLine(coordinator, "sandtable-coordinator", kStartDeadline, &error);
  ASSERT_TRUE(ready.has_value()) << error;
  const std::string events = ReadyString(*ready, "events");
  ASSERT_FALSE(events.empty()) << ready->dump();

  zmq::context_t context;
  proto::MessageCounters counters;
  auto sub = net::Socket::Create(&context, net::SocketType::kEventSubscriber);
  ASSERT_TRUE(sub.ok());
  ASSERT_TRUE((*sub)->Connect(events).ok());
  net::Channel channel(std::move(*sub), 951, 1, &counters);

  // Receive until the replay has ended (no event for kQuietDeadline after the first pose).
  struct Received {
    Rigid3d pose;
    int64_t sample_time_ns;
    std::chrono::steady_clock::time_point arrival;
  };
  std::vector<Received> poses;
  std::map<int64_t, Eigen::Vector3d> cursor_tip_of_time;
  // member_list events keep coming (every second): only tracker events count as activity.
  auto last_tracker_event = std::chrono::steady_clock::now();
  while (true) {
    const auto quiet = std::chrono::steady_clock::now() - last_tracker_event;
    if (quiet > (poses.empty() ? kEventDeadline : kQuietDeadline)) break;
    std::optional<net::Incoming> in = net::testing::ReceiveWithin(&channel, kQuietDeadline);
    if (!in) continue;
    const wire::Envelope& e = in->envelope;
    if (e.has_tracker_pose() || e.has_cursor())
      last_tracker_event = std::chrono::steady_clock::now();
    if (e.has_tracker_pose()) {
      Expected<Rigid3d> pose = proto::FromWire(e.tracker_pose().table_from_sensor());
      ASSERT_TRUE(pose.ok()) << pose.status().ToString();
      EXPECT_FALSE(e.tracker_pose().button_pressed());  // .traj has no button
      poses.push_back({*pose, e.tracker_pose().sample_time_ns(), std::chrono::steady_clock::now()});
    } else if (e.has_cursor()) {
      Expected<Eigen::Vector3d> tip = proto::FromWire(e.cursor().tip_in_table_m());
      ASSERT_TRUE(tip.ok());
      cursor_tip_of_time[e.cursor().sample_time_ns()] = *tip;
    }
  }
  ASSERT_GE(poses.size(), kMinPoses) << "too few tracker_pose events received";

  // Sample offsets from the sample times (10 ms grid), strictly increasing.
  std::vector<size_t> offset(poses.size(), 0);
  for (size_t k = 1; k < poses.size(); ++k) {
    const double steps =
        static_cast<double>(poses[k].sample_time_ns - poses[0].sample_time_ns) / kSamplePeriod_ns;
    ASSERT_NEAR(steps, std::round(steps), kGridTolerance) << "sample time off the 10 ms grid";
    offset[k] = static_cast<size_t>(std::llround(steps));
    ASSERT_GT(offset[k], offset[k - 1]) << "samples out of order or repeated";
  }
  ASSERT_LT(offset.back(), expected.size());
  // The trajectory index of the first received pose: the alignment with the smallest worst
  // position error (the hand rests at times, so one pose alone can match several samples).
  size_t first = 0;
  double best_worst_m = 1e300;
  for (size_t o = 0; o + offset.back() < expected.size(); ++o) {
    double worst_m = 0.0;
    for (size_t k = 0; k < poses.size() && worst_m < best_worst_m; ++k) {
      worst_m = std::max(worst_m,
                         (poses[k].pose.translation - expected[o + offset[k]].translation).norm());
    }
    if (worst_m < best_worst_m) best_worst_m = worst_m, first = o;
  }
  for (size_t k = 0; k < poses.size(); ++k) {
    const Rigid3d& want = expected[first + offset[k]];
    EXPECT_LT((poses[k].pose.translation - want.translation).norm(), kPosition_m)
        << "sample " << first + offset[k];
    EXPECT_LT(AngleBetween_rad(poses[k].pose.rotation, want.rotation), kRotation_rad)
        << "sample " << first + offset[k];
    auto tip = cursor_tip_of_time.find(poses[k].sample_time_ns);
    ASSERT_NE(tip, cursor_tip_of_time.end()) << "no cursor for sample " << first + offset[k];
    EXPECT_LT((tip->second - want.translation).norm(), kPosition_m);
  }
  // Every sample from the first one received to the end arrived (no gaps, nothing after).
  EXPECT_EQ(first + offset.back() + 1, expected.size());
  EXPECT_EQ(poses.size(), expected.size() - first);
  const double span_s =
      std::chrono::duration<double>(poses.back().arrival - poses.front().arrival).count();
  const double rate_hz = static_cast<double>(poses.size() - 1) / span_s;
  std::cout << "received " << poses.size() << " poses (samples " << first << ".."
            << first + offset.back() << ") and " << cursor_tip_of_time.size()
            << " cursors; worst position error " << best_worst_m << " m; arrivals over " << span_s
            << " s: " << rate_hz << " Hz\n";
  EXPECT_GE(rate_hz, kMinRate_hz);
  EXPECT_LE(rate_hz, kMaxRate_hz);

  coordinator.Signal(SIGTERM);
  EXPECT_EQ(coordinator.Wait(), 0);
  fs::remove(json);
}

TEST(WandReplayAcceptanceTest, BadTableFromTrackerFileStopsTheProgramWithExitCode2) {
  const fs::path json =
      fs::temp_directory_path() / ("sandtable_wand_bad_" + std::to_string(::getpid()) + ".json");
  std::ofstream(json) << "{\"rotation_wxyz\": [1, 0, 0]}";
  ChildProcess coordinator({SANDTABLE_COORDINATOR_BIN, "--tracker-replay", kTraj,
                            "--table-from-tracker", json.string()});
  EXPECT_EQ(coordinator.Wait(), 2);  // bad input file
  fs::remove(json);
}

TEST(WandReplayAcceptanceTest, MalformedSceneStopsTheProgramWithExitCode2) {
  // --scene loads the glTF the wand ray is cast against; a file that fails the loader's checks
  // (data README: a bufferView length of 1e300) must stop the program with a message, not crash.
  ChildProcess coordinator(
      {SANDTABLE_COORDINATOR_BIN, "--tracker-replay", kTraj, "--scene",
       "../shared/data/gltf/tinygltf/BoundsChecking/integer-out-of-bounds.gltf"});
  EXPECT_EQ(coordinator.Wait(), 2);  // bad input file
}

}  // namespace
}  // namespace sandtable
