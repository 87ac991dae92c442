// Parser of Polhemus binary motion records (Liberty, Liberty Latus, Patriot family), as a byte
// stream arrives from USB.
//
// LAYOUT, checked against VRPN's drivers for these devices (vrpn_Tracker_Liberty.C,
// vrpn_Tracker_LibertyHS.C; what matched and what was corrected: docs/tracker-formats.md):
//   header, 8 bytes:
//     0-1  ASCII tag: "LY" (Liberty), "PA" (Patriot), "LU" (Liberty Latus)
//     2    station number, binary, 1-based (1..kPolhemusMaxStations)
//     3    initiating command (ASCII, 'C' continuous or 'P' single)
//     4    error flag: ' ' (0x20) = none; anything else: the device flags the record
//     5    reserved
//     6-7  response size, uint16 little-endian (VRPN does not read it; neither do we: the
//          record length is fixed by the configured output list, as in VRPN)
//   body, the configured output items in order (output-list code), little-endian:
//     kPosition    (2)  3 x float32  x y z in the configured unit (U0 inches, U1 centimetres)
//     kQuaternion  (7)  4 x float32  w x y z (sensor -> transmitter rotation)
//     kTimestamp   (8)  1 x uint32   milliseconds since the device's clock was reset
//     kFrameCount  (9)  1 x uint32
//     kStylus      (10) 1 x uint32   stylus button, 0 = up, non-zero = pressed
//   then always (code 0) one ASCII space, the record terminator VRPN checks.
// Output: TrackerSample with tracker_from_sensor in metres, quaternion (w, x, y, z) normalised,
// sensor_index = station - 1, source_time_s from the timestamp (ms / 1000) if configured, else
// the frame count / kPolhemusFrameRate_hz, else 0.
// Robustness: bytes are skipped one by one until a tag (resync); a candidate record whose
// station is out of range, whose last byte is not the space terminator, or whose numbers are
// not finite / out of range (|position| > kMaxPosition_m, |q| not within
// kPolhemusQuaternionNormTolerance of 1) is dropped and counted, and the search resumes after
// its tag (never by trusting a length from the stream); a record the device flags (error byte
// not ' ' or 0) is dropped and counted whole; a torn record waits for more bytes (Finish()
// counts it when the stream ends). Never aborts; memory bounded by one record plus one Feed().
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "coordinator/tracker/tracker_source.h"

namespace sandtable::coordinator {

enum class PolhemusItem { kPosition, kQuaternion, kTimestamp, kFrameCount, kStylus };
enum class PolhemusUnit { kInch, kCentimetre };

constexpr size_t kPolhemusHeaderBytes = 8;
constexpr size_t kPolhemusTerminatorBytes = 1;  // the ' ' of output item 0
constexpr uint8_t kPolhemusMaxStations = 16;
constexpr double kMaxPosition_m = 10.0;
constexpr double kPolhemusQuaternionNormTolerance = 1e-2;
constexpr double kPolhemusFrameRate_hz = 240.0;  // Liberty's nominal rate, for frame-count times
// At most this many items in an output list (each item once).
constexpr size_t kPolhemusMaxItems = 5;

struct PolhemusFormat {
  std::vector<PolhemusItem> items = {PolhemusItem::kPosition, PolhemusItem::kQuaternion,
                                     PolhemusItem::kStylus};
  // Inches are the devices' power-up unit and what VRPN's Liberty driver reads.
  PolhemusUnit unit = PolhemusUnit::kInch;
  // INVALID_ARGUMENT: empty list, an item twice, more than kPolhemusMaxItems.
  Status Check() const;
  // Bytes of the body: the items plus the terminator.
  size_t PayloadBytes() const;
  size_t RecordBytes() const { return kPolhemusHeaderBytes + PayloadBytes(); }
  // The ASCII commands that put a device in this format and start streaming (each ends with
  // CR): binary output, units, output list for all stations ending in 0 (space), continuous.
  std::vector<std::string> ConfigurationCommands() const;
};

struct PolhemusParserCounters {
  uint64_t records = 0;         // valid records turned into samples
  uint64_t resync_bytes = 0;    // bytes skipped looking for a tag
  uint64_t bad_terminator = 0;  // no ' ' where the configured record ends
  uint64_t bad_station = 0;
  uint64_t bad_values = 0;     // non-finite, out of range, non-unit quaternion
  uint64_t device_errors = 0;  // error flag not ' ' (or 0)
  uint64_t truncated = 0;      // incomplete record at Finish()
  uint64_t Dropped() const {
    return bad_terminator + bad_station + bad_values + device_errors + truncated;
  }
};

class PolhemusRecordParser {
 public:
  // Any format parses safely; a device is configured only with one that passes Check().
  explicit PolhemusRecordParser(PolhemusFormat format = {});
  // Consumes bytes; appends complete valid records as samples.
  void Feed(std::string_view bytes, std::vector<TrackerSample>* out);
  // End of stream: a pending partial record is counted as truncated and dropped.
  void Finish();
  const PolhemusParserCounters& counters() const { return counters_; }
  // Bytes held back waiting for the rest of a record (< RecordBytes() after every Feed).
  size_t pending_bytes() const { return buffer_.size(); }
  // Builds one record in the layout above (tests, the fake device, fuzz seeds). The time
  // items carry `frame_count` (frame count) and `frame_count` * 1000 / kPolhemusFrameRate_hz
  // (timestamp, ms).
  static std::string EncodeRecord(const PolhemusFormat& format, uint8_t station,
                                  const TrackerSample& sample, uint32_t frame_count,
                                  uint8_t error_flag = ' ', const char tag[2] = "LY");

 private:
  bool ParsePayload(uint8_t station, std::string_view payload, TrackerSample* sample) const;
  PolhemusFormat format_;
  std::string buffer_;
  PolhemusParserCounters counters_;
};

}  // namespace sandtable::coordinator
