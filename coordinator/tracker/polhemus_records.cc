#include "coordinator/tracker/polhemus_records.h"

#include <cmath>
#include <cstring>

namespace sandtable::coordinator {
namespace {

constexpr double kMPerCm = 0.01;
constexpr double kMPerInch = 0.0254;
constexpr double kFrameRate_hz = 240.0;  // Liberty's nominal rate, for frame-count times

bool IsTag(const char* p) { return (p[0] == 'L' && p[1] == 'Y') || (p[0] == 'P' && p[1] == 'A'); }

float ReadF32(const char* p) {
  uint32_t bits = static_cast<uint32_t>(static_cast<uint8_t>(p[0])) |
                  static_cast<uint32_t>(static_cast<uint8_t>(p[1])) << 8 |
                  static_cast<uint32_t>(static_cast<uint8_t>(p[2])) << 16 |
                  static_cast<uint32_t>(static_cast<uint8_t>(p[3])) << 24;
  float v;
  std::memcpy(&v, &bits, 4);
  return v;
}
uint32_t ReadU32(const char* p) {
  return static_cast<uint32_t>(static_cast<uint8_t>(p[0])) |
         static_cast<uint32_t>(static_cast<uint8_t>(p[1])) << 8 |
         static_cast<uint32_t>(static_cast<uint8_t>(p[2])) << 16 |
         static_cast<uint32_t>(static_cast<uint8_t>(p[3])) << 24;
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
    case PolhemusItem::kFrameCount:
      return 4;
    case PolhemusItem::kStylus:
      return 4;
  }
  return 0;
}

}  // namespace

size_t PolhemusFormat::PayloadBytes() const {
  size_t n = 0;
  for (PolhemusItem item : items) n += ItemBytes(item);
  return n;
}

std::vector<std::string> PolhemusFormat::ConfigurationCommands() const {
  // Liberty/Patriot output-list item codes: position 2, quaternion 7, frame count 9, stylus 16.
  std::string list = "O*";
  for (PolhemusItem item : items) {
    switch (item) {
      case PolhemusItem::kPosition:
        list += ",2";
        break;
      case PolhemusItem::kQuaternion:
        list += ",7";
        break;
      case PolhemusItem::kFrameCount:
        list += ",9";
        break;
      case PolhemusItem::kStylus:
        list += ",16";
        break;
    }
  }
  return {"F1\r", unit == PolhemusUnit::kCentimetre ? "U1\r" : "U0\r", list + "\r", "C\r"};
}

PolhemusRecordParser::PolhemusRecordParser(PolhemusFormat format) : format_(std::move(format)) {}

bool PolhemusRecordParser::ParsePayload(uint8_t station, std::string_view payload,
                                        TrackerSample* sample) {
  const double m_per_unit = format_.unit == PolhemusUnit::kCentimetre ? kMPerCm : kMPerInch;
  const char* p = payload.data();
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
  for (PolhemusItem item : format_.items) {
    switch (item) {
      case PolhemusItem::kPosition:
        position_m = Eigen::Vector3d(ReadF32(p), ReadF32(p + 4), ReadF32(p + 8)) * m_per_unit;
        break;
      case PolhemusItem::kQuaternion:
        q = Eigen::Quaterniond(ReadF32(p), ReadF32(p + 4), ReadF32(p + 8), ReadF32(p + 12));
        break;
      case PolhemusItem::kFrameCount:
        sample->source_time_s = ReadU32(p) / kFrameRate_hz;
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
  const size_t payload_bytes = format_.PayloadBytes();
  while (buffer_.size() - at >= 2) {
    if (!IsTag(buffer_.data() + at)) {
      ++at;
      ++counters_.resync_bytes;
      continue;
    }
    if (buffer_.size() - at < kPolhemusHeaderBytes) break;  // wait for the header
    const char* h = buffer_.data() + at;
    const uint8_t station = static_cast<uint8_t>(h[2]);
    const uint8_t error = static_cast<uint8_t>(h[4]);
    const size_t size = static_cast<uint8_t>(h[6]) | static_cast<size_t>(static_cast<uint8_t>(h[7]))
                                                         << 8;
    if (size != payload_bytes) {
      // Not a record of the configured format (or a tag-like byte pair inside noise): skip
      // the tag and resync; never trust the size field to skip ahead.
      ++counters_.bad_size;
      at += 2;
      continue;
    }
    if (buffer_.size() - at < kPolhemusHeaderBytes + size) break;  // wait for the payload
    const std::string_view payload(buffer_.data() + at + kPolhemusHeaderBytes, size);
    if (station < 1 || station > 16) {
      ++counters_.bad_station;
      at += 2;
      continue;
    }
    if (error != 0) {
      ++counters_.device_errors;
      at += kPolhemusHeaderBytes + size;
      continue;
    }
    TrackerSample sample;
    if (!ParsePayload(station, payload, &sample)) {
      ++counters_.bad_values;
      at += 2;
      continue;
    }
    out->push_back(sample);
    ++counters_.records;
    at += kPolhemusHeaderBytes + size;
  }
  buffer_.erase(0, at);
}

void PolhemusRecordParser::Finish() {
  if (!buffer_.empty()) ++counters_.truncated;
  buffer_.clear();
}

std::string PolhemusRecordParser::EncodeRecord(const PolhemusFormat& format, uint8_t station,
                                               const TrackerSample& sample, uint32_t frame_count,
                                               uint8_t error_code, const char tag[2]) {
  std::string out;
  out.push_back(tag[0]);
  out.push_back(tag[1]);
  out.push_back(static_cast<char>(station));
  out.push_back('C');
  out.push_back(static_cast<char>(error_code));
  out.push_back(0);
  const size_t size = format.PayloadBytes();
  out.push_back(static_cast<char>(size & 0xff));
  out.push_back(static_cast<char>(size >> 8));
  const double unit_per_m = format.unit == PolhemusUnit::kCentimetre ? 100.0 : 1.0 / 0.0254;
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
      case PolhemusItem::kFrameCount:
        PutU32(&out, frame_count);
        break;
      case PolhemusItem::kStylus:
        PutU32(&out, sample.button_pressed ? 1u : 0u);
        break;
    }
  }
  return out;
}

}  // namespace sandtable::coordinator
