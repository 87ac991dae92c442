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
#include "net/curve.h"
#include "node/app/calibration_service.h"
#include "tests/coordinator/membership/child_process.h"
#include "tests/testing/network_namespace.h"

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
      {{"--id", "1", "--coordinator", "tcp://a:1,tcp://a:2", "--bind", "tcp://*:7100"},
       "--curve-keys"},
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
                     "--bind", "tcp://*:*", "--insecure"},
                    testing::ChildOutput::kStdoutAndStderr);
  std::string seen;
  ASSERT_TRUE(ReadUntil(node, "\"ready\"", kStartDeadline, &seen)) << seen;
  EXPECT_EQ(seen.find("\"peer\":\"tcp://0.0.0.0"), std::string::npos) << seen;
  EXPECT_NE(seen.find("\"peer\":\"tcp://127.0.0.1:"), std::string::npos) << seen;
  ASSERT_TRUE(
      ReadUntil(node, "no answer from the coordinator at " + requests, milliseconds(15000), &seen))
      << seen;
  EXPECT_NE(seen.find("is the address right"), std::string::npos) << seen;
  EXPECT_NE(seen.find("OPEN SITE (--insecure)"), std::string::npos) << seen;  // said at start

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

// A unit that advertises an address its neighbours cannot reach (here TEST-NET-1, which routes
// nowhere): the neighbour says so after 5 s, naming the unit and the address, and goes on.
TEST_F(NodeProgramTest, ANeighbourSaysWhenAPeersAdvertisedAddressIsNotReachable) {
  ChildProcess coordinator({SANDTABLE_COORDINATOR_BIN});
  std::string error;
  const std::optional<nlohmann::json> ready =
      testing::ReadReadyLine(coordinator, "sandtable-coordinator", kStartDeadline, &error);
  ASSERT_TRUE(ready.has_value()) << error;
  const std::string endpoints =
      testing::ReadyString(*ready, "requests") + "," + testing::ReadyString(*ready, "events");
  ChildProcess neighbour({SANDTABLE_NODE_BIN, "--id", "1", "--coordinator", endpoints},
                         testing::ChildOutput::kStdoutAndStderr);
  std::string seen;
  ASSERT_TRUE(ReadUntil(neighbour, "\"ready\"", kStartDeadline, &seen)) << seen;
  ChildProcess unit(
      {SANDTABLE_NODE_BIN, "--id", "2", "--coordinator", endpoints, "--advertise", "192.0.2.1"},
      testing::ChildOutput::kStdoutAndStderr);
  std::string unit_seen;
  ASSERT_TRUE(ReadUntil(unit, "\"ready\"", kStartDeadline, &unit_seen)) << unit_seen;
  ASSERT_TRUE(
      ReadUntil(neighbour, "peer 2 advertised tcp://192.0.2.1:", milliseconds(20000), &seen))
      << seen;
  EXPECT_NE(seen.find("is that address reachable from this host"), std::string::npos) << seen;
  for (ChildProcess* child : {&unit, &neighbour, &coordinator}) {
    child->Signal(SIGTERM);
    EXPECT_EQ(child->Wait(), 0);
  }
}

