// sandtable-world as a real process: make-scene, make-site, render, serve (with DEALER clients
// speaking the project protocol), and usage errors. Waits on events with deadlines; never
// sleeps for synchronisation.
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "common/scene/gltf_loader.h"
#include "common/scene/gltf_writer.h"
#include "common/scene/procedural_scene.h"
#include "net/channel.h"
#include "sim/app/world_server.h"
#include "sim/site/site_json.h"
#include "sim/site/site_presets.h"
#include "sim/transport/world.h"
#include "tests/coordinator/membership/child_process.h"
#include "tests/net/test_wait.h"

namespace sandtable::sim {
namespace {

using std::chrono::milliseconds;
using testing::ChildProcess;

// Generous for a loaded 2-core CI machine (normally well under a second).
constexpr milliseconds kProcessDeadline{60000};
constexpr milliseconds kReplyDeadline{30000};
// Noise of the server's captures is zero-mean; clamping at 0 DN biases dark pixels slightly.
constexpr double kMeanLevelTolerance_dn = 0.5;
constexpr double kMinLitFraction = 0.3;

class WorldAppTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("sandtable_world_app_" + std::to_string(getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }

  std::string Path(const std::string& name) const { return (dir_ / name).string(); }

  // Runs sandtable-world to completion; returns its exit code (stdout in *out).
  int Run(std::vector<std::string> args, std::string* out = nullptr) {
    args.insert(args.begin(), SANDTABLE_WORLD_BIN);
    ChildProcess child(args);
    std::string text;
    while (std::optional<std::string> line = child.ReadLine(kProcessDeadline)) text += *line + "\n";
    if (out) *out = text;
    return child.Wait();
  }

  // A small flat-4 site (cameras shrunk to 128x96 so the transport maps build fast) and a flat
  // scene, written as files the server loads.
  void WriteSmallSiteAndScene() {
    Site site = *MakeSitePreset("flat-4");
    for (UnitSpec& unit : site.units) {
      const CameraModel& m = unit.camera->model;
      const double s = 128.0 / m.width_px;
      unit.camera->model = CameraModel(128, 96, m.fx_px * s, m.fy_px * s, (m.cx_px + 0.5) * s - 0.5,
                                       (m.cy_px + 0.5) * s - 0.5, m.distortion);
    }
    ASSERT_TRUE(WriteSiteFile(site, Path("site.json")).ok());
    ProceduralSceneOptions options;
    options.preset = ScenePreset::kFlat;
    ASSERT_TRUE(WriteGltfScene(MakeProceduralScene(options)->scene, Path("scene.gltf")).ok());
  }

  std::filesystem::path dir_;
};

TEST_F(WorldAppTest, MakeSceneWritesLoadableGltf) {
  std::string out;
  ASSERT_EQ(Run({"make-scene", "--preset", "sandtable", "--seed", "3", "-o", Path("s.gltf")}, &out),
            0);
  Expected<Scene> loaded = LoadGltfScene(Path("s.gltf"));
  ASSERT_TRUE(loaded.ok()) << loaded.status().ToString();
  ProceduralSceneOptions options;
  options.seed = 3;
  const Scene expected = MakeProceduralScene(options)->scene;
  EXPECT_EQ(loaded->NumTriangles(), expected.NumTriangles());
  EXPECT_TRUE(loaded->Bounds().isApprox(expected.Bounds(), 1e-6)) << "same geometry, +z up";
  // Binary glTF too.
  ASSERT_EQ(Run({"make-scene", "--preset", "city", "-o", Path("c.glb")}), 0);
  EXPECT_TRUE(LoadGltfScene(Path("c.glb")).ok());
}

TEST_F(WorldAppTest, MakeSiteWritesValidSiteAndFactoryCalibrations) {
  ASSERT_EQ(Run({"make-site", "--preset", "grid-6", "--seed", "4", "--factory-dir", Path("factory"),
                 "-o", Path("site.json")}),
            0);
  Expected<Site> site = LoadSiteFile(Path("site.json"));  // parses and validates
  ASSERT_TRUE(site.ok()) << site.status().ToString();
  ASSERT_EQ(site->units.size(), 6u);
  for (const UnitSpec& unit : site->units) {
    std::ifstream file(Path("factory/unit-" + std::to_string(unit.id) + ".factory.json"));
    ASSERT_TRUE(file.good()) << "unit " << unit.id;
    const nlohmann::json json = nlohmann::json::parse(file, nullptr, false);
    ASSERT_FALSE(json.is_discarded());
    EXPECT_EQ(json.at("unit_id").get<NodeId>(), unit.id);
    // Imperfect knowledge: the factory focal length is close to, not equal to, the truth.
    const double fx = json.at("camera").at("fx_px").get<double>();
    EXPECT_NE(fx, unit.camera->model.fx_px);
    EXPECT_NEAR(fx / unit.camera->model.fx_px, 1.0, 0.05);
  }
}

TEST_F(WorldAppTest, BadFlagsAndFilesAreUsageErrors) {
  constexpr int kUsage = 2;
  EXPECT_EQ(Run({}), kUsage);
  EXPECT_EQ(Run({"explode"}), kUsage);
  EXPECT_EQ(Run({"make-scene", "--preset", "moon", "-o", Path("x.gltf")}), kUsage);
  EXPECT_EQ(Run({"make-scene", "--preset", "flat"}), kUsage);  // no -o
  EXPECT_EQ(Run({"make-scene", "--preset", "flat", "--seed", "abc", "-o", Path("x.gltf")}), kUsage);
  EXPECT_EQ(Run({"make-site", "--preset", "grid-99", "-o", Path("x.json")}), kUsage);
  EXPECT_EQ(Run({"make-site", "--preset", "flat-4", "--colour", "red", "-o", Path("x.json")}),
            kUsage);
  std::ofstream(Path("garbage.json")) << "{ not json";
  std::ofstream(Path("garbage.gltf")) << "{\"asset\": 5}";
  ASSERT_EQ(Run({"make-site", "--preset", "flat-4", "-o", Path("site.json")}), 0);
  ASSERT_EQ(Run({"make-scene", "--preset", "flat", "-o", Path("scene.gltf")}), 0);
  EXPECT_EQ(Run({"render", "--site", Path("garbage.json"), "--scene", Path("scene.gltf"), "--view",
                 "top", "-o", Path("x.png")}),
            kUsage);
  EXPECT_EQ(Run({"render", "--site", Path("site.json"), "--scene", Path("garbage.gltf"), "--view",
                 "top", "-o", Path("x.png")}),
            kUsage);
  EXPECT_EQ(Run({"render", "--site", Path("missing.json"), "--scene", Path("scene.gltf"), "--view",
                 "top", "-o", Path("x.png")}),
            kUsage);
  EXPECT_EQ(Run({"render", "--site", Path("site.json"), "--scene", Path("scene.gltf"), "--view",
                 "camera:77", "-o", Path("x.png")}),
            kUsage);
  EXPECT_EQ(Run({"render", "--site", Path("site.json"), "--scene", Path("scene.gltf"), "--view",
                 "top", "--frame", "0=" + Path("missing.png"), "-o", Path("x.png")}),
            kUsage);
  EXPECT_EQ(Run({"serve", "--site", Path("garbage.json"), "--scene", Path("scene.gltf")}), kUsage);
  EXPECT_FALSE(std::filesystem::exists(Path("x.png")));
}

TEST_F(WorldAppTest, RenderWritesPngOfTheRightSizeWithLitArea) {
  ASSERT_NO_FATAL_FAILURE(WriteSmallSiteAndScene());
  const std::vector<std::string> base = {
      "render", "--site", Path("site.json"), "--scene", Path("scene.gltf"), "--threads", "2"};
  auto render = [&](std::vector<std::string> extra, const std::string& name) {
    std::vector<std::string> args = base;
    args.insert(args.end(), extra.begin(), extra.end());
    args.insert(args.end(), {"-o", Path(name)});
    EXPECT_EQ(Run(args), 0) << name;
    return cv::imread(Path(name), cv::IMREAD_UNCHANGED);
  };
  // Top view of the 2.0 m x 1.5 m flat table: 200 px wide -> 150 px high.
  const cv::Mat white = render({"--white", "--view", "top", "--width", "200"}, "white.png");
  ASSERT_FALSE(white.empty());
  EXPECT_EQ(white.cols, 200);
  EXPECT_EQ(white.rows, 150);
  const double lit_all = cv::countNonZero(white > 64) / static_cast<double>(white.total());
  EXPECT_GT(lit_all, kMinLitFraction);
  // Only projector 2 showing a white PNG frame lights part of what all four light.
  cv::imwrite(Path("frame.png"), cv::Mat(800, 1280, CV_8UC1, cv::Scalar(255)));
  const cv::Mat one = render({"--frame", "2=" + Path("frame.png"), "--view", "top", "--width",
                              "200", "--white-nits", "400"},
                             "one.png");
  ASSERT_EQ(one.size(), white.size());
  const double lit_one = cv::countNonZero(one > 64) / static_cast<double>(one.total());
  EXPECT_GT(lit_one, 0.05);
  EXPECT_LT(lit_one, lit_all);
  // A camera's view has the camera's size.
  const cv::Mat camera = render({"--white", "--view", "camera:1"}, "camera.png");
  EXPECT_EQ(camera.cols, 128);
  EXPECT_EQ(camera.rows, 96);
  EXPECT_GT(cv::countNonZero(camera), 0);
}

// A DEALER client of the world server.
class Client {
 public:
  Client(zmq::context_t* context, const std::string& endpoint, uint32_t id) {
    auto socket = net::Socket::Create(context, net::SocketType::kDealer);
    EXPECT_TRUE(socket.ok());
    EXPECT_TRUE((*socket)->Connect(endpoint).ok());
    channel_ = std::make_unique<net::Channel>(std::move(*socket), id, 1, &counters_);
  }
  std::optional<wire::Envelope> Ask(wire::Envelope request) {
    if (!channel_->Send(std::move(request)).ok()) return std::nullopt;
    return Receive();
  }
  std::optional<wire::Envelope> Receive() {
    std::optional<net::Incoming> in = net::testing::ReceiveWithin(channel_.get(), kReplyDeadline);
    if (!in) return std::nullopt;
    return in->envelope;
  }
  net::Channel& channel() { return *channel_; }

