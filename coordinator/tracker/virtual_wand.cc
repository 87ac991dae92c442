#include "coordinator/tracker/virtual_wand.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <sstream>
#include <utility>

#include <Eigen/Geometry>

#include "common/base/check.h"
#include "common/base/file_io.h"

namespace sandtable::coordinator {
namespace {

constexpr double kEndSlack_s = 1e-9;  // t_k within this of t_last is still sampled

Status LineError(const std::string& name, int line, const std::string& field,
                 const std::string& cause) {
  return ParseError(name + ":" + std::to_string(line) + ": " + field + ": " + cause);
}

// Reads `n` finite numbers named `fields` from `in`, or a PARSE_ERROR naming the first bad one.
Status ReadNumbers(std::istringstream& in, const std::vector<const char*>& fields,
                   const std::string& name, int line, std::vector<double>* out) {
  out->clear();
  for (const char* field : fields) {
    std::string token;
    if (!(in >> token)) return LineError(name, line, field, "missing");
    char* end = nullptr;
    const double v = std::strtod(token.c_str(), &end);
    if (end == token.c_str() || *end != '\0') {
      return LineError(name, line, field, "'" + token + "' is not a number");
    }
    if (!std::isfinite(v)) return LineError(name, line, field, "'" + token + "' is not finite");
    out->push_back(v);
  }
  std::string extra;
  if (in >> extra) return LineError(name, line, "line", "unexpected extra token '" + extra + "'");
  return OkStatus();
}

Status CheckTime(const std::string& name, int line, double time_s) {
  if (std::abs(time_s) > kMaxVirtualWandTime_s) {
    return LineError(
        name, line, "time_s",
        "beyond kMaxVirtualWandTime_s (" + std::to_string(kMaxVirtualWandTime_s) + " s)");
  }
  return OkStatus();
}

// Sensor +x along `direction` (unit); deterministic for a given direction.
Eigen::Quaterniond SensorRotation(const Eigen::Vector3d& direction) {
  return Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitX(), direction);
}

}  // namespace

Expected<VirtualWandScript> ParseVirtualWandScript(const std::string& text,
                                                   const std::string& name) {
  VirtualWandScript script;
  std::istringstream lines(text);
  std::string raw;
  int line = 0;
  bool rate_seen = false;
  std::vector<double> v;
  while (std::getline(lines, raw)) {
    ++line;
    const size_t hash = raw.find('#');
    if (hash != std::string::npos) raw.resize(hash);
    std::istringstream in(raw);
    std::string keyword;
    if (!(in >> keyword)) continue;
    if (keyword == "rate_hz") {
      if (rate_seen || !script.waypoints.empty() || !script.button.empty()) {
        return LineError(name, line, "rate_hz", "must come once, before waypoints and buttons");
      }
      ST_RETURN_IF_ERROR(ReadNumbers(in, {"rate_hz"}, name, line, &v));
      if (!(v[0] > 0.0) || v[0] > kMaxVirtualWandRate_hz) {
        return LineError(name, line, "rate_hz", "must be in (0, 10000]");
      }
      script.rate_hz = v[0];
      rate_seen = true;
    } else if (keyword == "at") {
      ST_RETURN_IF_ERROR(
          ReadNumbers(in, {"time_s", "x_m", "y_m", "z_m", "dx", "dy", "dz"}, name, line, &v));
      VirtualWandWaypoint w;
      w.time_s = v[0];
      w.tip_in_table_m = Eigen::Vector3d(v[1], v[2], v[3]);
      w.direction_in_table = Eigen::Vector3d(v[4], v[5], v[6]);
      if (!(w.direction_in_table.norm() > 0.0)) {
        return LineError(name, line, "direction", "must be non-zero");
      }
      ST_RETURN_IF_ERROR(CheckTime(name, line, w.time_s));
      for (int i = 0; i < 3; ++i) {
        if (std::abs(w.tip_in_table_m[i]) > kMaxVirtualWandCoordinate_m) {
          return LineError(name, line, i == 0 ? "x_m" : (i == 1 ? "y_m" : "z_m"),
                           "beyond kMaxVirtualWandCoordinate_m (" +
                               std::to_string(kMaxVirtualWandCoordinate_m) + " m)");
        }
      }
      if (!script.waypoints.empty() && !(w.time_s > script.waypoints.back().time_s)) {
        return LineError(name, line, "time_s", "waypoint times must increase strictly");
      }
      script.waypoints.push_back(w);
    } else if (keyword == "down" || keyword == "up") {
      ST_RETURN_IF_ERROR(ReadNumbers(in, {"time_s"}, name, line, &v));
      ST_RETURN_IF_ERROR(CheckTime(name, line, v[0]));
      VirtualWandButtonEvent e{v[0], keyword == "down"};
      const bool was_down = !script.button.empty() && script.button.back().down;
      if (e.down == was_down) {
        return LineError(name, line, keyword,
                         e.down ? "button is already down" : "button is not down");
      }
      if (!script.button.empty() && e.time_s < script.button.back().time_s) {
        return LineError(name, line, "time_s", "button times must not decrease");
      }
      script.button.push_back(e);
    } else {
      return LineError(name, line, "keyword",
                       "unknown '" + keyword + "' (expected rate_hz, at, down or up)");
    }
  }
  if (script.waypoints.empty()) {
    return ParseError(name + ": no waypoints (add lines 'at T_s X_m Y_m Z_m DX DY DZ')");
  }
  const double span_s = script.waypoints.back().time_s - script.waypoints.front().time_s;
  if (span_s > kMaxVirtualWandSpan_s) {
    return ParseError(name + ": waypoints span " + std::to_string(span_s) +
                      " s, more than kMaxVirtualWandSpan_s (" +
                      std::to_string(kMaxVirtualWandSpan_s) + " s)");
  }
  const uint64_t samples = VirtualWandSampleCount(script);
  if (samples > kMaxVirtualWandSamples) {
    return ParseError(name + ": the script gives " + std::to_string(samples) +
                      " samples or more, more than kMaxVirtualWandSamples (" +
                      std::to_string(kMaxVirtualWandSamples) + "); lower rate_hz or the span");
  }
  return script;
}