// One site file for both programs and a unit file for the node (docs/config-file.md): the
// coordinator listens where the file says, the node finds it there with no --coordinator, takes
// its id from its unit file, and a flag on its command line wins over the file's.
TEST_F(NodeProgramTest, SiteAndUnitFilesStartACoordinatorAndANodeThatFindsIt) {
  const int requests_port = FreePort(), events_port = FreePort();
  ASSERT_GT(requests_port, 0);
  ASSERT_GT(events_port, 0);
  const fs::path site = dir_ / "site.json";
  std::ofstream(site) << "{\"format\": \"sandtable.site_config\", \"version\": 1,\n"
                      << " \"coordinator\": {\"host\": \"127.0.0.1\", \"listen\": \"127.0.0.1\","
                      << " \"requests_port\": " << requests_port
                      << ", \"events_port\": " << events_port << "},\n"
                      << " \"heartbeat_ms\": 80, \"node_flags\": {\"workers\": 2}}\n";
  const fs::path unit = dir_ / "unit-7.json";
  std::ofstream(unit) << R"({"format": "sandtable.unit_config", "version": 1, "id": 7,
                            "bind": "tcp://127.0.0.1:*"})";
  ChildProcess coordinator({SANDTABLE_COORDINATOR_BIN, "--site-config", site.string()});
  std::string error;
  std::optional<nlohmann::json> c =
      testing::ReadReadyLine(coordinator, "sandtable-coordinator", kStartDeadline, &error);
  ASSERT_TRUE(c.has_value()) << error;
  EXPECT_EQ(testing::ReadyString(*c, "requests"),
            "tcp://127.0.0.1:" + std::to_string(requests_port));
  ChildProcess node({SANDTABLE_NODE_BIN, "--site-config", site.string(), "--unit-config",
                     unit.string(), "--heartbeat-ms", "60"},
                    testing::ChildOutput::kStdoutAndStderr);
  std::string seen;
  ASSERT_TRUE(ReadUntil(node, "\"ready\"", kStartDeadline, &seen)) << seen;
  EXPECT_NE(seen.find("\"id\":7"), std::string::npos) << seen;
  EXPECT_TRUE(ReadUntil(node, "registered with the coordinator", kStartDeadline, &seen)) << seen;
  node.Signal(SIGTERM);
  EXPECT_EQ(node.Wait(), 0);
  coordinator.Signal(SIGTERM);
  EXPECT_EQ(coordinator.Wait(), 0);

  // A file that does not hold what it should: exit 2 naming the file and the key.
  const fs::path bad = dir_ / "bad-site.json";
  std::ofstream(bad) << R"({"format": "sandtable.site_config", "version": 1, "heartbeat": 5})";
  for (const char* program : {SANDTABLE_NODE_BIN, SANDTABLE_COORDINATOR_BIN}) {
    ChildProcess refused({program, "--site-config", bad.string()},
                         testing::ChildOutput::kStdoutAndStderr);
    std::string output;
    EXPECT_EQ(testing::RunToEnd(refused, milliseconds(10000), &output), 2) << output;
    EXPECT_NE(output.find("\"heartbeat\": unknown key"), std::string::npos) << output;
  }
}

// A coordinator that would listen beyond loopback without CURVE is refused (exit 2 naming
// --curve-keys); with --insecure it starts and says it is an open site.
TEST_F(NodeProgramTest, AnOpenCoordinatorIsRefusedUnlessAskedFor) {
  ChildProcess refused(
      {SANDTABLE_COORDINATOR_BIN, "--requests", "tcp://0.0.0.0:*", "--events", "tcp://127.0.0.1:*"},
      testing::ChildOutput::kStdoutAndStderr);
  std::string output;
  EXPECT_EQ(testing::RunToEnd(refused, milliseconds(10000), &output), 2) << output;
  EXPECT_NE(output.find("--curve-keys"), std::string::npos) << output;
  ChildProcess open({SANDTABLE_COORDINATOR_BIN, "--requests", "tcp://0.0.0.0:*", "--events",
                     "tcp://127.0.0.1:*", "--insecure"},
                    testing::ChildOutput::kStdoutAndStderr);
  std::string seen;
  EXPECT_TRUE(ReadUntil(open, "OPEN SITE (--insecure)", kStartDeadline, &seen)) << seen;
  open.Signal(SIGTERM);
  EXPECT_EQ(open.Wait(), 0);
}

// A network namespace's link for the discovery tests: two addresses on a veth pair, so a
// beacon has an interface that broadcasts.
constexpr char kSiteLink[] =
    "ip link add site0 type veth peer name site0p && "
    "ip addr add 10.64.0.1/24 dev site0 && ip addr add 10.64.0.2/24 dev site0p && "
    "ip link set site0p up && ip link set site0 up";

void GenerateSiteKeys(const std::string& path) {
  ChildProcess generate({SANDTABLE_COORDINATOR_BIN, "--generate-curve-keys", path});
  ASSERT_EQ(testing::RunToEnd(generate, milliseconds(10000)), 0);
}

