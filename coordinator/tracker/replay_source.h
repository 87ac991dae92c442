// Replay of recorded tracker samples: the real Polhemus FASTRAK trajectories (.traj, 100 Hz,
// ../shared/data/polhemus-hand/, formats in docs/tracker-formats.md) and the documented CSV
// format. ReplaySource emits each sample when its time has come (time_s / rate_scale after
// the first Poll), optionally looping.
//
// .traj: samples of 4 lines of 4 numbers (row-major [R t; 0 0 0 1], metres) plus an empty
// line; sample i at i / 100 s. Checked: 16 numbers per sample, finite, last row 0 0 0 1,
// |R^T R - I| <= kTrajRotationTolerance; a bad sample gives PARSE_ERROR naming file and line.
// CSV (header required):
//   time_s,sensor,x_m,y_m,z_m,qw,qx,qy,qz,button
// one sample per line, tracker_from_sensor with quaternion (w, x, y, z) (normalised; |q| must
// be within kCsvQuaternionTolerance of 1), button 0/1, time_s non-decreasing.
// Limits (docs/reliability.md): files are read through ReadInputFile (a directory,
// FIFO or /dev/zero is IO_ERROR before a byte is read; missing is NOT_FOUND) and at most
// kMaxTrackerReplayBytes; at most kMaxTrackerReplaySamples samples spanning at most
// kMaxTrackerReplaySpan_s; positions within kMaxTrackerCoordinate_m per axis. Each limit is a
// PARSE_ERROR / IO_ERROR naming it, before the samples past it are kept.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "coordinator/tracker/tracker_source.h"

namespace sandtable::coordinator {

constexpr double kFastrakTrajRate_hz = 100.0;
constexpr double kTrajRotationTolerance = 1e-4;
constexpr double kCsvQuaternionTolerance = 1e-3;
constexpr uint64_t kMaxTrackerReplayBytes = uint64_t{256} << 20;  // 256 MiB of text
constexpr uint64_t kMaxTrackerReplaySamples = 2'000'000;          // 5.5 h at 100 Hz, ~160 MB
constexpr double kMaxTrackerReplaySpan_s = 86400.0;               // one day
constexpr double kMaxTrackerCoordinate_m = 1e3;

Expected<std::vector<TrackerSample>> LoadFastrakTraj(const std::string& path);
Expected<std::vector<TrackerSample>> LoadTrackerCsv(const std::string& path);
// The parsers behind the loaders, from text (`name` is used in messages; fuzzing, tests).
Expected<std::vector<TrackerSample>> ParseFastrakTraj(std::string_view text,
                                                      const std::string& name);
Expected<std::vector<TrackerSample>> ParseTrackerCsv(std::string_view text,
                                                     const std::string& name);
// Writes samples in the CSV format above (for recording and tests), atomically.
Status WriteTrackerCsv(const std::string& path, const std::vector<TrackerSample>& samples);

class ReplaySource : public TrackerSource {
 public:
  // `samples` sorted by source_time_s. rate_scale: replay speed (1 = real time).
  ReplaySource(std::string name, std::vector<TrackerSample> samples, double rate_scale = 1.0,
               bool loop = false);

  Status Poll(TrackerClock::time_point now, std::vector<TrackerSample>* out) override;
  TrackerState state() const override;
  std::string Describe() const override;
  double rate_hz() const override { return rate_hz_; }
  size_t emitted() const { return emitted_total_; }

 private:
  std::string name_;
  std::vector<TrackerSample> samples_;
  double rate_scale_;
  bool loop_;
  double rate_hz_ = 0.0;
  bool started_ = false;
  TrackerClock::time_point start_;
  size_t next_ = 0;
  size_t emitted_total_ = 0;
  double loop_offset_s_ = 0.0;
};

}  // namespace sandtable::coordinator
