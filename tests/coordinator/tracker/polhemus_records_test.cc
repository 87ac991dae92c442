#include "coordinator/tracker/polhemus_records.h"

#include <gtest/gtest.h>

#include <cstring>
#include <random>

namespace sandtable::coordinator {
namespace {

// float32 on the wire: ~1e-7 relative, i.e. < 1e-5 m at 2 m (inches or cm).
constexpr double kPositionTolerance_m = 1e-5;
constexpr double kRotationTolerance_rad = 1e-5;
constexpr double kInch_m = 0.0254;

TrackerSample MakeSample(int i, bool button) {
  TrackerSample s;
  s.tracker_from_sensor =
      Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(0.1 * i, Eigen::Vector3d(1, 2, 3).normalized())),
              Eigen::Vector3d(0.1 * i, -0.25, 0.6 + 0.01 * i));
  s.button_pressed = button;
  return s;
}

// A record written byte by byte from VRPN's description of a Liberty binary report
// (vrpn_Tracker_Liberty.C, output list "O*,2,7,8,10,0"): "LY", station, command, error flag
// ' ', reserved, 2 size bytes; position x y z and quaternion w x y z as little-endian float32
// in inches; timestamp uint32 ms; stylus uint32; one space. Independent of EncodeRecord.
void PutLe32(std::string* out, uint32_t v) {
  for (int i = 0; i < 4; ++i) out->push_back(static_cast<char>((v >> (8 * i)) & 0xff));
}
void PutFloat(std::string* out, float f) {
  uint32_t bits;
  std::memcpy(&bits, &f, 4);
  PutLe32(out, bits);
}
std::string VrpnLibertyRecord(uint8_t station, const float position_in[3], const float wxyz[4],
                              uint32_t time_ms, uint32_t stylus, char error_flag = ' ',
                              const char* tag = "LY") {
  std::string r;
  r += tag[0];
  r += tag[1];
  r += static_cast<char>(station);
  r += 'C';
  r += error_flag;
  r += '\0';
  r += static_cast<char>(37);  // 12 + 16 + 4 + 4 + 1 body bytes
  r += '\0';
  for (int i = 0; i < 3; ++i) PutFloat(&r, position_in[i]);
  for (int i = 0; i < 4; ++i) PutFloat(&r, wxyz[i]);
  PutLe32(&r, time_ms);
  PutLe32(&r, stylus);
  r += ' ';
  return r;
}

PolhemusFormat VrpnLibertyFormat() {
  PolhemusFormat f;
  f.items = {PolhemusItem::kPosition, PolhemusItem::kQuaternion, PolhemusItem::kTimestamp,
             PolhemusItem::kStylus};
  f.unit = PolhemusUnit::kInch;
  return f;
}

// A recorded stream: `n` records for station 1.
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

