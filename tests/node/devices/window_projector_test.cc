// The GLFW window projector, run under Xvfb (CTest: xvfb-run -a ... with a 24-bit screen,
// label "window"): what a frame puts in the framebuffer, read back with glReadPixels after
// drawing, equals the frame exactly, and so do the window's pixels on the X server after the
// swap; windowed and fullscreen. A missing display or monitor is one clear line.
#include <atomic>
#include <chrono>
#include <cstdlib>
#include <functional>
#include <optional>
#include <string>
#include <thread>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "node/devices/device_factory.h"
#include "node/devices/window_projector_output.h"
#include "tests/node/devices/x_screen.h"

namespace sandtable::node {
namespace {

const cv::Size kWindowSize_px(320, 200);
constexpr double kExact_dn = 0.0;  // read back equals shown: no tolerance

bool HaveDisplay() {
  const char* display = std::getenv("DISPLAY");
  return display != nullptr && display[0] != '\0';
}

#define REQUIRE_DISPLAY() \
  if (!HaveDisplay()) GTEST_SKIP() << "no DISPLAY: run this test under xvfb-run (ctest does)"

cv::Mat RandomFrame(cv::Size size, int type, uint64_t seed) {
  cv::Mat frame(size, type);
  cv::RNG rng(seed);
  rng.fill(frame, cv::RNG::UNIFORM, 0, 256);
  return frame;
}

// A GRAY8 frame reads back with R = G = B = its value.
cv::Mat AsRgb(const cv::Mat& frame) {
  if (frame.channels() == 3) return frame;
  cv::Mat rgb;
  cv::merge(std::vector<cv::Mat>{frame, frame, frame}, rgb);
  return rgb;
}

// The X server receives the swapped image on the GL client's connection; ours may look a
// moment earlier. Waits (bounded) for it to show `expected`.
constexpr std::chrono::milliseconds kScreenDeadline{5000};
constexpr std::chrono::milliseconds kScreenPollInterval{5};
double ScreenDifference(cv::Rect area, const cv::Mat& expected) {
  const auto until = std::chrono::steady_clock::now() + kScreenDeadline;
  double difference = -1.0;
  do {
    const cv::Mat screen = testing::ReadXScreen(area);
    if (screen.empty()) return -1.0;
    difference = cv::norm(screen, expected, cv::NORM_INF);
    if (difference != kExact_dn) std::this_thread::sleep_for(kScreenPollInterval);
  } while (difference != kExact_dn && std::chrono::steady_clock::now() < until);
  return difference;
}

WindowOptions Windowed(cv::Size size) {
  WindowOptions options;
  options.windowed = true;
  options.windowed_size_px = size;
  options.keep_read_back = true;
  return options;
}

// `area`: where the window lies on the screen (no window manager under Xvfb: where GLFW put it).
void ExpectShownExactly(WindowProjectorOutput* output, const cv::Mat& frame, cv::Rect area) {
  Expected<ShownFrame> shown = output->Show(frame);
  ASSERT_TRUE(shown.ok()) << shown.status().ToString();
  const cv::Mat& drawn = output->last_read_back();
  ASSERT_EQ(drawn.size(), frame.size());
  ASSERT_EQ(drawn.type(), CV_8UC3);
  EXPECT_EQ(cv::norm(drawn, AsRgb(frame), cv::NORM_INF), kExact_dn) << "GL back buffer";
  EXPECT_EQ(ScreenDifference(area, AsRgb(frame)), kExact_dn) << "X server";
}

TEST(WindowProjectorTest, WindowedFramesReadBackExactly) {
  REQUIRE_DISPLAY();
  Expected<std::unique_ptr<WindowProjectorOutput>> output =
      WindowProjectorOutput::Open(Windowed(kWindowSize_px));
  ASSERT_TRUE(output.ok()) << output.status().ToString();
  EXPECT_EQ((*output)->size(), kWindowSize_px);
  EXPECT_EQ((*output)->description(), "window:0:windowed");
  EXPECT_TRUE((*output)->last_read_back().empty());
  const cv::Rect area(cv::Point(0, 0), kWindowSize_px);  // placed at monitor 0's origin
  // Before any frame: black.
  EXPECT_EQ(ScreenDifference(area, cv::Mat(kWindowSize_px, CV_8UC3, cv::Scalar::all(0))),
            kExact_dn);

  ASSERT_NO_FATAL_FAILURE(
      ExpectShownExactly(output->get(), RandomFrame(kWindowSize_px, CV_8UC3, 1), area));
  ASSERT_NO_FATAL_FAILURE(
      ExpectShownExactly(output->get(), RandomFrame(kWindowSize_px, CV_8UC1, 2), area));
  // Channel order: RGB8 means channel 0 is red.
  cv::Mat red(kWindowSize_px, CV_8UC3, cv::Scalar(255, 0, 0));
  ASSERT_NO_FATAL_FAILURE(ExpectShownExactly(output->get(), red, area));
  // A ROI of a larger image (not continuous, odd stride).
  const cv::Mat big =
      RandomFrame(cv::Size(kWindowSize_px.width + 3, kWindowSize_px.height + 2), CV_8UC3, 3);
  ASSERT_NO_FATAL_FAILURE(
      ExpectShownExactly(output->get(), big(cv::Rect(cv::Point(1, 1), kWindowSize_px)), area));
  // A Gray-code-like sequence: every frame shown is the frame read back; indices and times
  // advance.
  DeviceClock::time_point last{};
  for (int bit = 0; bit < 8; ++bit) {
    cv::Mat stripes(kWindowSize_px, CV_8UC1);
    for (int x = 0; x < stripes.cols; ++x)
      stripes.col(x).setTo(((x ^ (x >> 1)) >> bit) & 1 ? 255 : 0);
    Expected<ShownFrame> shown = (*output)->Show(stripes);
    ASSERT_TRUE(shown.ok());
    EXPECT_EQ(shown->frame_index, static_cast<uint64_t>(5 + bit));
    EXPECT_GE(shown->shown_time, last);
    last = shown->shown_time;
    EXPECT_EQ(cv::norm((*output)->last_read_back(), AsRgb(stripes), cv::NORM_INF), kExact_dn)
        << "bit " << bit;
    EXPECT_EQ(ScreenDifference(area, AsRgb(stripes)), kExact_dn) << "bit " << bit;
  }
}

// A node opens the window on its main thread and shows from others (the render thread, the
// calibration's workers), in turns and at once: every frame reads back exactly.
TEST(WindowProjectorTest, FramesShownFromOtherThreadsThanTheOpenersReadBackExactly) {
  REQUIRE_DISPLAY();
  Expected<std::unique_ptr<WindowProjectorOutput>> output =
      WindowProjectorOutput::Open(Windowed(kWindowSize_px));
  ASSERT_TRUE(output.ok()) << output.status().ToString();
  const cv::Rect area(cv::Point(0, 0), kWindowSize_px);
  std::thread([&] {
    ExpectShownExactly(output->get(), RandomFrame(kWindowSize_px, CV_8UC3, 11), area);
  }).join();
  ASSERT_NO_FATAL_FAILURE(
      ExpectShownExactly(output->get(), RandomFrame(kWindowSize_px, CV_8UC3, 12), area));
  // Two threads showing at once take turns: every call succeeds and the window ends up showing
  // one of the two frames exactly.
  const cv::Mat a = RandomFrame(kWindowSize_px, CV_8UC3, 13);
  const cv::Mat b = RandomFrame(kWindowSize_px, CV_8UC3, 14);
  constexpr int kShowsPerThread = 20;
  std::atomic<int> failed{0};
  auto show_many = [&](const cv::Mat& frame) {
    for (int i = 0; i < kShowsPerThread; ++i) {
      if (!(*output)->Show(frame).ok()) ++failed;
    }
  };
  std::thread first(show_many, std::cref(a)), second(show_many, std::cref(b));
  first.join();
  second.join();
  EXPECT_EQ(failed.load(), 0);
  const cv::Mat& last = (*output)->last_read_back();
  const bool is_a = cv::norm(last, a, cv::NORM_INF) == kExact_dn;
  const bool is_b = cv::norm(last, b, cv::NORM_INF) == kExact_dn;
  EXPECT_TRUE(is_a || is_b) << "the last frame read back is one of the two shown";
  EXPECT_EQ(ScreenDifference(area, is_a ? a : b), kExact_dn) << "X server";
}

TEST(WindowProjectorTest, FullscreenOnMonitorZeroTakesItsModeAndReadsBackExactly) {
  REQUIRE_DISPLAY();
  WindowOptions options;
  options.keep_read_back = true;
  Expected<std::unique_ptr<WindowProjectorOutput>> window = WindowProjectorOutput::Open(options);
  ASSERT_TRUE(window.ok()) << window.status().ToString();
  const cv::Size size = (*window)->size();
  const std::optional<cv::Size> screen_size = testing::XScreenSize();
  ASSERT_TRUE(screen_size.has_value());
  const cv::Size screen = *screen_size;
  EXPECT_EQ(size, screen) << "fullscreen takes the monitor's mode";
  ASSERT_NO_FATAL_FAILURE(
      ExpectShownExactly(window->get(), RandomFrame(size, CV_8UC3, 4), cv::Rect({0, 0}, size)));
  // Through the factory too.
  window->reset();
  Expected<std::unique_ptr<ProjectorOutput>> output = MakeProjectorOutput("window:0", {});
  ASSERT_TRUE(output.ok()) << output.status().ToString();
  EXPECT_EQ((*output)->size(), screen);
  const cv::Mat gray = RandomFrame(size, CV_8UC1, 5);
  ASSERT_TRUE((*output)->Show(gray).ok());
  EXPECT_EQ(ScreenDifference(cv::Rect({0, 0}, size), AsRgb(gray)), kExact_dn) << "X server";
}

TEST(WindowProjectorTest, WrongFramesAreRefusedAndTheWindowStaysUsable) {
  REQUIRE_DISPLAY();
  Expected<std::unique_ptr<ProjectorOutput>> output =
      MakeProjectorOutput("window:0:windowed:320x200", {});
  ASSERT_TRUE(output.ok()) << output.status().ToString();
  Expected<ShownFrame> shown = (*output)->Show(cv::Mat(100, 100, CV_8UC3, cv::Scalar::all(0)));
  ASSERT_FALSE(shown.ok());
  EXPECT_EQ(shown.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(shown.status().message(),
            "window:0:windowed: frame is 100x100 RGB8, projector is 320x200");
  shown = (*output)->Show(cv::Mat(kWindowSize_px, CV_32FC1, cv::Scalar(0)));
  ASSERT_FALSE(shown.ok());
  EXPECT_NE(shown.status().message().find("32FC1"), std::string::npos);
  shown = (*output)->Show(cv::Mat());
  EXPECT_FALSE(shown.ok());
  shown = (*output)->Show(cv::Mat(kWindowSize_px, CV_8UC1, cv::Scalar(7)));
  ASSERT_TRUE(shown.ok()) << shown.status().ToString();
  EXPECT_EQ(shown->frame_index, 1u);
}

TEST(WindowProjectorTest, NoSuchMonitorIsOneClearLine) {
  REQUIRE_DISPLAY();
  Expected<std::unique_ptr<ProjectorOutput>> output = MakeProjectorOutput("window:7", {});
  ASSERT_FALSE(output.ok());
  EXPECT_EQ(output.status().code(), StatusCode::kUnavailable);
  EXPECT_EQ(output.status().message().rfind("window:7: no monitor 7 (1 connected: 0 '", 0), 0u)
      << output.status().ToString();
  EXPECT_EQ(output.status().message().find('\n'), std::string::npos);
}

// Runs last in this binary's order only by chance; it restores DISPLAY for the others.
TEST(WindowProjectorTest, NoDisplayIsOneClearLineNotACrash) {
  const char* saved = std::getenv("DISPLAY");
  const std::optional<std::string> display =
      saved ? std::optional<std::string>(saved) : std::nullopt;
  unsetenv("DISPLAY");
  const char* wayland = std::getenv("WAYLAND_DISPLAY");
  const std::optional<std::string> saved_wayland =
      wayland ? std::optional<std::string>(wayland) : std::nullopt;
  unsetenv("WAYLAND_DISPLAY");
  Expected<std::unique_ptr<ProjectorOutput>> output = MakeProjectorOutput("window:0", {});
  Expected<std::unique_ptr<ProjectorOutput>> windowed =
      MakeProjectorOutput("window:1:windowed", {});
  if (display) setenv("DISPLAY", display->c_str(), 1);
  if (saved_wayland) setenv("WAYLAND_DISPLAY", saved_wayland->c_str(), 1);
  ASSERT_FALSE(output.ok());
  EXPECT_EQ(output.status().code(), StatusCode::kUnavailable);
  EXPECT_EQ(output.status().message(), "window:0: no display: set DISPLAY or run under xvfb-run");
  ASSERT_FALSE(windowed.ok());
  EXPECT_EQ(windowed.status().message(),
            "window:1:windowed: no display: set DISPLAY or run under xvfb-run");
  // A display that is named but not there.
  setenv("DISPLAY", ":97", 1);
  output = MakeProjectorOutput("window:0", {});
  if (display) {
    setenv("DISPLAY", display->c_str(), 1);
  } else {
    unsetenv("DISPLAY");
  }
  ASSERT_FALSE(output.ok());
  EXPECT_EQ(output.status().message().rfind("window:0: no display: set DISPLAY or run under "
                                            "xvfb-run (",
                                            0),
            0u)
      << output.status().ToString();
  EXPECT_EQ(output.status().message().find('\n'), std::string::npos);
}

}  // namespace
}  // namespace sandtable::node
