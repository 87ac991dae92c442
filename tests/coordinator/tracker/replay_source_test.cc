#include "coordinator/tracker/replay_source.h"

#include <gtest/gtest.h>

#include <sys/stat.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "common/base/file_io.h"

namespace sandtable::coordinator {
namespace {

namespace fs = std::filesystem;
using std::chrono::milliseconds;

const char* kTraj = "../shared/data/polhemus-hand/pick_and_place/user1_cup0.traj";
constexpr double kRoundTripTolerance_m = 1e-8;

TEST(ReplaySourceTest, LoadsARealFastrakTrajectory) {
  if (!fs::exists(kTraj)) GTEST_SKIP() << kTraj << " not present (run from the project root)";
  Expected<std::vector<TrackerSample>> samples = LoadFastrakTraj(kTraj);
  ASSERT_TRUE(samples.ok()) << samples.status().ToString();
  ASSERT_GE(samples->size(), 165u);  // README: 165..422 samples per pick_and_place file
  ASSERT_LE(samples->size(), 422u);
  EXPECT_DOUBLE_EQ((*samples)[100].source_time_s, 1.0);
  for (const TrackerSample& s : *samples) {  // README: z in [1.11, 3.06] m over all files
    EXPECT_GT(s.tracker_from_sensor.translation.z(), 1.0);
    EXPECT_LT(s.tracker_from_sensor.translation.z(), 3.1);
  }
}

TEST(ReplaySourceTest, MalformedTrajectoriesNameTheSample) {
  const std::string path = (fs::temp_directory_path() / "sandtable_bad.traj").string();
  std::ofstream(path) << "1 0 0 0.5\n0 1 0 0.2\n0 0 1 1.5\n0 0 0 1\n\n"
                      << "1 0 0 0.5\n0 2 0 0.2\n0 0 1 1.5\n0 0 0 1\n\n";
  Expected<std::vector<TrackerSample>> bad = LoadFastrakTraj(path);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("sample 1"), std::string::npos) << bad.status().ToString();
  std::ofstream(path) << "1 0 0 0.5\n0 1 0 0.2\n0 0 1\n\n";  // truncated sample
  EXPECT_FALSE(LoadFastrakTraj(path).ok());
  std::ofstream(path) << "1 0 0 x\n";
  EXPECT_FALSE(LoadFastrakTraj(path).ok());
  fs::remove(path);
}

TEST(ReplaySourceTest, CsvRoundTripAndErrors) {
  const std::string path = (fs::temp_directory_path() / "sandtable_track.csv").string();
  std::vector<TrackerSample> samples(3);
  for (int i = 0; i < 3; ++i) {
    samples[i].source_time_s = 0.01 * i;
    samples[i].sensor_index = 1;
    samples[i].button_pressed = i == 1;
    samples[i].tracker_from_sensor =
        Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(0.3 * i, Eigen::Vector3d::UnitZ())),
                Eigen::Vector3d(0.1 * i, 0.2, 0.3));
  }
  ASSERT_TRUE(WriteTrackerCsv(path, samples).ok());
  Expected<std::vector<TrackerSample>> back = LoadTrackerCsv(path);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  ASSERT_EQ(back->size(), 3u);
  EXPECT_TRUE((*back)[1].button_pressed);
  EXPECT_LT(
      ((*back)[2].tracker_from_sensor.translation - samples[2].tracker_from_sensor.translation)
          .norm(),
      kRoundTripTolerance_m);
  std::ofstream(path) << "time_s,sensor,x_m,y_m,z_m,qw,qx,qy,qz,button\n0,0,0,0,0,2,0,0,0,0\n";
  Expected<std::vector<TrackerSample>> bad = LoadTrackerCsv(path);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("line 2"), std::string::npos);
  std::ofstream(path) << "x,y\n";
  EXPECT_FALSE(LoadTrackerCsv(path).ok());
  fs::remove(path);
}

TEST(ReplaySourceTest, EmitsSamplesWhenDueAndEnds) {
  std::vector<TrackerSample> samples(10);
  for (int i = 0; i < 10; ++i) samples[i].source_time_s = 0.01 * i;
  ReplaySource source("test", samples, /*rate_scale=*/2.0);
  EXPECT_NEAR(source.rate_hz(), 100.0, 1e-9);
  const TrackerClock::time_point t0{};
  std::vector<TrackerSample> out;
  ASSERT_TRUE(source.Poll(t0, &out).ok());
  EXPECT_EQ(out.size(), 1u);  // sample 0 at once
  ASSERT_TRUE(source.Poll(t0 + milliseconds(20), &out).ok());
  EXPECT_EQ(out.size(), 5u);  // 40 ms of source time at x2: samples 0..4
  EXPECT_EQ(source.state(), TrackerState::kStreaming);
  ASSERT_TRUE(source.Poll(t0 + milliseconds(1000), &out).ok());
  EXPECT_EQ(out.size(), 10u);
  EXPECT_EQ(source.state(), TrackerState::kEnded);
}

