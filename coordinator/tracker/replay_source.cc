#include "coordinator/tracker/replay_source.h"

#include <cmath>
#include <fstream>
#include <iomanip>
#include <sstream>

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

Expected<std::vector<TrackerSample>> LoadFastrakTraj(const std::string& path) {
  std::ifstream in(path);
  if (!in) return IoError("tracker replay " + path + ": cannot open");
  std::vector<TrackerSample> samples;
  std::string line;
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
    samples.push_back(s);
    values.clear();
    return OkStatus();
  };
  while (std::getline(in, line)) {
    ++line_number;
    std::istringstream words(line);
    std::string word;
    bool any = false;
    while (words >> word) {
      if (values.empty() && !any) block_start_line = line_number;
      any = true;
      char* end = nullptr;
      const double v = std::strtod(word.c_str(), &end);
      if (end == word.c_str() || *end != '\0') {
        return ParseError(path + ": line " + std::to_string(line_number) + ": \"" + word +
                          "\" is not a number");
      }
      values.push_back(v);
    }
    if (!any) ST_RETURN_IF_ERROR(flush());
  }
  ST_RETURN_IF_ERROR(flush());
  if (samples.empty()) return ParseError(path + ": no samples");
  return samples;
}

Expected<std::vector<TrackerSample>> LoadTrackerCsv(const std::string& path) {
  std::ifstream in(path);
  if (!in) return IoError("tracker replay " + path + ": cannot open");
  std::string line;
  const std::string kHeader = "time_s,sensor,x_m,y_m,z_m,qw,qx,qy,qz,button";
  if (!std::getline(in, line) || line.substr(0, kHeader.size()) != kHeader) {
    return ParseError(path + ": line 1 must be the header " + kHeader);
  }
  std::vector<TrackerSample> samples;
  for (int line_number = 2; std::getline(in, line); ++line_number) {
    if (line.empty()) continue;
    std::istringstream fields(line);
    double v[10];
    std::string field;
    int n = 0;
    for (; n < 10 && std::getline(fields, field, ','); ++n) {
      char* end = nullptr;
      v[n] = std::strtod(field.c_str(), &end);
      if (end == field.c_str() || !std::isfinite(v[n])) {
        return ParseError(path + ": line " + std::to_string(line_number) + ": field " +
                          std::to_string(n + 1) + " \"" + field + "\" is not a finite number");
      }
    }
    const std::string where = path + ": line " + std::to_string(line_number);
    if (n != 10) return ParseError(where + ": 10 fields expected");
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
    TrackerSample s;
    s.source_time_s = v[0];
    s.sensor_index = static_cast<uint32_t>(v[1]);
    s.tracker_from_sensor = Rigid3d(q, Eigen::Vector3d(v[2], v[3], v[4]));
    s.button_pressed = v[9] != 0.0;
    samples.push_back(s);
  }
  if (samples.empty()) return ParseError(path + ": no samples");
  return samples;
}

Status WriteTrackerCsv(const std::string& path, const std::vector<TrackerSample>& samples) {
  std::ofstream out(path, std::ios::trunc);
  if (!out) return IoError(path + ": cannot open for writing");
  out << "time_s,sensor,x_m,y_m,z_m,qw,qx,qy,qz,button\n" << std::setprecision(9);
  for (const TrackerSample& s : samples) {
    const Eigen::Quaterniond& q = s.tracker_from_sensor.rotation;
    const Eigen::Vector3d& t = s.tracker_from_sensor.translation;
    out << s.source_time_s << ',' << s.sensor_index << ',' << t.x() << ',' << t.y() << ',' << t.z()
        << ',' << q.w() << ',' << q.x() << ',' << q.y() << ',' << q.z() << ','
        << (s.button_pressed ? 1 : 0) << '\n';
  }
  if (!out) return IoError(path + ": write failed");
  return OkStatus();
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
