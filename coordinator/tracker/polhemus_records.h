// Parser of Polhemus binary motion records (Liberty / Liberty HS / Patriot / Patriot HS family
// "P-frame" layout), as a byte stream arrives from USB.
//
// IMPLEMENTED LAYOUT (from the vendors' published description of the binary output format;
// NOT verified against hardware, see docs/tracker-formats.md):
//   header, 8 bytes:
//     0-1  ASCII tag of the family: "LY" (Liberty, Liberty HS) or "PA" (Patriot, Patriot HS)
//     2    station number, 1-based (1..16)
//     3    initiating command (ASCII, 'C' continuous or 'P' single)
//     4    error code (0 = none; other values: the device reports a problem, sample dropped)
//     5    reserved
//     6-7  payload size in bytes, uint16 little-endian
//   payload, the configured output items in order, little-endian:
//     kPosition    3 x float32  x y z in the configured unit (U0 inches, U1 centimetres)
//     kQuaternion  4 x float32  w x y z (sensor -> transmitter rotation)
//     kFrameCount  1 x uint32
//     kStylus      1 x uint32   stylus button, 0 = up, 1 = pressed
// Output: TrackerSample with tracker_from_sensor in metres, quaternion (w, x, y, z) normalised,
// sensor_index = station - 1.
// Robustness: unknown tags are skipped byte by byte until a tag is found (resync); a record
// whose payload size does not match the configured items, whose station is out of range, or
// whose numbers are not finite / out of range (|position| > kMaxPosition_m, |q| not within
// kQuaternionNormTolerance of 1) is dropped and counted; a truncated record waits for more
// bytes (Finish() counts it when the stream ends). Never aborts; memory bounded by one record.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "coordinator/tracker/tracker_source.h"

namespace sandtable::coordinator {

enum class PolhemusItem { kPosition, kQuaternion, kFrameCount, kStylus };
enum class PolhemusUnit { kInch, kCentimetre };

constexpr size_t kPolhemusHeaderBytes = 8;
constexpr double kMaxPosition_m = 10.0;
constexpr double kPolhemusQuaternionNormTolerance = 1e-2;

struct PolhemusFormat {
  std::vector<PolhemusItem> items = {PolhemusItem::kPosition, PolhemusItem::kQuaternion,
                                     PolhemusItem::kStylus};
  PolhemusUnit unit = PolhemusUnit::kCentimetre;
  size_t PayloadBytes() const;
  // The ASCII commands that put a device in this format and start streaming (each ends with
  // CR): binary output, units, output list for all stations, continuous mode.
  std::vector<std::string> ConfigurationCommands() const;
};

struct PolhemusParserCounters {
  uint64_t records = 0;       // valid records turned into samples
  uint64_t resync_bytes = 0;  // bytes skipped looking for a header
  uint64_t bad_size = 0;      // payload size differs from the configured items
  uint64_t bad_station = 0;
  uint64_t bad_values = 0;     // non-finite, out of range, non-unit quaternion
  uint64_t device_errors = 0;  // error byte != 0
  uint64_t truncated = 0;      // incomplete record at Finish()
  uint64_t Dropped() const {
    return bad_size + bad_station + bad_values + device_errors + truncated;
  }
};

class PolhemusRecordParser {
 public:
  explicit PolhemusRecordParser(PolhemusFormat format = {});
  // Consumes bytes; appends complete valid records as samples (source_time_s: frame count /
  // rate when kFrameCount is configured, else 0).
  void Feed(std::string_view bytes, std::vector<TrackerSample>* out);
  // End of stream: a pending partial record is counted as truncated and dropped.
  void Finish();
  const PolhemusParserCounters& counters() const { return counters_; }
  // Builds one record in the implemented layout (tests, the fake device).
  static std::string EncodeRecord(const PolhemusFormat& format, uint8_t station,
                                  const TrackerSample& sample, uint32_t frame_count,
                                  uint8_t error_code = 0, const char tag[2] = "LY");

 private:
  bool ParsePayload(uint8_t station, std::string_view payload, TrackerSample* sample);
  PolhemusFormat format_;
  std::string buffer_;
  PolhemusParserCounters counters_;
};

}  // namespace sandtable::coordinator