 private:
  proto::MessageCounters counters_;
  std::unique_ptr<net::Channel> channel_;
};

wire::Envelope SetFrame(uint32_t projector, int width, int height, int value, size_t bytes = 0) {
  wire::Envelope e;
  auto* r = e.mutable_set_frame_request();
  r->set_projector_id(projector);
  r->set_width_px(width);
  r->set_height_px(height);
  r->set_encoding(wire::PIXEL_ENCODING_GRAY8);
  r->set_pixels(
      std::string(bytes ? bytes : static_cast<size_t>(width) * height, static_cast<char>(value)));
  return e;
}

wire::Envelope Capture(uint32_t camera) {
  wire::Envelope e;
  e.mutable_capture_request()->set_camera_id(camera);
  return e;
}

TEST_F(WorldAppTest, ServeAnswersNodesAndSurvivesBadRequests) {
  ASSERT_NO_FATAL_FAILURE(WriteSmallSiteAndScene());
  ChildProcess server({SANDTABLE_WORLD_BIN, "serve", "--site", Path("site.json"), "--scene",
                       Path("scene.gltf"), "--bind", "tcp://127.0.0.1:0", "--noise-seed", "7",
                       "--threads", "2"});
  std::string error;
  const std::optional<nlohmann::json> ready =
      testing::ReadReadyLine(server, "sandtable-world", kProcessDeadline, &error);
  ASSERT_TRUE(ready.has_value()) << error;
  const std::string endpoint = testing::ReadyString(*ready, "world");
  ASSERT_EQ(endpoint.rfind("tcp://127.0.0.1:", 0), 0u) << ready->dump();

  zmq::context_t context;
  Client node0(&context, endpoint, 0), node1(&context, endpoint, 1);

  // White frame on projector 0; capture camera 0.
  std::optional<wire::Envelope> reply = node0.Ask(SetFrame(0, 1280, 800, 255));
  ASSERT_TRUE(reply && reply->has_set_frame_reply());
  EXPECT_TRUE(reply->set_frame_reply().ok()) << reply->set_frame_reply().message();
  // An RGB frame is accepted too (projector 3 stays on for the rest of the test).
  wire::Envelope rgb = SetFrame(3, 1280, 800, 255, 1280 * 800 * 3);
  rgb.mutable_set_frame_request()->set_encoding(wire::PIXEL_ENCODING_RGB8);
  reply = node1.Ask(rgb);
  ASSERT_TRUE(reply && reply->has_set_frame_reply());
  EXPECT_TRUE(reply->set_frame_reply().ok()) << reply->set_frame_reply().message();
  // Two nodes ask at once: each gets its own camera's picture.
  ASSERT_TRUE(node1.channel().Send(Capture(1)).ok());
  reply = node0.Ask(Capture(0));
  std::optional<wire::Envelope> reply1 = node1.Receive();
  ASSERT_TRUE(reply && reply->has_capture_reply());
  ASSERT_TRUE(reply1 && reply1->has_capture_reply());
  EXPECT_EQ(reply1->capture_reply().camera_id(), 1u);
  const wire::CaptureReply& capture = reply->capture_reply();
  ASSERT_TRUE(capture.ok()) << capture.message();
  EXPECT_EQ(capture.camera_id(), 0u);
  ASSERT_EQ(capture.width_px(), 128u);
  ASSERT_EQ(capture.height_px(), 96u);
  ASSERT_EQ(capture.encoding(), wire::PIXEL_ENCODING_GRAY8);
  ASSERT_EQ(capture.pixels().size(), 128u * 96u);
  const cv::Mat served(96, 128, CV_8UC1, const_cast<char*>(capture.pixels().data()));

  // The library's own capture of the same world: equal mean (noise is zero-mean), and
  // identical with the server's seed for camera 0's first capture.
  auto world = World::Create(*LoadSiteFile(Path("site.json")), *LoadGltfScene(Path("scene.gltf")));
  ASSERT_TRUE(world.ok());
  ASSERT_TRUE((*world)->SetProjectorUniform(0, 255).ok());
  ASSERT_TRUE(
      (*world)->SetProjectorFrame(3, cv::Mat(800, 1280, CV_8UC3, cv::Scalar(255, 255, 255))).ok());
  const cv::Mat clean = *(*world)->Capture(0, {.enabled = false});
  EXPECT_GT(cv::mean(clean)[0], 20.0) << "the camera sees the white frame";
  EXPECT_NEAR(cv::mean(served)[0], cv::mean(clean)[0], kMeanLevelTolerance_dn);
  const cv::Mat same_seed = *(*world)->Capture(0, {.enabled = true, .seed = CaptureSeed(7, 0, 0)});
  EXPECT_EQ(cv::norm(served, same_seed, cv::NORM_INF), 0.0);

  // Ground truth: the table point on projector 0's ray through its image centre.
  const ProjectorSpec& projector = (*world)->site().units[0].projector;
  const Eigen::Vector3d ray = projector.table_from_projector.rotation *
                              *projector.model.Unproject(Eigen::Vector2d(640.0, 400.0));
  const Eigen::Vector3d centre = projector.table_from_projector.translation;
  const Eigen::Vector3d point = centre - centre.z() / ray.z() * ray;
  wire::Envelope truth_request;
  auto* t = truth_request.mutable_ground_truth_request();
  t->set_projector_id(0);
  t->add_points_in_table_m()->set_x(point.x());
  t->mutable_points_in_table_m(0)->set_y(point.y());
  t->mutable_points_in_table_m(0)->set_z(point.z());
  reply = node0.Ask(truth_request);
  ASSERT_TRUE(reply && reply->has_ground_truth_reply());
  ASSERT_TRUE(reply->ground_truth_reply().ok()) << reply->ground_truth_reply().message();
  ASSERT_EQ(reply->ground_truth_reply().samples_size(), 1);
  const Expected<ProjectorTruth> expected = (*world)->ProjectorTruthAtPoint(0, point);
  ASSERT_TRUE(expected.ok());
  ASSERT_TRUE(expected->sample.visible);
  EXPECT_NEAR(expected->sample.pixel_px.x(), 640.0, 1e-6);
  EXPECT_GT(expected->luminance_nits, 0.0);
  const wire::GroundTruthSample& sample = reply->ground_truth_reply().samples(0);
  EXPECT_EQ(sample.visible(), expected->sample.visible);
  EXPECT_EQ(sample.projector_px().x(), expected->sample.pixel_px.x());
  EXPECT_EQ(sample.projector_px().y(), expected->sample.pixel_px.y());
  EXPECT_EQ(sample.luminance_cd_per_m2(), expected->luminance_nits);

  // Bad requests: each gets an error reply, and the server keeps answering.
  reply = node0.Ask(SetFrame(9, 1280, 800, 255));  // unknown projector
  ASSERT_TRUE(reply && reply->has_set_frame_reply());
  EXPECT_FALSE(reply->set_frame_reply().ok());
  EXPECT_NE(reply->set_frame_reply().message().find("no such projector"), std::string::npos);
  reply = node0.Ask(SetFrame(0, 640, 400, 255));  // wrong size
  ASSERT_TRUE(reply && reply->has_set_frame_reply());
  EXPECT_FALSE(reply->set_frame_reply().ok());
  reply = node0.Ask(SetFrame(0, 1280, 800, 255, 1000));  // pixels do not match the size
  ASSERT_TRUE(reply && reply->has_set_frame_reply());
  EXPECT_FALSE(reply->set_frame_reply().ok());
  reply = node0.Ask(SetFrame(0, 100000, 100000, 255, 10));  // absurd size, few bytes
  ASSERT_TRUE(reply && reply->has_set_frame_reply());
  EXPECT_FALSE(reply->set_frame_reply().ok());
  wire::Envelope nan_point;
  nan_point.mutable_ground_truth_request()->set_projector_id(0);
  nan_point.mutable_ground_truth_request()->add_points_in_table_m()->set_x(std::nan(""));
  reply = node0.Ask(nan_point);
  ASSERT_TRUE(reply && reply->has_ground_truth_reply());
  EXPECT_FALSE(reply->ground_truth_reply().ok());
  reply = node0.Ask(Capture(42));
  ASSERT_TRUE(reply && reply->has_capture_reply());
  EXPECT_FALSE(reply->capture_reply().ok());
  wire::Envelope hello;
  hello.mutable_hello();
  reply = node0.Ask(hello);  // a body the world does not serve
  ASSERT_TRUE(reply && reply->has_rejected());
  // Raw garbage (not an Envelope) from a third client: answered with Rejected.
  auto raw = net::Socket::Create(&context, net::SocketType::kDealer);
  ASSERT_TRUE(raw.ok() && (*raw)->Connect(endpoint).ok());
  ASSERT_TRUE((*raw)->Send({std::string("\x08\xff\xff garbage", 12)}).ok());
  proto::MessageCounters raw_counters;
  net::Channel raw_channel(std::move(*raw), 77, 1, &raw_counters);
  const std::optional<net::Incoming> rejected =
      net::testing::ReceiveWithin(&raw_channel, kReplyDeadline);
  ASSERT_TRUE(rejected && rejected->envelope.has_rejected());
  // Still serving.
  reply = node0.Ask(Capture(0));
  ASSERT_TRUE(reply && reply->has_capture_reply());
  EXPECT_TRUE(reply->capture_reply().ok());

  server.Signal(SIGTERM);
  EXPECT_EQ(server.Wait(), 0) << "clean exit on SIGTERM";
}

}  // namespace
}  // namespace sandtable::sim