constexpr char kCsvHeader[] = "time_s,sensor,x_m,y_m,z_m,qw,qx,qy,qz,button\n";

std::string TrajSample(double x_m) {
  return "1 0 0 " + std::to_string(x_m) + "\n0 1 0 0.2\n0 0 1 1.5\n0 0 0 1\n\n";
}

TEST(ReplaySourceTest, FilesAreReadThroughTheBoundedReader) {
  for (auto* load : {&LoadFastrakTraj, &LoadTrackerCsv}) {
    Expected<std::vector<TrackerSample>> zero = (*load)("/dev/zero");
    ASSERT_FALSE(zero.ok());
    EXPECT_EQ(zero.status().code(), StatusCode::kIoError);
    EXPECT_NE(zero.status().message().find("not a regular file"), std::string::npos)
        << zero.status().ToString();
    EXPECT_EQ((*load)(fs::temp_directory_path().string()).status().code(), StatusCode::kIoError);
    EXPECT_EQ((*load)("/nonexistent/track.csv").status().code(), StatusCode::kNotFound);
  }
  const std::string fifo =
      (fs::temp_directory_path() / ("sandtable_replay_fifo_" + std::to_string(::getpid())))
          .string();
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  EXPECT_EQ(LoadTrackerCsv(fifo).status().code(), StatusCode::kIoError);  // no hang
  fs::remove(fifo);
}

TEST(ReplaySourceTest, LimitsAreNamed) {
  // Span: two CSV samples a day and a second apart.
  Expected<std::vector<TrackerSample>> span = ParseTrackerCsv(
      std::string(kCsvHeader) + "0,0,0,0,0,1,0,0,0,0\n86401,0,0,0,0,1,0,0,0,0\n", "span.csv");
  ASSERT_FALSE(span.ok());
  EXPECT_NE(span.status().message().find("kMaxTrackerReplaySpan_s"), std::string::npos)
      << span.status().ToString();
  EXPECT_NE(span.status().message().find("span.csv: line 3"), std::string::npos);
  // Coordinates: 1e19 m would reach the ray caster.
  Expected<std::vector<TrackerSample>> far =
      ParseTrackerCsv(std::string(kCsvHeader) + "0,0,1e19,0,0,1,0,0,0,0\n", "far.csv");
  ASSERT_FALSE(far.ok());
  EXPECT_NE(far.status().message().find("kMaxTrackerCoordinate_m"), std::string::npos);
  Expected<std::vector<TrackerSample>> far_traj = ParseFastrakTraj(TrajSample(1e19), "far.traj");
  ASSERT_FALSE(far_traj.ok());
  EXPECT_NE(far_traj.status().message().find("kMaxTrackerCoordinate_m"), std::string::npos);
  // Sample count: kMaxTrackerReplaySamples + 1 lines, refused at the first one past the limit.
  std::string many(kCsvHeader);
  const std::string row = "0,0,0,0,0,1,0,0,0,0\n";
  many.reserve(many.size() + row.size() * (kMaxTrackerReplaySamples + 1));
  for (uint64_t i = 0; i <= kMaxTrackerReplaySamples; ++i) many += row;
  Expected<std::vector<TrackerSample>> count = ParseTrackerCsv(many, "many.csv");
  ASSERT_FALSE(count.ok());
  EXPECT_NE(count.status().message().find("kMaxTrackerReplaySamples"), std::string::npos)
      << count.status().ToString();
  // A .traj "sample" that never ends (numbers without an empty line) stops at 17 numbers.
  std::string endless_text;
  for (int i = 0; i < 17; ++i) endless_text += "0 ";
  Expected<std::vector<TrackerSample>> endless = ParseFastrakTraj(endless_text, "endless.traj");
  ASSERT_FALSE(endless.ok());
  EXPECT_NE(endless.status().message().find("more than 16 numbers"), std::string::npos)
      << endless.status().ToString();
  // Junk after a number, extra fields and a button of 2 are refused, not read as something.
  for (const char* row_text :
       {"0,0,0.1abc,0,0,1,0,0,0,0\n", "0,0,0,0,0,1,0,0,0,0,7\n", "0,0,0,0,0,1,0,0,0,2\n"}) {
    EXPECT_EQ(ParseTrackerCsv(std::string(kCsvHeader) + row_text, "j.csv").status().code(),
              StatusCode::kParseError)
        << row_text;
  }
  // CRLF line ends are read.
  Expected<std::vector<TrackerSample>> crlf = ParseTrackerCsv(
      "time_s,sensor,x_m,y_m,z_m,qw,qx,qy,qz,button\r\n0,0,0,0,0,1,0,0,0,1\r\n", "crlf.csv");
  ASSERT_TRUE(crlf.ok()) << crlf.status().ToString();
  EXPECT_TRUE((*crlf)[0].button_pressed);
}

}  // namespace
}  // namespace sandtable::coordinator
