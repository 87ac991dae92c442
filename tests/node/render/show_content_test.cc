// What the show puts on the model at a media time (node/render/show_content.h) and the render
// loop driving a projector (node/render/render_loop.h) on llvmpipe.
#include "node/render/show_content.h"

#include <atomic>
#include <map>
#include <thread>
#include <utility>

#include <gtest/gtest.h>

#include "common/scene/procedural_scene.h"
#include "node/render/render_loop.h"
#include "tests/node/render/render_test_scene.h"

namespace sandtable::node {
namespace {

constexpr double kTolerance_m = 1e-9;

// Track 7 walks along y = 0.05 from x = 0 to 1 m in 10 s, a sample a second.
cluster::PersonnelTracks Walker() {
  std::string csv = "track_id,t_s,x_m,y_m,z_m\n";
  for (int t = 0; t <= 10; ++t)
    csv += "7," + std::to_string(t) + "," + std::to_string(0.1 * t) + ",0.05,0\n";
  Expected<cluster::PersonnelTracks> tracks = cluster::PersonnelTracks::Parse(csv, "walker.csv");
  EXPECT_TRUE(tracks.ok()) << tracks.status().ToString();
  return *tracks;
}

TEST(ShowContentTest, TracesRunUpToTheMediaTimeAndAreDrapedOnRoofs) {
  // A box 0.2 m tall over x in [0.4, 0.6]: the walker crosses its roof.
  Scene scene =
      MakeBoxMesh(Eigen::Vector3d(0.5, 0.05, 0.0), Eigen::Vector3d(0.2, 0.2, 0.2), 0.0, 0);
  scene.materials.resize(1);
  const std::vector<DrapedTrack> draped = DrapeTracks(Walker(), &scene, 0.0);
  ASSERT_EQ(draped.size(), 1u);
  ShowInputs inputs;
  inputs.tracks = std::make_shared<const std::vector<DrapedTrack>>(draped);
  inputs.sun.enabled = false;
  // At 5 s the head is half way, over the box: on its roof.
  RenderContent at5 = BuildContent(inputs, 5.0);
  ASSERT_EQ(at5.traces.size(), 1u);
  ASSERT_EQ(at5.markers.size(), 1u);
  EXPECT_NEAR(at5.markers[0].position_in_table_m.x(), 0.5, kTolerance_m);
  EXPECT_NEAR(at5.markers[0].position_in_table_m.z(), 0.2, 1e-6);
  // Samples 0..5 (the head is sample 5), draped: on the table before the box, on its roof after.
  ASSERT_EQ(at5.traces[0].points_in_table_m.size(), 7u);
  EXPECT_NEAR(at5.traces[0].points_in_table_m[2].z(), 0.0, 1e-6);
  EXPECT_FALSE(at5.sun_direction_in_table.has_value());
  // Later, the trace is longer and the overlay's version changes; the same time, the same one.
  RenderContent at9 = BuildContent(inputs, 9.0);
  EXPECT_NE(at9.overlay_version, at5.overlay_version);
  EXPECT_EQ(BuildContent(inputs, 9.0).overlay_version, at9.overlay_version);
  // Before the track starts: nothing drawn.
  EXPECT_TRUE(BuildContent(inputs, -1.0).traces.empty());
}

TEST(ShowContentTest, SunFollowsTheTimeOfDay) {
  ShowInputs inputs;
  inputs.sun.start_hour = 6.0;
  inputs.sun.hours_per_media_s = 1.0;
  // 12 h: due south (-y), at the highest elevation; 18 h: west, on the horizon.
  const Eigen::Vector3d noon = *BuildContent(inputs, 6.0).sun_direction_in_table;
  EXPECT_NEAR(noon.x(), 0.0, 1e-9);
  EXPECT_LT(noon.y(), 0.0);
  EXPECT_NEAR(std::asin(noon.z()) * 180.0 / M_PI, inputs.sun.max_elevation_deg, 1e-9);
  const Eigen::Vector3d dusk = *BuildContent(inputs, 12.0).sun_direction_in_table;
  EXPECT_NEAR(dusk.x(), -1.0, 1e-9);
  EXPECT_NEAR(dusk.z(), 0.0, 1e-9);
}

// A projector that keeps what it is shown (the world's and the window's outputs are tested in
// node/devices; here only what the loop gives them matters).
class KeptFrames : public ProjectorOutput {
 public:
  explicit KeptFrames(cv::Size size) : size_(size) {}
  cv::Size size() const override { return size_; }
  std::string description() const override { return "kept frames"; }
  Expected<ShownFrame> Show(const cv::Mat& frame) override {
    ST_RETURN_IF_ERROR(CheckProjectorFrame(frame, size_, description()));
    std::lock_guard<std::mutex> lock(mutex_);
    last_ = frame.clone();
    ShownFrame shown;
    shown.frame_index = ++count_;
    shown.shown_time = DeviceClock::now();
    return shown;
  }
  uint64_t count() {
    std::lock_guard<std::mutex> lock(mutex_);
    return count_;
  }
  cv::Mat last() {
    std::lock_guard<std::mutex> lock(mutex_);
    return last_.clone();
  }

