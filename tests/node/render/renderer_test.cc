// The renderer on Mesa's llvmpipe through EGL (no GPU, no display): the GL projection of the
// calibrated model against CameraModel::Project (distortion included), raw patterns exact,
// passes skipped when a frame does not need them, the overlay's depth test, the mask in
// linear light, and golden images of each pass.
//
// Golden images: tests/node/render/golden/<name>.png. SANDTABLE_UPDATE_GOLDEN=1 rewrites
// them (look at them before committing).
#include <cmath>
#include <cstdlib>
#include <iostream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "node/render/gl_context.h"
#include "node/render/renderer.h"
#include "node/render/test_patterns.h"
#include "tests/node/render/render_test_scene.h"

namespace sandtable::node {
namespace {

constexpr int kW = 320, kH = 200;
// The bound: GL puts a table point within 0.05 px of CameraModel::Project.
constexpr double kProjectionTolerance_px = 0.05;
// Golden images: llvmpipe is deterministic for one Mesa build; these leave room for another
// build's rounding on edges, never for a wrong picture.
constexpr double kGoldenMaxDiff = 48.0;  // levels, any channel of any pixel
constexpr double kGoldenMeanDiff = 0.5;  // levels, mean over all channels and pixels
// Share of channel samples off by more than kGoldenMaxDiff before the 3x3 allowance (edges and
// 1-px lines a driver draws a pixel over).
constexpr double kGoldenMovedShare = 0.01;

std::unique_ptr<GlContext> MakeContext(OutputFormat format = OutputFormat::kRgba8) {
  Expected<std::unique_ptr<GlContext>> context = CreateEglContext(cv::Size(kW, kH), format);
  EXPECT_TRUE(context.ok()) << context.status().ToString();
  return context.ok() ? std::move(*context) : nullptr;
}

std::unique_ptr<Renderer> MakeRenderer(GlContext* context, bool distortion,
                                       const RendererOptions& options = {}) {
  const Scene scene = testing::RenderTestScene();
  Expected<std::unique_ptr<Renderer>> renderer = Renderer::Create(context, scene, options);
  EXPECT_TRUE(renderer.ok()) << renderer.status().ToString();
  if (!renderer.ok()) return nullptr;
  Expected<ProjectorView> view =
      PrepareProjectorView(testing::RenderTestProjector(kW, kH, distortion),
                           testing::RenderTestProjectorFromTable(), scene.Bounds());
  EXPECT_TRUE(view.ok()) << view.status().ToString();
  EXPECT_TRUE((*renderer)->SetView(*view).ok());
  return std::move(*renderer);
}

cv::Mat RenderToImage(GlContext* context, Renderer* renderer, const RenderContent& content,
                      FrameStats* stats = nullptr) {
  Expected<FrameStats> rendered = renderer->Render(content);
  EXPECT_TRUE(rendered.ok()) << rendered.status().ToString();
  if (stats && rendered.ok()) *stats = *rendered;
  Expected<cv::Mat> image = context->ReadOutput();
  EXPECT_TRUE(image.ok()) << image.status().ToString();
  return image.ok() ? *image : cv::Mat();
}

void ExpectGolden(const cv::Mat& rgb, const std::string& name) {
  const std::string path = "tests/node/render/golden/" + name + ".png";
  cv::Mat bgr;
  cv::cvtColor(rgb, bgr, cv::COLOR_RGB2BGR);
  const char* update = std::getenv("SANDTABLE_UPDATE_GOLDEN");
  if (update && std::string(update) == "1") {
    ASSERT_TRUE(cv::imwrite(path, bgr)) << path;
    return;
  }
  const cv::Mat golden = cv::imread(path, cv::IMREAD_COLOR);
  ASSERT_FALSE(golden.empty()) << "no golden image " << path
                               << " (SANDTABLE_UPDATE_GOLDEN=1 writes it)";
  ASSERT_EQ(golden.size(), bgr.size()) << path;
  // The largest difference counts a pixel off by its distance to the range of the golden's
  // 3x3 neighbourhood (per channel): another driver's derivatives or rounding move an edge or a
  // thin line by a pixel (NVIDIA's driver against llvmpipe: the grid's lines, 255 levels), never
  // a colour. The pixels off by more than kGoldenMaxDiff without that allowance are bounded too.
  cv::Mat low, high, below, above, off, diff;
  const cv::Mat square = cv::getStructuringElement(cv::MORPH_RECT, cv::Size(3, 3));
  cv::erode(golden, low, square);
  cv::dilate(golden, high, square);
  cv::subtract(low, bgr, below);  // saturates at 0
  cv::subtract(bgr, high, above);
  cv::max(below, above, off);
  double max_diff = 0.0;
  cv::minMaxLoc(off.reshape(1), nullptr, &max_diff);
  cv::absdiff(golden, bgr, diff);
  const double moved_share =
      static_cast<double>(cv::countNonZero(diff.reshape(1) > kGoldenMaxDiff)) / diff.total();
  const cv::Scalar mean = cv::mean(diff);
  const double mean_diff = (mean[0] + mean[1] + mean[2]) / 3.0;
  EXPECT_LE(max_diff, kGoldenMaxDiff) << name;
  EXPECT_LE(mean_diff, kGoldenMeanDiff) << name;
  EXPECT_LE(moved_share, kGoldenMovedShare) << name;
  if (max_diff > kGoldenMaxDiff || mean_diff > kGoldenMeanDiff || moved_share > 0) {
    cv::imwrite(::testing::TempDir() + name + "-rendered.png", bgr);
    std::cout << name << ": off by " << max_diff << " levels at most (3x3 allowance), mean "
              << mean_diff << ", " << 100.0 * moved_share << " % of samples off by more than "
              << kGoldenMaxDiff << " without the allowance\n";
  }
}

// Every 3rd output pixel the table covers: the float output holds the table point that pixel
// shows; the calibrated model must project it back onto the pixel.
double MaxProjectionError_px(bool distortion, bool fold, int* checked) {
  std::unique_ptr<GlContext> context = MakeContext(OutputFormat::kRgba32f);
  if (!context) return 1e9;
  RendererOptions options;
  options.fold_prewarp = fold;
  std::unique_ptr<Renderer> renderer = MakeRenderer(context.get(), distortion, options);
  if (!renderer) return 1e9;
  RenderContent content;
  content.debug_positions = true;
  const cv::Mat positions = RenderToImage(context.get(), renderer.get(), content);
  const CameraModel projector = testing::RenderTestProjector(kW, kH, distortion);
  const Rigid3d projector_from_table = testing::RenderTestProjectorFromTable();
  double worst = 0.0;
  *checked = 0;
  for (int v = 4; v < kH - 4; v += 3) {
    for (int u = 4; u < kW - 4; u += 3) {
      const cv::Vec3f p = positions.at<cv::Vec3f>(v, u);
      // Table pixels only, away from the table's edge and the buildings' outlines (where the
      // pre-warp's bilinear lookup mixes two surfaces).
      if (std::abs(p[2]) > 1e-6 || std::abs(p[0]) > 0.55 || std::abs(p[1]) > 0.35) continue;
      bool near_building = false;
      for (int dv = -2; dv <= 2 && !near_building; ++dv) {
        for (int du = -2; du <= 2; ++du) {
          const cv::Vec3f q = positions.at<cv::Vec3f>(v + dv, u + du);
          // A building, or the background (cleared to 0, 0, 0).
          if (std::abs(q[2]) > 1e-6 || (q[0] == 0.0f && q[1] == 0.0f)) near_building = true;
        }
      }
      if (near_building) continue;
      const std::optional<Eigen::Vector2d> pixel =
          projector.Project(projector_from_table * Eigen::Vector3d(p[0], p[1], p[2]));
      if (!pixel) continue;
      worst = std::max(worst, (*pixel - Eigen::Vector2d(u, v)).norm());
      ++*checked;
    }
  }
  return worst;
}

TEST(RendererTest, GlProjectionPutsTablePointsOnCameraModelPixels) {
  int checked = 0;
  const double pinhole_px = MaxProjectionError_px(/*distortion=*/false, false, &checked);
  EXPECT_GT(checked, 1000);
  EXPECT_LE(pinhole_px, kProjectionTolerance_px);
  // The pre-warp as a pass (the default) and folded into the vertex shader.
  const double warp_pass_px = MaxProjectionError_px(/*distortion=*/true, false, &checked);
  EXPECT_GT(checked, 1000);
  EXPECT_LE(warp_pass_px, kProjectionTolerance_px);
  const double folded_px = MaxProjectionError_px(/*distortion=*/true, true, &checked);
  EXPECT_GT(checked, 1000);
  EXPECT_LE(folded_px, kProjectionTolerance_px);
  std::cout << "max |GL - CameraModel::Project|: pinhole " << pinhole_px
            << " px, distorted with the warp pass " << warp_pass_px << " px, folded " << folded_px
            << " px over " << checked << " pixels\n";
}

TEST(RendererTest, DistortionMapSkippedBelowATenthOfAPixel) {
  const Scene scene = testing::RenderTestScene();
  CameraModel tiny = testing::RenderTestProjector(kW, kH, false);
  tiny.distortion.k1 = 1e-7;
  Expected<ProjectorView> view =
      PrepareProjectorView(tiny, testing::RenderTestProjectorFromTable(), scene.Bounds());
  ASSERT_TRUE(view.ok());
  EXPECT_LT(view->max_displacement_px, kSkipDistortion_px);
  EXPECT_FALSE(view->needs_prewarp());
  view = PrepareProjectorView(testing::RenderTestProjector(kW, kH, true),
                              testing::RenderTestProjectorFromTable(), scene.Bounds());
  ASSERT_TRUE(view.ok());
  EXPECT_GT(view->max_displacement_px, 1.0);
  EXPECT_TRUE(view->needs_prewarp());
}

int CountDifferent(const cv::Mat& a, const cv::Mat& b) {
  cv::Mat diff;
  cv::absdiff(a, b, diff);
  return cv::countNonZero(diff.reshape(1));
}

TEST(RendererTest, RawPatternsAreExact) {
  std::unique_ptr<GlContext> context = MakeContext();
  ASSERT_TRUE(context);
  std::unique_ptr<Renderer> renderer = MakeRenderer(context.get(), true);
  ASSERT_TRUE(renderer);
  RenderContent content;
  content.pattern = TestPattern::kRawWhite;
  cv::Mat image = RenderToImage(context.get(), renderer.get(), content);
  EXPECT_EQ(cv::countNonZero(image.reshape(1) != 255), 0);
  content.pattern = TestPattern::kColourBars;
  image = RenderToImage(context.get(), renderer.get(), content);
  EXPECT_EQ(CountDifferent(image, ColourBarsPattern(image.size())), 0);
  content.pattern = TestPattern::kProjectorId;
  content.projector_id = 7;
  image = RenderToImage(context.get(), renderer.get(), content);
  EXPECT_EQ(CountDifferent(image, ProjectorIdPattern(image.size(), 7)), 0);
  ExpectGolden(image, "pattern-id");
}

TEST(RendererTest, PassesAFrameDoesNotNeedAreSkipped) {
  std::unique_ptr<GlContext> context = MakeContext();
  ASSERT_TRUE(context);
  std::unique_ptr<Renderer> renderer = MakeRenderer(context.get(), /*distortion=*/false);
  ASSERT_TRUE(renderer);
  auto ran = [](const FrameStats& s, Pass p) { return s.ran[static_cast<int>(p)]; };
  RenderContent content;
  FrameStats stats;
  // The show is deferred: the surface cache drawn by the first frame of a view, then only the
  // light pass.
  RenderToImage(context.get(), renderer.get(), content, &stats);
  EXPECT_TRUE(ran(stats, Pass::kScene));
  EXPECT_TRUE(ran(stats, Pass::kLight));
  EXPECT_FALSE(ran(stats, Pass::kWarp)) << "no distortion: the cache is drawn straight";
  EXPECT_FALSE(ran(stats, Pass::kOverlay)) << "no strokes";
  EXPECT_FALSE(ran(stats, Pass::kShadow)) << "no sun";
  EXPECT_EQ(stats.groups_drawn, 3);
  RenderToImage(context.get(), renderer.get(), content, &stats);
  EXPECT_FALSE(ran(stats, Pass::kScene)) << "the surface cache is kept";
  EXPECT_TRUE(ran(stats, Pass::kLight));
  EXPECT_EQ(stats.groups_drawn, 3) << "what the cache holds";
  content.sun_direction_in_table = SunDirection(10.0);
  RenderToImage(context.get(), renderer.get(), content, &stats);
  EXPECT_TRUE(ran(stats, Pass::kShadow));
  RenderToImage(context.get(), renderer.get(), content, &stats);
  EXPECT_FALSE(ran(stats, Pass::kShadow)) << "the sun did not move";
  content.sun_direction_in_table = SunDirection(10.5);
  RenderToImage(context.get(), renderer.get(), content, &stats);
  EXPECT_TRUE(ran(stats, Pass::kShadow));
  ASSERT_TRUE(renderer->SetMask(cv::Mat(kH, kW, CV_32FC1, cv::Scalar(0.5))).ok());
  RenderToImage(context.get(), renderer.get(), content, &stats);
  EXPECT_TRUE(stats.masked) << "a mask, in the light pass";
  EXPECT_FALSE(ran(stats, Pass::kWarp));
  // Not deferred (a test pattern through the pipeline): a mask needs the warp pass.
  content.pattern = TestPattern::kWhite;
  RenderToImage(context.get(), renderer.get(), content, &stats);
  EXPECT_TRUE(ran(stats, Pass::kScene));
  EXPECT_FALSE(ran(stats, Pass::kLight));
  EXPECT_TRUE(ran(stats, Pass::kWarp)) << "a mask";
  content.pattern = TestPattern::kNone;
  // A projector looking away from the model: every group culled, the scene pass skipped.
  const Scene scene = testing::RenderTestScene();
  const Rigid3d away = Rigid3d(Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()).toRotationMatrix(),
                               Eigen::Vector3d::Zero()) *
                       testing::RenderTestProjectorFromTable();
  Expected<ProjectorView> view =
      PrepareProjectorView(testing::RenderTestProjector(kW, kH, false), away, scene.Bounds());
  ASSERT_TRUE(view.ok());
  ASSERT_TRUE(renderer->SetView(*view).ok());
  RenderToImage(context.get(), renderer.get(), content, &stats);
  EXPECT_EQ(stats.groups_drawn, 0);
  EXPECT_EQ(stats.groups_culled, 3);
  EXPECT_FALSE(ran(stats, Pass::kScene));
  EXPECT_TRUE(ran(stats, Pass::kLight)) << "the mask still applies (to black)";
  ASSERT_TRUE(renderer->SetMask(cv::Mat()).ok());
  RenderToImage(context.get(), renderer.get(), content, &stats);
  EXPECT_FALSE(ran(stats, Pass::kLight)) << "nothing in view, no mask: cleared to black";
}

// A point's output pixel (the calibrated model's projection, rounded).
cv::Point PixelOf(const Eigen::Vector3d& x_in_table_m, bool distortion) {
  const std::optional<Eigen::Vector2d> px =
      testing::RenderTestProjector(kW, kH, distortion)
          .Project(testing::RenderTestProjectorFromTable() * x_in_table_m);
  return px ? cv::Point(static_cast<int>(std::lround(px->x())),
                        static_cast<int>(std::lround(px->y())))
            : cv::Point(-1, -1);
}

TEST(RendererTest, StrokesAreHiddenBehindBuildingsAndShownOnSurfaces) {
  std::unique_ptr<GlContext> context = MakeContext();
  ASSERT_TRUE(context);
  std::unique_ptr<Renderer> renderer = MakeRenderer(context.get(), /*distortion=*/true);
  ASSERT_TRUE(renderer);
  RenderContent content;
  content.pattern = TestPattern::kNone;
  // Green stroke on the open table, a magenta one on the table right behind the tower as the
  // projector sees it (the tower stands at (-0.25, -0.1), 0.3 m tall, the projector at
  // (0, -0.9, 1.3): the ray to (-0.29, 0.03, 0) meets the tower 0.18 m up), a blue one on the
  // box's roof.
  Polyline open;
  open.points_in_table_m = {{0.3, -0.25, 0.0}, {0.45, -0.2, 0.0}};
  open.colour = {0.0f, 1.0f, 0.0f};
  open.width_m = 0.02;
  Polyline hidden;
  hidden.points_in_table_m = {{-0.28, 0.0, 0.0}, {-0.3, 0.06, 0.0}};
  hidden.colour = {1.0f, 0.0f, 1.0f};
  hidden.width_m = 0.02;
  Polyline roof;
  roof.points_in_table_m = {{0.08, 0.04, 0.15}, {0.12, 0.06, 0.15}};
  roof.colour = {0.0f, 0.0f, 1.0f};
  roof.width_m = 0.02;
  content.strokes = {open, hidden, roof};
  Marker cursor;
  cursor.position_in_table_m = Eigen::Vector3d(0.35, 0.2, 0.0);
  cursor.ring = true;
  cursor.radius_m = 0.03;
  content.markers = {cursor};
  content.overlay_version = 1;
  FrameStats stats;
  const cv::Mat image = RenderToImage(context.get(), renderer.get(), content, &stats);
  EXPECT_TRUE(stats.ran[static_cast<int>(Pass::kOverlay)]);
  EXPECT_TRUE(stats.overlay_rebuilt);
  auto at = [&](const Eigen::Vector3d& x) {
    const cv::Point p = PixelOf(x, true);
    return image.at<cv::Vec3b>(p);
  };
  EXPECT_EQ(at({0.375, -0.225, 0.0}), cv::Vec3b(0, 255, 0));
  EXPECT_EQ(at({0.10, 0.05, 0.15}), cv::Vec3b(0, 0, 255));
  const cv::Vec3b behind = at({-0.29, 0.03, 0.0});
  EXPECT_NE(behind, cv::Vec3b(255, 0, 255)) << "a stroke shows through the tower";
  // The cursor's ring: yellow at its radius, not at its centre.
  EXPECT_EQ(at({0.35 + 0.85 * 0.03, 0.2, 0.0}), cv::Vec3b(255, 255, 0));
  EXPECT_NE(at({0.35, 0.2, 0.0}), cv::Vec3b(255, 255, 0));
  ExpectGolden(image, "overlay");
  // The same content again: nothing rebuilt.
  RenderToImage(context.get(), renderer.get(), content, &stats);
  EXPECT_FALSE(stats.overlay_rebuilt);
}

// The mask multiplies in linear light: 255 where it is 1, 0.5 encoded with the display's 2.2
// power law (255 x 0.5^(1 / 2.2) = 186.1) where it is 0.5. It lives in the warp's packed texture
// with a pre-warp and in its own without one: it follows the renderer through views with and
// without distortion, and an empty mask drops it.
TEST(RendererTest, MaskMultipliesInLinearLightWithAndWithoutPrewarp) {
  std::unique_ptr<GlContext> context = MakeContext();
  ASSERT_TRUE(context);
  std::unique_ptr<Renderer> renderer = MakeRenderer(context.get(), /*distortion=*/false);
  ASSERT_TRUE(renderer);
  cv::Mat mask(kH, kW, CV_32FC1, cv::Scalar(1.0));
  mask.colRange(0, kW / 2).setTo(0.5);
  ASSERT_TRUE(renderer->SetMask(mask).ok());
  RenderContent content;
  content.pattern = TestPattern::kWhite;
  auto view_of = [](bool distortion) {
    return PrepareProjectorView(testing::RenderTestProjector(kW, kH, distortion),
                                testing::RenderTestProjectorFromTable(),
                                testing::RenderTestScene().Bounds());
  };
  // A table pixel in each half of the output.
  auto expect_halves = [&](bool distortion, uint8_t left_value, const char* step) {
    SCOPED_TRACE(step);
    const cv::Mat image = RenderToImage(context.get(), renderer.get(), content);
    const cv::Point left = PixelOf({-0.4, -0.3, 0.0}, distortion);
    const cv::Point right = PixelOf({0.4, -0.3, 0.0}, distortion);
    ASSERT_LT(left.x, kW / 2);
    ASSERT_GE(right.x, kW / 2);
    EXPECT_EQ(image.at<cv::Vec3b>(right), cv::Vec3b(255, 255, 255));
    EXPECT_NEAR(image.at<cv::Vec3b>(left)[0], left_value, 1);
  };
  expect_halves(false, 186, "the mask set before any pre-warp");
  Expected<ProjectorView> distorted = view_of(true);
  ASSERT_TRUE(distorted.ok());
  ASSERT_TRUE(distorted->needs_prewarp());
  ASSERT_TRUE(renderer->SetView(*distorted).ok());
  expect_halves(true, 186, "a view with a pre-warp takes the mask into its texture");
  mask.colRange(0, kW / 2).setTo(0.25);  // 255 x 0.25^(1 / 2.2) = 136.6
  ASSERT_TRUE(renderer->SetMask(mask).ok());
  expect_halves(true, 137, "a new mask under the pre-warp");
  Expected<ProjectorView> plain = view_of(false);
  ASSERT_TRUE(plain.ok());
  ASSERT_TRUE(renderer->SetView(*plain).ok());
  expect_halves(false, 137, "back to a view without a pre-warp: the mask goes with it");
  ASSERT_TRUE(renderer->SetMask(cv::Mat()).ok());
  expect_halves(false, 255, "an empty mask drops it");
  ASSERT_TRUE(renderer->SetView(*distorted).ok());
  expect_halves(true, 255, "and a pre-warp after it has none");
}

// A mask swapped in after a frame: the warp pass alone over the last frame (or, for a deferred
// frame, the mask over the frame the light pass and the overlay kept before their mask) shows what
// a whole new frame with that mask shows; nothing to warp before a frame or after a new view.
TEST(RendererTest, RewarpShowsTheLastFrameUnderANewMask) {
  std::unique_ptr<GlContext> context = MakeContext();
  ASSERT_TRUE(context);
  for (const bool deferred : {false, true}) {
    SCOPED_TRACE(deferred ? "deferred" : "warp pass");
    RendererOptions options;
    options.deferred = deferred;
    std::unique_ptr<Renderer> renderer = MakeRenderer(context.get(), /*distortion=*/true, options);
    ASSERT_TRUE(renderer);
    EXPECT_FALSE(renderer->CanRewarp());
    EXPECT_EQ(renderer->Rewarp().status().code(), StatusCode::kUnavailable);
    RenderContent content;
    content.sun_direction_in_table = SunDirection(10.0);
    Polyline stroke;
    stroke.points_in_table_m = {{-0.4, -0.25, 0.0}, {0.4, -0.2, 0.0}};
    stroke.colour = {0.0f, 1.0f, 0.0f};
    stroke.width_m = 0.02;
    content.strokes = {stroke};
    content.overlay_version = 1;
    const cv::Mat before = RenderToImage(context.get(), renderer.get(), content);
    ASSERT_TRUE(renderer->CanRewarp()) << "distortion: the frame went through the warp pass";
    cv::Mat mask(kH, kW, CV_32FC1, cv::Scalar(1.0));
    mask.colRange(0, kW / 2).setTo(0.25);
    ASSERT_TRUE(renderer->SetMask(mask).ok());
    Expected<FrameStats> rewarped = renderer->Rewarp();
    ASSERT_TRUE(rewarped.ok()) << rewarped.status().ToString();
    EXPECT_TRUE(rewarped->ran[static_cast<int>(Pass::kWarp)])
        << "one full-screen pass: the warp pass, or for a deferred frame the mask over the frame "
           "the light pass kept before its mask";
    EXPECT_FALSE(rewarped->ran[static_cast<int>(Pass::kLight)]);
    EXPECT_FALSE(rewarped->ran[static_cast<int>(Pass::kOverlay)])
        << "the stroke is in the kept frame";
    EXPECT_FALSE(rewarped->ran[static_cast<int>(Pass::kScene)]);
    Expected<cv::Mat> fast = context->ReadOutput();
    ASSERT_TRUE(fast.ok());
    const cv::Mat full = RenderToImage(context.get(), renderer.get(), content);
    // Deferred, the kept frame is 8-bit before the mask (the whole frame masks the light pass's
    // float colour): half a level before a factor <= 1, at most one level after rounding.
    const double tolerance_levels = deferred ? 1.0 : 0.0;
    EXPECT_LE(cv::norm(*fast, full, cv::NORM_INF), tolerance_levels)
        << "the same frame under the same mask";
    EXPECT_GT(cv::norm(before, full, cv::NORM_INF), 50.0) << "the mask changed the frame";
  }
  std::unique_ptr<Renderer> renderer = MakeRenderer(context.get(), /*distortion=*/true);
  ASSERT_TRUE(renderer);
  RenderContent content;
  RenderToImage(context.get(), renderer.get(), content);
  ASSERT_TRUE(renderer->CanRewarp());
  Expected<ProjectorView> view = PrepareProjectorView(testing::RenderTestProjector(kW, kH, true),
                                                      testing::RenderTestProjectorFromTable(),
                                                      testing::RenderTestScene().Bounds());
  ASSERT_TRUE(view.ok());
  ASSERT_TRUE(renderer->SetView(*view).ok());
  EXPECT_FALSE(renderer->CanRewarp()) << "the ideal image is of the old view";
  content.pattern = TestPattern::kColourBars;
  RenderToImage(context.get(), renderer.get(), content);
  EXPECT_FALSE(renderer->CanRewarp()) << "a raw pattern does not go through the warp pass";
}

// Prepared masks (a re-blend's mask made ahead of time): UseMask shows exactly what SetMask of
// the same mask shows, the other prepared masks go with it, a new view drops them, and the mask
// used survives a view change (its texels are kept for the next view).
TEST(RendererTest, APreparedMaskShowsWhatSetMaskShows) {
  std::unique_ptr<GlContext> context = MakeContext();
  ASSERT_TRUE(context);
  cv::Mat left_half(kH, kW, CV_32FC1, cv::Scalar(1.0)), right_half(kH, kW, CV_32FC1);
  left_half.colRange(0, kW / 2).setTo(0.25);
  for (int u = 0; u < kW; ++u) right_half.col(u).setTo(u < kW / 2 ? 1.0 : 0.2 + 0.5 * u / kW);
  cv::Mat lift(kH, kW, CV_32FC1, cv::Scalar(0.0)), with_lift;
  lift.rowRange(0, kH / 2).setTo(0.02);
  cv::merge(std::vector<cv::Mat>{right_half, lift}, with_lift);
  for (const bool distortion : {false, true}) {
    for (const bool deferred : {false, true}) {
      SCOPED_TRACE(std::string(distortion ? "pre-warp" : "no pre-warp") +
                   (deferred ? ", deferred" : ", forward"));
      RendererOptions options;
      options.deferred = deferred;
      std::unique_ptr<Renderer> renderer = MakeRenderer(context.get(), distortion, options);
      ASSERT_TRUE(renderer);
      RenderContent content;
      content.sun_direction_in_table = SunDirection(10.0);
      ASSERT_TRUE(renderer->SetMask(left_half).ok());
      RenderToImage(context.get(), renderer.get(), content);
      EXPECT_EQ(renderer->UseMask(7).code(), StatusCode::kNotFound);
      ASSERT_TRUE(renderer->PrepareMask(1, right_half).ok());
      ASSERT_TRUE(renderer->PrepareMask(2, with_lift).ok());
      EXPECT_TRUE(renderer->HasPreparedMask(1) && renderer->HasPreparedMask(2));
      for (const bool use_lift : {false, true}) {
        SCOPED_TRACE(use_lift ? "with a lift" : "factor alone");
        const cv::Mat& mask = use_lift ? with_lift : right_half;
        if (use_lift) {
          ASSERT_TRUE(renderer->PrepareMask(2, with_lift).ok());
        }
        ASSERT_TRUE(renderer->UseMask(use_lift ? 2 : 1).ok());
        EXPECT_FALSE(renderer->HasPreparedMask(1) || renderer->HasPreparedMask(2))
            << "the others were made for the blend before";
        ASSERT_TRUE(renderer->CanRewarp());
        ASSERT_TRUE(renderer->Rewarp().ok());
        Expected<cv::Mat> used = context->ReadOutput();
        ASSERT_TRUE(used.ok());
        const cv::Mat used_full = RenderToImage(context.get(), renderer.get(), content);
        ASSERT_TRUE(renderer->SetMask(mask).ok());
        ASSERT_TRUE(renderer->Rewarp().ok());
        Expected<cv::Mat> set = context->ReadOutput();
        ASSERT_TRUE(set.ok());
        EXPECT_EQ(cv::norm(*used, *set, cv::NORM_INF), 0.0) << "the same mask, swapped in";
        EXPECT_EQ(cv::norm(used_full, RenderToImage(context.get(), renderer.get(), content),
                           cv::NORM_INF),
                  0.0)
            << "and in the next whole frame";
        // Back to the first mask for the next round.
        ASSERT_TRUE(renderer->SetMask(left_half).ok());
        ASSERT_TRUE(renderer->PrepareMask(1, right_half).ok());
      }
      // A new view drops the prepared masks; the mask in use goes on under the new view.
      ASSERT_TRUE(renderer->UseMask(1).ok());
      ASSERT_TRUE(renderer->PrepareMask(3, left_half).ok());
      Expected<ProjectorView> other = PrepareProjectorView(
          testing::RenderTestProjector(kW, kH, !distortion),
          testing::RenderTestProjectorFromTable(), testing::RenderTestScene().Bounds());
      ASSERT_TRUE(other.ok());
      ASSERT_TRUE(renderer->SetView(*other).ok());
      EXPECT_FALSE(renderer->HasPreparedMask(3)) << "made for the old view";
      const cv::Mat after_use = RenderToImage(context.get(), renderer.get(), content);
      ASSERT_TRUE(renderer->SetMask(right_half).ok());
      EXPECT_EQ(
          cv::norm(after_use, RenderToImage(context.get(), renderer.get(), content), cv::NORM_INF),
          0.0)
          << "the mask used, carried into the new view";
    }
  }
  std::unique_ptr<Renderer> renderer = MakeRenderer(context.get(), true);
  ASSERT_TRUE(renderer);
  EXPECT_EQ(renderer->PrepareMask(1, cv::Mat()).code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(renderer->PrepareMask(1, cv::Mat(kH, kW / 2, CV_32FC1)).code(),
            StatusCode::kInvalidArgument);
}

// Black-level matching: a (factor, lift) mask adds the lift in linear light after the factor,
// in the pre-warp pass and folded into the scene pass alike; "black" through the pipeline shows
// the lift alone.
TEST(RendererTest, MaskLiftAddsInLinearLight) {
  std::unique_ptr<GlContext> context = MakeContext();
  ASSERT_TRUE(context);
  for (const bool fold : {false, true}) {
    SCOPED_TRACE(fold ? "folded" : "pre-warp pass");
    RendererOptions options;
    options.fold_prewarp = fold;
    std::unique_ptr<Renderer> renderer = MakeRenderer(context.get(), /*distortion=*/false, options);
    ASSERT_TRUE(renderer);
    cv::Mat factor(kH, kW, CV_32FC1, cv::Scalar(0.5)), lift(kH, kW, CV_32FC1, cv::Scalar(0.0));
    lift.colRange(0, kW / 2).setTo(0.01);
    cv::Mat mask;
    cv::merge(std::vector<cv::Mat>{factor, lift}, mask);
    ASSERT_TRUE(renderer->SetMask(mask).ok());
    const cv::Point left = PixelOf({-0.4, -0.3, 0.0}, false);
    const cv::Point right = PixelOf({0.4, -0.3, 0.0}, false);
    ASSERT_LT(left.x, kW / 2);
    ASSERT_GE(right.x, kW / 2);
    RenderContent content;
    content.pattern = TestPattern::kWhite;
    cv::Mat image = RenderToImage(context.get(), renderer.get(), content);
    // 255 (0.5 + 0.01)^(1 / 2.2) = 188.1 with the lift, 255 x 0.5^(1 / 2.2) = 186.1 without.
    EXPECT_NEAR(image.at<cv::Vec3b>(left)[0], 188, 1);
    EXPECT_NEAR(image.at<cv::Vec3b>(right)[0], 186, 1);
    content.pattern = TestPattern::kBlack;
    image = RenderToImage(context.get(), renderer.get(), content);
    // 255 x 0.01^(1 / 2.2) = 31.7; no lift: 0.
    EXPECT_NEAR(image.at<cv::Vec3b>(left)[0], 32, 1);
    EXPECT_EQ(image.at<cv::Vec3b>(right), cv::Vec3b(0, 0, 0));
    // A mask without a lift again: no lift anywhere.
    ASSERT_TRUE(renderer->SetMask(factor).ok());
    image = RenderToImage(context.get(), renderer.get(), content);
    EXPECT_EQ(image.at<cv::Vec3b>(left), cv::Vec3b(0, 0, 0));
  }
}

// The deferred show against the forward one (every frame's scene and warp pass): the same picture
// but on outlines, where the cache takes the nearest ideal pixel's surface instead of blending
// two, and on the overlay's edges, drawn straight into output pixels instead of resampled. With
// and without a pre-warp; sun and shadows, strokes hidden behind the tower, a mask with a lift.
// The cache is kept between frames and drawn anew for a new view.
// (Without the shadow lookup, 2-3 % of the pixels are off by more than kDeferredPixelDiff.)
constexpr double kDeferredMeanDiff = 0.5;   // levels, mean over all channels and pixels
constexpr double kDeferredPixelDiff = 3.0;  // levels: rounding of the cached colour
// Pixels off by more than kDeferredPixelDiff: none but rounding without a pre-warp, the outlines
// with one (0.3-0.7 % measured).
constexpr double kDeferredOffShare = 0.001;
constexpr double kDeferredOffSharePrewarp = 0.01;

TEST(RendererTest, DeferredShowMatchesTheForwardPasses) {
  std::unique_ptr<GlContext> context = MakeContext();
  ASSERT_TRUE(context);
  for (const bool distortion : {false, true}) {
    SCOPED_TRACE(distortion ? "with a pre-warp" : "without a pre-warp");
    RendererOptions forward_options;
    forward_options.deferred = false;
    std::unique_ptr<Renderer> forward = MakeRenderer(context.get(), distortion, forward_options);
    std::unique_ptr<Renderer> deferred = MakeRenderer(context.get(), distortion);
    ASSERT_TRUE(forward && deferred);
    cv::Mat factor(kH, kW, CV_32FC1), lift(kH, kW, CV_32FC1, cv::Scalar(0.0));
    for (int u = 0; u < kW; ++u) factor.col(u).setTo(0.3 + 0.7 * u / kW);
    lift.rowRange(0, kH / 2).setTo(0.02);
    cv::Mat mask;
    cv::merge(std::vector<cv::Mat>{factor, lift}, mask);
    RenderContent content;
    Polyline hidden;  // behind the tower (see StrokesAreHiddenBehindBuildingsAndShownOnSurfaces)
    hidden.points_in_table_m = {{-0.28, 0.0, 0.0}, {-0.3, 0.06, 0.0}};
    hidden.colour = {1.0f, 0.0f, 1.0f};
    hidden.width_m = 0.02;
    Polyline open;
    open.points_in_table_m = {{0.3, -0.25, 0.0}, {0.45, -0.2, 0.0}};
    open.colour = {0.0f, 1.0f, 0.0f};
    open.width_m = 0.02;
    auto compare = [&](const char* step) {
      SCOPED_TRACE(step);
      FrameStats stats;
      const cv::Mat want = RenderToImage(context.get(), forward.get(), content);
      const cv::Mat got = RenderToImage(context.get(), deferred.get(), content, &stats);
      EXPECT_TRUE(stats.ran[static_cast<int>(Pass::kLight)]);
      cv::Mat diff;
      cv::absdiff(want, got, diff);
      const cv::Scalar mean = cv::mean(diff);
      EXPECT_LE((mean[0] + mean[1] + mean[2]) / 3.0, kDeferredMeanDiff);
      cv::Mat channels[3];
      cv::split(diff, channels);
      const cv::Mat worst = cv::max(cv::max(channels[0], channels[1]), channels[2]);
      const double share = cv::countNonZero(worst > kDeferredPixelDiff) / double(kW * kH);
      EXPECT_LE(share, distortion ? kDeferredOffSharePrewarp : kDeferredOffShare);
      std::cout << "deferred against forward, " << (distortion ? "pre-warp, " : "") << step
                << ": mean " << (mean[0] + mean[1] + mean[2]) / 3.0 << " levels, " << 100.0 * share
                << " % of pixels off by more than " << kDeferredPixelDiff << "\n";
      EXPECT_GT(cv::norm(got, cv::NORM_INF), 100.0) << "a picture, not black";
      return got;
    };
    compare("unlit");
    content.sun_direction_in_table = SunDirection(9.0);
    const cv::Mat lit = compare("sun and shadows");
    content.sun_direction_in_table = SunDirection(15.5);
    const cv::Mat later = compare("the sun moved");
    EXPECT_GT(cv::norm(lit, later, cv::NORM_INF), 50.0) << "the light follows the sun";
    content.strokes = {hidden, open};
    content.overlay_version = 1;
    const cv::Mat stroked = compare("strokes");
    const cv::Point behind = PixelOf({-0.29, 0.03, 0.0}, distortion);
    EXPECT_NE(stroked.at<cv::Vec3b>(behind), cv::Vec3b(255, 0, 255)) << "through the tower";
    EXPECT_EQ(stroked.at<cv::Vec3b>(PixelOf({0.375, -0.225, 0.0}, distortion)),
              cv::Vec3b(0, 255, 0));
    ASSERT_TRUE(forward->SetMask(mask).ok());
    ASSERT_TRUE(deferred->SetMask(mask).ok());
    compare("a mask with a lift");
    // A new view (the same pose): the cache is drawn again, then kept.
    Expected<ProjectorView> view = PrepareProjectorView(
        testing::RenderTestProjector(kW, kH, distortion), testing::RenderTestProjectorFromTable(),
        testing::RenderTestScene().Bounds());
    ASSERT_TRUE(view.ok());
    ASSERT_TRUE(deferred->SetView(*view).ok());
    FrameStats stats;
    RenderToImage(context.get(), deferred.get(), content, &stats);
    EXPECT_TRUE(stats.ran[static_cast<int>(Pass::kScene)]);
    EXPECT_EQ(stats.ran[static_cast<int>(Pass::kWarp)], distortion);
    RenderToImage(context.get(), deferred.get(), content, &stats);
    EXPECT_FALSE(stats.ran[static_cast<int>(Pass::kScene)]);
    EXPECT_FALSE(stats.ran[static_cast<int>(Pass::kWarp)]);
  }
}

TEST(RendererTest, GoldenImagesOfEachPass) {
  std::unique_ptr<GlContext> context = MakeContext();
  ASSERT_TRUE(context);
  {
    std::unique_ptr<Renderer> renderer = MakeRenderer(context.get(), /*distortion=*/false);
    ASSERT_TRUE(renderer);
    RenderContent content;
    ExpectGolden(RenderToImage(context.get(), renderer.get(), content), "scene");
    content.sun_direction_in_table = SunDirection(9.0);
    ExpectGolden(RenderToImage(context.get(), renderer.get(), content), "scene-sun");
    content.pattern = TestPattern::kTableGrid;
    ExpectGolden(RenderToImage(context.get(), renderer.get(), content), "grid");
  }
  // The grid through a left-to-right mask ramp and the distortion pre-warp: as a pass, and
  // folded into the scene pass (the same picture).
  for (const bool fold : {false, true}) {
    RendererOptions options;
    options.fold_prewarp = fold;
    std::unique_ptr<Renderer> renderer = MakeRenderer(context.get(), /*distortion=*/true, options);
    ASSERT_TRUE(renderer);
    cv::Mat mask(kH, kW, CV_32FC1);
    for (int u = 0; u < kW; ++u) mask.col(u).setTo(std::min(1.0, 2.0 * u / kW));
    ASSERT_TRUE(renderer->SetMask(mask).ok());
    RenderContent content;
    content.pattern = TestPattern::kTableGrid;
    ExpectGolden(RenderToImage(context.get(), renderer.get(), content),
                 fold ? "folded-mask-grid" : "warp-mask-grid");
  }
}

// The EGL device platform (the back-end NVIDIA's driver offers without a display server),
// forced on Mesa's software device: the same golden picture as the surfaceless platform.
TEST(RendererTest, TheEglDevicePlatformDrawsTheSamePicture) {
  ASSERT_EQ(setenv("SANDTABLE_EGL_PLATFORM", "device", 1), 0);
  Expected<std::unique_ptr<GlContext>> context = CreateEglContext(cv::Size(kW, kH));
  ASSERT_EQ(unsetenv("SANDTABLE_EGL_PLATFORM"), 0);
  ASSERT_TRUE(context.ok()) << context.status().ToString();
  EXPECT_EQ((*context)->description().rfind("EGL device", 0), 0u) << (*context)->description();
  std::unique_ptr<Renderer> renderer = MakeRenderer(context->get(), /*distortion=*/false);
  ASSERT_TRUE(renderer);
  RenderContent content;
  ExpectGolden(RenderToImage(context->get(), renderer.get(), content), "scene");
  content.pattern = TestPattern::kProjectorId;
  content.projector_id = 7;
  const cv::Mat image = RenderToImage(context->get(), renderer.get(), content);
  EXPECT_EQ(CountDifferent(image, ProjectorIdPattern(image.size(), 7)), 0);
  content.pattern = TestPattern::kTableGrid;
  ExpectGolden(RenderToImage(context->get(), renderer.get(), content), "grid");
}

TEST(RendererTest, RefusesAViewOfAnotherSizeAndABadMask) {
  std::unique_ptr<GlContext> context = MakeContext();
  ASSERT_TRUE(context);
  std::unique_ptr<Renderer> renderer = MakeRenderer(context.get(), false);
  ASSERT_TRUE(renderer);
  const Scene scene = testing::RenderTestScene();
  Expected<ProjectorView> view =
      PrepareProjectorView(testing::RenderTestProjector(640, 400, false),
                           testing::RenderTestProjectorFromTable(), scene.Bounds());
  ASSERT_TRUE(view.ok());
  const Status refused = renderer->SetView(*view);
  EXPECT_EQ(refused.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(refused.message().find("640x400"), std::string::npos) << refused.message();
  EXPECT_EQ(renderer->SetMask(cv::Mat(10, 10, CV_32FC1)).code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(renderer->SetMask(cv::Mat(kH, kW, CV_32FC3)).code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(CreateEglContext(cv::Size(0, 10)).status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace sandtable::node
