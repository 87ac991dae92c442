// The node application's parts a test can drive without a site: the configuration (flags into
// NodeConfig, its Check and the options it derives) and the hand-off from a calibration to the
// blend (the export on a worker, the blend started on the calling thread, the line written
// after the files).
#include "node/app/node_app.h"

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <thread>

#include <gtest/gtest.h>

#include "common/cli/command_line.h"
#include "node/app/node_config.h"
#include "node/calibration/cluster_initializer.h"
#include "node/calibration/display_frames.h"
#include "node/calibration/projector_response.h"
#include "node/render/overlay_geometry.h"

namespace sandtable::node {
namespace {

namespace fs = std::filesystem;

constexpr auto kWorkerWait = std::chrono::seconds(20);

NodeConfig ValidConfig() {
  NodeConfig c;
  c.id = 3;
  c.coordinator_requests = "tcp://127.0.0.1:5000";
  c.coordinator_events = "tcp://127.0.0.1:5001";
  return c;
}

// Parses `args` (after the program name) into a fresh config; nullopt on a parse error.
std::optional<NodeConfig> Parse(std::vector<std::string> args) {
  CLI::App app{"test", "sandtable-node"};
  cli::Configure(app);
  NodeConfig config;
  AddNodeFlags(app, config);
  try {
    std::reverse(args.begin(), args.end());  // CLI11 takes them last first
    app.parse(args);
  } catch (const CLI::ParseError&) {
    return std::nullopt;
  }
  return config;
}

TEST(NodeConfig, FlagsFillTheConfigWithEnums) {
  std::optional<NodeConfig> c = Parse({"--id",
                                       "7",
                                       "--coordinator",
                                       "tcp://a:1,tcp://a:2",
                                       "--render",
                                       "off",
                                       "--sun",
                                       "off",
                                       "--blend",
                                       "off",
                                       "--black-match",
                                       "on",
                                       "--calibration-path",
                                       "full",
                                       "--bundle-free",
                                       "poses",
                                       "--heartbeat-ms",
                                       "40",
                                       "--blend-edge-soft-mm",
                                       "3"});
  ASSERT_TRUE(c.has_value());
  EXPECT_EQ(c->id, 7u);
  EXPECT_EQ(c->coordinator_requests, "tcp://a:1");
  EXPECT_EQ(c->coordinator_events, "tcp://a:2");
  EXPECT_EQ(c->render, RenderMode::kOff);
  EXPECT_FALSE(c->sun.enabled);
  EXPECT_FALSE(c->blend);
  EXPECT_TRUE(c->black_match);
  EXPECT_EQ(c->calibration_path, SelfCalibrationOptions::Path::kFull);
  EXPECT_EQ(c->bundle_free, BundleFree::kPoses);
  EXPECT_TRUE(c->Check().ok()) << c->Check().ToString();

  const SelfCalibrationOptions sc = c->SelfCalibration();
  EXPECT_EQ(sc.path, SelfCalibrationOptions::Path::kFull);
  EXPECT_FALSE(sc.solve.bundle.free_mounts);
  EXPECT_FALSE(sc.solve.bundle.free_camera_intrinsics);
  // Timeouts at least five heartbeats.
  const NodeOptions o = c->RuntimeOptions();
  EXPECT_EQ(o.heartbeat_period, std::chrono::milliseconds(40));
  EXPECT_GE(o.peer_timeout, 5 * o.heartbeat_period);
  EXPECT_GE(o.coordinator_timeout, 5 * o.heartbeat_period);
}

TEST(NodeConfig, DefaultsMatchTheFlagsDefaults) {
  std::optional<NodeConfig> c = Parse({"--id", "1", "--coordinator", "tcp://a:1,tcp://a:2"});
  ASSERT_TRUE(c.has_value());
  EXPECT_EQ(c->render, RenderMode::kAuto);
  EXPECT_TRUE(c->sun.enabled);
  EXPECT_TRUE(c->blend);
  EXPECT_FALSE(c->black_match);
  EXPECT_EQ(c->bundle_free, BundleFree::kAll);
  const SelfCalibrationOptions sc = c->SelfCalibration();
  const SelfCalibrationOptions defaults;
  EXPECT_EQ(sc.grid_step_px, defaults.grid_step_px);
  EXPECT_EQ(sc.plan.phase_steps, defaults.plan.phase_steps);
  EXPECT_EQ(sc.solve.bundle.max_iterations, defaults.solve.bundle.max_iterations);
  EXPECT_TRUE(sc.solve.bundle.free_mounts);
}

TEST(NodeConfig, BadEnumValuesDoNotParse) {
  EXPECT_FALSE(Parse({"--render", "sometimes"}).has_value());
  EXPECT_FALSE(Parse({"--bundle-free", "none"}).has_value());
  EXPECT_FALSE(Parse({"--blend", "yes"}).has_value());
}

TEST(NodeConfig, CheckNamesWhatIsWrong) {
  struct Case {
    std::function<void(NodeConfig&)> change;
    std::string names;
  };
  const std::vector<Case> cases = {
      {[](NodeConfig& c) { c.id = kInvalidNodeId; }, "--id"},
      {[](NodeConfig& c) { c.coordinator_events.clear(); }, "--coordinator"},
      {[](NodeConfig& c) { c.true_pose_path = "pose.json"; }, "--true-pose needs --factory"},
      {[](NodeConfig& c) { c.saved_calibration_path = "unit-3.json"; }, "--saved-calibration"},
      {[](NodeConfig& c) { c.heartbeat_ms = 0; }, "--heartbeat-ms"},
      {[](NodeConfig& c) { c.grid_step_px = 2; }, "--grid-step-px"},
      {[](NodeConfig& c) { c.blend_fill_limit = 0.5; }, "--blend-fill-limit"},
      {[](NodeConfig& c) { c.projector_spec = "hdmi"; }, "--projector"},
      {[](NodeConfig& c) { c.camera_spec = "nope:1"; }, "--camera"},
  };
  EXPECT_TRUE(ValidConfig().Check().ok());
  for (const Case& k : cases) {
    NodeConfig c = ValidConfig();
    k.change(c);
    const Status s = c.Check();
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << k.names;
    EXPECT_NE(s.message().find(k.names), std::string::npos) << s.message();
  }
}

// Every options struct the node is made of: its defaults check, one bad value does not.
TEST(NodeOptionsCheck, DefaultsPassAndABadValueFails) {
  EXPECT_TRUE(SelfCalibrationOptions{}.Check().ok()) << SelfCalibrationOptions{}.Check().ToString();
  EXPECT_TRUE(ClusterSolveOptions{}.Check().ok());
  EXPECT_TRUE(PlanarSolveOptions{}.Check().ok());
  EXPECT_TRUE(LocalGeometryOptions{}.Check().ok());
  EXPECT_TRUE(ProjectorResponseOptions{}.Check().ok());
  EXPECT_TRUE(JoinBlankOptions{}.Check().ok());
  EXPECT_TRUE(BlendServiceOptions{}.Check().ok());
  EXPECT_TRUE(RenderServiceOptions{}.Check().ok());
  EXPECT_TRUE(OverlayOptions{}.Check().ok());
  EXPECT_TRUE(DeviceOptions{}.Check().ok());

  SelfCalibrationOptions sc;
  sc.lit_threshold = 0;
  EXPECT_EQ(sc.Check().code(), StatusCode::kInvalidArgument);
  sc = {};
  sc.solve.max_scale_correction = 1.5;  // a nested struct's error reaches the top
  EXPECT_EQ(sc.Check().code(), StatusCode::kInvalidArgument);
  PlanarSolveOptions planar;
  planar.min_shared_cells = 0;
  EXPECT_FALSE(planar.Check().ok());
  LocalGeometryOptions local;
  local.max_triangulation_rms_px = 0;
  EXPECT_FALSE(local.Check().ok());
  ProjectorResponseOptions response;
  response.min_signal_dn = 255;
  EXPECT_FALSE(response.Check().ok());
  JoinBlankOptions blank;
  blank.sample_step_px = 0;
  EXPECT_FALSE(blank.Check().ok());
  BlendServiceOptions blend;
  blend.ask_again_max = std::chrono::milliseconds(100);  // under ask_again
  EXPECT_FALSE(blend.Check().ok());
  RenderServiceOptions render;
  render.summary_period = std::chrono::milliseconds(0);
  EXPECT_FALSE(render.Check().ok());
  OverlayOptions overlay;
  overlay.round_segments = 2;
  EXPECT_FALSE(overlay.Check().ok());
  DeviceOptions devices;
  devices.camera_bit_depth = 20;
  EXPECT_FALSE(devices.Check().ok());
}

TEST(NodeApp, RefusesABadFactoryFileNamingTheFlag) {
  const fs::path dir = fs::temp_directory_path() / ("node_app_test_" + std::to_string(getpid()));
  fs::create_directories(dir);
  const std::string bad = (dir / "factory.json").string();
  std::ofstream(bad) << "{\"format\": \"not a unit file\"}";
  NodeConfig c = ValidConfig();
  c.factory_path = bad;
  Expected<std::unique_ptr<NodeApp>> app = NodeApp::Create(c, [](const report::ReportLine&) {});
  ASSERT_FALSE(app.ok());
  EXPECT_EQ(app.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(app.status().message().find("--factory"), std::string::npos);
  fs::remove_all(dir);
}

TEST(NodeApp, ACameraOfAnotherSizeThanTheFactoryFileIsRefused) {
  const CameraModel factory(1024, 768, 900, 900, 511.5, 383.5);
  EXPECT_TRUE(CheckCameraMatchesFactory(cv::Size(1024, 768), "replay:x", factory).ok());
  const Status other = CheckCameraMatchesFactory(cv::Size(1280, 1024), "replay:x", factory);
  EXPECT_EQ(other.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(other.message().find("1280x1024"), std::string::npos) << other.message();
  EXPECT_NE(other.message().find("1024x768"), std::string::npos) << other.message();
  EXPECT_NE(other.message().find("--factory"), std::string::npos) << other.message();
}

class ExportAndBlendTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("export_and_blend_" + std::to_string(getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    outcome_.calibration.unit_id = 3;
    outcome_.calibration.source = kSourceStructuredLight;
    outcome_.calibration.camera = CameraModel(1280, 1024, 1100, 1100, 640, 512);
    outcome_.calibration.projector = CameraModel(1920, 1080, 2000, 2000, 960, 1000);
    outcome_.calibration.table_from_projector = Rigid3d();
    outcome_.calibration.table_from_model = Rigid3d();
    outcome_.report = {{"runner", 3}};
    outcome_.round = 2;
  }
  void TearDown() override { fs::remove_all(dir_); }

  // Runs the pool's completions (the network thread's part) until `done` or the wait is over.
  bool Drain(WorkerPool& pool, const std::function<bool()>& done) {
    const auto until = std::chrono::steady_clock::now() + kWorkerWait;
    while (!done() && std::chrono::steady_clock::now() < until) {
      pool.RunCompletions();
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    return done();
  }

  fs::path dir_;
  SelfCalibrationOutcome outcome_;
};

TEST_F(ExportAndBlendTest, StartsTheBlendAtOnceAndWritesTheLineAfterTheFiles) {
  WorkerPool pool(1);
  std::vector<std::string> events;
  std::vector<nlohmann::json> lines;
  const fs::path unit_file = dir_ / "unit-3.json";
  ExportAndBlend handoff(
      3, dir_.string(), &pool,
      [&](const SelfCalibrationOutcome& o) {
        events.push_back("start round " + std::to_string(o.round));
      },
      [&](const SelfCalibrationOutcome&) {
        events.push_back(fs::exists(unit_file) ? "exported, file there" : "exported, no file");
      },
      [&](const report::ReportLine& line) { lines.push_back(report::ToJson(line)); });
  handoff.OnCalibrated(outcome_);
  // The blend started on this thread, before any completion ran.
  ASSERT_EQ(events.size(), 1u);
  EXPECT_EQ(events[0], "start round 2");
  ASSERT_TRUE(Drain(pool, [&] { return !lines.empty(); }));
  ASSERT_EQ(events.size(), 2u);
  EXPECT_EQ(events[1], "exported, file there");
  EXPECT_EQ(lines[0].value("calibrated", -1), 3);
  EXPECT_EQ(lines[0].value("json", std::string()), unit_file.string());
  EXPECT_TRUE(fs::exists(dir_ / "self_calibration_report.json"));  // the runner's report
}

TEST_F(ExportAndBlendTest, AFailedExportIsLoggedAndTheBlendStillRuns) {
  WorkerPool pool(1);
  const fs::path not_a_dir = dir_ / "file";
  std::ofstream(not_a_dir) << "x";
  int started = 0, exported = 0;
  std::vector<nlohmann::json> lines;
  ExportAndBlend handoff(
      3, not_a_dir.string(), &pool, [&](const SelfCalibrationOutcome&) { ++started; },
      [&](const SelfCalibrationOutcome&) { ++exported; },
      [&](const report::ReportLine& line) { lines.push_back(report::ToJson(line)); });
  handoff.OnCalibrated(outcome_);
  ASSERT_TRUE(Drain(pool, [&] { return exported == 1; }));
  EXPECT_EQ(started, 1);
  EXPECT_TRUE(lines.empty());  // no `calibrated` line for files not written
}

TEST_F(ExportAndBlendTest, WithoutAnExportDirectoryNothingIsWritten) {
  WorkerPool pool(1);
  int started = 0, exported = 0;
  std::vector<nlohmann::json> lines;
  ExportAndBlend handoff(
      3, "", &pool, [&](const SelfCalibrationOutcome&) { ++started; },
      [&](const SelfCalibrationOutcome&) { ++exported; },
      [&](const report::ReportLine& line) { lines.push_back(report::ToJson(line)); });
  handoff.OnCalibrated(outcome_);
  EXPECT_EQ(started, 1);
  EXPECT_EQ(exported, 1);
  EXPECT_EQ(pool.busy(), 0u);
  EXPECT_TRUE(lines.empty());
  EXPECT_TRUE(fs::is_empty(dir_));
}

}  // namespace
}  // namespace sandtable::node