TEST(PolhemusRecordsTest, LengthsAndCommandsAreVrpns) {
  // VRPN report_length(): 9 (8 header + 1 space) + 12 + 16 + 4 (timestamp) + 4 (stylus or
  // frame count).
  EXPECT_EQ(VrpnLibertyFormat().RecordBytes(), 45u);
  PolhemusFormat hs;
  hs.items = {PolhemusItem::kPosition, PolhemusItem::kQuaternion, PolhemusItem::kTimestamp,
              PolhemusItem::kFrameCount};
  EXPECT_EQ(hs.RecordBytes(), 45u);
  EXPECT_EQ(hs.ConfigurationCommands()[2], "O*,2,7,8,9,0\r");  // vrpn_Tracker_LibertyHS.C
  const std::vector<std::string> commands = VrpnLibertyFormat().ConfigurationCommands();
  ASSERT_EQ(commands.size(), 4u);
  EXPECT_EQ(commands[0], "F1\r");  // binary
  EXPECT_EQ(commands[1], "U0\r");  // inches
  EXPECT_EQ(commands[2], "O*,2,7,8,10,0\r");
  EXPECT_EQ(commands[3], "C\r");  // continuous
  PolhemusFormat twice;
  twice.items = {PolhemusItem::kPosition, PolhemusItem::kPosition};
  EXPECT_EQ(twice.Check().code(), StatusCode::kInvalidArgument);
  PolhemusFormat empty;
  empty.items.clear();
  EXPECT_EQ(empty.Check().code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(PolhemusFormat{}.Check().ok());
}

TEST(PolhemusRecordsTest, ParsesRecordsBuiltFromVrpnsDescription) {
  const float position_in[3] = {10.0f, -5.5f, 20.25f};
  const double h = std::sqrt(0.5);
  const float wxyz[4] = {static_cast<float>(h), 0.0f, static_cast<float>(h), 0.0f};
  std::string bytes = VrpnLibertyRecord(1, position_in, wxyz, 1500, 0) +
                      VrpnLibertyRecord(2, position_in, wxyz, 1504, 1, ' ', "PA") +
                      VrpnLibertyRecord(16, position_in, wxyz, 1508, 7, ' ', "LU");
  PolhemusRecordParser parser(VrpnLibertyFormat());
  std::vector<TrackerSample> out;
  parser.Feed(bytes, &out);
  ASSERT_EQ(out.size(), 3u);
  EXPECT_EQ(parser.counters().Dropped(), 0u);
  EXPECT_EQ(parser.pending_bytes(), 0u);
  const Eigen::Vector3d expected_m(10.0 * kInch_m, -5.5 * kInch_m, 20.25 * kInch_m);
  for (const TrackerSample& s : out) {
    EXPECT_LT((s.tracker_from_sensor.translation - expected_m).norm(), kPositionTolerance_m);
    // w x y z on the wire = Eigen (w, x, y, z): 90 degrees about y.
    const Eigen::Vector3d x_in_tracker = s.tracker_from_sensor.rotation * Eigen::Vector3d::UnitX();
    EXPECT_LT((x_in_tracker - Eigen::Vector3d(0, 0, -1)).norm(), kRotationTolerance_rad);
  }
  EXPECT_EQ(out[0].sensor_index, 0u);
  EXPECT_EQ(out[1].sensor_index, 1u);
  EXPECT_EQ(out[2].sensor_index, 15u);
  EXPECT_DOUBLE_EQ(out[0].source_time_s, 1.5);  // timestamp in ms
  EXPECT_FALSE(out[0].button_pressed);
  EXPECT_TRUE(out[1].button_pressed);
  EXPECT_TRUE(out[2].button_pressed);  // any non-zero stylus word
  // EncodeRecord writes the same bytes as the description.
  TrackerSample s = out[0];
  EXPECT_EQ(PolhemusRecordParser::EncodeRecord(VrpnLibertyFormat(), 1, s, 360),
            VrpnLibertyRecord(1, position_in, wxyz, 1500, 0));
}

TEST(PolhemusRecordsTest, ParsesAStreamInAnyChunking) {
  PolhemusFormat format;
  std::vector<TrackerSample> truth;
  const std::string bytes = Stream(format, 50, &truth);
  ASSERT_EQ(bytes.size(), 50 * format.RecordBytes());
  std::mt19937 rng(3);
  for (int trial = 0; trial < 20; ++trial) {
    PolhemusRecordParser parser(format);
    std::vector<TrackerSample> out;
    for (size_t at = 0; at < bytes.size();) {
      const size_t chunk = std::min<size_t>(1 + rng() % 97, bytes.size() - at);
      parser.Feed(std::string_view(bytes).substr(at, chunk), &out);
      EXPECT_LT(parser.pending_bytes(), format.RecordBytes());
      at += chunk;
    }
    ASSERT_EQ(out.size(), truth.size());
    for (size_t i = 0; i < out.size(); ++i) ExpectSame(out[i], truth[i]);
    EXPECT_EQ(out[0].sensor_index, 0u);
    EXPECT_EQ(parser.counters().Dropped(), 0u);
  }
}

// Every split of a record over two reads (including inside the tag and the header), and over
// three reads, yields the record once.
TEST(PolhemusRecordsTest, TornRecordsAreJoinedAcrossReads) {
  const PolhemusFormat format = VrpnLibertyFormat();
  std::vector<TrackerSample> truth;
  const std::string bytes = Stream(format, 2, &truth);
  const size_t record = format.RecordBytes();
  for (size_t cut = 1; cut < record; ++cut) {
    PolhemusRecordParser parser(format);
    std::vector<TrackerSample> out;
    parser.Feed(std::string_view(bytes).substr(0, cut), &out);
    EXPECT_TRUE(out.empty()) << cut;
    parser.Feed(std::string_view(bytes).substr(cut, record - cut + 3), &out);
    parser.Feed(std::string_view(bytes).substr(record + 3), &out);
    ASSERT_EQ(out.size(), 2u) << "cut at " << cut;
    ExpectSame(out[0], truth[0]);
    ExpectSame(out[1], truth[1]);
    EXPECT_EQ(parser.counters().Dropped(), 0u) << cut;
    EXPECT_EQ(parser.counters().resync_bytes, 0u) << cut;
  }
  // One byte at a time.
  PolhemusRecordParser parser(format);
  std::vector<TrackerSample> out;
  for (char c : bytes) parser.Feed(std::string_view(&c, 1), &out);
  EXPECT_EQ(out.size(), 2u);
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

// Garbage before, between and inside records: tag-like pairs with bad stations, a record cut
// short by a new one (the device restarted its output), a flagged record, bad values, random
// bytes. Every intact record after the garbage is found again.
TEST(PolhemusRecordsTest, StreamsResynchroniseAfterGarbage) {
  const PolhemusFormat format = VrpnLibertyFormat();
  std::vector<TrackerSample> truth;
  const std::string good = Stream(format, 10, &truth);
  const size_t record = format.RecordBytes();
  auto rec = [&](int i) { return good.substr(i * record, record); };
  std::mt19937 rng(17);
  std::string noise(300, '\0');
  for (char& c : noise) c = static_cast<char>(rng() & 0xff);
  std::string bad_values = rec(5);
  for (int k = 0; k < 16; ++k) bad_values[kPolhemusHeaderBytes + 12 + k] = 0x41;  // |q| != 1
  std::string flagged = rec(7);
  flagged[4] = 'E';
  const std::string lead("\x01\x02LY\x00\x00LU\x11PA", 11);  // NULs inside: sized
  std::string bytes = lead + rec(0) + "garbageLYLY" + rec(1) + rec(2).substr(0, 20) + rec(3) +
                      noise + rec(4) + bad_values + rec(6) + flagged + std::string("LY\x01", 3) +
                      rec(8) + rec(9);
  std::vector<int> expected = {0, 1, 3, 4, 6, 8, 9};
  for (size_t chunk : {bytes.size(), size_t{1}, size_t{7}, size_t{44}}) {
    PolhemusRecordParser parser(format);
    std::vector<TrackerSample> out;
    for (size_t at = 0; at < bytes.size(); at += chunk) {
      parser.Feed(std::string_view(bytes).substr(at, chunk), &out);
    }
    parser.Finish();
    // Random noise may, rarely, hold a valid-looking record; this seed's does not.
    ASSERT_EQ(out.size(), expected.size()) << "chunk " << chunk;
    for (size_t i = 0; i < expected.size(); ++i) ExpectSame(out[i], truth[expected[i]]);
    EXPECT_EQ(parser.counters().device_errors, 1u);
    EXPECT_EQ(parser.counters().bad_values, 1u);
    EXPECT_GE(parser.counters().bad_station, 2u);     // "LY\0" and "LU\x11"
    EXPECT_GE(parser.counters().bad_terminator, 1u);  // the record cut short by record 3
    EXPECT_GT(parser.counters().resync_bytes, noise.size() / 2);
  }
}

TEST(PolhemusRecordsTest, CentimetresAndFrameCountsConvertToMetresAndSeconds) {
  PolhemusFormat format;
  format.unit = PolhemusUnit::kCentimetre;
  format.items = {PolhemusItem::kFrameCount, PolhemusItem::kPosition, PolhemusItem::kQuaternion};
  const TrackerSample s = MakeSample(7, false);
  PolhemusRecordParser parser(format);
  std::vector<TrackerSample> out;
  parser.Feed(PolhemusRecordParser::EncodeRecord(format, 3, s, 480, ' ', "PA"), &out);
  ASSERT_EQ(out.size(), 1u);
  ExpectSame(out[0], s);
  EXPECT_EQ(out[0].sensor_index, 2u);
  EXPECT_DOUBLE_EQ(out[0].source_time_s, 2.0);  // 480 frames at 240 Hz
  EXPECT_EQ(format.ConfigurationCommands()[1], "U1\r");
  // A zero error byte is also taken as "no error".
  std::vector<TrackerSample> more;
  parser.Feed(PolhemusRecordParser::EncodeRecord(format, 3, s, 481, 0), &more);
  EXPECT_EQ(more.size(), 1u);
}

TEST(PolhemusRecordsTest, RandomBytesNeverCrashAndYieldNoBogusSamples) {
  PolhemusFormat format;
  std::mt19937 rng(99);
  PolhemusRecordParser parser(format);
  std::vector<TrackerSample> out;
  std::string noise(1 << 16, '\0');
  for (char& c : noise) c = static_cast<char>(rng() & 0xff);
  parser.Feed(noise, &out);
  EXPECT_LT(parser.pending_bytes(), format.RecordBytes());
  parser.Finish();
  for (const TrackerSample& s : out) {  // anything accepted passed the value checks
    EXPECT_LE(s.tracker_from_sensor.translation.norm(), kMaxPosition_m);
  }
  EXPECT_LT(out.size(), 3u);
}

}  // namespace
}  // namespace sandtable::coordinator
