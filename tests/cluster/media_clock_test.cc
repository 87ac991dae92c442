#include "cluster/media_clock.h"

#include <cmath>
#include <limits>

#include <gtest/gtest.h>

namespace sandtable::cluster {
namespace {

constexpr double kTolerance_s = 1e-9;
constexpr int64_t kNsPerS = 1'000'000'000;
constexpr int64_t kT0_ns = 5'000 * kNsPerS;  // an arbitrary steady-clock origin

MediaClock MakeClock(double duration_s = 100.0) {
  MediaClockOptions options;
  options.duration_s = duration_s;
  return MediaClock(options);
}

TEST(TimelineMediaClockTest, StartsPausedAtZero) {
  MediaClock clock = MakeClock();
  EXPECT_FALSE(clock.state().playing);
  EXPECT_NEAR(clock.MediaTimeAt(kT0_ns + 3 * kNsPerS), 0.0, kTolerance_s);
}

TEST(TimelineMediaClockTest, PlayAdvancesAtRateAndPauseFreezes) {
  MediaClock clock = MakeClock();
  ASSERT_TRUE(clock.Play(kT0_ns).ok());
  EXPECT_NEAR(clock.MediaTimeAt(kT0_ns + 2'500'000'000), 2.5, kTolerance_s);
  ASSERT_TRUE(clock.Pause(kT0_ns + 4 * kNsPerS).ok());
  EXPECT_NEAR(clock.MediaTimeAt(kT0_ns + 60 * kNsPerS), 4.0, kTolerance_s);
  // Resume: continues from 4 s.
  ASSERT_TRUE(clock.Play(kT0_ns + 10 * kNsPerS).ok());
  EXPECT_NEAR(clock.MediaTimeAt(kT0_ns + 11 * kNsPerS), 5.0, kTolerance_s);
  EXPECT_EQ(clock.state().change_count, 3u);
}

TEST(TimelineMediaClockTest, RateChangeKeepsMediaTimeContinuous) {
  MediaClock clock = MakeClock();
  ASSERT_TRUE(clock.Play(kT0_ns).ok());
  ASSERT_TRUE(clock.SetRate(kT0_ns + 2 * kNsPerS, 4.0).ok());  // at media 2 s
  EXPECT_NEAR(clock.MediaTimeAt(kT0_ns + 2 * kNsPerS), 2.0, kTolerance_s);
  EXPECT_NEAR(clock.MediaTimeAt(kT0_ns + 3 * kNsPerS), 6.0, kTolerance_s);
  ASSERT_TRUE(clock.SetRate(kT0_ns + 3 * kNsPerS, 0.25).ok());
  EXPECT_NEAR(clock.MediaTimeAt(kT0_ns + 7 * kNsPerS), 7.0, kTolerance_s);
}

TEST(TimelineMediaClockTest, NegativeZeroAndNonFiniteRatesAreRefusedAndChangeNothing) {
  MediaClock clock = MakeClock();
  ASSERT_TRUE(clock.Play(kT0_ns).ok());
  const MediaClockState before = clock.state();
  for (double rate : {-1.0, 0.0, std::nan(""), std::numeric_limits<double>::infinity(), 65.0}) {
    const Status s = clock.SetRate(kT0_ns + kNsPerS, rate);
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << rate;
  }
  EXPECT_EQ(clock.state().change_count, before.change_count);
  EXPECT_NEAR(clock.MediaTimeAt(kT0_ns + 2 * kNsPerS), 2.0, kTolerance_s);
  EXPECT_NE(clock.SetRate(kT0_ns, -1.0).message().find("reverse"), std::string::npos);
}

TEST(TimelineMediaClockTest, SeekClampsToTheRecordedSpan) {
  MediaClock clock = MakeClock(30.0);
  ASSERT_TRUE(clock.Seek(kT0_ns, 1e6).ok());
  EXPECT_NEAR(clock.MediaTimeAt(kT0_ns), 30.0, kTolerance_s);
  ASSERT_TRUE(clock.Seek(kT0_ns, -5.0).ok());
  EXPECT_NEAR(clock.MediaTimeAt(kT0_ns), 0.0, kTolerance_s);
  EXPECT_FALSE(clock.Seek(kT0_ns, std::nan("")).ok());
  // Seek while playing keeps playing from the new position.
  ASSERT_TRUE(clock.Play(kT0_ns).ok());
  ASSERT_TRUE(clock.Seek(kT0_ns + kNsPerS, 20.0).ok());
  EXPECT_NEAR(clock.MediaTimeAt(kT0_ns + 3 * kNsPerS), 22.0, kTolerance_s);
}

TEST(TimelineMediaClockTest, ReachingTheEndPausesThereAndPlayRestarts) {
  MediaClock clock = MakeClock(10.0);
  ASSERT_TRUE(clock.Play(kT0_ns).ok());
  EXPECT_NEAR(clock.MediaTimeAt(kT0_ns + 12 * kNsPerS), 10.0, kTolerance_s);  // clamped
  EXPECT_FALSE(clock.Advance(kT0_ns + 9 * kNsPerS));
  EXPECT_TRUE(clock.Advance(kT0_ns + 12 * kNsPerS));
  EXPECT_FALSE(clock.state().playing);
  EXPECT_NEAR(clock.MediaTimeAt(kT0_ns + 20 * kNsPerS), 10.0, kTolerance_s);
  ASSERT_TRUE(clock.Play(kT0_ns + 20 * kNsPerS).ok());
  EXPECT_NEAR(clock.MediaTimeAt(kT0_ns + 21 * kNsPerS), 1.0, kTolerance_s);
}

TEST(TimelineMediaClockTest, ScheduledPlayHoldsUntilItsTime) {
  MediaClock clock = MakeClock();
  ASSERT_TRUE(clock.Seek(kT0_ns, 3.0).ok());
  ASSERT_TRUE(clock.Play(kT0_ns, kT0_ns + kNsPerS / 2).ok());  // start in 0.5 s
  EXPECT_NEAR(clock.MediaTimeAt(kT0_ns + kNsPerS / 4), 3.0, kTolerance_s);
  EXPECT_NEAR(clock.MediaTimeAt(kT0_ns + 3 * kNsPerS / 2), 4.0, kTolerance_s);
  // The published sample keeps the future anchor until it passes.
  EXPECT_EQ(clock.SampleAt(kT0_ns).anchor_time_ns, kT0_ns + kNsPerS / 2);
  const MediaClockState later = clock.SampleAt(kT0_ns + 2 * kNsPerS);
  EXPECT_EQ(later.anchor_time_ns, kT0_ns + 2 * kNsPerS);
  EXPECT_NEAR(later.media_time_s, 4.5, kTolerance_s);
  // Too far from now: refused.
  EXPECT_FALSE(clock.Play(kT0_ns, kT0_ns + 60 * kNsPerS).ok());
  EXPECT_FALSE(clock.Pause(kT0_ns, kT0_ns + kNsPerS).ok());  // pause in the future
}

TEST(TimelineMediaClockTest, PauseAtAPastInstantUsesTheMediaTimeThen) {
  MediaClock clock = MakeClock();
  ASSERT_TRUE(clock.Play(kT0_ns).ok());
  ASSERT_TRUE(clock.Pause(kT0_ns + 5 * kNsPerS, kT0_ns + 4 * kNsPerS).ok());
  EXPECT_NEAR(clock.MediaTimeAt(kT0_ns + 9 * kNsPerS), 4.0, kTolerance_s);
}

TEST(TimelineMediaClockTest, OptionsCheckRefusesBadDuration) {
  MediaClockOptions options;
  options.duration_s = -1.0;
  EXPECT_FALSE(options.Check().ok());
  options.duration_s = std::nan("");
  EXPECT_FALSE(options.Check().ok());
}

}  // namespace
}  // namespace sandtable::cluster
