// Scripted virtual wand for the lab: a TrackerSource that plays a text script of
// wand-tip waypoints, pointing directions and button presses (format: docs/tracker-formats.md).
//
//   # comment; blank lines ignored
//   rate_hz 100                       (optional, default 100; at most once, before samples)
//   at T_s X_m Y_m Z_m DX DY DZ       waypoint: time, tip in the table frame, pointing direction
//   down T_s                          button pressed at T_s
//   up T_s                            button released at T_s
//
// Sampling: sample k is at t_k = t_first + k / rate_hz for every t_k <= t_last (+1e-9 s), where
// t_first / t_last are the first / last waypoint times. The tip is interpolated linearly
// between the waypoints around t_k; the direction is interpolated linearly and normalised. The
// button is down at t_k when the last button event at or before t_k is "down" (up before any).
// Deterministic: the same script always gives the same samples (bit for bit).
//
// Frames: the script is written in the table frame, and the samples are tracker_from_sensor
// with the tracker frame equal to the table frame (run with table_from_tracker = identity).
// The sensor's +x axis (the default wand ray, WandOptions::ray_in_sensor) points along the
// direction; the sensor sits at the tip (tip_in_sensor_m = 0).
// Errors: PARSE_ERROR "NAME:LINE: FIELD: cause" (waypoint times strictly increasing, button
// times non-decreasing and alternating down/up, direction non-zero, numbers finite, at least
// one waypoint, 0 < rate_hz <= 10000, tip coordinates within kMaxVirtualWandCoordinate_m,
// times within kMaxVirtualWandTime_s). Limits of what a script may generate, checked after
// parsing and before any sample is made (PARSE_ERROR naming the limit): the waypoints span at
// most kMaxVirtualWandSpan_s, and the script gives at most kMaxVirtualWandSamples samples.
// A script file is read through ReadInputFile: not a regular file (a directory, FIFO,
// /dev/zero) or larger than kMaxVirtualWandScriptBytes is IO_ERROR, missing is NOT_FOUND.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "coordinator/tracker/replay_source.h"
#include "coordinator/tracker/tracker_source.h"

namespace sandtable::coordinator {

constexpr double kDefaultVirtualWandRate_hz = 100.0;
constexpr double kMaxVirtualWandRate_hz = 10000.0;
constexpr uint64_t kMaxVirtualWandScriptBytes = uint64_t{4} << 20;  // 4 MiB of text
constexpr double kMaxVirtualWandSpan_s = 3600.0;                    // last - first waypoint
constexpr uint64_t kMaxVirtualWandSamples = 1'000'000;              // ~80 MB of samples
constexpr double kMaxVirtualWandTime_s = 1e6;        // |time_s| of any waypoint or button
constexpr double kMaxVirtualWandCoordinate_m = 1e3;  // |x|, |y|, |z| of a tip

struct VirtualWandWaypoint {
  double time_s = 0.0;
  Eigen::Vector3d tip_in_table_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d direction_in_table = -Eigen::Vector3d::UnitZ();  // not necessarily unit
};

struct VirtualWandButtonEvent {
  double time_s = 0.0;
  bool down = false;
};

struct VirtualWandScript {
  double rate_hz = kDefaultVirtualWandRate_hz;
  std::vector<VirtualWandWaypoint> waypoints;  // strictly increasing time_s
  std::vector<VirtualWandButtonEvent> button;  // non-decreasing time_s, down/up alternating
};

// `name` is used in error messages (the file name).
Expected<VirtualWandScript> ParseVirtualWandScript(const std::string& text,
                                                   const std::string& name);
Expected<VirtualWandScript> LoadVirtualWandScript(const std::string& path);

// Number of samples the sampling rule gives for `script` (0 for no waypoints; saturates at
// kMaxVirtualWandSamples + 1 for absurd spans or rates).
uint64_t VirtualWandSampleCount(const VirtualWandScript& script);

// The samples of a script (see the sampling rule above); source_time_s = t_k. Never more
// than kMaxVirtualWandSamples (a script that would give more is cut there; parsed scripts
// never do).
std::vector<TrackerSample> SampleVirtualWand(const VirtualWandScript& script);

// Plays the samples like a replay (each when its time has come after the first Poll).
class VirtualWandSource : public TrackerSource {
 public:
  VirtualWandSource(std::string name, const VirtualWandScript& script, bool loop = false);

  Status Poll(TrackerClock::time_point now, std::vector<TrackerSample>* out) override {
    return replay_.Poll(now, out);
  }
  TrackerState state() const override { return replay_.state(); }
  std::string Describe() const override;
  double rate_hz() const override { return rate_hz_; }

 private:
  VirtualWandSource(std::string name, double rate_hz, std::vector<TrackerSample> samples,
                    bool loop);

  std::string name_;
  double rate_hz_;
  size_t sample_count_;
  ReplaySource replay_;
};

}  // namespace sandtable::coordinator
