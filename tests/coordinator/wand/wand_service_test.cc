// WandService without sockets: events per sample, scheduled by sample time (synthetic clock,
// no waiting), the table-plane cursor, and the table_from_tracker JSON loader.
#include "coordinator/wand/wand_service.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "common/base/units.h"
#include "coordinator/tracker/replay_source.h"
#include "proto/convert.h"

namespace sandtable::coordinator {
namespace {

namespace fs = std::filesystem;
constexpr double kPosition_m = 1e-9;
constexpr int64_t kPeriod_ns = 10'000'000;  // 100 Hz
constexpr int64_t kStart_ns = 5'000'000'000;

// Wand at (x, 0, 1) in the tracker frame pointing straight down (sensor +x -> tracker -z).
std::vector<TrackerSample> DownwardSamples(int n) {
  std::vector<TrackerSample> out;
  const Eigen::Quaterniond down(Eigen::AngleAxisd(DegToRad(90.0), Eigen::Vector3d::UnitY()));
  for (int i = 0; i < n; ++i) {
    TrackerSample s;
    s.tracker_from_sensor = Rigid3d(down, Eigen::Vector3d(0.01 * i, 0.0, 1.0));
    s.source_time_s = i / 100.0;
    s.button_pressed = (i % 2) == 1;
    out.push_back(s);
  }
  return out;
}

TEST(WandServiceTest, EventsGoOutWhenDueWithSampleTimesFromTheSource) {
  WandServiceOptions options;
  options.table_from_tracker = Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0, 0.5, 0));
  WandService service(std::make_unique<ReplaySource>("test", DownwardSamples(10)), options);
  // First poll: sample 0 only.
  std::vector<wire::Envelope> events = service.PollEvents(kStart_ns);
  ASSERT_EQ(events.size(), 2u);
  // A step 35 ms late delivers samples 1..3 together, each stamped with its own due time.
  events = service.PollEvents(kStart_ns + 35'000'000);
  ASSERT_EQ(events.size(), 6u);
  for (int k = 0; k < 3; ++k) {
    const int i = k + 1;
    const wire::TrackerPose& pose = events[2 * k].tracker_pose();
    const wire::Cursor& cursor = events[2 * k + 1].cursor();
    EXPECT_EQ(pose.sample_time_ns(), kStart_ns + i * kPeriod_ns);
    EXPECT_EQ(cursor.sample_time_ns(), pose.sample_time_ns());
    EXPECT_EQ(pose.button_pressed(), i % 2 == 1);
    Expected<Rigid3d> table_from_sensor = proto::FromWire(pose.table_from_sensor());
    ASSERT_TRUE(table_from_sensor.ok());
    EXPECT_NEAR(table_from_sensor->translation.x(), 0.01 * i, kPosition_m);
    EXPECT_NEAR(table_from_sensor->translation.y(), 0.5, kPosition_m);
    // Straight down from z = 1 onto the table plane.
    ASSERT_TRUE(cursor.hit());
    EXPECT_NEAR(cursor.hit_in_table_m().x(), 0.01 * i, kPosition_m);
    EXPECT_NEAR(cursor.hit_in_table_m().y(), 0.5, kPosition_m);
    EXPECT_NEAR(cursor.hit_in_table_m().z(), 0.0, kPosition_m);
    EXPECT_NEAR(cursor.normal_in_table().z(), 1.0, kPosition_m);
  }
  // Nothing new before the next sample is due; the rest by the end.
  EXPECT_TRUE(service.PollEvents(kStart_ns + 39'000'000).empty());
  EXPECT_EQ(service.PollEvents(kStart_ns + 1'000'000'000).size(), 12u);
  EXPECT_EQ(service.source().state(), TrackerState::kEnded);
  EXPECT_EQ(service.counters().samples, 10u);
  EXPECT_EQ(service.counters().cursor_hits, 10u);
}

TEST(WandServiceTest, RayMissingTheTablePlaneGivesCursorWithoutHit) {
  WandServiceOptions options;
  options.scene_half_extent_m = 0.055;  // samples beyond x = 0.055 miss the quad
  WandService service(std::make_unique<ReplaySource>("test", DownwardSamples(10)), options);
  (void)service.PollEvents(kStart_ns);
  const std::vector<wire::Envelope> events = service.PollEvents(kStart_ns + 1'000'000'000);
  ASSERT_EQ(events.size(), 18u);
  EXPECT_TRUE(events[7].cursor().hit());          // sample 4, x = 0.04
  EXPECT_FALSE(events[11].cursor().hit());        // sample 6, x = 0.06
  EXPECT_EQ(service.counters().cursor_hits, 6u);  // x = 0 .. 0.05
}

class TableFromTrackerFileTest : public ::testing::Test {
 protected:
  void SetUp() override {
    path_ = (fs::temp_directory_path() / ("sandtable_tft_" + std::to_string(::getpid()) + ".json"))
                .string();
  }
  void TearDown() override { fs::remove(path_); }
  void Write(const std::string& text) { std::ofstream(path_) << text; }
  std::string path_;
};

TEST_F(TableFromTrackerFileTest, LoadsRotationAndTranslation) {
  const double half = DegToRad(30.0) / 2;
  Write("{\"rotation_wxyz\": [" + std::to_string(std::cos(half)) + ", 0, 0, " +
        std::to_string(std::sin(half)) + "], \"translation_m\": [0.1, -0.2, 0.3]}");
  Expected<Rigid3d> t = LoadTableFromTracker(path_);
  ASSERT_TRUE(t.ok()) << t.status().ToString();
  const Eigen::Vector3d x = *t * Eigen::Vector3d(1, 0, 0);
  constexpr double kPrintedTolerance_m = 1e-6;  // std::to_string keeps 6 decimals
  EXPECT_NEAR(x.x(), std::cos(DegToRad(30.0)) + 0.1, kPrintedTolerance_m);
  EXPECT_NEAR(x.y(), std::sin(DegToRad(30.0)) - 0.2, kPrintedTolerance_m);
  EXPECT_NEAR(x.z(), 0.3, kPrintedTolerance_m);
}

TEST_F(TableFromTrackerFileTest, BadFilesGiveErrorsNamingTheField) {
  EXPECT_EQ(LoadTableFromTracker(path_ + ".absent").status().code(), StatusCode::kIoError);
  Write("{\"rotation_wxyz\": [1, 0, 0], \"translation_m\": [0, 0, 0]}");
  Status s = LoadTableFromTracker(path_).status();
  EXPECT_EQ(s.code(), StatusCode::kParseError);
  EXPECT_NE(s.message().find("rotation_wxyz"), std::string::npos) << s.ToString();
  Write("{\"rotation_wxyz\": [2, 0, 0, 0], \"translation_m\": [0, 0, 0]}");
  s = LoadTableFromTracker(path_).status();
  EXPECT_NE(s.message().find("norm"), std::string::npos) << s.ToString();
  Write("{\"rotation_wxyz\": [1, 0, 0, 0], \"translation_m\": [0, \"x\", 0]}");
  s = LoadTableFromTracker(path_).status();
  EXPECT_NE(s.message().find("translation_m"), std::string::npos) << s.ToString();
  Write("not json");
  EXPECT_EQ(LoadTableFromTracker(path_).status().code(), StatusCode::kParseError);
}

}  // namespace
}  // namespace sandtable::coordinator