uint64_t VirtualWandSampleCount(const VirtualWandScript& script) {
  if (script.waypoints.empty() || !(script.rate_hz > 0.0)) return 0;
  const double span_s = script.waypoints.back().time_s - script.waypoints.front().time_s;
  const double n = std::floor((span_s + kEndSlack_s) * script.rate_hz) + 1.0;
  if (!(n <= static_cast<double>(kMaxVirtualWandSamples))) return kMaxVirtualWandSamples + 1;
  return static_cast<uint64_t>(n);
}

Expected<VirtualWandScript> LoadVirtualWandScript(const std::string& path) {
  Expected<std::string> text =
      ReadInputFile(path, kMaxVirtualWandScriptBytes, "kMaxVirtualWandScriptBytes");
  if (!text.ok()) return text.status().WithContext("virtual wand script");
  return ParseVirtualWandScript(*text, path);
}

std::vector<TrackerSample> SampleVirtualWand(const VirtualWandScript& script) {
  ST_CHECK(!script.waypoints.empty()) << "SampleVirtualWand needs a parsed script";
  ST_CHECK(script.rate_hz > 0.0) << "SampleVirtualWand: rate_hz must be > 0";
  const std::vector<VirtualWandWaypoint>& w = script.waypoints;
  const double t_first = w.front().time_s;
  const double t_last = w.back().time_s;
  std::vector<TrackerSample> out;
  const uint64_t count = std::min(VirtualWandSampleCount(script), kMaxVirtualWandSamples);
  out.reserve(count);
  size_t segment = 0;  // w[segment].time_s <= t < w[segment + 1].time_s
  size_t button = 0;   // button events at or before t: [0, button)
  for (uint64_t k = 0; k < kMaxVirtualWandSamples; ++k) {
    // t_k from k (not accumulated) so the times carry no summed rounding error.
    const double t = t_first + static_cast<double>(k) / script.rate_hz;
    if (t > t_last + kEndSlack_s) break;
    while (segment + 1 < w.size() && w[segment + 1].time_s <= t) ++segment;
    Eigen::Vector3d tip = w[segment].tip_in_table_m;
    Eigen::Vector3d direction = w[segment].direction_in_table;
    if (segment + 1 < w.size()) {
      const double a = (t - w[segment].time_s) / (w[segment + 1].time_s - w[segment].time_s);
      tip = (1.0 - a) * w[segment].tip_in_table_m + a * w[segment + 1].tip_in_table_m;
      direction = (1.0 - a) * w[segment].direction_in_table + a * w[segment + 1].direction_in_table;
      // Opposite directions interpolate through zero: keep the nearer waypoint's direction.
      if (!(direction.norm() > 1e-12)) {
        direction = a < 0.5 ? w[segment].direction_in_table : w[segment + 1].direction_in_table;
      }
    }
    while (button < script.button.size() && script.button[button].time_s <= t) ++button;
    TrackerSample s;
    s.sensor_index = 0;
    s.tracker_from_sensor = Rigid3d(SensorRotation(direction.normalized()), tip);
    s.button_pressed = button > 0 && script.button[button - 1].down;
    s.source_time_s = t;
    out.push_back(s);
  }
  return out;
}

VirtualWandSource::VirtualWandSource(std::string name, const VirtualWandScript& script, bool loop)
    : VirtualWandSource(std::move(name), script.rate_hz, SampleVirtualWand(script), loop) {}

VirtualWandSource::VirtualWandSource(std::string name, double rate_hz,
                                     std::vector<TrackerSample> samples, bool loop)
    : name_(std::move(name)),
      rate_hz_(rate_hz),
      sample_count_(samples.size()),
      replay_(name_, std::move(samples), /*rate_scale=*/1.0, loop) {}

std::string VirtualWandSource::Describe() const {
  std::ostringstream out;
  out << "virtual wand " << name_ << " " << rate_hz_ << " Hz, " << sample_count_ << " samples";
  return out.str();
}

}  // namespace sandtable::coordinator
