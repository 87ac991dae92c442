#include "coordinator/tracker/replay_source.h"

#include <cmath>
#include <cstdlib>
#include <iomanip>
#include <optional>
#include <sstream>

#include "common/base/file_io.h"

namespace sandtable::coordinator {

const char* TrackerStateName(TrackerState state) {
  switch (state) {
    case TrackerState::kNoDevice:
      return "no_device";
    case TrackerState::kConnecting:
      return "connecting";
    case TrackerState::kStreaming:
      return "streaming";
    case TrackerState::kEnded:
      return "ended";
    case TrackerState::kError:
      return "error";
  }
  return "unknown";
}

namespace {

// One line of `text` per call (without '\n', a trailing '\r' removed); false at the end.
bool NextLine(std::string_view text, size_t* at, std::string_view* line) {
  if (*at >= text.size()) return false;
  const size_t end = text.find('\n', *at);
  const size_t stop = end == std::string_view::npos ? text.size() : end;
  *line = text.substr(*at, stop - *at);
  if (!line->empty() && line->back() == '\r') line->remove_suffix(1);
  *at = stop == text.size() ? stop : stop + 1;
  return true;
}

// The number in `word` (whole word), or nullopt.
std::optional<double> ParseNumber(const std::string& word) {
  if (word.empty()) return std::nullopt;
  char* end = nullptr;
  const double v = std::strtod(word.c_str(), &end);
  if (end == word.c_str()) return std::nullopt;
  while (*end == ' ' || *end == '\t') ++end;
  if (*end != '\0') return std::nullopt;
  return v;
}

Status CheckCommonLimits(const std::string& where, const std::vector<TrackerSample>& samples,
                         const TrackerSample& s) {
  if (samples.size() >= kMaxTrackerReplaySamples) {
    return ParseError(where + ": more than kMaxTrackerReplaySamples (" +
                      std::to_string(kMaxTrackerReplaySamples) + ") samples");
  }
  if (s.tracker_from_sensor.translation.cwiseAbs().maxCoeff() > kMaxTrackerCoordinate_m) {
    return ParseError(where + ": position beyond kMaxTrackerCoordinate_m (" +
                      std::to_string(kMaxTrackerCoordinate_m) + " m)");
  }
  if (!samples.empty() &&
      s.source_time_s - samples.front().source_time_s > kMaxTrackerReplaySpan_s) {
    return ParseError(where + ": the samples span more than kMaxTrackerReplaySpan_s (" +
                      std::to_string(kMaxTrackerReplaySpan_s) + " s)");
  }
  return OkStatus();
}

}  // namespace

Expected<std::vector<TrackerSample>> ParseFastrakTraj(std::string_view text,
                                                      const std::string& path) {
  std::vector<TrackerSample> samples;
  std::string_view line;
  size_t at = 0;
  int line_number = 0;
  std::vector<double> values;
  int block_start_line = 1;
  auto flush = [&]() -> Status {
    if (values.empty()) return OkStatus();
    const std::string where = path + ": sample " + std::to_string(samples.size()) + " (line " +
                              std::to_string(block_start_line) + ")";
    if (values.size() != 16) {
      return ParseError(where + ": " + std::to_string(values.size()) +
                        " numbers, a sample is 4 lines of 4");
    }
    Eigen::Matrix4d m;
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c) m(r, c) = values[4 * r + c];
    if (!m.allFinite()) return ParseError(where + ": non-finite number");
    if (m(3, 0) != 0.0 || m(3, 1) != 0.0 || m(3, 2) != 0.0 || m(3, 3) != 1.0) {
      return ParseError(where + ": last row is not 0 0 0 1");
    }
    const Eigen::Matrix3d r = m.topLeftCorner<3, 3>();
    const double orthogonality =
        (r.transpose() * r - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
    if (orthogonality > kTrajRotationTolerance || r.determinant() < 0.0) {
      return ParseError(where + ": upper-left 3x3 is not a rotation (|R^T R - I| = " +
                        std::to_string(orthogonality) + ")");
    }
    TrackerSample s;
    s.tracker_from_sensor = Rigid3d(r, m.topRightCorner<3, 1>());
    s.source_time_s = static_cast<double>(samples.size()) / kFastrakTrajRate_hz;
    ST_RETURN_IF_ERROR(CheckCommonLimits(where, samples, s));
    samples.push_back(s);
    values.clear();
    return OkStatus();
  };
  while (NextLine(text, &at, &line)) {
    ++line_number;
    std::istringstream words{std::string(line)};
    std::string word;
    bool any = false;
    while (words >> word) {
      if (values.empty() && !any) block_start_line = line_number;
      any = true;
      const std::optional<double> v = ParseNumber(word);
      if (!v) {
        return ParseError(path + ": line " + std::to_string(line_number) + ": \"" +
                          word.substr(0, 40) + "\" is not a number");
      }
      if (values.size() == 16) {
        return ParseError(path + ": sample " + std::to_string(samples.size()) + " (line " +
                          std::to_string(block_start_line) +
                          "): more than 16 numbers, a sample is 4 lines of 4 then an empty line");
      }
      values.push_back(*v);
    }
    if (!any) ST_RETURN_IF_ERROR(flush());
  }
  ST_RETURN_IF_ERROR(flush());
  if (samples.empty()) return ParseError(path + ": no samples");
  return samples;
}

Expected<std::vector<TrackerSample>> LoadFastrakTraj(const std::string& path) {
  Expected<std::string> text =
      ReadInputFile(path, kMaxTrackerReplayBytes, "kMaxTrackerReplayBytes");
  if (!text.ok()) return text.status().WithContext("tracker replay");
  return ParseFastrakTraj(*text, path);
}

Expected<std::vector<TrackerSample>> ParseTrackerCsv(std::string_view text,
                                                     const std::string& path) {
  std::string_view line;
  size_t at = 0;
  const std::string kHeader = "time_s,sensor,x_m,y_m,z_m,qw,qx,qy,qz,button";
  if (!NextLine(text, &at, &line) || line.substr(0, kHeader.size()) != kHeader) {
    return ParseError(path + ": line 1 must be the header " + kHeader);
  }
  std::vector<TrackerSample> samples;
  for (int line_number = 2; NextLine(text, &at, &line); ++line_number) {
    if (line.empty()) continue;
    std::istringstream fields{std::string(line)};
    double v[10];
    std::string field;
    int n = 0;
    for (; n < 10 && std::getline(fields, field, ','); ++n) {
      const std::optional<double> value = ParseNumber(field);
      if (!value || !std::isfinite(*value)) {
        return ParseError(path + ": line " + std::to_string(line_number) + ": field " +
                          std::to_string(n + 1) + " \"" + field.substr(0, 40) +
                          "\" is not a finite number");
      }
      v[n] = *value;
    }
    const std::string where = path + ": line " + std::to_string(line_number);
    if (n != 10 || std::getline(fields, field, ',')) {
      return ParseError(where + ": 10 fields expected");
    }
    const Eigen::Quaterniond q(v[5], v[6], v[7], v[8]);
    if (std::abs(q.norm() - 1.0) > kCsvQuaternionTolerance) {
      return ParseError(where + ": quaternion norm " + std::to_string(q.norm()) + " is not 1");
    }
    if (!samples.empty() && v[0] < samples.back().source_time_s) {
      return ParseError(where + ": time_s goes backwards");
    }
    if (v[1] < 0 || v[1] > 255 || v[1] != std::floor(v[1])) {
      return ParseError(where + ": sensor must be an integer 0..255");
    }
    if (v[9] != 0.0 && v[9] != 1.0) return ParseError(where + ": button must be 0 or 1");
    TrackerSample s;
    s.source_time_s = v[0];
    s.sensor_index = static_cast<uint32_t>(v[1]);
    s.tracker_from_sensor = Rigid3d(q.normalized(), Eigen::Vector3d(v[2], v[3], v[4]));
    s.button_pressed = v[9] != 0.0;
    ST_RETURN_IF_ERROR(CheckCommonLimits(where, samples, s));
    samples.push_back(s);
  }
  if (samples.empty()) return ParseError(path + ": no samples");
  return samples;
}

Expected<std::vector<TrackerSample>> LoadTrackerCsv(const std::string& path) {
  Expected<std::string> text =
      ReadInputFile(path, kMaxTrackerReplayBytes, "kMaxTrackerReplayBytes");
  if (!text.ok()) return text.status().WithContext("tracker replay");
  return ParseTrackerCsv(*text, path);
}

Status WriteTrackerCsv(const std::string& path, const std::vector<TrackerSample>& samples) {
  std::ostringstream out;
  out << "time_s,sensor,x_m,y_m,z_m,qw,qx,qy,qz,button\n" << std::setprecision(9);
  for (const TrackerSample& s : samples) {
    const Eigen::Quaterniond& q = s.tracker_from_sensor.rotation;
    const Eigen::Vector3d& t = s.tracker_from_sensor.translation;
    out << s.source_time_s << ',' << s.sensor_index << ',' << t.x() << ',' << t.y() << ',' << t.z()
        << ',' << q.w() << ',' << q.x() << ',' << q.y() << ',' << q.z() << ','
        << (s.button_pressed ? 1 : 0) << '\n';
  }
  return WriteFileAtomically(path, out.str());
}

ReplaySource::ReplaySource(std::string name, std::vector<TrackerSample> samples, double rate_scale,
                           bool loop)
    : name_(std::move(name)), samples_(std::move(samples)), rate_scale_(rate_scale), loop_(loop) {
  ST_CHECK(rate_scale_ > 0.0) << "ReplaySource: rate_scale must be > 0";
  if (samples_.size() >= 2) {
    const double span_s = samples_.back().source_time_s - samples_.front().source_time_s;
    if (span_s > 0.0) rate_hz_ = static_cast<double>(samples_.size() - 1) / span_s;
  }
}

Status ReplaySource::Poll(TrackerClock::time_point now, std::vector<TrackerSample>* out) {
  if (samples_.empty()) return OkStatus();
  if (!started_) {
    started_ = true;
    start_ = now;
  }
  const double elapsed_s = std::chrono::duration<double>(now - start_).count() * rate_scale_;
  const double t0_s = samples_.front().source_time_s;
  const double span_s =
      samples_.back().source_time_s - t0_s + (rate_hz_ > 0 ? 1.0 / rate_hz_ : 0.0);
  while (true) {
    if (next_ >= samples_.size()) {
      if (!loop_ || span_s <= 0.0) return OkStatus();
      next_ = 0;
      loop_offset_s_ += span_s;
    }
    const double due_s = samples_[next_].source_time_s - t0_s + loop_offset_s_;
    if (due_s > elapsed_s) return OkStatus();
    out->push_back(samples_[next_++]);
    ++emitted_total_;
  }
}

TrackerState ReplaySource::state() const {
  if (samples_.empty()) return TrackerState::kError;
  if (!loop_ && next_ >= samples_.size()) return TrackerState::kEnded;
  return TrackerState::kStreaming;
}

std::string ReplaySource::Describe() const {
  std::ostringstream s;
  s << "replay " << name_ << ", " << samples_.size() << " samples at " << rate_hz_ << " Hz x"
    << rate_scale_ << (loop_ ? ", looping" : "");
  return s.str();
}

}  // namespace sandtable::coordinator