// LAN discovery with the two programs, in a network namespace of their own: a coordinator that
// beacons its site and a node given no address at all but the site's key file; the node hears
// the beacon, trusts the key, and registers.
TEST_F(NodeProgramTest, ANodeWithNoAddressFindsItsSiteByTheBeacon) {
  const std::string keys = (dir_ / "site.keys").string();
  ASSERT_NO_FATAL_FAILURE(GenerateSiteKeys(keys));
  const test_support::NamespaceRun run =
      test_support::InOwnNetworkNamespace(kSiteLink, [&](std::string* text) {
        ChildProcess coordinator(
            {SANDTABLE_COORDINATOR_BIN, "--requests", "tcp://*:7000", "--events", "tcp://*:7001",
             "--curve-keys", keys, "--beacon", "5673", "--site-name", "lab-1"},
            testing::ChildOutput::kStdoutAndStderr);
        std::string seen;
        if (!ReadUntil(coordinator, "\"ready\"", kStartDeadline, &seen)) {
          *text = "coordinator: " + seen;
          return 1;
        }
        ChildProcess node({SANDTABLE_NODE_BIN, "--id", "4", "--coordinator", "discover",
                           "--discovery-port", "5673", "--curve-keys", keys, "--bind", "tcp://*:*"},
                          testing::ChildOutput::kStdoutAndStderr);
        const bool registered =
            ReadUntil(node, "registered with the coordinator", kStartDeadline, &seen);
        node.Signal(SIGTERM);
        const int node_exit = node.Wait();
        coordinator.Signal(SIGTERM);
        const int coordinator_exit = coordinator.Wait();
        *text = seen;
        return registered && node_exit == 0 && coordinator_exit == 0 ? 0 : 1;
      });
  if (run.code == test_support::NamespaceRun::kSkipped) GTEST_SKIP() << run.text;
  ASSERT_EQ(run.code, 0) << run.text;
  EXPECT_NE(run.text.find("discovery: site lab-1 at 10.64.0."), std::string::npos) << run.text;
  EXPECT_NE(run.text.find("CURVE key trusted"), std::string::npos) << run.text;
}

// First time on a site (docs/deploy.md, "Accepting a new unit"): a unit with no site key at all
// (--enroll names where it will keep it) hears the beacon, asks, and waits; the operator lists
// it with `sandtable-coordinator enrollment`, accepts it by the fingerprint the unit logged, and
// the unit writes the site's key and registers over CURVE. Started again it trusts that key.
TEST_F(NodeProgramTest, AUnitWithNoKeyJoinsOnceTheOperatorAcceptsIt) {
  const std::string keys = (dir_ / "site.keys").string();
  const std::string unit_keys = (dir_ / "unit" / "site.keys").string();
  std::filesystem::create_directories(dir_ / "unit");
  ASSERT_NO_FATAL_FAILURE(GenerateSiteKeys(keys));
  const test_support::NamespaceRun run =
      test_support::InOwnNetworkNamespace(kSiteLink, [&](std::string* text) {
        ChildProcess coordinator({SANDTABLE_COORDINATOR_BIN, "--requests", "tcp://*:7000",
                                  "--events", "tcp://*:7001", "--enroll", "tcp://*:7002",
                                  "--curve-keys", keys, "--beacon", "5674", "--site-name", "lab-2"},
                                 testing::ChildOutput::kStdoutAndStderr);
        std::string seen;
        if (!ReadUntil(coordinator, "\"ready\"", kStartDeadline, &seen)) {
          *text = "coordinator: " + seen;
          return 1;
        }
        const std::vector<std::string> node_args = {
            SANDTABLE_NODE_BIN, "--id", "4",        "--coordinator", "discover",
            "--discovery-port", "5674", "--enroll", unit_keys,       "--bind",
            "tcp://*:*"};
        ChildProcess node(node_args, testing::ChildOutput::kStdoutAndStderr);
        const std::string ask = "sandtable-coordinator enrollment --accept ";
        if (!ReadUntil(node, ask, kStartDeadline, &seen)) {
          *text = "node never said how to accept it: " + seen;
          return 1;
        }
        const size_t at = seen.rfind(ask) + ask.size();
        const std::string fingerprint = seen.substr(at, 19);
        // The operator's list shows it pending, from the unit's address.
        std::string list;
        ChildProcess lister({SANDTABLE_COORDINATOR_BIN, "enrollment", "--requests",
                             "tcp://10.64.0.1:7000", "--curve-keys", keys},
                            testing::ChildOutput::kStdoutAndStderr);
        const int list_exit = testing::RunToEnd(lister, milliseconds(10000), &list);
        std::string decision;
        ChildProcess accept({SANDTABLE_COORDINATOR_BIN, "enrollment", "--requests",
                             "tcp://10.64.0.1:7000", "--curve-keys", keys, "--accept", fingerprint},
                            testing::ChildOutput::kStdoutAndStderr);
        const int accept_exit = testing::RunToEnd(accept, milliseconds(10000), &decision);
        const bool registered =
            ReadUntil(node, "registered with the coordinator", kStartDeadline, &seen);
        node.Signal(SIGTERM);
        const int node_exit = node.Wait();
        // Started again, the unit trusts the key it was handed and asks no one.
        ChildProcess again(node_args, testing::ChildOutput::kStdoutAndStderr);
        const bool trusted =
            ReadUntil(again, "CURVE key trusted", kStartDeadline, &seen) &&
            ReadUntil(again, "registered with the coordinator", kStartDeadline, &seen);
        again.Signal(SIGTERM);
        const int again_exit = again.Wait();
        coordinator.Signal(SIGTERM);
        const int coordinator_exit = coordinator.Wait();
        *text = seen + "\n--- list (exit " + std::to_string(list_exit) + "):\n" + list +
                "\n--- accept (exit " + std::to_string(accept_exit) + "):\n" + decision;
        const bool listed = list_exit == 0 && list.find(fingerprint) != std::string::npos &&
                            list.find("pending") != std::string::npos &&
                            list.find("10.64.0.") != std::string::npos;
        return listed && accept_exit == 0 && registered && trusted && node_exit == 0 &&
                       again_exit == 0 && coordinator_exit == 0
                   ? 0
                   : 1;
      });
  if (run.code == test_support::NamespaceRun::kSkipped) GTEST_SKIP() << run.text;
  ASSERT_EQ(run.code, 0) << run.text;
  EXPECT_NE(run.text.find("accepted unit"), std::string::npos) << run.text;
  Expected<net::CurveKeyPair> written = net::ReadCurveKeyFile(unit_keys);  // mode 0600 checked
  ASSERT_TRUE(written.ok()) << written.status().ToString();
  Expected<net::CurveKeyPair> site = net::ReadCurveKeyFile(keys);
  ASSERT_TRUE(site.ok());
  EXPECT_EQ(written->public_key_z85, site->public_key_z85);
}

