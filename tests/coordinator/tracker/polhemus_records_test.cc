#include "coordinator/tracker/polhemus_records.h"

#include <gtest/gtest.h>

#include <random>

namespace sandtable::coordinator {
namespace {

// float32 on the wire in cm: ~1e-6 relative, i.e. < 1e-5 m at 2 m.
constexpr double kPositionTolerance_m = 1e-5;
constexpr double kRotationTolerance_rad = 1e-5;

TrackerSample MakeSample(int i, bool button) {
  TrackerSample s;
  s.tracker_from_sensor =
      Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(0.1 * i, Eigen::Vector3d(1, 2, 3).normalized())),
              Eigen::Vector3d(0.1 * i, -0.25, 0.6 + 0.01 * i));
  s.button_pressed = button;
  return s;
}

// A recorded stream: `n` records for station 1 (and every third for station 2).
std::string Stream(const PolhemusFormat& format, int n, std::vector<TrackerSample>* truth) {
  std::string bytes;
  for (int i = 0; i < n; ++i) {
    const TrackerSample s = MakeSample(i, i % 4 == 0);
    bytes += PolhemusRecordParser::EncodeRecord(format, 1, s, static_cast<uint32_t>(i));
    truth->push_back(s);
  }
  return bytes;
}

void ExpectSame(const TrackerSample& a, const TrackerSample& b) {
  EXPECT_LT((a.tracker_from_sensor.translation - b.tracker_from_sensor.translation).norm(),
            kPositionTolerance_m);
  EXPECT_LT(RotationAngleBetween_rad(a.tracker_from_sensor, b.tracker_from_sensor),
            kRotationTolerance_rad);
  EXPECT_EQ(a.button_pressed, b.button_pressed);
}

TEST(PolhemusRecordsTest, ParsesAStreamInAnyChunking) {
  PolhemusFormat format;
  std::vector<TrackerSample> truth;
  const std::string bytes = Stream(format, 50, &truth);
  ASSERT_EQ(bytes.size(), 50 * (kPolhemusHeaderBytes + format.PayloadBytes()));
  std::mt19937 rng(3);
  for (int trial = 0; trial < 20; ++trial) {
    PolhemusRecordParser parser(format);
    std::vector<TrackerSample> out;
    for (size_t at = 0; at < bytes.size();) {
      const size_t chunk = std::min<size_t>(1 + rng() % 97, bytes.size() - at);
      parser.Feed(std::string_view(bytes).substr(at, chunk), &out);
      at += chunk;
    }
    ASSERT_EQ(out.size(), truth.size());
    for (size_t i = 0; i < out.size(); ++i) ExpectSame(out[i], truth[i]);
    EXPECT_EQ(out[0].sensor_index, 0u);
    EXPECT_EQ(parser.counters().Dropped(), 0u);
  }
}

TEST(PolhemusRecordsTest, InchesAndFrameCountsConvertToMetresAndSeconds) {
  PolhemusFormat format;
  format.unit = PolhemusUnit::kInch;
  format.items = {PolhemusItem::kFrameCount, PolhemusItem::kPosition, PolhemusItem::kQuaternion};
  const TrackerSample s = MakeSample(7, false);
  PolhemusRecordParser parser(format);
  std::vector<TrackerSample> out;
  parser.Feed(PolhemusRecordParser::EncodeRecord(format, 3, s, 480, 0, "PA"), &out);
  ASSERT_EQ(out.size(), 1u);
  ExpectSame(out[0], s);
  EXPECT_EQ(out[0].sensor_index, 2u);
  EXPECT_DOUBLE_EQ(out[0].source_time_s, 2.0);  // 480 frames at 240 Hz
  EXPECT_EQ(format.ConfigurationCommands()[1], "U0\r");
}

TEST(PolhemusRecordsTest, TruncatedRecordIsHeldThenCountedAtTheEnd) {
  PolhemusFormat format;
  std::vector<TrackerSample> truth;
  const std::string bytes = Stream(format, 3, &truth);
  PolhemusRecordParser parser(format);
  std::vector<TrackerSample> out;
  parser.Feed(std::string_view(bytes).substr(0, bytes.size() - 5), &out);
  EXPECT_EQ(out.size(), 2u);
  parser.Finish();
  EXPECT_EQ(parser.counters().truncated, 1u);
  EXPECT_EQ(out.size(), 2u);
}

TEST(PolhemusRecordsTest, CorruptedRecordsAreDroppedAndTheStreamResyncs) {
  PolhemusFormat format;
  std::vector<TrackerSample> truth;
  std::string bytes = Stream(format, 10, &truth);
  const size_t record = kPolhemusHeaderBytes + format.PayloadBytes();
  // Record 2: payload size field corrupted. Record 5: quaternion replaced by garbage (norm != 1).
  // Record 7: device error byte set. Noise between records 8 and 9.
  bytes[2 * record + 6] = static_cast<char>(0x7f);
  for (int k = 0; k < 16; ++k) bytes[5 * record + kPolhemusHeaderBytes + 12 + k] = 0x41;
  bytes[7 * record + 4] = 0x03;
  bytes.insert(9 * record, "xxLYjunk\xff\x01");
  PolhemusRecordParser parser(format);
  std::vector<TrackerSample> out;
  parser.Feed(bytes, &out);
  parser.Finish();
  ASSERT_EQ(out.size(), 7u);  // 10 minus records 2, 5, 7
  ExpectSame(out[2], truth[3]);
  ExpectSame(out[4], truth[6]);
  ExpectSame(out[6], truth[9]);
  EXPECT_EQ(parser.counters().device_errors, 1u);
  EXPECT_GE(parser.counters().bad_size, 2u);  // record 2 and the fake "LY" in the noise
  EXPECT_EQ(parser.counters().bad_values, 1u);
  EXPECT_GT(parser.counters().resync_bytes, 0u);
}

TEST(PolhemusRecordsTest, RandomBytesNeverCrashAndYieldNoBogusSamples) {
  PolhemusFormat format;
  std::mt19937 rng(99);
  PolhemusRecordParser parser(format);
  std::vector<TrackerSample> out;
  std::string noise(1 << 16, '\0');
  for (char& c : noise) c = static_cast<char>(rng() & 0xff);
  parser.Feed(noise, &out);
  parser.Finish();
  for (const TrackerSample& s : out) {  // anything accepted passed the value checks
    EXPECT_LE(s.tracker_from_sensor.translation.norm(), kMaxPosition_m);
  }
  EXPECT_LT(out.size(), 3u);
}

}  // namespace
}  // namespace sandtable::coordinator
