#include "common/base/log.h"
#include "common/base/log_rate_limit.h"

#include <gtest/gtest.h>

#include <chrono>
#include <thread>

namespace sandtable {
namespace {

TEST(LogTest, ParsesLevels) {
  LogLevel level = LogLevel::kInfo;
  EXPECT_TRUE(ParseLogLevel("DEBUG", &level));
  EXPECT_EQ(level, LogLevel::kDebug);
  EXPECT_TRUE(ParseLogLevel("warning", &level));
  EXPECT_EQ(level, LogLevel::kWarning);
  EXPECT_FALSE(ParseLogLevel("loud", &level));
  EXPECT_EQ(level, LogLevel::kWarning);
}

TEST(LogTest, ThresholdFiltersAndLinesCarryTagAndFile) {
  SetLogTag("test-7");
  SetLogLevel(LogLevel::kWarning);
  testing::internal::CaptureStderr();
  ST_LOG(kInfo) << "hidden";
  ST_LOG(kWarning) << "shown " << 42;
  const std::string out = testing::internal::GetCapturedStderr();
  EXPECT_EQ(out.find("hidden"), std::string::npos);
  EXPECT_NE(out.find(" W test-7 log_test.cc:"), std::string::npos) << out;
  EXPECT_NE(out.find("shown 42"), std::string::npos);
  SetLogLevel(LogLevel::kInfo);
  SetLogTag("");
}

// 300 refused clients (one warning each, from one place) write at most kLogBurstLines lines per
// interval; the next line after the interval carries the count of the suppressed ones.
TEST(LogTest, RepeatedWarningsFromOnePlaceAreRateLimitedWithACount) {
  constexpr int kFlood = 300;
  SetLogRateInterval(std::chrono::milliseconds(60000));
  testing::internal::CaptureStderr();
  const uint64_t suppressed_before = SuppressedLogLines();
  for (int i = 0; i < kFlood; ++i) ST_LOG(kWarning) << "refused client " << i;
  ST_LOG(kInfo) << "info is not limited";
  std::string out = testing::internal::GetCapturedStderr();
  auto count_lines = [](const std::string& text, const std::string& what) {
    int n = 0;
    for (size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
    return n;
  };
  EXPECT_EQ(count_lines(out, "refused client"), kLogBurstLines) << out;
  EXPECT_EQ(count_lines(out, "info is not limited"), 1);
  EXPECT_EQ(SuppressedLogLines() - suppressed_before, uint64_t{kFlood - kLogBurstLines});

  // A new interval: the first line of the same place says how many the previous one
  // suppressed. The interval is generous against scheduling: 5 lines take microseconds.
  constexpr auto kShortInterval = std::chrono::milliseconds(300);
  SetLogRateInterval(kShortInterval);
  auto warn = [](int i) { ST_LOG(kWarning) << "burst " << i; };
  testing::internal::CaptureStderr();
  for (int i = 0; i < 5; ++i) warn(i);
  std::this_thread::sleep_for(kShortInterval + std::chrono::milliseconds(50));
  warn(99);
  out = testing::internal::GetCapturedStderr();
  EXPECT_NE(out.find("burst 99 [2 similar lines suppressed"), std::string::npos) << out;
  SetLogRateInterval(kLogRateInterval);
}

}  // namespace
}  // namespace sandtable