 private:
  cv::Size size_;
  std::mutex mutex_;
  cv::Mat last_;
  uint64_t count_ = 0;
};

UnitCalibration TestCalibration() {
  UnitCalibration c;
  c.projector = testing::RenderTestProjector(320, 200, true);
  c.camera = c.projector;
  c.table_from_projector = testing::RenderTestProjectorFromTable().Inverse();
  c.table_from_model = Rigid3d::Identity();
  return c;
}

// A loop on the test scene at up to 200 frames a second.
Expected<std::unique_ptr<RenderLoop>> StartTestLoop(KeptFrames* projector, int floor_samples) {
  auto model = std::make_shared<const Scene>(testing::RenderTestScene());
  RenderLoopOptions options;
  options.max_fps = 200.0;
  options.floor_samples = floor_samples;
  return RenderLoop::Start(projector, model, options);
}

// The brightest green code of a frame (-1 for none).
double Brightest(const cv::Mat& frame) {
  if (frame.empty()) return -1.0;
  cv::Mat grey;
  cv::extractChannel(frame, grey, 1);
  double lo = 0, hi = 0;
  cv::minMaxLoc(grey, &lo, &hi);
  return hi;
}

TEST(RenderLoopTest, DrawsOnChangeOnlyAndStepsAsideForCalibration) {
  KeptFrames projector(cv::Size(320, 200));
  Expected<std::unique_ptr<RenderLoop>> loop = StartTestLoop(&projector, 3);
  ASSERT_TRUE(loop.ok()) << loop.status().ToString();
  // Nothing before a calibration.
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  EXPECT_EQ(projector.count(), 0u);
  ASSERT_TRUE((*loop)->ShowCalibration(TestCalibration()).ok());
  EXPECT_GE(projector.count(), 1u);
  // A static show is not drawn again.
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  const uint64_t settled = projector.count();
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  EXPECT_EQ(projector.count(), settled);
  // A pattern change is drawn: raw white.
  ShowInputs inputs;
  inputs.pattern = TestPattern::kRawWhite;
  (*loop)->SetInputs(inputs);
  for (int i = 0; i < 100 && projector.count() == settled; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  ASSERT_GT(projector.count(), settled);
  cv::Mat white = projector.last();
  EXPECT_EQ(cv::countNonZero(white.reshape(1) != 255), 0);
  // A playing timeline draws continuously (the sun moves 30 degrees a second: every frame
  // differs); suspended, nothing is shown.
  TimelineView playing;
  playing.known = true;
  playing.playing = true;
  playing.rate = 1.0;
  playing.duration_s = 100.0;
  playing.anchor_coordinator_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                                      std::chrono::steady_clock::now().time_since_epoch())
                                      .count();
  inputs.pattern = TestPattern::kNone;
  inputs.sun.hours_per_media_s = 2.0;
  (*loop)->SetInputs(inputs);
  (*loop)->SetTimeline(playing);
  std::this_thread::sleep_for(std::chrono::milliseconds(400));
  const uint64_t before = projector.count();
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  EXPECT_GT(projector.count(), before + 1);
  (*loop)->Suspend();
  const uint64_t suspended = projector.count();
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  EXPECT_EQ(projector.count(), suspended);
  // A mask (a neighbour's join blanking the left half) is shown once the loop resumes.
  (*loop)->Resume();
  cv::Mat mask(200, 320, CV_8UC1, cv::Scalar(255));
  mask.colRange(0, 160).setTo(0);
  ASSERT_TRUE((*loop)->ShowMask(mask).ok());
  const cv::Mat blanked = projector.last();
  EXPECT_EQ(cv::countNonZero(blanked.colRange(0, 160).reshape(1)), 0);
  EXPECT_GT(cv::countNonZero(blanked.colRange(160, 320).reshape(1)), 0);
  const RenderSummary summary = (*loop)->Summary();
  EXPECT_GT(summary.frames_shown, 3u);
  EXPECT_EQ(summary.frames_failed, 0u);
  EXPECT_GT(summary.floor_ms, 0.0);
  EXPECT_GT(summary.frame_ms_p50, 0.0);
  EXPECT_GT(summary.first_frame_ms, 0.0);  // kept apart from the percentiles
}

// A blend factor of 0.5 on white, on a 2.2 display.
constexpr int kHalfCode = 186;     // 255 x 0.5^(1 / 2.2)
constexpr int kCodeTolerance = 2;  // 8-bit rounding, the mask's 16-bit texture

// A loop showing white through the pipeline with the test calibration.
Expected<std::unique_ptr<RenderLoop>> StartWhiteLoop(KeptFrames* projector) {
  Expected<std::unique_ptr<RenderLoop>> loop = StartTestLoop(projector, 0);
  if (!loop.ok()) return loop;
  ST_RETURN_IF_ERROR((*loop)->ShowCalibration(TestCalibration()));
  ShowInputs inputs;
  inputs.pattern = TestPattern::kWhite;
  (*loop)->SetInputs(inputs);
  return loop;
}

// A blend posted while calibration holds the projector (the loop suspended) is not waited for:
// the caller, on the node's one worker, gets UNAVAILABLE at once instead of holding the worker
// for the timeout while the round's steps queue behind it; the blend shows once the loop resumes.
TEST(RenderLoopTest, ABlendPostedWhileSuspendedAnswersAtOnceAndShowsOnResume) {
  // Far under the 10 s the wait would last; far over a loaded machine's scheduling.
  constexpr auto kAtOnce = std::chrono::milliseconds(2000);
  KeptFrames projector(cv::Size(320, 200));
  Expected<std::unique_ptr<RenderLoop>> loop = StartWhiteLoop(&projector);
  ASSERT_TRUE(loop.ok()) << loop.status().ToString();
  (*loop)->Suspend();
  const auto start = std::chrono::steady_clock::now();
  const cv::Mat half(200, 320, CV_32FC1, cv::Scalar(0.5));
  Expected<int64_t> shown = (*loop)->ShowBlend(half, cv::Mat(), std::chrono::seconds(10));
  EXPECT_FALSE(shown.ok());
  EXPECT_EQ(shown.status().code(), StatusCode::kUnavailable);
  EXPECT_LT(std::chrono::steady_clock::now() - start, kAtOnce);
  (*loop)->Resume();
  for (int i = 0; i < 200; ++i) {
    if (std::abs(Brightest(projector.last()) - kHalfCode) <= kCodeTolerance) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  EXPECT_NEAR(Brightest(projector.last()), kHalfCode, kCodeTolerance);
}

// The blend's factor multiplies white in linear light (a 2.2 display: 0.5 shows as 186), the
// join's blanking multiplies it, and a new calibration drops the blend (it was computed for the
// old one) but keeps the blanking.
TEST(RenderLoopTest, BlendMaskComposesWithTheBlankingAndDropsWithANewCalibration) {
  KeptFrames projector(cv::Size(320, 200));
  Expected<std::unique_ptr<RenderLoop>> loop = StartWhiteLoop(&projector);
  ASSERT_TRUE(loop.ok()) << loop.status().ToString();
  const cv::Mat half(200, 320, CV_32FC1, cv::Scalar(0.5));
  Expected<int64_t> shown = (*loop)->ShowBlend(half);
  ASSERT_TRUE(shown.ok()) << shown.status().ToString();
  EXPECT_GT(*shown, 0);
  EXPECT_NEAR(Brightest(projector.last()), kHalfCode, kCodeTolerance);
  cv::Mat blank(200, 320, CV_8UC1, cv::Scalar(255));
  blank.colRange(0, 160).setTo(0);
  ASSERT_TRUE((*loop)->ShowMask(blank).ok());
  cv::Mat both = projector.last();
  EXPECT_EQ(cv::countNonZero(both.colRange(0, 160).reshape(1)), 0);
  EXPECT_NEAR(Brightest(both.colRange(160, 320)), kHalfCode, kCodeTolerance);
  ASSERT_TRUE((*loop)->ShowCalibration(TestCalibration()).ok());
  const cv::Mat recalibrated = projector.last();
  EXPECT_EQ(cv::countNonZero(recalibrated.colRange(0, 160).reshape(1)), 0);
  EXPECT_EQ(Brightest(recalibrated.colRange(160, 320)), 255);
  EXPECT_FALSE((*loop)->ShowBlend(cv::Mat(200, 320, CV_8UC1)).ok());  // not a factor
}

// Strokes being painted when a new mask comes (a neighbour left mid-annotation): the frame
// already drawn goes out under the mask at once (the warp pass alone), and the new strokes
// follow in the next whole frame. A new pattern is drawn whole (DrawsOnChangeOnly...).
TEST(RenderLoopTest, NewStrokesDoNotHoldBackANewMask) {
  KeptFrames projector(cv::Size(320, 200));
  auto model = std::make_shared<const Scene>(testing::RenderTestScene());
  RenderLoopOptions options;
  options.max_fps = 2.0;  // a whole frame waits 0.5 s for its turn; a mask does not
  Expected<std::unique_ptr<RenderLoop>> loop = RenderLoop::Start(&projector, model, options);
  ASSERT_TRUE(loop.ok()) << loop.status().ToString();
  const UnitCalibration calibration = TestCalibration();
  ASSERT_TRUE((*loop)->ShowCalibration(calibration).ok());
  // Where a table point shows on the projector (the test scene leaves both in view).
  auto pixel_of = [&](const Eigen::Vector3d& x_in_table_m) {
    const std::optional<Eigen::Vector2d> p =
        calibration.projector.Project(testing::RenderTestProjectorFromTable() * x_in_table_m);
    EXPECT_TRUE(p.has_value());
    return p ? cv::Point(static_cast<int>(std::lround(p->x())),
                         static_cast<int>(std::lround(p->y())))
             : cv::Point(0, 0);
  };
  const Eigen::Vector3d a_in_table_m(-0.4, -0.3, 0.0), b_in_table_m(0.4, -0.3, 0.0);
  auto stroke_at = [](const Eigen::Vector3d& centre, const Eigen::Vector3f& colour) {
    Polyline line;
    line.points_in_table_m = {centre - Eigen::Vector3d(0.03, 0, 0),
                              centre + Eigen::Vector3d(0.03, 0, 0)};
    line.colour = colour;
    line.width_m = 0.04;
    return std::make_shared<const std::vector<Polyline>>(std::vector<Polyline>{line});
  };
  // Green where a stroke is: the table and buildings of the test scene are grey.
  auto green = [](const cv::Mat& frame, cv::Point p) {
    const cv::Vec3b c = frame.at<cv::Vec3b>(p);
    return c[1] > 100 && c[0] < 60 && c[2] < 60;
  };
  ShowInputs inputs;
  inputs.sun.enabled = false;
  inputs.strokes = stroke_at(a_in_table_m, Eigen::Vector3f(0, 1, 0));
  inputs.strokes_version = 1;
  (*loop)->SetInputs(inputs);
  const cv::Point a = pixel_of(a_in_table_m), b = pixel_of(b_in_table_m);
  for (int i = 0; i < 100 && !green(projector.last(), a); ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  ASSERT_TRUE(green(projector.last(), a)) << "stroke A drawn";
  ASSERT_FALSE(green(projector.last(), b));
  // Stroke B replaces A, and a mask comes at once.
  inputs.strokes = stroke_at(b_in_table_m, Eigen::Vector3f(0, 1, 0));
  inputs.strokes_version = 2;
  (*loop)->SetInputs(inputs);
  const cv::Mat half(200, 320, CV_32FC1, cv::Scalar(0.5));
  ASSERT_TRUE((*loop)->ShowBlend(half).ok());
  EXPECT_TRUE((*loop)->LastMaskFrame().rewarped);
  const cv::Mat first = projector.last();
  EXPECT_TRUE(green(first, a)) << "the frame already drawn, under the mask";
  EXPECT_FALSE(green(first, b));
  EXPECT_LT(first.at<cv::Vec3b>(a)[1], 200) << "under the mask (255 x 0.5^(1 / 2.2) = 186)";
  for (int i = 0; i < 100 && !green(projector.last(), b); ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  const cv::Mat next = projector.last();
  EXPECT_TRUE(green(next, b)) << "the new stroke in the next whole frame";
  EXPECT_FALSE(green(next, a));
  EXPECT_EQ((*loop)->Summary().frames_rewarped, 1u);
}

// A mask that comes while a whole frame is being drawn (a neighbour left mid-frame): that frame
// goes out once, under the new mask, not first under the old one and then again.
TEST(RenderLoopTest, AMaskThatComesMidFrameGoesOutWithThatFrame) {
  KeptFrames projector(cv::Size(320, 200));
  auto model = std::make_shared<const Scene>(testing::RenderTestScene());
  RenderLoopOptions options;
  options.max_fps = 200.0;
  options.floor_samples = 0;
  std::atomic<RenderLoop*> running{nullptr};
  std::atomic<bool> armed{false}, drawn{false};
  // The armed frame, drawn, waits on the render thread until the mask has been posted.
  options.after_render_for_test = [&] {
    if (!armed.exchange(false)) return;
    drawn = true;
    for (int i = 0; i < 1000 && !(running.load() && running.load()->MaskPending()); ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
  };
  Expected<std::unique_ptr<RenderLoop>> loop = RenderLoop::Start(&projector, model, options);
  ASSERT_TRUE(loop.ok()) << loop.status().ToString();
  running = loop->get();
  ASSERT_TRUE((*loop)->ShowCalibration(TestCalibration()).ok());
  ShowInputs inputs;
  inputs.sun.enabled = false;
  inputs.pattern = TestPattern::kNone;
  armed = true;
  (*loop)->SetInputs(inputs);  // a new whole frame
  for (int i = 0; i < 1000 && !drawn; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  ASSERT_TRUE(drawn) << "the armed frame was drawn";
  const uint64_t before = projector.count();
  const cv::Mat half(200, 320, CV_32FC1, cv::Scalar(0.5));
  ASSERT_TRUE((*loop)->ShowBlend(half).ok());
  const MaskFrameTimes times = (*loop)->LastMaskFrame();
  EXPECT_TRUE(times.late);
  EXPECT_TRUE(times.rewarped);
  EXPECT_EQ(projector.count(), before + 1) << "the frame drawn went out once, under the mask";
  // Under the mask: nothing brighter than 255 x 0.5^(1 / 2.2) = 186 (+ rounding).
  double hi = 0;
  cv::minMaxLoc(projector.last().reshape(1), nullptr, &hi);
  EXPECT_LE(hi, 188.0);
  EXPECT_GT(hi, 20.0) << "the scene is there";
}

// A re-blend after a neighbour left, prepared ahead of time (PrepareBlends): the prepared mask
// goes out with the frame already drawn, swapped in (no upload), and the same blend shown again
// by the full composition (ShowBlend) changes nothing: one frame, not two.
TEST(RenderLoopTest, APreparedBlendGoesOutOnceWithoutAnUpload) {
  KeptFrames projector(cv::Size(320, 200));
  Expected<std::unique_ptr<RenderLoop>> loop = StartTestLoop(&projector, 0);
  ASSERT_TRUE(loop.ok()) << loop.status().ToString();
  ASSERT_TRUE((*loop)->ShowCalibration(TestCalibration()).ok());
  ShowInputs inputs;
  inputs.sun.enabled = false;
  inputs.pattern = TestPattern::kNone;
  (*loop)->SetInputs(inputs);
  const cv::Mat half(200, 320, CV_32FC1, cv::Scalar(0.5));
  const cv::Mat quarter(200, 320, CV_32FC1, cv::Scalar(0.25));
  EXPECT_FALSE((*loop)->ShowPreparedBlend(5)) << "nothing prepared yet";
  uint64_t blend = 0;
  ASSERT_TRUE((*loop)->ShowBlend(half, cv::Mat(), std::chrono::seconds(10), &blend).ok());
  EXPECT_GT(blend, 0u);
  std::map<NodeId, std::pair<cv::Mat, cv::Mat>> standby;
  standby[5] = {quarter, cv::Mat()};
  standby[6] = {half, cv::Mat()};
  (*loop)->PrepareBlends(blend - 1, standby);  // for an older blend: dropped
  EXPECT_FALSE((*loop)->ShowPreparedBlend(5));
  (*loop)->PrepareBlends(blend, standby);
  for (int i = 0; i < 1000 && (*loop)->Summary().masks_prepared < 2; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  ASSERT_EQ((*loop)->Summary().masks_prepared, 2) << "the render thread prepared both";
  const uint64_t before = projector.count();
  uint64_t posted = 0;
  ASSERT_TRUE((*loop)->ShowPreparedBlend(5, &posted));
  uint64_t again = 0;
  Expected<int64_t> shown =
      (*loop)->ShowBlend(quarter, cv::Mat(), std::chrono::seconds(10), &again);
  ASSERT_TRUE(shown.ok()) << shown.status().ToString();
  EXPECT_EQ(again, posted) << "the blend already posted";
  const MaskFrameTimes times = (*loop)->LastMaskFrame();
  EXPECT_EQ(times.generation, posted);
  EXPECT_TRUE(times.prepared) << "swapped in, not uploaded";
  EXPECT_TRUE(times.rewarped);
  EXPECT_EQ(times.shown_ns, *shown);
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  EXPECT_EQ(projector.count(), before + 1) << "one frame under the new blend";
  // Under the quarter: nothing brighter than 255 x 0.25^(1 / 2.2) = 136 (+ rounding).
  double hi = 0;
  cv::minMaxLoc(projector.last().reshape(1), nullptr, &hi);
  EXPECT_LE(hi, 138.0);
  EXPECT_GT(hi, 20.0) << "the scene is there";
  EXPECT_FALSE((*loop)->ShowPreparedBlend(6)) << "made for the blend before";
  EXPECT_EQ((*loop)->Summary().masks_prepared, 0);
}

TEST(RenderLoopTest, RefusesACalibrationOfAnotherSize) {
  KeptFrames projector(cv::Size(640, 400));
  Expected<std::unique_ptr<RenderLoop>> loop = RenderLoop::Start(&projector, nullptr, {});
  ASSERT_TRUE(loop.ok());
  const Status refused = (*loop)->ShowCalibration(TestCalibration());
  EXPECT_EQ(refused.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(refused.message().find("320x200"), std::string::npos) << refused.message();
}

}  // namespace
}  // namespace sandtable::node
