// sandtable-node as a program, against the real sandtable-world and sandtable-coordinator:
// a node starts from the factory file the world wrote for it, announces itself with its JSON
// readiness line, holds the lab's labelled test-mode pose, exports unit-<id>.json and .yaml,
// and both load back (the YAML through cv::FileStorage); bad flags and files exit 2 naming
// the flag.
#include <gtest/gtest.h>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include <opencv2/core.hpp>

#include "common/io/unit_calibration_file.h"
#include "node/app/calibration_service.h"
#include "tests/coordinator/membership/child_process.h"

namespace sandtable::node {
namespace {

namespace fs = std::filesystem;
using std::chrono::milliseconds;
using testing::ChildProcess;

constexpr milliseconds kStartDeadline{15000};
constexpr double kExact = 1e-9;  // values written with full precision come back exactly

class NodeProgramTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("sandtable_node_program_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

TEST_F(NodeProgramTest, StartsFromTheWorldsFactoryFileAndExportsItsCalibration) {
  // The world writes the site and one factory file per unit.
  ChildProcess make_site({SANDTABLE_WORLD_BIN, "make-site", "--preset", "sandtable-3",
                          "--factory-dir", (dir_ / "factory").string(), "-o",
                          (dir_ / "site.json").string()});
  ASSERT_EQ(testing::RunToEnd(make_site, milliseconds(30000)), 0);
  const fs::path factory = dir_ / "factory" / "unit-1.factory.json";
  ASSERT_TRUE(fs::exists(factory));
  Expected<UnitCalibration> loaded = LoadUnitCalibration(factory.string());
  ASSERT_TRUE(loaded.ok()) << loaded.status().ToString();

  // The lab's test-mode pose for unit 1.
  TruePose pose;
  pose.unit_id = 1;
  pose.table_from_projector = Rigid3d(
      Eigen::Quaterniond(Eigen::AngleAxisd(2.5, Eigen::Vector3d(0.2, 0.9, 0.3).normalized())),
      Eigen::Vector3d(0.4, -0.7, 1.55));
  pose.table_from_model = Rigid3d();
  const fs::path pose_file = dir_ / "pose-1.json";
  std::ofstream(pose_file) << TruePoseToJson(pose);

  ChildProcess coordinator({SANDTABLE_COORDINATOR_BIN, "--requests", "tcp://127.0.0.1:*",
                            "--events", "tcp://127.0.0.1:*"});
  std::string error;
  std::optional<nlohmann::json> c =
      testing::ReadReadyLine(coordinator, "sandtable-coordinator", kStartDeadline, &error);
  ASSERT_TRUE(c.has_value()) << error;
  const std::string endpoints =
      testing::ReadyString(*c, "requests") + "," + testing::ReadyString(*c, "events");

  const fs::path exports = dir_ / "calibration";
  ChildProcess node({SANDTABLE_NODE_BIN, "--id", "1", "--coordinator", endpoints, "--factory",
                     factory.string(), "--true-pose", pose_file.string(), "--export-dir",
                     exports.string()});
  std::optional<nlohmann::json> ready =
      testing::ReadReadyLine(node, "sandtable-node", kStartDeadline, &error);
  ASSERT_TRUE(ready.has_value()) << error;
  EXPECT_EQ(ready->value("id", -1), 1);
  std::optional<std::string> line = node.ReadLine(kStartDeadline);
  ASSERT_TRUE(line.has_value());
  const nlohmann::json calibrated = nlohmann::json::parse(*line, nullptr, false);
  ASSERT_TRUE(calibrated.is_object()) << *line;
  EXPECT_EQ(calibrated.value("calibrated", -1), 1);
  EXPECT_EQ(calibrated.value("source", ""), "factory+true_pose");

  Expected<UnitCalibration> exported = LoadUnitCalibration(calibrated.value("json", ""));
  ASSERT_TRUE(exported.ok()) << exported.status().ToString();
  EXPECT_EQ(exported->source, "factory+true_pose");
  EXPECT_EQ(exported->unit_id, 1u);
  ASSERT_TRUE(exported->table_from_projector.has_value());
  EXPECT_LT(
      (exported->table_from_projector->translation - pose.table_from_projector.translation).norm(),
      kExact);
  EXPECT_NEAR(exported->projector.fx_px, loaded->projector.fx_px, kExact);

  // The YAML, read by OpenCV: x_in_projector = R x_in_model + T.
  cv::FileStorage yaml(calibrated.value("yaml", ""), cv::FileStorage::READ);
  ASSERT_TRUE(yaml.isOpened());
  cv::Mat k, r, t;
  yaml["camera_matrix"] >> k;
  yaml["R"] >> r;
  yaml["T"] >> t;
  ASSERT_EQ(k.rows, 3);
  ASSERT_EQ(r.rows, 3);
  ASSERT_EQ(t.rows, 3);
  EXPECT_NEAR(k.at<double>(0, 0), loaded->projector.fx_px, kExact);
  const Rigid3d projector_from_model = pose.table_from_projector.Inverse() * pose.table_from_model;
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(t.at<double>(i, 0), projector_from_model.translation[i], kExact);
  }
  EXPECT_EQ(static_cast<int>(yaml["image_width"]), loaded->projector.width_px);

  node.Signal(SIGTERM);
  EXPECT_EQ(node.Wait(), 0);
  coordinator.Signal(SIGTERM);
  EXPECT_EQ(coordinator.Wait(), 0);
}

TEST_F(NodeProgramTest, BadFlagsAndFilesExitTwoNamingTheFlag) {
  struct Case {
    std::vector<std::string> args;
    std::string names;
  };
  std::ofstream(dir_ / "garbage.json") << "{\"format\": 3";
  const std::vector<Case> cases = {
      {{"--id", "abc", "--coordinator", "tcp://a:1,tcp://a:2"}, "--id"},
      {{"--id", "4294967295", "--coordinator", "tcp://a:1,tcp://a:2"}, "--id"},
      {{"--id", "1", "--coordinator", "tcp://a:1"}, "--coordinator"},
      {{"--id", "1", "--coordinator", "tcp://a:1,tcp://a:2", "--heartbeat-ms", "abc"},
       "--heartbeat-ms"},
      {{"--id", "1", "--coordinator", "tcp://a:1,tcp://a:2", "--factory",
        (dir_ / "garbage.json").string()},
       "--factory"},
      {{"--id", "1", "--coordinator", "tcp://a:1,tcp://a:2", "--no-such-flag"}, "--no-such-flag"},
      {{"--id", "1", "--coordinator", "tcp://a:1,tcp://a:2", "--projector", "beamer:3"},
       "--projector"},
      {{"--id", "1", "--coordinator", "tcp://a:1,tcp://a:2", "--camera", "eye:1"}, "--camera"},
  };
  for (const Case& c : cases) {
    std::vector<std::string> argv{SANDTABLE_NODE_BIN};
    argv.insert(argv.end(), c.args.begin(), c.args.end());
    ChildProcess node(argv, testing::ChildOutput::kStdoutAndStderr);
    std::string output;
    const int status = testing::RunToEnd(node, milliseconds(10000), &output);
    EXPECT_EQ(status, 2) << output;
    EXPECT_NE(output.find(c.names), std::string::npos) << output;
  }
}

// A free TCP port on loopback (bound once by the kernel, then released).
int FreePort() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t length = sizeof(address);
  const bool ok = ::bind(fd, reinterpret_cast<sockaddr*>(&address), sizeof(address)) == 0 &&
                  ::getsockname(fd, reinterpret_cast<sockaddr*>(&address), &length) == 0;
  ::close(fd);
  return ok ? ntohs(address.sin_port) : -1;
}

// Reads the child's lines until one holds `text` (true) or the deadline passes; all of them
// are appended to `seen`.
bool ReadUntil(ChildProcess& child, const std::string& text, milliseconds deadline,
               std::string* seen) {
  const auto end = std::chrono::steady_clock::now() + deadline;
  while (std::chrono::steady_clock::now() < end) {
    const auto left =
        std::chrono::duration_cast<milliseconds>(end - std::chrono::steady_clock::now());
    std::optional<std::string> line = child.ReadLine(left);
    if (!line) return false;
    *seen += *line + "\n";
    if (line->find(text) != std::string::npos) return true;
  }
  return false;
}

// A node whose coordinator is not there yet: it advertises a reachable peer address (bound to
// every interface, never 0.0.0.0), says within seconds that nobody answers and what to check,
// and registers as soon as the coordinator starts.
TEST_F(NodeProgramTest, ANodeWithNoCoordinatorSaysSoAndRegistersWhenItComes) {
  const int requests_port = FreePort(), events_port = FreePort();
  ASSERT_GT(requests_port, 0);
  ASSERT_GT(events_port, 0);
  const std::string requests = "tcp://127.0.0.1:" + std::to_string(requests_port);
  const std::string events = "tcp://127.0.0.1:" + std::to_string(events_port);
  ChildProcess node({SANDTABLE_NODE_BIN, "--id", "1", "--coordinator", requests + "," + events,
                     "--bind", "tcp://*:*"},
                    testing::ChildOutput::kStdoutAndStderr);
  std::string seen;
  ASSERT_TRUE(ReadUntil(node, "\"ready\"", kStartDeadline, &seen)) << seen;
  EXPECT_EQ(seen.find("\"peer\":\"tcp://0.0.0.0"), std::string::npos) << seen;
  EXPECT_NE(seen.find("\"peer\":\"tcp://127.0.0.1:"), std::string::npos) << seen;
  ASSERT_TRUE(
      ReadUntil(node, "no answer from the coordinator at " + requests, milliseconds(15000), &seen))
      << seen;
  EXPECT_NE(seen.find("is the address right"), std::string::npos) << seen;

  ChildProcess coordinator({SANDTABLE_COORDINATOR_BIN, "--requests", requests, "--events", events});
  std::string error;
  ASSERT_TRUE(testing::ReadReadyLine(coordinator, "sandtable-coordinator", kStartDeadline, &error))
      << error;
  EXPECT_TRUE(ReadUntil(node, "registered with the coordinator after", kStartDeadline, &seen))
      << seen;
  node.Signal(SIGTERM);
  EXPECT_EQ(node.Wait(), 0);
  coordinator.Signal(SIGTERM);
  EXPECT_EQ(coordinator.Wait(), 0);
}

TEST_F(NodeProgramTest, HelpListsEveryFlag) {
  ChildProcess node({SANDTABLE_NODE_BIN, "--help"});
  std::string output;
  ASSERT_EQ(testing::RunToEnd(node, milliseconds(10000), &output), 0);
  for (const char* flag :
       {"--id", "--coordinator", "--bind", "--curve-keys", "--heartbeat-ms", "--workers",
        "--advertise", "--world", "--projector", "--camera", "--factory", "--true-pose",
        "--export-dir", "--expect-units", "calibrate-unit"}) {
    EXPECT_NE(output.find(flag), std::string::npos) << flag << " missing from:\n" << output;
  }
}

}  // namespace
}  // namespace sandtable::node
