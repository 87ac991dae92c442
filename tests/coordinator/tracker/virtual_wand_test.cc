// Virtual wand: script parsing (errors name line and field), sampling at the script rate with
// linear interpolation of the tip and the direction, button state, determinism, playback.
#include "coordinator/tracker/virtual_wand.h"

#include <gtest/gtest.h>

#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <string>

#include "common/base/file_io.h"

namespace sandtable::coordinator {
namespace {

constexpr double kPosition_m = 1e-12;
constexpr double kDirection = 1e-12;
constexpr double kTime_s = 1e-12;

constexpr char kScript[] = R"(# a line over the table
rate_hz 50
at 0.0   0.0 0.0 0.5   0 0 -1
at 0.2   0.2 0.1 0.3   1 0 -1   # direction tilts towards +x
down 0.05
up 0.15
)";

TEST(VirtualWandTest, SamplesAtTheRateWithLinearInterpolation) {
  Expected<VirtualWandScript> script = ParseVirtualWandScript(kScript, "lab.txt");
  ASSERT_TRUE(script.ok()) << script.status().ToString();
  EXPECT_EQ(script->rate_hz, 50.0);
  const std::vector<TrackerSample> samples = SampleVirtualWand(*script);
  ASSERT_EQ(samples.size(), 11u);  // 0, 0.02, ..., 0.2
  for (size_t k = 0; k < samples.size(); ++k) {
    const double t = k / 50.0;
    const double a = t / 0.2;
    EXPECT_NEAR(samples[k].source_time_s, t, kTime_s);
    const Eigen::Vector3d tip =
        (1 - a) * Eigen::Vector3d(0, 0, 0.5) + a * Eigen::Vector3d(0.2, 0.1, 0.3);
    EXPECT_LT((samples[k].tracker_from_sensor.translation - tip).norm(), kPosition_m) << k;
    const Eigen::Vector3d direction =
        ((1 - a) * Eigen::Vector3d(0, 0, -1) + a * Eigen::Vector3d(1, 0, -1)).normalized();
    const Eigen::Vector3d sensor_x =
        samples[k].tracker_from_sensor.rotation * Eigen::Vector3d::UnitX();
    EXPECT_LT((sensor_x - direction).norm(), kDirection) << k;
    // Down from 0.05 (inclusive) to 0.15 (exclusive): samples 3..7 (t = 0.06 .. 0.14).
    EXPECT_EQ(samples[k].button_pressed, k >= 3 && k <= 7) << k;
  }
}

TEST(VirtualWandTest, DefaultRateAndDeterminism) {
  Expected<VirtualWandScript> script =
      ParseVirtualWandScript("at 1 0 0 1 0 0 -1\nat 2 1 0 1 0 0 -1\n", "s");
  ASSERT_TRUE(script.ok()) << script.status().ToString();
  EXPECT_EQ(script->rate_hz, kDefaultVirtualWandRate_hz);
  const std::vector<TrackerSample> a = SampleVirtualWand(*script);
  const std::vector<TrackerSample> b = SampleVirtualWand(*script);
  ASSERT_EQ(a.size(), 101u);
  EXPECT_NEAR(a.front().source_time_s, 1.0, kTime_s);
  EXPECT_NEAR(a.back().source_time_s, 2.0, kTime_s);
  for (size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].tracker_from_sensor.translation, b[i].tracker_from_sensor.translation);
    EXPECT_EQ(a[i].tracker_from_sensor.rotation.coeffs(),
              b[i].tracker_from_sensor.rotation.coeffs());
    EXPECT_FALSE(a[i].button_pressed);
  }
}

TEST(VirtualWandTest, ErrorsNameLineAndField) {
  struct Case {
    const char* text;
    const char* expected;
  };
  const Case cases[] = {
      {"at 0 0 0 1 0 0 -1\nat 0.1 0 0 x 0 0 -1\n", "s.txt:2: z_m: 'x' is not a number"},
      {"at 0 0 0 1 0 0\n", "s.txt:1: dz: missing"},
      {"at 0 0 0 1 0 0 0\n", "s.txt:1: direction: must be non-zero"},
      {"at 0 0 0 1 0 0 -1\nat 0 0 0 1 0 0 -1\n", "s.txt:2: time_s: waypoint times must increase"},
      {"at 0 0 0 1 0 0 -1\nup 0.1\n", "s.txt:2: up: button is not down"},
      {"at 0 0 0 1 0 0 -1\ndown 0.2\nup 0.1\n", "s.txt:3: time_s: button times must not decrease"},
      {"\n\nrate_hz -5\nat 0 0 0 1 0 0 -1\n", "s.txt:3: rate_hz: must be in (0, 10000]"},
      {"at 0 0 0 1 0 0 -1\nrate_hz 10\n", "s.txt:2: rate_hz: must come once"},
      {"at 0 0 0 1 0 0 -1\nfly 3\n", "s.txt:2: keyword: unknown 'fly'"},
      {"at 0 0 0 1 0 0 -1 7\n", "s.txt:1: line: unexpected extra token '7'"},
      {"at 0 0 0 inf 0 0 -1\n", "s.txt:1: z_m: 'inf' is not finite"},
      {"# only a comment\n", "s.txt: no waypoints"},
  };
  for (const Case& c : cases) {
    Expected<VirtualWandScript> script = ParseVirtualWandScript(c.text, "s.txt");
    ASSERT_FALSE(script.ok()) << c.text;
    EXPECT_EQ(script.status().code(), StatusCode::kParseError) << c.text;
    EXPECT_NE(script.status().message().find(c.expected), std::string::npos)
        << script.status().ToString() << " (expected '" << c.expected << "')";
  }
  EXPECT_EQ(LoadVirtualWandScript("/nonexistent/wand.txt").status().code(), StatusCode::kNotFound);
}

