// The world-backed ProjectorOutput and CameraInput against a real WorldServer (the server of
// `sandtable-world serve`) running in-process on a thread, on a small flat-4 site. Nodes see
// only the interfaces, made by the factory from "world:ENDPOINT" specs.
#include <atomic>
#include <chrono>
#include <thread>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "common/scene/procedural_scene.h"
#include "net/socket.h"
#include "node/devices/device_factory.h"
#include "node/devices/paced_camera.h"
#include "node/devices/world_link.h"
#include "node/devices/world_projector_output.h"
#include "sim/app/world_server.h"
#include "sim/site/site_presets.h"
#include "sim/transport/world.h"

namespace sandtable::node {
namespace {

using std::chrono::milliseconds;

const cv::Size kProjectorSize_px(1280, 800);  // DefaultProjector()
const cv::Size kCameraSize_px(128, 96);       // shrunk below so transport maps build fast
// The camera of unit 0 sees its own projector's footprint: white lifts the mean well above
// black (about 40 DN here; black level and ambient alone stay under 10).
constexpr double kMinWhiteOverBlack_dn = 15.0;
// A dead world must be reported within the connect timeout plus scheduling slack.
constexpr milliseconds kConnectTimeout{300};
constexpr milliseconds kDeadWorldBound{3000};

class WorldDevicesTest : public ::testing::Test {
 protected:
  void SetUp() override {
    Expected<sim::Site> site = sim::MakeSitePreset("flat-4");
    ASSERT_TRUE(site.ok()) << site.status().ToString();
    for (sim::UnitSpec& unit : site->units) {
      unit.timing = timing_;
      const CameraModel& m = unit.camera->model;
      const double s = static_cast<double>(kCameraSize_px.width) / m.width_px;
      unit.camera->model =
          CameraModel(kCameraSize_px.width, kCameraSize_px.height, m.fx_px * s, m.fy_px * s,
                      (m.cx_px + 0.5) * s - 0.5, (m.cy_px + 0.5) * s - 0.5, m.distortion);
    }
    ProceduralSceneOptions scene_options;
    scene_options.preset = ScenePreset::kFlat;
    Expected<ProceduralScene> scene = MakeProceduralScene(scene_options);
    ASSERT_TRUE(scene.ok());
    Expected<std::unique_ptr<sim::World>> world = sim::World::Create(*site, scene->scene);
    ASSERT_TRUE(world.ok()) << world.status().ToString();
    server_ = std::make_unique<sim::WorldServer>(std::move(*world), sim::WorldServerOptions{});
    ASSERT_TRUE(server_->Start().ok());
    spec_ = "world:" + server_->endpoint();
    thread_ = std::thread([this] { served_ = server_->Run(stop_); });
  }
  void TearDown() override { StopWorld(); }

  void StopWorld() {
    if (!server_) return;
    stop_ = true;
    thread_.join();
    EXPECT_TRUE(served_.ok()) << served_.ToString();
    server_.reset();
  }

  DeviceOptions Unit(NodeId id) const {
    DeviceOptions options;
    options.node_id = id;
    options.projector_size_px = kProjectorSize_px;
    options.camera_size_px = kCameraSize_px;
    options.camera_bit_depth = 8;
    options.world_connect_timeout = kConnectTimeout;
    return options;
  }

