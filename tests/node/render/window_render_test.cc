// The renderer's second back-end: a GLFW window (node/devices/window_projector_output.h) under
// Xvfb (CTest runs this binary under xvfb-run, label "window"). The same content drawn into the
// window's back buffer and into a headless EGL context gives the same picture: one renderer code,
// two contexts. The render loop on a window draws into it and swaps, with no read back, and
// calibration's frames go out between its frames. Without a display the tests skip.
#include <chrono>
#include <cstdlib>
#include <thread>

#include <gtest/gtest.h>

#include "node/devices/window_projector_output.h"
#include "node/render/gl_context.h"
#include "node/render/render_loop.h"
#include "node/render/renderer.h"
#include "tests/node/devices/x_screen.h"
#include "tests/node/render/render_test_scene.h"

namespace sandtable::node {
namespace {

constexpr int kW = 320, kH = 200;
// The two contexts are both llvmpipe here: identical but for the window's own framebuffer
// format (8-bit RGB either way).
constexpr double kSameMaxDiff = 2.0;

cv::Mat Draw(GlContext* context, const RenderContent& content) {
  const Scene scene = ::sandtable::testing::RenderTestScene();
  Expected<std::unique_ptr<Renderer>> renderer = Renderer::Create(context, scene);
  EXPECT_TRUE(renderer.ok()) << renderer.status().ToString();
  if (!renderer.ok()) return cv::Mat();
  Expected<ProjectorView> view =
      PrepareProjectorView(::sandtable::testing::RenderTestProjector(kW, kH, true),
                           ::sandtable::testing::RenderTestProjectorFromTable(), scene.Bounds());
  EXPECT_TRUE(view.ok());
  EXPECT_TRUE((*renderer)->SetView(*view).ok());
  EXPECT_TRUE((*renderer)->Render(content).ok());
  Expected<cv::Mat> image = context->ReadOutput();
  EXPECT_TRUE(image.ok()) << image.status().ToString();
  return image.ok() ? *image : cv::Mat();
}

bool HaveDisplay() {
  const char* display = std::getenv("DISPLAY");
  return display != nullptr && display[0] != '\0';
}

// A kW x kH window at the screen's origin.
Expected<std::unique_ptr<WindowProjectorOutput>> OpenTestWindow() {
  WindowOptions options;
  options.windowed = true;
  options.windowed_size_px = cv::Size(kW, kH);
  return WindowProjectorOutput::Open(options);
}

TEST(WindowRenderTest, TheWindowShowsWhatTheHeadlessContextDraws) {
  if (!HaveDisplay()) GTEST_SKIP() << "no DISPLAY (ctest uses xvfb-run)";
  Expected<std::unique_ptr<WindowProjectorOutput>> window = OpenTestWindow();
  ASSERT_TRUE(window.ok()) << window.status().ToString();
  std::unique_ptr<GlContext> window_context = CreateWindowContext(window->get());
  EXPECT_NE(window_context->description().find("GLFW window"), std::string::npos);
  RenderContent content;
  content.sun_direction_in_table = SunDirection(10.0);
  content.pattern = TestPattern::kNone;
  const cv::Mat in_window = Draw(window_context.get(), content);
  Expected<ShownFrame> shown = window_context->Present();
  ASSERT_TRUE(shown.ok()) << shown.status().ToString();
  EXPECT_EQ(shown->frame_index, 1u);

  // EGL on its own thread: this one has the window's GLX context current (glvnd refuses to make
  // an EGL context current over it).
  cv::Mat offscreen;
  std::thread([&] {
    Expected<std::unique_ptr<GlContext>> headless = CreateEglContext(cv::Size(kW, kH));
    ASSERT_TRUE(headless.ok()) << headless.status().ToString();
    offscreen = Draw(headless->get(), content);
  }).join();
  ASSERT_EQ(in_window.size(), offscreen.size());
  EXPECT_LE(cv::norm(in_window, offscreen, cv::NORM_INF), kSameMaxDiff);
  EXPECT_GT(cv::countNonZero(in_window.reshape(1)), kW * kH / 4) << "the window drew the scene";
}

UnitCalibration WindowCalibration() {
  UnitCalibration c;
  c.projector = ::sandtable::testing::RenderTestProjector(kW, kH, true);
  c.camera = c.projector;
  c.table_from_projector = ::sandtable::testing::RenderTestProjectorFromTable().Inverse();
  c.table_from_model = Rigid3d::Identity();
  return c;
}

// The X server receives a swap on the GL client's connection; ours may look a moment earlier.
constexpr std::chrono::milliseconds kScreenDeadline{5000};
// Waits (bounded) until the window on the screen is uniformly `level` (`equal`) or is not.
bool ScreenUniform(int level, bool equal = true) {
  const auto until = std::chrono::steady_clock::now() + kScreenDeadline;
  const cv::Mat expected(kH, kW, CV_8UC3, cv::Scalar::all(level));
  do {
    const cv::Mat screen = testing::ReadXScreen(cv::Rect(0, 0, kW, kH));
    if (!screen.empty() && (cv::norm(screen, expected, cv::NORM_INF) == 0.0) == equal) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  } while (std::chrono::steady_clock::now() < until);
  return false;
}

TEST(WindowRenderTest, TheRenderLoopDrawsIntoTheWindowAndCalibrationShowsBetweenItsFrames) {
  if (!HaveDisplay()) GTEST_SKIP() << "no DISPLAY (ctest uses xvfb-run)";
  Expected<std::unique_ptr<WindowProjectorOutput>> window = OpenTestWindow();
  ASSERT_TRUE(window.ok()) << window.status().ToString();
  RenderLoopOptions options;
  options.max_fps = 200.0;
  options.floor_samples = 0;
  Expected<std::unique_ptr<RenderLoop>> loop = RenderLoop::Start(
      window->get(), std::make_shared<const Scene>(::sandtable::testing::RenderTestScene()),
      options);
  ASSERT_TRUE(loop.ok()) << loop.status().ToString();
  EXPECT_NE((*loop)->Summary().context.find("GLFW window"), std::string::npos)
      << (*loop)->Summary().context;
  ASSERT_TRUE((*loop)->ShowCalibration(WindowCalibration()).ok());
  ShowInputs inputs;
  inputs.pattern = TestPattern::kRawWhite;
  (*loop)->SetInputs(inputs);
  EXPECT_TRUE(ScreenUniform(255)) << "the loop's raw white reaches the window";
  // Calibration takes the projector from another thread while the loop is suspended...
  (*loop)->Suspend();
  std::thread([&] {
    EXPECT_TRUE((*window)->Show(cv::Mat(kH, kW, CV_8UC1, cv::Scalar(40))).ok());
  }).join();
  EXPECT_TRUE(ScreenUniform(40)) << "calibration's frame reaches the window";
  // ... and gives it back: the loop's next frame (colour bars) goes out.
  (*loop)->Resume();
  inputs.pattern = TestPattern::kColourBars;
  (*loop)->SetInputs(inputs);
  EXPECT_TRUE(ScreenUniform(40, /*equal=*/false)) << "the loop draws again after calibration";
  const RenderSummary summary = (*loop)->Summary();
  EXPECT_GE(summary.frames_shown, 2u);
  EXPECT_EQ(summary.frames_failed, 0u);
}

}  // namespace
}  // namespace sandtable::node
