#include "coordinator/tracker/polhemus_records.h"

#include <cmath>
#include <cstring>

namespace sandtable::coordinator {
namespace {

constexpr double kMPerCm = 0.01;
constexpr double kMPerInch = 0.0254;
constexpr char kTerminator = ' ';

bool IsTag(const char* p) {
  return (p[0] == 'L' && (p[1] == 'Y' || p[1] == 'U')) || (p[0] == 'P' && p[1] == 'A');
}

uint32_t ReadU32(const char* p) {
  return static_cast<uint32_t>(static_cast<uint8_t>(p[0])) |
         static_cast<uint32_t>(static_cast<uint8_t>(p[1])) << 8 |
         static_cast<uint32_t>(static_cast<uint8_t>(p[2])) << 16 |
         static_cast<uint32_t>(static_cast<uint8_t>(p[3])) << 24;
}
float ReadF32(const char* p) {
  const uint32_t bits = ReadU32(p);
  float v;
  std::memcpy(&v, &bits, 4);
  return v;
}
void PutU32(std::string* out, uint32_t v) {
  for (int i = 0; i < 4; ++i) out->push_back(static_cast<char>((v >> (8 * i)) & 0xff));
}
void PutF32(std::string* out, float f) {
  uint32_t bits;
  std::memcpy(&bits, &f, 4);
  PutU32(out, bits);
}

size_t ItemBytes(PolhemusItem item) {
  switch (item) {
    case PolhemusItem::kPosition:
      return 12;
    case PolhemusItem::kQuaternion:
      return 16;
    case PolhemusItem::kTimestamp:
    case PolhemusItem::kFrameCount:
    case PolhemusItem::kStylus:
      return 4;
  }
  return 0;
}

// Output-list codes of the Liberty/Patriot command set, as VRPN's drivers send them.
const char* ItemCode(PolhemusItem item) {
  switch (item) {
    case PolhemusItem::kPosition:
      return "2";
    case PolhemusItem::kQuaternion:
      return "7";
    case PolhemusItem::kTimestamp:
      return "8";
    case PolhemusItem::kFrameCount:
      return "9";
    case PolhemusItem::kStylus:
      return "10";
  }
  return "";
}

}  // namespace

Status PolhemusFormat::Check() const {
  if (items.empty()) return InvalidArgumentError("polhemus format: empty output item list");
  if (items.size() > kPolhemusMaxItems) {
    return InvalidArgumentError("polhemus format: more than kPolhemusMaxItems (" +
                                std::to_string(kPolhemusMaxItems) + ") output items");
  }
  for (size_t i = 0; i < items.size(); ++i) {
    for (size_t j = i + 1; j < items.size(); ++j) {
      if (items[i] == items[j]) {
        return InvalidArgumentError(std::string("polhemus format: output item ") +
                                    ItemCode(items[i]) + " listed twice");
      }
    }
  }
  return OkStatus();
}

size_t PolhemusFormat::PayloadBytes() const {
  size_t n = kPolhemusTerminatorBytes;
  for (PolhemusItem item : items) n += ItemBytes(item);
  return n;
}

std::vector<std::string> PolhemusFormat::ConfigurationCommands() const {
  std::string list = "O*";
  for (PolhemusItem item : items) list += std::string(",") + ItemCode(item);
  list += ",0";  // the space terminator
  return {"F1\r", unit == PolhemusUnit::kCentimetre ? "U1\r" : "U0\r", list + "\r", "C\r"};
}

PolhemusRecordParser::PolhemusRecordParser(PolhemusFormat format) : format_(std::move(format)) {}

bool PolhemusRecordParser::ParsePayload(uint8_t station, std::string_view payload,
                                        TrackerSample* sample) const {
  const double m_per_unit = format_.unit == PolhemusUnit::kCentimetre ? kMPerCm : kMPerInch;
  const char* p = payload.data();
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
  bool have_timestamp = false;
  for (PolhemusItem item : format_.items) {
    switch (item) {
      case PolhemusItem::kPosition:
        position_m = Eigen::Vector3d(ReadF32(p), ReadF32(p + 4), ReadF32(p + 8)) * m_per_unit;
        break;
      case PolhemusItem::kQuaternion:
        q = Eigen::Quaterniond(ReadF32(p), ReadF32(p + 4), ReadF32(p + 8), ReadF32(p + 12));
        break;
      case PolhemusItem::kTimestamp:
        sample->source_time_s = ReadU32(p) / 1000.0;
        have_timestamp = true;
        break;
      case PolhemusItem::kFrameCount:
        if (!have_timestamp) sample->source_time_s = ReadU32(p) / kPolhemusFrameRate_hz;
        break;
      case PolhemusItem::kStylus:
        sample->button_pressed = ReadU32(p) != 0;
        break;
    }
    p += ItemBytes(item);
  }
  if (!position_m.allFinite() || position_m.norm() > kMaxPosition_m || !q.coeffs().allFinite() ||
      std::abs(q.norm() - 1.0) > kPolhemusQuaternionNormTolerance) {
    return false;
  }
  sample->sensor_index = station - 1u;
  sample->tracker_from_sensor = Rigid3d(q.normalized(), position_m);
  return true;
}

void PolhemusRecordParser::Feed(std::string_view bytes, std::vector<TrackerSample>* out) {
  buffer_.append(bytes);
  size_t at = 0;
  const size_t record_bytes = format_.RecordBytes();
  while (buffer_.size() - at >= 2) {
    const char* h = buffer_.data() + at;
    if (!IsTag(h)) {
      ++at;
      ++counters_.resync_bytes;
      continue;
    }
    if (buffer_.size() - at < kPolhemusHeaderBytes) break;  // torn header: wait
    const uint8_t station = static_cast<uint8_t>(h[2]);
    if (station < 1 || station > kPolhemusMaxStations) {
      // Decided from the header alone, so noise with a tag-like pair costs no wait.
      ++counters_.bad_station;
      at += 2;
      continue;
    }
    if (buffer_.size() - at < record_bytes) break;  // torn body: wait for the rest
    if (h[record_bytes - 1] != kTerminator) {
      // Not a record of the configured format, or a tag-like pair inside noise: skip the tag.
      ++counters_.bad_terminator;
      at += 2;
      continue;
    }
    const uint8_t error = static_cast<uint8_t>(h[4]);
    if (error != static_cast<uint8_t>(' ') && error != 0) {
      ++counters_.device_errors;
      at += record_bytes;
      continue;
    }
    TrackerSample sample;
    const std::string_view payload(h + kPolhemusHeaderBytes, record_bytes - kPolhemusHeaderBytes);
    if (!ParsePayload(station, payload, &sample)) {
      ++counters_.bad_values;
      at += 2;
      continue;
    }
    out->push_back(sample);
    ++counters_.records;
    at += record_bytes;
  }
  buffer_.erase(0, at);
}

void PolhemusRecordParser::Finish() {
  if (!buffer_.empty()) ++counters_.truncated;
  buffer_.clear();
}

std::string PolhemusRecordParser::EncodeRecord(const PolhemusFormat& format, uint8_t station,
                                               const TrackerSample& sample, uint32_t frame_count,
                                               uint8_t error_flag, const char tag[2]) {
  std::string out;
  out.push_back(tag[0]);
  out.push_back(tag[1]);
  out.push_back(static_cast<char>(station));
  out.push_back('C');
  out.push_back(static_cast<char>(error_flag));
  out.push_back(0);
  const size_t size = format.PayloadBytes();
  out.push_back(static_cast<char>(size & 0xff));
  out.push_back(static_cast<char>(size >> 8));
  const double unit_per_m =
      format.unit == PolhemusUnit::kCentimetre ? 1.0 / kMPerCm : 1.0 / kMPerInch;
  const Eigen::Vector3d& t = sample.tracker_from_sensor.translation;
  const Eigen::Quaterniond& q = sample.tracker_from_sensor.rotation;
  for (PolhemusItem item : format.items) {
    switch (item) {
      case PolhemusItem::kPosition:
        for (int i = 0; i < 3; ++i) PutF32(&out, static_cast<float>(t[i] * unit_per_m));
        break;
      case PolhemusItem::kQuaternion:
        PutF32(&out, static_cast<float>(q.w()));
        PutF32(&out, static_cast<float>(q.x()));
        PutF32(&out, static_cast<float>(q.y()));
        PutF32(&out, static_cast<float>(q.z()));
        break;
      case PolhemusItem::kTimestamp:
        PutU32(&out,
               static_cast<uint32_t>(std::llround(frame_count * 1000.0 / kPolhemusFrameRate_hz)));
        break;
      case PolhemusItem::kFrameCount:
        PutU32(&out, frame_count);
        break;
      case PolhemusItem::kStylus:
        PutU32(&out, sample.button_pressed ? 1u : 0u);
        break;
    }
  }
  out.push_back(kTerminator);
  return out;
}

}  // namespace sandtable::coordinator
