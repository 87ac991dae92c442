// libFuzzer target over the tracker file and stream parsers (coordinator/tracker/), from
// bytes. The first byte picks the parser:
//   0 mod 4  Polhemus binary records (polhemus_records.h): byte 1 picks the output list and
//            unit, byte 2 the read size; the rest is the stream, fed in reads of that size
//   1 mod 4  FASTRAK .traj text (replay_source.h)
//   2 mod 4  tracker CSV text (replay_source.h)
//   3 mod 4  virtual-wand script (virtual_wand.h)
// Invariants: the parser never holds back a whole record; every sample is finite, within the
// documented position range, with a unit quaternion; a Polhemus sample re-encodes to a record
// that parses to the same station; a parsed wand script gives at most kMaxVirtualWandSamples.
// Seeds in tests/fuzz/tracker_files_corpus/ (crafted; see docs/reliability.md).
#include <cmath>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "common/base/check.h"
#include "coordinator/tracker/polhemus_records.h"
#include "coordinator/tracker/replay_source.h"
#include "coordinator/tracker/virtual_wand.h"

namespace {

using namespace sandtable;
using namespace sandtable::coordinator;

// Wand scripts sampled in full only up to this many samples (sampling is linear in them).
constexpr uint64_t kMaxFuzzWandSamples = 20000;
constexpr double kUnitQuaternionTolerance = 1e-6;
constexpr double kCoordinateRoundingSlack = 1e-9;  // relative: interpolation may round up

void CheckSample(const TrackerSample& s, double max_coordinate_m) {
  ST_CHECK(s.tracker_from_sensor.translation.allFinite());
  ST_CHECK(s.tracker_from_sensor.translation.cwiseAbs().maxCoeff() <=
           max_coordinate_m * (1.0 + kCoordinateRoundingSlack));
  ST_CHECK(std::abs(s.tracker_from_sensor.rotation.norm() - 1.0) < kUnitQuaternionTolerance);
  ST_CHECK(std::isfinite(s.source_time_s));
}

PolhemusFormat FormatFromByte(uint8_t b) {
  static const PolhemusItem kAll[] = {PolhemusItem::kPosition, PolhemusItem::kQuaternion,
                                      PolhemusItem::kTimestamp, PolhemusItem::kFrameCount,
                                      PolhemusItem::kStylus};
  PolhemusFormat f;
  f.items.clear();
  for (int i = 0; i < 5; ++i) {
    if (b & (1u << i)) f.items.push_back(kAll[i]);
  }
  if (f.items.empty()) f.items = PolhemusFormat{}.items;
  if (b & 0x20) std::swap(f.items.front(), f.items.back());
  f.unit = (b & 0x40) ? PolhemusUnit::kCentimetre : PolhemusUnit::kInch;
  return f;
}

void FuzzPolhemus(std::string_view bytes) {
  if (bytes.size() < 2) return;
  const PolhemusFormat format = FormatFromByte(static_cast<uint8_t>(bytes[0]));
  const size_t read = 1 + static_cast<uint8_t>(bytes[1]);
  bytes.remove_prefix(2);
  PolhemusRecordParser parser(format);
  std::vector<TrackerSample> out;
  for (size_t at = 0; at < bytes.size(); at += read) {
    parser.Feed(bytes.substr(at, read), &out);
    ST_CHECK(parser.pending_bytes() < format.RecordBytes());
  }
  parser.Finish();
  ST_CHECK(parser.pending_bytes() == 0);
  ST_CHECK(out.size() == parser.counters().records);
  for (const TrackerSample& s : out) {
    CheckSample(s, kMaxPosition_m);
    ST_CHECK(s.sensor_index < kPolhemusMaxStations);
    PolhemusRecordParser again(format);
    std::vector<TrackerSample> back;
    again.Feed(
        PolhemusRecordParser::EncodeRecord(format, static_cast<uint8_t>(s.sensor_index + 1), s, 0),
        &back);
    // A sample at the edge of the position range may round past it as float32: then dropped.
    ST_CHECK(back.size() <= 1);
    if (!back.empty()) ST_CHECK(back[0].sensor_index == s.sensor_index);
  }
}

void FuzzReplay(std::string_view text, bool csv) {
  Expected<std::vector<TrackerSample>> samples =
      csv ? ParseTrackerCsv(text, "fuzz.csv") : ParseFastrakTraj(text, "fuzz.traj");
  if (!samples.ok()) return;
  ST_CHECK(!samples->empty());
  ST_CHECK(samples->size() <= kMaxTrackerReplaySamples);
  for (const TrackerSample& s : *samples) {
    CheckSample(s, kMaxTrackerCoordinate_m);
    ST_CHECK(s.source_time_s - samples->front().source_time_s <= kMaxTrackerReplaySpan_s);
  }
}

void FuzzWand(std::string_view text) {
  Expected<VirtualWandScript> script = ParseVirtualWandScript(std::string(text), "fuzz.wand");
  if (!script.ok()) return;
  const uint64_t count = VirtualWandSampleCount(*script);
  ST_CHECK(count >= 1 && count <= kMaxVirtualWandSamples);
  if (count > kMaxFuzzWandSamples) return;
  const std::vector<TrackerSample> samples = SampleVirtualWand(*script);
  ST_CHECK(!samples.empty() && samples.size() <= count + 1);
  for (const TrackerSample& s : samples) CheckSample(s, kMaxVirtualWandCoordinate_m);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  // Past 1 MiB the parsers' cost, not their logic, is exercised.
  if (size < 1 || size > (1u << 20)) return 0;
  const std::string_view rest(reinterpret_cast<const char*>(data) + 1, size - 1);
  switch (data[0] % 4) {
    case 0:
      FuzzPolhemus(rest);
      break;
    case 1:
      FuzzReplay(rest, /*csv=*/false);
      break;
    case 2:
      FuzzReplay(rest, /*csv=*/true);
      break;
    default:
      FuzzWand(rest);
      break;
  }
  return 0;
}
