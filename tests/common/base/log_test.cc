#include "common/base/log.h"

#include <gtest/gtest.h>

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

}  // namespace
}  // namespace sandtable
