// Device timing in the world: a projector's frames come on after its lag, on a refresh; a
// streaming camera's reads return queued (older) exposures first, wait for the next one when
// none is queued, skip dropped exposures and repeat pictures at the drawn rates.
#include "sim/transport/device_clock.h"

#include <cmath>

#include <gtest/gtest.h>

namespace sandtable::sim {
namespace {

constexpr double kTimeTol = 1e-9;

TEST(ProjectorTimeline, FrameComesOnAfterItsLagOnARefresh) {
  DeviceTiming t;
  t.lag_frames = 2;
  t.refresh_hz = 50.0;  // 20 ms refreshes from t = 0
  ProjectorTimeline timeline(t, 0.0);
  const cv::Mat a(2, 2, CV_8UC1, cv::Scalar(10)), b(2, 2, CV_8UC1, cv::Scalar(200));
  EXPECT_NEAR(timeline.Send(0.005, a, true), 0.060, kTimeTol);  // 0.045 -> next refresh 0.060
  EXPECT_NEAR(timeline.Send(0.065, b, true), 0.120, kTimeTol);  // 0.105 -> 0.120
  EXPECT_EQ(timeline.At(0.059), nullptr);
  ASSERT_NE(timeline.At(0.060), nullptr);
  EXPECT_EQ(timeline.At(0.100)->frame.at<uint8_t>(0, 0), 10);
  EXPECT_EQ(timeline.At(0.120)->frame.at<uint8_t>(0, 0), 200);
  // The light cut keeps the frame it showed.
  timeline.Send(0.130, cv::Mat(), false);
  const ProjectorTimeline::Entry* cut = timeline.At(1.0);
  ASSERT_NE(cut, nullptr);
  EXPECT_FALSE(cut->on);
  EXPECT_EQ(cut->frame.at<uint8_t>(0, 0), 200);
  timeline.ForgetBefore(0.125);
  EXPECT_EQ(timeline.size(), 2u);  // b (on at 0.125) and the cut
  EXPECT_EQ(timeline.At(0.125)->frame.at<uint8_t>(0, 0), 200);
}

TEST(ProjectorTimeline, WithoutLagAFrameIsOnAtOnce) {
  ProjectorTimeline timeline(DeviceTiming{}, 0.0);
  EXPECT_NEAR(timeline.Send(0.0123, cv::Mat(1, 1, CV_8UC1), true), 0.0123, kTimeTol);
}

TEST(CameraClock, ReadsQueuedExposuresOldestFirstThenWaits) {
  DeviceTiming t;
  t.camera_fps = 10.0;  // exposures at 0.0, 0.1, 0.2, ...
  t.camera_latency_s = 0.03;
  t.queue_frames = 2;
  CameraClock clock(t, 0.0, 7);
  // At 0.55 exposures up to 0.5 are readable (0.5 + 0.03 <= 0.55); the queue holds 0.4, 0.5.
  CameraClock::Read r = clock.Next(0.55);
  EXPECT_NEAR(r.exposure_start_s, 0.4, kTimeTol);
  EXPECT_NEAR(r.ready_s, 0.55, kTimeTol);
  r = clock.Next(0.56);
  EXPECT_NEAR(r.exposure_start_s, 0.5, kTimeTol);
  // Nothing unread left: the next exposure (0.6) is readable at 0.63.
  r = clock.Next(0.57);
  EXPECT_NEAR(r.exposure_start_s, 0.6, kTimeTol);
  EXPECT_NEAR(r.ready_s, 0.63, kTimeTol);
}

TEST(CameraClock, DropsAndRepeatsAtTheirRates) {
  DeviceTiming t;
  t.camera_fps = 30.0;
  t.queue_frames = 1;
  t.drop_rate = 0.1;
  t.repeat_rate = 0.05;
  CameraClock clock(t, 0.0, 3);
  constexpr int kReads = 20000;
  constexpr double kRateTol = 0.01;
  int64_t previous = -1, skipped = 0;
  double now = 0.0;
  for (int i = 0; i < kReads; ++i) {
    const CameraClock::Read r = clock.Next(now);
    ASSERT_GE(r.ready_s, now);
    if (previous >= 0) {
      ASSERT_GT(r.exposure, previous);
      skipped += r.exposure - previous - 1;
    }
    previous = r.exposure;
    now = r.ready_s;  // reads as fast as frames come: every exposure that arrives is read
  }
  EXPECT_NEAR(static_cast<double>(skipped) / static_cast<double>(previous), t.drop_rate, kRateTol);
  EXPECT_NEAR(static_cast<double>(clock.repeats()) / kReads, t.repeat_rate, kRateTol);
}

}  // namespace
}  // namespace sandtable::sim