// The operator's command says what is wrong instead of waiting forever or guessing.
TEST_F(NodeProgramTest, TheEnrollmentCommandSaysWhenNobodyAnswers) {
  const std::string keys = (dir_ / "site.keys").string();
  ASSERT_NO_FATAL_FAILURE(GenerateSiteKeys(keys));
  std::string output;
  ChildProcess nobody({SANDTABLE_COORDINATOR_BIN, "enrollment", "--requests", "tcp://127.0.0.1:9",
                       "--curve-keys", keys, "--timeout-ms", "500"},
                      testing::ChildOutput::kStdoutAndStderr);
  EXPECT_EQ(testing::RunToEnd(nobody, milliseconds(10000), &output), 1) << output;
  EXPECT_NE(output.find("no answer from tcp://127.0.0.1:9"), std::string::npos) << output;
  ChildProcess missing({SANDTABLE_COORDINATOR_BIN, "enrollment", "--curve-keys", keys},
                       testing::ChildOutput::kStdoutAndStderr);
  output.clear();
  EXPECT_EQ(testing::RunToEnd(missing, milliseconds(10000), &output), 2) << output;
  EXPECT_NE(output.find("--requests"), std::string::npos) << output;
  ChildProcess no_keys({SANDTABLE_COORDINATOR_BIN, "--requests", "tcp://127.0.0.1:*", "--enroll",
                        "tcp://127.0.0.1:*"},
                       testing::ChildOutput::kStdoutAndStderr);
  output.clear();
  EXPECT_EQ(testing::RunToEnd(no_keys, milliseconds(10000), &output), 2) << output;
  EXPECT_NE(output.find("--enroll needs --curve-keys"), std::string::npos) << output;
}

TEST_F(NodeProgramTest, HelpListsEveryFlag) {
  ChildProcess node({SANDTABLE_NODE_BIN, "--help"});
  std::string output;
  ASSERT_EQ(testing::RunToEnd(node, milliseconds(10000), &output), 0);
  for (const char* flag :
       {"--id", "--coordinator", "--bind", "--curve-keys", "--heartbeat-ms", "--workers",
        "--advertise", "--world", "--projector", "--camera", "--factory", "--true-pose", "--enroll",
        "--export-dir", "--expect-units", "calibrate-unit"}) {
    EXPECT_NE(output.find(flag), std::string::npos) << flag << " missing from:\n" << output;
  }
}

}  // namespace
}  // namespace sandtable::node