  sim::DeviceTiming timing_;  // every unit's (set by a derived fixture's constructor)
  std::unique_ptr<sim::WorldServer> server_;
  std::string spec_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
  Status served_;
};

TEST_F(WorldDevicesTest, FrameShownIsCapturedByTheCamera) {
  Expected<std::unique_ptr<ProjectorOutput>> projector = MakeProjectorOutput(spec_, Unit(0));
  ASSERT_TRUE(projector.ok()) << projector.status().ToString();
  Expected<std::unique_ptr<CameraInput>> camera = MakeCameraInput(spec_, Unit(0));
  ASSERT_TRUE(camera.ok()) << camera.status().ToString();
  EXPECT_EQ((*projector)->size(), kProjectorSize_px);
  EXPECT_EQ((*camera)->size(), kCameraSize_px);
  EXPECT_EQ((*camera)->bit_depth(), 8);

  auto show_and_capture = [&](const cv::Mat& frame, ShownFrame* shown) {
    Expected<ShownFrame> s = (*projector)->Show(frame);
    EXPECT_TRUE(s.ok()) << s.status().ToString();
    Expected<CapturedFrame> c = (*camera)->Capture(Seconds(0.0));
    EXPECT_TRUE(c.ok()) << c.status().ToString();
    if (!s.ok() || !c.ok()) return -1.0;
    *shown = *s;
    EXPECT_GE(c->capture_time, s->shown_time) << "the capture sees the frame shown before it";
    EXPECT_EQ(c->image.type(), CV_8UC1);
    EXPECT_EQ(c->image.size(), kCameraSize_px);
    return cv::mean(c->image)[0];
  };
  ShownFrame first, second, third;
  const double black = show_and_capture(cv::Mat(kProjectorSize_px, CV_8UC1, cv::Scalar(0)), &first);
  const double white =
      show_and_capture(cv::Mat(kProjectorSize_px, CV_8UC1, cv::Scalar(255)), &second);
  // RGB8 works too; a non-continuous ROI of a larger image is fine.
  cv::Mat big(kProjectorSize_px.height + 10, kProjectorSize_px.width + 10, CV_8UC3,
              cv::Scalar(255, 255, 255));
  const double white_rgb =
      show_and_capture(big(cv::Rect(cv::Point(5, 5), kProjectorSize_px)), &third);
  EXPECT_GT(white, black + kMinWhiteOverBlack_dn) << "black " << black << " white " << white;
  EXPECT_GT(white_rgb, black + kMinWhiteOverBlack_dn);
  EXPECT_EQ(first.frame_index, 1u);
  EXPECT_EQ(second.frame_index, 2u);
  EXPECT_EQ(third.frame_index, 3u);
  EXPECT_LE(first.shown_time, second.shown_time);
  EXPECT_EQ(server_->stats().frames_set, 3u);
  EXPECT_EQ(server_->stats().captures, 3u);
  EXPECT_EQ(server_->stats().bad_requests, 0u);
}

TEST_F(WorldDevicesTest, ProjectorAndCameraOfAUnitShareOneLink) {
  WorldLinkOptions options;
  options.endpoint = server_->endpoint();
  options.node_id = 2;
  Expected<std::shared_ptr<WorldLink>> a = WorldLink::Shared(options);
  Expected<std::shared_ptr<WorldLink>> b = WorldLink::Shared(options);
  ASSERT_TRUE(a.ok() && b.ok());
  EXPECT_EQ(a->get(), b->get());
  options.node_id = 3;
  Expected<std::shared_ptr<WorldLink>> other = WorldLink::Shared(options);
  ASSERT_TRUE(other.ok());
  EXPECT_NE(a->get(), other->get());
}

// A projector frame goes to the world as it is: deflating 3 MB a frame for a world on the same
// machine cost more than the frame's render (WorldLinkOptions::compress_requests); with the
// option on, the same frame (black: it deflates well) goes compressed.
TEST_F(WorldDevicesTest, FramesGoToTheWorldUncompressedUnlessAsked) {
  const size_t frame_bytes = static_cast<size_t>(kProjectorSize_px.area()) * 3;
  for (const bool compress : {false, true}) {
    SCOPED_TRACE(compress ? "compressed" : "as it is");
    WorldLinkOptions options;
    options.endpoint = server_->endpoint();
    options.node_id = 7;
    options.compress_requests = compress;
    Expected<std::shared_ptr<WorldLink>> link = WorldLink::Connect(options);
    ASSERT_TRUE(link.ok()) << link.status().ToString();
    Expected<std::unique_ptr<WorldProjectorOutput>> projector =
        WorldProjectorOutput::Create(*link, 0, kProjectorSize_px);
    ASSERT_TRUE(projector.ok()) << projector.status().ToString();
    const cv::Mat black(kProjectorSize_px, CV_8UC3, cv::Scalar(0, 0, 0));
    Expected<ShownFrame> shown = (*projector)->Show(black);
    ASSERT_TRUE(shown.ok()) << shown.status().ToString();
    const uint64_t sent = (*link)->stats().bytes_sent;
    if (compress) {
      EXPECT_LT(sent, frame_bytes / 10);
    } else {
      EXPECT_GE(sent, frame_bytes);
    }
  }
}

TEST_F(WorldDevicesTest, CameraSizeAndDepthAreProbedWhenUnknown) {
  DeviceOptions options = Unit(1);
  options.camera_size_px.reset();
  options.camera_bit_depth.reset();
  Expected<std::unique_ptr<CameraInput>> camera = MakeCameraInput(spec_, options);
  ASSERT_TRUE(camera.ok()) << camera.status().ToString();
  EXPECT_EQ((*camera)->size(), kCameraSize_px);
  EXPECT_EQ((*camera)->bit_depth(), 8);
  Expected<CapturedFrame> frame = (*camera)->Capture(Seconds(0.0));
  ASSERT_TRUE(frame.ok()) << frame.status().ToString();
  EXPECT_EQ(frame->index, 1u) << "the probe is not counted";
  // A unit that believes in another camera size is told so.
  options.camera_size_px = cv::Size(1024, 768);
  camera = MakeCameraInput(spec_, options);
  ASSERT_FALSE(camera.ok());
  EXPECT_NE(camera.status().message().find("1024x768"), std::string::npos)
      << camera.status().ToString();
}

TEST_F(WorldDevicesTest, WrongFramesAreRefusedWithAClearMessage) {
  Expected<std::unique_ptr<ProjectorOutput>> projector = MakeProjectorOutput(spec_, Unit(0));
  ASSERT_TRUE(projector.ok()) << projector.status().ToString();
  // Refused here: the frame does not match the projector.
  Expected<ShownFrame> shown = (*projector)->Show(cv::Mat(400, 640, CV_8UC1, cv::Scalar(255)));
  ASSERT_FALSE(shown.ok());
  EXPECT_EQ(shown.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(shown.status().message().find("frame is 640x400 GRAY8, projector is 1280x800"),
            std::string::npos)
      << shown.status().ToString();
  shown = (*projector)->Show(cv::Mat(kProjectorSize_px, CV_16UC1, cv::Scalar(0)));
  ASSERT_FALSE(shown.ok());
  EXPECT_NE(shown.status().message().find("16UC1"), std::string::npos);
  EXPECT_EQ(server_->stats().bad_requests, 0u) << "nothing was sent";

  // A unit that believes its projector is 640x400: the world refuses, in its own words.
  DeviceOptions wrong = Unit(0);
  wrong.projector_size_px = cv::Size(640, 400);
  Expected<std::unique_ptr<ProjectorOutput>> mistaken = MakeProjectorOutput(spec_, wrong);
  ASSERT_TRUE(mistaken.ok());
  shown = (*mistaken)->Show(cv::Mat(400, 640, CV_8UC1, cv::Scalar(255)));
  ASSERT_FALSE(shown.ok());
  EXPECT_EQ(shown.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(shown.status().message().find(
                "set_frame projector 0: frame is 640x400, projector is 1280x800"),
            std::string::npos)
      << shown.status().ToString();
  EXPECT_EQ(server_->stats().bad_requests, 1u);

  // Both stay usable.
  EXPECT_TRUE((*projector)->Show(cv::Mat(kProjectorSize_px, CV_8UC1, cv::Scalar(9))).ok());

  // A camera the site does not have.
  DeviceOptions stranger = Unit(9);
  EXPECT_FALSE(MakeProjectorOutput(spec_, stranger)
                   .value()
                   ->Show(cv::Mat(kProjectorSize_px, CV_8UC1, cv::Scalar(0)))
                   .ok());
  Expected<std::unique_ptr<CameraInput>> camera = MakeCameraInput(spec_, stranger);
  ASSERT_TRUE(camera.ok());
  Expected<CapturedFrame> capture = (*camera)->Capture(Seconds(0.0));
  ASSERT_FALSE(capture.ok());
  EXPECT_NE(capture.status().message().find("no such camera"), std::string::npos)
      << capture.status().ToString();
  // A bad exposure is refused before it is sent.
  camera = MakeCameraInput(spec_, Unit(0));
  ASSERT_TRUE(camera.ok());
  EXPECT_EQ((*camera)->Capture(Seconds(-1.0)).status().code(), StatusCode::kInvalidArgument);
}

TEST_F(WorldDevicesTest, DeadWorldIsUnavailableNeverAHang) {
  Expected<std::unique_ptr<ProjectorOutput>> projector = MakeProjectorOutput(spec_, Unit(1));
  ASSERT_TRUE(projector.ok());
  Expected<std::unique_ptr<CameraInput>> camera = MakeCameraInput(spec_, Unit(1));
  ASSERT_TRUE(camera.ok());
  ASSERT_TRUE((*projector)->Show(cv::Mat(kProjectorSize_px, CV_8UC1, cv::Scalar(255))).ok());
  StopWorld();  // the world dies under a running node

  auto start = std::chrono::steady_clock::now();
  Expected<ShownFrame> shown =
      (*projector)->Show(cv::Mat(kProjectorSize_px, CV_8UC1, cv::Scalar(0)));
  ASSERT_FALSE(shown.ok());
  EXPECT_EQ(shown.status().code(), StatusCode::kUnavailable) << shown.status().ToString();
  EXPECT_NE(shown.status().message().find("sandtable-world serve"), std::string::npos)
      << shown.status().ToString();
  EXPECT_LT(std::chrono::steady_clock::now() - start, kDeadWorldBound);
  start = std::chrono::steady_clock::now();
  Expected<CapturedFrame> captured = (*camera)->Capture(Seconds(0.0));
  ASSERT_FALSE(captured.ok());
  EXPECT_EQ(captured.status().code(), StatusCode::kUnavailable);
  EXPECT_LT(std::chrono::steady_clock::now() - start, kDeadWorldBound);

  // A node started against no world at all: its devices are made (no request is sent), and
  // the first request says the world is not reachable.
  DeviceOptions options = Unit(1);
  options.camera_size_px.reset();  // needs a probe capture: fails at once
  start = std::chrono::steady_clock::now();
  Expected<std::unique_ptr<CameraInput>> probed =
      MakeCameraInput("world:tcp://127.0.0.1:1", options);
  ASSERT_FALSE(probed.ok());
  EXPECT_EQ(probed.status().code(), StatusCode::kUnavailable);
  EXPECT_NE(probed.status().message().find("not reachable"), std::string::npos)
      << probed.status().ToString();
  EXPECT_LT(std::chrono::steady_clock::now() - start, kDeadWorldBound);
}

TEST_F(WorldDevicesTest, BadWorldSpecsAreClearErrors) {
  EXPECT_EQ(MakeProjectorOutput("world:", Unit(0)).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(MakeProjectorOutput("world:not-an-endpoint", Unit(0)).status().code(),
            StatusCode::kInvalidArgument);
  DeviceOptions no_size = Unit(0);
  no_size.projector_size_px.reset();
  Expected<std::unique_ptr<ProjectorOutput>> projector = MakeProjectorOutput(spec_, no_size);
  ASSERT_FALSE(projector.ok());
  EXPECT_NE(projector.status().message().find("projector size is unknown"), std::string::npos);
  DeviceOptions no_id = Unit(0);
  no_id.node_id = kInvalidNodeId;
  EXPECT_EQ(MakeProjectorOutput(spec_, no_id).status().code(), StatusCode::kInvalidArgument);
}

// A "world" that takes requests and never answers, then closes: the two ways a live connection
// can fail a request. A bare ROUTER socket, so nothing but the link's deadlines can end a wait.
class SilentWorld {
 public:
  SilentWorld() {
    Expected<std::unique_ptr<net::Socket>> socket =
        net::Socket::Create(&context_, net::SocketType::kRouter);
    EXPECT_TRUE(socket.ok());
    socket_ = std::move(*socket);
    Expected<std::string> endpoint = socket_->Bind("tcp://127.0.0.1:*");
    EXPECT_TRUE(endpoint.ok());
    endpoint_ = *endpoint;
  }
  const std::string& endpoint() const { return endpoint_; }
  // Waits (bounded) for one request, then closes the socket: the world died mid-request.
  void CloseAfterOneRequest() {
    thread_ = std::thread([this] {
      std::vector<bool> readable;
      const Status polled = net::Socket::Poll({socket_.get()}, kRequestDeadline, &readable);
      if (polled.ok() && readable[0]) socket_->TryReceive().ok();
      socket_.reset();
    });
  }
  ~SilentWorld() {
    if (thread_.joinable()) thread_.join();
  }

 private:
  static constexpr milliseconds kRequestDeadline{10000};
  zmq::context_t context_;
  std::unique_ptr<net::Socket> socket_;
  std::string endpoint_;
  std::thread thread_;
};

Expected<std::unique_ptr<WorldProjectorOutput>> ProjectorOf(const std::string& endpoint,
                                                            milliseconds reply_timeout) {
  WorldLinkOptions options;
  options.endpoint = endpoint;
  options.node_id = 0;
  options.connect_timeout = kConnectTimeout;
  options.reply_timeout = reply_timeout;
  Expected<std::shared_ptr<WorldLink>> link = WorldLink::Connect(options);
  if (!link.ok()) return link.status();
  return WorldProjectorOutput::Create(*link, 0, kProjectorSize_px);
}

TEST(WorldLinkTest, AWorldThatDoesNotAnswerIsUnavailableAtTheReplyDeadline) {
  SilentWorld world;
  constexpr milliseconds kReplyTimeout{400};
  Expected<std::unique_ptr<WorldProjectorOutput>> projector =
      ProjectorOf(world.endpoint(), kReplyTimeout);
  ASSERT_TRUE(projector.ok()) << projector.status().ToString();
  const auto start = std::chrono::steady_clock::now();
  Expected<ShownFrame> shown =
      (*projector)->Show(cv::Mat(kProjectorSize_px, CV_8UC1, cv::Scalar(0)));
  const auto waited = std::chrono::steady_clock::now() - start;
  ASSERT_FALSE(shown.ok());
  EXPECT_EQ(shown.status().code(), StatusCode::kUnavailable);
  EXPECT_NE(shown.status().message().find("no set_frame_reply to set_frame_request within 400 ms"),
            std::string::npos)
      << shown.status().ToString();
  EXPECT_GE(waited, kReplyTimeout);
  EXPECT_LT(waited, kDeadWorldBound);
}

TEST(WorldLinkTest, AWorldThatDiesMidRequestIsUnavailableWithinTheConnectTimeout) {
  SilentWorld world;
  constexpr milliseconds kLongReplyTimeout{60000};
  Expected<std::unique_ptr<WorldProjectorOutput>> projector =
      ProjectorOf(world.endpoint(), kLongReplyTimeout);
  ASSERT_TRUE(projector.ok()) << projector.status().ToString();
  world.CloseAfterOneRequest();
  const auto start = std::chrono::steady_clock::now();
  Expected<ShownFrame> shown =
      (*projector)->Show(cv::Mat(kProjectorSize_px, CV_8UC1, cv::Scalar(0)));
  ASSERT_FALSE(shown.ok());
  EXPECT_EQ(shown.status().code(), StatusCode::kUnavailable);
  EXPECT_NE(shown.status().message().find("went away while answering set_frame_request"),
            std::string::npos)
      << shown.status().ToString();
  EXPECT_LT(std::chrono::steady_clock::now() - start, kDeadWorldBound)
      << "not the 60 s reply timeout";
}

// Real devices' timing (sim/site/device_timing.h): a frame is on the table two 60 Hz refreshes
// after it is sent, the 30 fps camera delivers an exposure 10 ms after it began and its driver
// keeps two unread frames.
class TimedWorldDevicesTest : public WorldDevicesTest {
 protected:
  TimedWorldDevicesTest() {
    timing_ = sim::RealHardwareTiming();
    timing_.drop_rate = 0.0;
    timing_.repeat_rate = 0.0;
  }
};

// The projector's lag: 2 refreshes of 60 Hz.
constexpr double kLagS = 2.0 / 60.0;
// shown_time is stamped by the node after the world took the frame: up to this much later.
constexpr double kStampSlackS = 0.005;
// The most a flash can take to be seen: the lag, a refresh's phase, a camera frame's phase,
// the camera's latency, and the loaded machine's scheduling.
constexpr double kMaxFlashLatencyS = kLagS + 1.0 / 60 + 1.0 / 30 + 0.010 + 0.150;

TEST_F(TimedWorldDevicesTest, AReadRightAfterAFrameShowsTheOldOneAndPacedCapturesWait) {
  Expected<std::unique_ptr<ProjectorOutput>> projector = MakeProjectorOutput(spec_, Unit(0));
  ASSERT_TRUE(projector.ok()) << projector.status().ToString();
  Expected<std::unique_ptr<CameraInput>> opened = MakeCameraInput(spec_, Unit(0));
  ASSERT_TRUE(opened.ok()) << opened.status().ToString();
  const cv::Mat black(kProjectorSize_px, CV_8UC1, cv::Scalar(0));
  const cv::Mat white(kProjectorSize_px, CV_8UC1, cv::Scalar(255));
  ASSERT_TRUE((*projector)->Show(black).ok());
  std::this_thread::sleep_for(milliseconds(300));  // black on the table, the queue full of it
  Expected<CapturedFrame> dark = (*opened)->Capture(Seconds(0));
  ASSERT_TRUE(dark.ok()) << dark.status().ToString();
  const double black_dn = cv::mean(dark->image)[0];

  // A read right after white was sent: a queued exposure from before it.
  Expected<ShownFrame> flash = (*projector)->Show(white);
  ASSERT_TRUE(flash.ok());
  Expected<CapturedFrame> stale = (*opened)->Capture(Seconds(0));
  ASSERT_TRUE(stale.ok());
  EXPECT_LT(stale->capture_time, flash->shown_time);
  EXPECT_LT(cv::mean(stale->image)[0], black_dn + kMinWhiteOverBlack_dn);

  // The paced camera measures the flash and keeps a lit picture.
  ASSERT_TRUE((*projector)->Show(black).ok());
  std::this_thread::sleep_for(milliseconds(300));
  PacedCamera paced(std::move(*opened));
  flash = (*projector)->Show(white);
  ASSERT_TRUE(flash.ok());
  auto lit = [&](const cv::Mat& image) {
    return cv::mean(image)[0] > black_dn + kMinWhiteOverBlack_dn;
  };
  Expected<CapturedFrame> seen = paced.CaptureFlash(flash->shown_time, lit);
  ASSERT_TRUE(seen.ok()) << seen.status().ToString();
  EXPECT_TRUE(lit(seen->image));
  const CaptureTimingStats stats = paced.stats();
  EXPECT_EQ(stats.flashes, 1);
  EXPECT_GE(stats.latency_s, kLagS - kStampSlackS);
  EXPECT_LE(stats.latency_s, kMaxFlashLatencyS);
  EXPECT_GT(stats.settle_s, stats.latency_s);  // plus a camera frame
  EXPECT_GT(stats.reads, 1u);                  // the queued dark frames came first

  // Back to black: the paced capture waits out the lag and the queue.
  Expected<ShownFrame> off = (*projector)->Show(black);
  ASSERT_TRUE(off.ok());
  Expected<CapturedFrame> after = paced.CaptureAfter(off->shown_time);
  ASSERT_TRUE(after.ok());
  EXPECT_LT(cv::mean(after->image)[0], black_dn + kMinWhiteOverBlack_dn);
  EXPECT_GE(after->capture_time - off->shown_time,
            std::chrono::duration_cast<DeviceClock::duration>(Seconds(paced.stats().settle_s)));
}

// A driver that hands the previous picture again: the paced camera reads again.
class RepeatingWorldDevicesTest : public WorldDevicesTest {
 protected:
  RepeatingWorldDevicesTest() {
    timing_ = sim::RealHardwareTiming();
    timing_.repeat_rate = 0.5;
  }
};

TEST_F(RepeatingWorldDevicesTest, RepeatedPicturesAreReadAgain) {
  Expected<std::unique_ptr<CameraInput>> opened = MakeCameraInput(spec_, Unit(0));
  ASSERT_TRUE(opened.ok()) << opened.status().ToString();
  PacedCamera paced(std::move(*opened), PacedCameraOptions{.default_settle = Seconds(0)});
  constexpr int kCaptures = 12;
  cv::Mat previous;
  for (int i = 0; i < kCaptures; ++i) {
    Expected<CapturedFrame> frame = paced.CaptureAfter(DeviceClock::now());
    ASSERT_TRUE(frame.ok()) << frame.status().ToString();
    if (!previous.empty()) {
      EXPECT_GT(cv::norm(frame->image, previous, cv::NORM_INF), 0.0) << "capture " << i;
    }
    previous = frame->image.clone();
  }
  const CaptureTimingStats stats = paced.stats();
  EXPECT_EQ(stats.captures, static_cast<uint64_t>(kCaptures));
  EXPECT_GT(stats.repeated, 0u);
  EXPECT_EQ(stats.gave_up, 0u);
}

}  // namespace
}  // namespace sandtable::node
