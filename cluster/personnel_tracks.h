// Recorded personnel tracks for after-action review: positions over media time, table frame.
// The coordinator replays them on its timeline; nodes draw them as traces (node/render).
//
// File format (CSV, docs/coordinator.md "Timeline"): a header line, exactly
//   track_id,t_s,x_m,y_m,z_m
// then one sample per line: track_id an unsigned 32-bit integer, t_s the media time in
// seconds (finite, >= 0, strictly increasing within a track; tracks may interleave), x_m y_m
// z_m the position in the table frame in metres (finite). Blank lines and lines starting
// with '#' are skipped. Any other line is a PARSE_ERROR naming the file, line number and field.
//
// Limits (docs/reliability.md): the file at most kMaxTimelineFileBytes, at most
// kMaxTimelineTracks tracks (every clock event on the PUB carries one position per track, so
// this bounds that message: ~40 bytes per track, far below the codec's 64 MiB) and at most
// kMaxTimelineSamples samples (memory: 32 bytes each). Past a limit: PARSE_ERROR naming the file,
// the line and the limit.
//
// Position at a media time: linear interpolation between the two samples around it; before a
// track's first sample or after its last, the end sample (reported inactive).
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "common/base/status.h"

namespace sandtable::cluster {

constexpr uint64_t kMaxTimelineFileBytes = uint64_t{256} << 20;
constexpr size_t kMaxTimelineTracks = 1024;
constexpr size_t kMaxTimelineSamples = 4'000'000;

struct TrackSample {
  double t_s = 0.0;
  Eigen::Vector3d position_in_table_m = Eigen::Vector3d::Zero();
};

struct TrackPositionAt {
  Eigen::Vector3d position_in_table_m = Eigen::Vector3d::Zero();
  bool active = false;  // t within [first t_s, last t_s] of the track
};

class PersonnelTracks {
 public:
  PersonnelTracks() = default;

  // Parses the CSV text; `source_name` names it in errors ("tracks.csv:12: field t_s: ...").
  static Expected<PersonnelTracks> Parse(std::string_view text, const std::string& source_name);
  static Expected<PersonnelTracks> Load(const std::string& path);

  // Track id -> samples sorted by t_s (strictly increasing).
  const std::map<uint32_t, std::vector<TrackSample>>& tracks() const { return tracks_; }
  // Last sample time over all tracks (0 when empty): media time runs over [0, duration_s].
  double duration_s() const { return duration_s_; }
  size_t sample_count() const;

  // Position of `track_id` at media time t_s. NOT_FOUND for an unknown track; t_s must be
  // finite (INVALID_ARGUMENT otherwise).
  Expected<TrackPositionAt> PositionAt(uint32_t track_id, double t_s) const;

  // Distance travelled along the track (the interpolated polyline) between media times
  // from_s <= to_s, in metres; times outside the recorded span are clamped to it.
  Expected<double> DistanceAlong_m(uint32_t track_id, double from_s, double to_s) const;

 private:
  std::map<uint32_t, std::vector<TrackSample>> tracks_;
  double duration_s_ = 0.0;
};

}  // namespace sandtable::cluster