TEST(VirtualWandTest, SourcePlaysSamplesWhenDue) {
  Expected<VirtualWandScript> script = ParseVirtualWandScript(kScript, "lab.txt");
  ASSERT_TRUE(script.ok());
  VirtualWandSource source("lab.txt", *script);
  EXPECT_NE(source.Describe().find("50 Hz, 11 samples"), std::string::npos) << source.Describe();
  const TrackerClock::time_point t0{std::chrono::seconds(100)};
  std::vector<TrackerSample> out;
  ASSERT_TRUE(source.Poll(t0, &out).ok());
  EXPECT_EQ(out.size(), 1u);
  ASSERT_TRUE(source.Poll(t0 + std::chrono::milliseconds(45), &out).ok());
  EXPECT_EQ(out.size(), 3u);  // 0, 0.02, 0.04
  ASSERT_TRUE(source.Poll(t0 + std::chrono::seconds(1), &out).ok());
  EXPECT_EQ(out.size(), 11u);
  EXPECT_EQ(source.state(), TrackerState::kEnded);
}

// What a script may generate is bounded before any sample is made: the span of its
// waypoints, the number of samples (span x rate), times and coordinates; each refusal names
// its limit.
TEST(VirtualWandTest, ScriptsThatWouldGenerateTooMuchAreRefusedNamingTheLimit) {
  struct Case {
    std::string text;
    std::string limit;
  };
  const std::vector<Case> cases = {
      {"at 0 0 0 0 0 0 -1\nat 3601 0 0 0 0 0 -1\n", "kMaxVirtualWandSpan_s"},
      {"at 0 0 0 0 0 0 -1\nat 1e300 0 0 0 0 0 -1\n", "kMaxVirtualWandTime_s"},
      {"rate_hz 10000\nat 0 0 0 0 0 0 -1\nat 1000 0 0 0 0 0 -1\n", "kMaxVirtualWandSamples"},
      {"at 0 1e19 0 0 0 0 -1\n", "kMaxVirtualWandCoordinate_m"},
      {"at 0 0 0 0 0 0 -1\ndown 1e12\n", "kMaxVirtualWandTime_s"},
  };
  for (const Case& c : cases) {
    Expected<VirtualWandScript> script = ParseVirtualWandScript(c.text, "big.txt");
    ASSERT_FALSE(script.ok()) << c.text;
    EXPECT_EQ(script.status().code(), StatusCode::kParseError);
    EXPECT_NE(script.status().message().find(c.limit), std::string::npos)
        << script.status().ToString();
    EXPECT_NE(script.status().message().find("big.txt"), std::string::npos);
  }
  // Just inside the limits: an hour at 250 Hz is 900 001 samples, accepted and generated.
  Expected<VirtualWandScript> hour =
      ParseVirtualWandScript("rate_hz 250\nat 0 0 0 0 0 0 -1\nat 3600 0 0 0 0 0 -1\n", "h.txt");
  ASSERT_TRUE(hour.ok()) << hour.status().ToString();
  EXPECT_EQ(VirtualWandSampleCount(*hour), 900'001u);
  EXPECT_EQ(SampleVirtualWand(*hour).size(), 900'001u);
  // A script built in code past the limits is cut at kMaxVirtualWandSamples, never more.
  VirtualWandScript huge = *hour;
  huge.rate_hz = 1e9;
  EXPECT_GT(VirtualWandSampleCount(huge), kMaxVirtualWandSamples);
  EXPECT_EQ(SampleVirtualWand(huge).size(), kMaxVirtualWandSamples);
}

TEST(VirtualWandTest, ScriptFilesAreReadThroughTheBoundedReader) {
  // /dev/zero would never end: refused before a byte is read.
  Expected<VirtualWandScript> zero = LoadVirtualWandScript("/dev/zero");
  ASSERT_FALSE(zero.ok());
  EXPECT_EQ(zero.status().code(), StatusCode::kIoError);
  EXPECT_NE(zero.status().message().find("not a regular file"), std::string::npos)
      << zero.status().ToString();
  const std::filesystem::path dir = std::filesystem::temp_directory_path();
  EXPECT_EQ(LoadVirtualWandScript(dir.string()).status().code(), StatusCode::kIoError);
  const std::string fifo = (dir / ("sandtable_wand_fifo_" + std::to_string(::getpid()))).string();
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  EXPECT_EQ(LoadVirtualWandScript(fifo).status().code(), StatusCode::kIoError);  // no hang
  std::filesystem::remove(fifo);
  const std::string big = (dir / ("sandtable_wand_big_" + std::to_string(::getpid()))).string();
  ASSERT_TRUE(WriteFileAtomically(big, std::string(kMaxVirtualWandScriptBytes + 1, '#')).ok());
  Expected<VirtualWandScript> too_big = LoadVirtualWandScript(big);
  ASSERT_FALSE(too_big.ok());
  EXPECT_NE(too_big.status().message().find("kMaxVirtualWandScriptBytes"), std::string::npos)
      << too_big.status().ToString();
  ASSERT_TRUE(WriteFileAtomically(big, kScript).ok());
  EXPECT_TRUE(LoadVirtualWandScript(big).ok());
  std::filesystem::remove(big);
}

}  // namespace
}  // namespace sandtable::coordinator
