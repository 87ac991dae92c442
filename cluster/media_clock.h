// MediaClock: the timeline's play/pause/seek/rate arithmetic, on explicit times (the
// coordinator's steady clock in ns) so it is testable without waiting.
//
// State: an anchor (media_time_s at anchor_time_ns), a rate (media seconds per wall second)
// and a playing flag. Media time at T:
//   playing: clamp(media_time_s + rate * max(0, T - anchor_time_ns) * 1e-9, 0, duration_s)
//   paused:  media_time_s
// T before the anchor (a Play scheduled slightly ahead so all nodes start together) gives
// media_time_s. Every change re-anchors at the time of the change, so no history is kept.
//
// Rules: rate must be finite and in (0, max_rate]; negative (reverse), zero and NaN rates are
// refused with INVALID_ARGUMENT (seek instead of reversing; pause instead of rate 0). Seek
// clamps to [0, duration_s] (NaN refused). Play at the end restarts from 0. Reaching the end
// while playing pauses the clock at duration_s (Advance() reports it). Play/Pause with an
// explicit time must be within max_schedule_offset of now (Pause only at or before now).
#pragma once

#include <cstdint>

#include "common/base/status.h"

namespace sandtable::cluster {

struct MediaClockOptions {
  double duration_s = 0.0;
  double max_rate = 64.0;
  int64_t max_schedule_offset_ns = 10'000'000'000;  // 10 s
  Status Check() const;
};

struct MediaClockState {
  double media_time_s = 0.0;  // at anchor_time_ns
  double rate = 1.0;
  bool playing = false;
  int64_t anchor_time_ns = 0;
  uint64_t change_count = 0;
};

class MediaClock {
 public:
  explicit MediaClock(MediaClockOptions options);

  // The formula above for any published state (a receiver's extrapolation; times on the
  // clock the state was sampled on).
  static double MediaTimeOf(const MediaClockState& state, double duration_s, int64_t now_ns);

  double MediaTimeAt(int64_t now_ns) const;
  // The state re-sampled at now_ns (anchor moved to now unless it is still ahead), for
  // publishing: a receiver extrapolates with the formula above.
  MediaClockState SampleAt(int64_t now_ns) const;

  // at_ns 0: now. Starts (or re-anchors) playing from the current media time.
  Status Play(int64_t now_ns, int64_t at_ns = 0);
  Status Pause(int64_t now_ns, int64_t at_ns = 0);
  Status Seek(int64_t now_ns, double position_s);
  Status SetRate(int64_t now_ns, double rate);
  // Pauses at the end when playing reached it; true when that changed the state.
  bool Advance(int64_t now_ns);

  const MediaClockState& state() const { return state_; }
  double duration_s() const { return options_.duration_s; }

 private:
  void Reanchor(int64_t now_ns);

  MediaClockOptions options_;
  MediaClockState state_;
};

}  // namespace sandtable::cluster
