// CameraInput implementations without hardware: the recorded kamino410 capture folder replayed
// as a live camera, OpenCV VideoCapture on a video file written here and on devices that do not
// exist, and the spec strings of the factory.
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include "node/devices/device_factory.h"
#include "node/devices/replay_camera_input.h"
#include "node/devices/video_camera_input.h"

namespace sandtable::node {
namespace {

namespace fs = std::filesystem;

const std::string kCaptureDir = "../shared/data/procam-kamino410/capture_0";
const cv::Size kKaminoSize_px(1280, 1024);
constexpr size_t kKaminoFrames = 42;
// ../shared/data/README.md: mean gray of the white frame (graycode_40) is 78-90 over the five
// poses (rounded; pose 0 is 90.05), of the black frame (graycode_41) about 6.5.
constexpr double kWhiteMinMean_dn = 78.0, kWhiteMaxMean_dn = 91.0;
constexpr double kBlackMaxMean_dn = 10.0;
// MJPEG of a uniform frame: the decoded mean stays within a few DN of the value written.
constexpr double kMjpegMeanTolerance_dn = 3.0;

class TempDir {
 public:
  TempDir() {
    path_ = fs::temp_directory_path() /
            ("sandtable_devices_" + std::to_string(getpid()) + "_" +
             ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(path_);
  }
  ~TempDir() { fs::remove_all(path_); }
  std::string operator/(const std::string& name) const { return (path_ / name).string(); }
  std::string str() const { return path_.string(); }

 private:
  fs::path path_;
};

TEST(ReplayCameraTest, ReplaysTheKaminoRecordingLikeALiveCamera) {
  Expected<std::unique_ptr<CameraInput>> camera = MakeCameraInput("replay:" + kCaptureDir, {});
  ASSERT_TRUE(camera.ok()) << camera.status().ToString();
  EXPECT_EQ((*camera)->size(), kKaminoSize_px);
  EXPECT_EQ((*camera)->bit_depth(), 8);
  EXPECT_EQ((*camera)->description(), "replay " + kCaptureDir);
  std::vector<double> means;
  DeviceClock::time_point last{};
  for (size_t i = 0; i < kKaminoFrames; ++i) {
    const DeviceClock::time_point before = DeviceClock::now();
    Expected<CapturedFrame> frame = (*camera)->Capture(Seconds(0.01));  // exposure: recorded
    ASSERT_TRUE(frame.ok()) << "frame " << i << ": " << frame.status().ToString();
    EXPECT_EQ(frame->index, i + 1);
    EXPECT_EQ(frame->image.type(), CV_8UC1);
    EXPECT_EQ(frame->image.size(), kKaminoSize_px);
    EXPECT_GE(frame->capture_time, before);
    EXPECT_GE(frame->capture_time, last);
    last = frame->capture_time;
    if (i == 0) {
      char name[32];
      std::snprintf(name, sizeof(name), "/graycode_%02zu.png", i);
      const cv::Mat file = cv::imread(kCaptureDir + name, cv::IMREAD_UNCHANGED);
      EXPECT_EQ(cv::norm(frame->image, file, cv::NORM_INF), 0.0) << "bytes as recorded";
    }
    means.push_back(cv::mean(frame->image)[0]);
  }
  EXPECT_GT(means[40], kWhiteMinMean_dn) << "graycode_40 is the white frame";
  EXPECT_LT(means[40], kWhiteMaxMean_dn);
  EXPECT_LT(means[41], kBlackMaxMean_dn) << "graycode_41 is the black frame";
  // Then the recording ends, clearly, every time.
  for (int again = 0; again < 2; ++again) {
    Expected<CapturedFrame> end = (*camera)->Capture(Seconds(0.0));
    ASSERT_FALSE(end.ok());
    EXPECT_EQ(end.status().code(), StatusCode::kOutOfRange);
    EXPECT_EQ(end.status().message(),
              "replay " + kCaptureDir + ": end of recording (all 42 frames were captured)");
  }
}

TEST(ReplayCameraTest, NaturalOrderSixteenBitAndBadFiles) {
  TempDir dir;
  // frame_2 before frame_10; 16-bit values kept (not rescaled).
  for (int i : {10, 2, 1}) {
    cv::imwrite(dir / ("frame_" + std::to_string(i) + ".png"),
                cv::Mat(6, 8, CV_16UC1, cv::Scalar(1000 + i)));
  }
  cv::imwrite(dir / "frame_3.png", cv::Mat(5, 8, CV_16UC1, cv::Scalar(0)));  // wrong size
  std::ofstream(dir / "frame_4.png") << "not a png";
  std::ofstream(dir / "notes.txt") << "ignored";
  Expected<std::unique_ptr<ReplayCameraInput>> camera = ReplayCameraInput::Open(dir.str());
  ASSERT_TRUE(camera.ok()) << camera.status().ToString();
  EXPECT_EQ((*camera)->frame_count(), 5u);
  EXPECT_EQ((*camera)->bit_depth(), 16);
  EXPECT_EQ((*camera)->size(), cv::Size(8, 6));
  auto value_of = [&](uint64_t index) {
    Expected<CapturedFrame> frame = (*camera)->Capture(Seconds(0.0));
    EXPECT_TRUE(frame.ok()) << frame.status().ToString();
    if (!frame.ok()) return -1;
    EXPECT_EQ(frame->index, index);
    EXPECT_EQ(frame->image.type(), CV_16UC1);
    return static_cast<int>(frame->image.at<uint16_t>(0, 0));
  };
  EXPECT_EQ(value_of(1), 1001);
  EXPECT_EQ(value_of(2), 1002);
  Expected<CapturedFrame> bad = (*camera)->Capture(Seconds(0.0));  // frame_3: 8x5
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("frame_3.png: 8x5 16 bit, the recording is 8x6 16 bit"),
            std::string::npos)
      << bad.status().ToString();
  bad = (*camera)->Capture(Seconds(0.0));  // frame_4: not an image
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::kIoError);
  EXPECT_NE(bad.status().message().find("frame_4.png"), std::string::npos);
  EXPECT_EQ(value_of(5), 1010) << "a bad file is a dropped frame; indices still name files";
  EXPECT_EQ((*camera)->Capture(Seconds(0.0)).status().code(), StatusCode::kOutOfRange);

