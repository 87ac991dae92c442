// The renderer's second back-end: a GLFW window (node/devices/window_projector_output.h) under
// Xvfb (CTest runs this binary under xvfb-run, label "window"). The same content drawn into the
// window's back buffer and into a headless EGL context gives the same picture: one renderer code,
// two contexts. Without a display the test skips.
#include <cstdlib>
#include <thread>

#include <gtest/gtest.h>

#include "node/devices/window_projector_output.h"
#include "node/render/gl_context.h"
#include "node/render/renderer.h"
#include "tests/node/render/render_test_scene.h"

namespace sandtable::node {
namespace {

constexpr int kW = 320, kH = 200;
// The two contexts are both llvmpipe here: identical but for the window's own framebuffer
// format (8-bit RGB either way).
constexpr double kSameMaxDiff = 2.0;

cv::Mat Draw(GlContext* context, const RenderContent& content) {
  const Scene scene = testing::RenderTestScene();
  Expected<std::unique_ptr<Renderer>> renderer = Renderer::Create(context, scene);
  EXPECT_TRUE(renderer.ok()) << renderer.status().ToString();
  if (!renderer.ok()) return cv::Mat();
  Expected<ProjectorView> view =
      PrepareProjectorView(testing::RenderTestProjector(kW, kH, true),
                           testing::RenderTestProjectorFromTable(), scene.Bounds());
  EXPECT_TRUE(view.ok());
  EXPECT_TRUE((*renderer)->SetView(*view).ok());
  EXPECT_TRUE((*renderer)->Render(content).ok());
  Expected<cv::Mat> image = context->ReadOutput();
  EXPECT_TRUE(image.ok()) << image.status().ToString();
  return image.ok() ? *image : cv::Mat();
}

TEST(WindowRenderTest, TheWindowShowsWhatTheHeadlessContextDraws) {
  const char* display = std::getenv("DISPLAY");
  if (display == nullptr || display[0] == '\0') GTEST_SKIP() << "no DISPLAY (ctest uses xvfb-run)";
  WindowOptions options;
  options.windowed = true;
  options.windowed_size_px = cv::Size(kW, kH);
  Expected<std::unique_ptr<WindowProjectorOutput>> window = WindowProjectorOutput::Open(options);
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

}  // namespace
}  // namespace sandtable::node
