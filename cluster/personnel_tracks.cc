#include "cluster/personnel_tracks.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <fstream>
#include <sstream>

#include "common/base/file_io.h"

namespace sandtable::cluster {
namespace {

constexpr std::string_view kHeader = "track_id,t_s,x_m,y_m,z_m";
constexpr const char* kFieldNames[] = {"track_id", "t_s", "x_m", "y_m", "z_m"};

std::string_view Trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r')) {
    s.remove_suffix(1);
  }
  return s;
}

// Position of `sample` interpolated at t within segment [a, b] (a.t_s < b.t_s).
Eigen::Vector3d Lerp(const TrackSample& a, const TrackSample& b, double t_s) {
  const double w = (t_s - a.t_s) / (b.t_s - a.t_s);
  return (1.0 - w) * a.position_in_table_m + w * b.position_in_table_m;
}

}  // namespace

size_t PersonnelTracks::sample_count() const {
  size_t n = 0;
  for (const auto& [id, samples] : tracks_) n += samples.size();
  return n;
}

Expected<PersonnelTracks> PersonnelTracks::Parse(std::string_view text,
                                                 const std::string& source_name) {
  PersonnelTracks result;
  bool header_seen = false;
  size_t line_number = 0;
  size_t sample_total = 0;
  size_t start = 0;
  while (start <= text.size()) {
    size_t end = text.find('\n', start);
    if (end == std::string_view::npos) end = text.size();
    const std::string_view line = Trim(text.substr(start, end - start));
    start = end + 1;
    ++line_number;
    const std::string where = source_name + ":" + std::to_string(line_number) + ": ";
    if (line.empty() || line.front() == '#') continue;
    if (!header_seen) {
      if (line != kHeader) {
        return ParseError(where + "header must be '" + std::string(kHeader) + "', got '" +
                          std::string(line.substr(0, 80)) + "'");
      }
      header_seen = true;
      continue;
    }
    std::string_view fields[5];
    size_t count = 0, field_start = 0;
    while (true) {
      const size_t comma = line.find(',', field_start);
      const std::string_view field =
          Trim(line.substr(field_start, comma == std::string_view::npos ? std::string_view::npos
                                                                        : comma - field_start));
      if (count < 5) fields[count] = field;
      ++count;
      if (comma == std::string_view::npos) break;
      field_start = comma + 1;
    }
    if (count != 5) {
      return ParseError(where + "expected 5 fields (" + std::string(kHeader) + "), got " +
                        std::to_string(count));
    }
    uint32_t track_id = 0;
    {
      const auto [ptr, ec] =
          std::from_chars(fields[0].data(), fields[0].data() + fields[0].size(), track_id);
      if (ec != std::errc() || ptr != fields[0].data() + fields[0].size() || fields[0].empty()) {
        return ParseError(where + "field track_id: '" + std::string(fields[0]) +
                          "' is not an unsigned 32-bit integer");
      }
    }
    double values[4];
    for (int k = 0; k < 4; ++k) {
      const std::string_view f = fields[k + 1];
      const auto [ptr, ec] = std::from_chars(f.data(), f.data() + f.size(), values[k]);
      if (f.empty() || ec != std::errc() || ptr != f.data() + f.size()) {
        return ParseError(where + "field " + kFieldNames[k + 1] + ": '" + std::string(f) +
                          "' is not a number");
      }
      if (!std::isfinite(values[k])) {
        return ParseError(where + "field " + kFieldNames[k + 1] + ": '" + std::string(f) +
                          "' is not finite");
      }
    }
    if (values[0] < 0.0) {
      return ParseError(where + "field t_s: " + std::string(fields[1]) +
                        " is negative; media time starts at 0");
    }
    if (result.tracks_.size() >= kMaxTimelineTracks && result.tracks_.count(track_id) == 0) {
      return ParseError(where + "track " + std::to_string(track_id) + " is one more than " +
                        std::to_string(kMaxTimelineTracks) +
                        " tracks (kMaxTimelineTracks: every timeline clock carries one "
                        "position per track)");
    }
    if (++sample_total > kMaxTimelineSamples) {
      return ParseError(where + "more than " + std::to_string(kMaxTimelineSamples) +
                        " samples (kMaxTimelineSamples)");
    }
    std::vector<TrackSample>& samples = result.tracks_[track_id];
    if (!samples.empty() && values[0] <= samples.back().t_s) {
      return ParseError(where + "field t_s: " + std::string(fields[1]) + " of track " +
                        std::to_string(track_id) + " is not after its previous sample (" +
                        std::to_string(samples.back().t_s) +
                        " s); times must increase strictly within a track");
    }
    samples.push_back({values[0], Eigen::Vector3d(values[1], values[2], values[3])});
    result.duration_s_ = std::max(result.duration_s_, values[0]);
  }
  if (!header_seen) {
    return ParseError(source_name + ": empty; expected the header '" + std::string(kHeader) + "'");
  }
  return result;
}

Expected<PersonnelTracks> PersonnelTracks::Load(const std::string& path) {
  Expected<std::string> text = ReadInputFile(path, kMaxTimelineFileBytes, "kMaxTimelineFileBytes");
  if (!text.ok()) return text.status().WithContext("personnel tracks");
  return Parse(*text, path);
}

Expected<TrackPositionAt> PersonnelTracks::PositionAt(uint32_t track_id, double t_s) const {
  const auto it = tracks_.find(track_id);
  if (it == tracks_.end()) return NotFoundError("no track " + std::to_string(track_id));
  if (!std::isfinite(t_s)) return InvalidArgumentError("track position: time is not finite");
  const std::vector<TrackSample>& s = it->second;
  if (t_s <= s.front().t_s)
    return TrackPositionAt{s.front().position_in_table_m, t_s == s.front().t_s};
  if (t_s >= s.back().t_s)
    return TrackPositionAt{s.back().position_in_table_m, t_s == s.back().t_s};
  // First sample after t_s; its predecessor is at or before t_s.
  const auto after = std::upper_bound(s.begin(), s.end(), t_s,
                                      [](double t, const TrackSample& x) { return t < x.t_s; });
  return TrackPositionAt{Lerp(*(after - 1), *after, t_s), true};
}

Expected<double> PersonnelTracks::DistanceAlong_m(uint32_t track_id, double from_s,
                                                  double to_s) const {
  const auto it = tracks_.find(track_id);
  if (it == tracks_.end()) return NotFoundError("no track " + std::to_string(track_id));
  if (!std::isfinite(from_s) || !std::isfinite(to_s) || from_s > to_s) {
    return InvalidArgumentError("distance along track: need finite from_s <= to_s, got " +
                                std::to_string(from_s) + " and " + std::to_string(to_s));
  }
  const std::vector<TrackSample>& s = it->second;
  from_s = std::clamp(from_s, s.front().t_s, s.back().t_s);
  to_s = std::clamp(to_s, s.front().t_s, s.back().t_s);
  // Walk the polyline: the interpolated start, every sample strictly inside, the end.
  Eigen::Vector3d previous = PositionAt(track_id, from_s)->position_in_table_m;
  double distance_m = 0.0;
  for (const TrackSample& sample : s) {
    if (sample.t_s <= from_s) continue;
    if (sample.t_s >= to_s) break;
    distance_m += (sample.position_in_table_m - previous).norm();
    previous = sample.position_in_table_m;
  }
  distance_m += (PositionAt(track_id, to_s)->position_in_table_m - previous).norm();
  return distance_m;
}

}  // namespace sandtable::cluster
