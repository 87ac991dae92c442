#include "cluster/media_clock.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "common/base/check.h"

namespace sandtable::cluster {

Status MediaClockOptions::Check() const {
  if (!std::isfinite(duration_s) || duration_s < 0.0) {
    return InvalidArgumentError("media clock: duration_s = " + std::to_string(duration_s) +
                                " must be finite and >= 0");
  }
  if (!std::isfinite(max_rate) || max_rate <= 0.0) {
    return InvalidArgumentError("media clock: max_rate must be finite and > 0");
  }
  if (max_schedule_offset_ns < 0) {
    return InvalidArgumentError("media clock: max_schedule_offset_ns must be >= 0");
  }
  return OkStatus();
}

MediaClock::MediaClock(MediaClockOptions options) : options_(options) {
  const Status ok = options_.Check();
  ST_CHECK(ok.ok()) << ok.ToString() << "; check MediaClockOptions before constructing";
}

double MediaClock::MediaTimeOf(const MediaClockState& state, double duration_s, int64_t now_ns) {
  if (!state.playing) return state.media_time_s;
  // Integer difference first: ns since the anchor are exact in int64, and doubles keep
  // ns precision up to ~104 days of elapsed time.
  const int64_t elapsed_ns = std::max<int64_t>(0, now_ns - state.anchor_time_ns);
  const double t_s = state.media_time_s + state.rate * static_cast<double>(elapsed_ns) * 1e-9;
  return std::clamp(t_s, 0.0, duration_s);
}

double MediaClock::MediaTimeAt(int64_t now_ns) const {
  return MediaTimeOf(state_, options_.duration_s, now_ns);
}

MediaClockState MediaClock::SampleAt(int64_t now_ns) const {
  MediaClockState sample = state_;
  if (now_ns > state_.anchor_time_ns) {
    sample.media_time_s = MediaTimeAt(now_ns);
    sample.anchor_time_ns = now_ns;
  }
  return sample;
}

void MediaClock::Reanchor(int64_t now_ns) {
  if (now_ns > state_.anchor_time_ns) {
    state_.media_time_s = MediaTimeAt(now_ns);
    state_.anchor_time_ns = now_ns;
  }
}

Status MediaClock::Play(int64_t now_ns, int64_t at_ns) {
  if (at_ns == 0) at_ns = now_ns;
  if (std::llabs(at_ns - now_ns) > options_.max_schedule_offset_ns) {
    return InvalidArgumentError("play: at_time_ns is " + std::to_string((at_ns - now_ns) * 1e-9) +
                                " s from the coordinator's now; allowed within " +
                                std::to_string(options_.max_schedule_offset_ns * 1e-9) +
                                " s (use the coordinator clock from time sync)");
  }
  Reanchor(std::min(now_ns, at_ns));
  if (state_.media_time_s >= options_.duration_s) state_.media_time_s = 0.0;  // replay
  state_.anchor_time_ns = at_ns;
  state_.playing = true;
  ++state_.change_count;
  return OkStatus();
}

Status MediaClock::Pause(int64_t now_ns, int64_t at_ns) {
  if (at_ns == 0) at_ns = now_ns;
  if (at_ns > now_ns || now_ns - at_ns > options_.max_schedule_offset_ns) {
    return InvalidArgumentError("pause: at_time_ns must be at or before now and within " +
                                std::to_string(options_.max_schedule_offset_ns * 1e-9) +
                                " s of it; got " + std::to_string((at_ns - now_ns) * 1e-9) + " s");
  }
  // Pausing "at" a past instant: media time as it was then (nodes that rendered past it
  // step back by at most the request's latency).
  state_.media_time_s = std::max(MediaTimeAt(at_ns), 0.0);
  state_.anchor_time_ns = now_ns;
  state_.playing = false;
  ++state_.change_count;
  return OkStatus();
}

Status MediaClock::Seek(int64_t now_ns, double position_s) {
  if (!std::isfinite(position_s)) return InvalidArgumentError("seek: position_s is not finite");
  state_.media_time_s = std::clamp(position_s, 0.0, options_.duration_s);
  state_.anchor_time_ns = now_ns;  // a scheduled start is replaced by "from now"
  ++state_.change_count;
  return OkStatus();
}

Status MediaClock::SetRate(int64_t now_ns, double rate) {
  if (!std::isfinite(rate) || rate <= 0.0 || rate > options_.max_rate) {
    return InvalidArgumentError("rate " + std::to_string(rate) + " refused: must be in (0, " +
                                std::to_string(options_.max_rate) +
                                "]; reverse play is not supported (seek back instead), pause "
                                "instead of rate 0");
  }
  Reanchor(now_ns);
  state_.rate = rate;
  ++state_.change_count;
  return OkStatus();
}

bool MediaClock::Advance(int64_t now_ns) {
  if (!state_.playing || MediaTimeAt(now_ns) < options_.duration_s) return false;
  state_.media_time_s = options_.duration_s;
  state_.anchor_time_ns = now_ns;
  state_.playing = false;
  ++state_.change_count;
  return true;
}

}  // namespace sandtable::cluster