  EXPECT_TRUE(NaturalLess("graycode_09.png", "graycode_10.png"));
  EXPECT_TRUE(NaturalLess("a2", "a10"));
  EXPECT_FALSE(NaturalLess("a10", "a2"));
  EXPECT_TRUE(NaturalLess("a", "a0"));
  EXPECT_FALSE(NaturalLess("a1", "a1"));
}

TEST(ReplayCameraTest, MissingOrEmptyFolderIsOneClearLine) {
  Expected<std::unique_ptr<CameraInput>> camera = MakeCameraInput("replay:/no/such/recording", {});
  ASSERT_FALSE(camera.ok());
  EXPECT_EQ(camera.status().code(), StatusCode::kNotFound);
  EXPECT_EQ(camera.status().message(),
            "replay /no/such/recording: no such directory (a folder of recorded captures)");
  TempDir empty;
  camera = MakeCameraInput("replay:" + empty.str(), {});
  ASSERT_FALSE(camera.ok());
  EXPECT_EQ(camera.status().code(), StatusCode::kNotFound);
  EXPECT_NE(camera.status().message().find("no images"), std::string::npos);
}

TEST(VideoCameraTest, MissingDeviceIsOneLineNamingIt) {
  if (fs::exists("/dev/video9")) GTEST_SKIP() << "this machine has a /dev/video9";
  Expected<std::unique_ptr<CameraInput>> camera = MakeCameraInput("video:9", {});
  ASSERT_FALSE(camera.ok());
  EXPECT_EQ(camera.status().code(), StatusCode::kUnavailable);
  EXPECT_EQ(camera.status().message(), "video:9: no camera: /dev/video9 does not exist");
  camera = MakeCameraInput("video:/no/such/stream.mp4", {});
  ASSERT_FALSE(camera.ok());
  EXPECT_EQ(camera.status().code(), StatusCode::kUnavailable);
  EXPECT_EQ(camera.status().message(), "video:/no/such/stream.mp4: no such file");
  camera = MakeCameraInput("video:rtsp://127.0.0.1:1/none", {});
  ASSERT_FALSE(camera.ok());
  EXPECT_EQ(camera.status().code(), StatusCode::kUnavailable);
  EXPECT_NE(camera.status().message().find("video:rtsp://127.0.0.1:1/none: cannot open"),
            std::string::npos)
      << camera.status().ToString();
  EXPECT_EQ(camera.status().message().find('\n'), std::string::npos);
}

TEST(VideoCameraTest, VideoCaptureStreamIsAGrayCamera) {
  TempDir dir;
  const std::string file = dir / "stream.avi";
  const cv::Size size(64, 48);
  {
    // OpenCV's built-in MJPEG writer: no external codec needed.
    cv::VideoWriter writer(file, cv::CAP_OPENCV_MJPEG, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'),
                           30.0, size, true);
    ASSERT_TRUE(writer.isOpened());
    for (int i = 0; i < 8; ++i) writer.write(cv::Mat(size, CV_8UC3, cv::Scalar::all(20 * i + 40)));
  }
  VideoCameraOptions options;
  options.device = file;
  options.discard_frames = 0;
  Expected<std::unique_ptr<VideoCameraInput>> camera = VideoCameraInput::Open(options);
  ASSERT_TRUE(camera.ok()) << camera.status().ToString();
  EXPECT_EQ((*camera)->size(), size);
  EXPECT_EQ((*camera)->bit_depth(), 8);
  // Open() read frame 0; captures continue with frames 1, 2, ...
  for (int i = 1; i < 8; ++i) {
    Expected<CapturedFrame> frame = (*camera)->Capture(Seconds(0.0));
    ASSERT_TRUE(frame.ok()) << frame.status().ToString();
    EXPECT_EQ(frame->image.type(), CV_8UC1);
    EXPECT_NEAR(cv::mean(frame->image)[0], 20 * i + 40, kMjpegMeanTolerance_dn) << "frame " << i;
  }
  Expected<CapturedFrame> end = (*camera)->Capture(Seconds(0.0));
  ASSERT_FALSE(end.ok());
  EXPECT_EQ(end.status().code(), StatusCode::kUnavailable);
  EXPECT_NE(end.status().message().find("no frame"), std::string::npos);
}

TEST(DeviceSpecTest, ParsesEveryFormAndRefusesTheRest) {
  Expected<DeviceSpec> spec = ParseProjectorSpec("world:tcp://127.0.0.1:5555");
  ASSERT_TRUE(spec.ok());
  EXPECT_EQ(spec->kind, DeviceSpec::Kind::kWorld);
  EXPECT_EQ(spec->target, "tcp://127.0.0.1:5555");
  spec = ParseProjectorSpec("window:0");
  ASSERT_TRUE(spec.ok());
  EXPECT_EQ(spec->kind, DeviceSpec::Kind::kWindow);
  EXPECT_EQ(spec->monitor_index, 0);
  EXPECT_FALSE(spec->windowed);
  spec = ParseProjectorSpec("window:2:windowed");
  ASSERT_TRUE(spec.ok());
  EXPECT_EQ(spec->monitor_index, 2);
  EXPECT_TRUE(spec->windowed);
  EXPECT_FALSE(spec->window_size_px.has_value());
  spec = ParseProjectorSpec("window:0:windowed:640x400");
  ASSERT_TRUE(spec.ok());
  EXPECT_EQ(spec->window_size_px, cv::Size(640, 400));
  spec = ParseCameraSpec("video:0");
  ASSERT_TRUE(spec.ok());
  EXPECT_EQ(spec->kind, DeviceSpec::Kind::kVideo);
  EXPECT_EQ(spec->target, "0");
  spec = ParseCameraSpec("video:rtsp://10.0.0.5:554/stream");
  ASSERT_TRUE(spec.ok());
  EXPECT_EQ(spec->target, "rtsp://10.0.0.5:554/stream");
  spec = ParseCameraSpec("replay:../shared/data/procam-kamino410/capture_0");
  ASSERT_TRUE(spec.ok());
  EXPECT_EQ(spec->kind, DeviceSpec::Kind::kReplay);
  spec = ParseCameraSpec("world:tcp://127.0.0.1:5555");
  ASSERT_TRUE(spec.ok());
  EXPECT_EQ(spec->kind, DeviceSpec::Kind::kWorld);

  for (const char* bad :
       {"", "window", "window:", "window:-1", "window:x", "window:0:full", "window:0:windowed:640",
        "window:0:windowed:0x400", "video:0", "hdmi:1", "world:"}) {
    spec = ParseProjectorSpec(bad);
    ASSERT_FALSE(spec.ok()) << bad;
    EXPECT_EQ(spec.status().code(), StatusCode::kInvalidArgument);
    EXPECT_NE(spec.status().message().find(kProjectorSpecForms), std::string::npos)
        << spec.status().ToString();
  }
  for (const char* bad : {"", "video", "video:", "replay:", "window:0", "usb:1"}) {
    spec = ParseCameraSpec(bad);
    ASSERT_FALSE(spec.ok()) << bad;
    EXPECT_NE(spec.status().message().find(kCameraSpecForms), std::string::npos)
        << spec.status().ToString();
  }
}

}  // namespace
}  // namespace sandtable::node
