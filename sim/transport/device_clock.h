// The timing of a unit's real devices in the world (sim/site/device_timing.h): which frame a
// projector has on the table at a given time, and which exposure a camera read returns and
// when. Times are seconds on one clock (the world server's steady clock).
// Threading: not thread-safe (the server serialises requests).
#pragma once

#include <cstdint>
#include <deque>

#include <opencv2/core.hpp>

#include "sim/site/device_timing.h"

namespace sandtable::sim {

// The frames one projector was sent, each with the time from which it is on the table.
class ProjectorTimeline {
 public:
  struct Entry {
    double from_s = 0.0;
    cv::Mat frame;  // empty before the first frame (the light is then only on or off)
    bool on = true;
    uint64_t version = 0;  // distinct for every entry of every timeline
  };

  // `phase_s`: when one of the projector's refreshes starts.
  ProjectorTimeline(const DeviceTiming& timing, double phase_s);

  // A frame sent at `sent_s` (empty: the frame it shows, with the light cut or restored);
  // returns when it is on the table: the first refresh at least lag_frames refreshes later
  // (with no lag: at once). A frame replaces one sent earlier for the same refresh.
  double Send(double sent_s, const cv::Mat& frame, bool on);
  // What is on the table at `t_s`; nullptr before the first frame is on.
  const Entry* At(double t_s) const;
  // Drops the entries that no time from `t_s` on can see.
  void ForgetBefore(double t_s);
  size_t size() const { return entries_.size(); }

 private:
  DeviceTiming timing_;
  double phase_s_;
  std::deque<Entry> entries_;
};

// Which exposure each read of a streaming camera (camera_fps > 0) returns.
class CameraClock {
 public:
  struct Read {
    int64_t exposure = 0;         // index of the exposure delivered
    double exposure_start_s = 0;  // when it began
    double ready_s = 0;           // when the read returns (>= the read's own time)
    bool repeat = false;          // the driver hands the previous read's picture again
  };

  // `phase_s`: when one exposure begins; `seed` picks the dropped exposures and repeated reads.
  CameraClock(const DeviceTiming& timing, double phase_s, uint64_t seed);

  // A read at `now_s`: the oldest of the newest queue_frames unread exposures that are
  // readable by then, or else the next one to become readable.
  Read Next(double now_s);
  uint64_t repeats() const { return repeats_; }

 private:
  bool Dropped(int64_t exposure) const;
  double Start(int64_t exposure) const {
    return phase_s_ + static_cast<double>(exposure) * period_s_;
  }

  DeviceTiming timing_;
  double phase_s_;
  double period_s_;
  uint64_t seed_;
  int64_t last_ = 0;
  bool any_ = false;
  uint64_t reads_ = 0;
  uint64_t repeats_ = 0;
};

}  // namespace sandtable::sim
