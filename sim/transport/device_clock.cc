#include "sim/transport/device_clock.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <vector>

#include "common/base/check.h"

namespace sandtable::sim {

namespace {

std::atomic<uint64_t> next_version{1};

// A uniform draw in [0, 1) from (seed, index, stream).
double Draw(uint64_t seed, uint64_t index, uint64_t stream) {
  uint64_t x = seed ^ (index * 0x9E3779B97F4A7C15ull) ^ (stream * 0xC2B2AE3D27D4EB4Full);
  x ^= x >> 30;
  x *= 0xBF58476D1CE4E5B9ull;
  x ^= x >> 27;
  x *= 0x94D049BB133111EBull;
  x ^= x >> 31;
  return static_cast<double>(x >> 11) * 0x1.0p-53;
}

}  // namespace

ProjectorTimeline::ProjectorTimeline(const DeviceTiming& timing, double phase_s)
    : timing_(timing), phase_s_(phase_s) {}

double ProjectorTimeline::Send(double sent_s, const cv::Mat& frame, bool on) {
  double from = sent_s;
  if (timing_.lag_frames > 0) {
    const double period = 1.0 / timing_.refresh_hz;
    const double earliest = sent_s + timing_.lag_frames * period;
    from = phase_s_ + std::ceil((earliest - phase_s_) / period - 1e-9) * period;
  }
  Entry entry{from, frame, on, next_version.fetch_add(1)};
  if (frame.empty() && !entries_.empty()) entry.frame = entries_.back().frame;
  // Sent after a frame that is due later (cannot happen with a fixed lag) or for the same
  // refresh: it replaces those.
  while (!entries_.empty() && entries_.back().from_s >= from) entries_.pop_back();
  entries_.push_back(std::move(entry));
  return from;
}

const ProjectorTimeline::Entry* ProjectorTimeline::At(double t_s) const {
  const Entry* found = nullptr;
  for (const Entry& e : entries_) {
    if (e.from_s > t_s) break;
    found = &e;
  }
  return found;
}

void ProjectorTimeline::ForgetBefore(double t_s) {
  while (entries_.size() > 1 && entries_[1].from_s <= t_s) entries_.pop_front();
}

CameraClock::CameraClock(const DeviceTiming& timing, double phase_s, uint64_t seed)
    : timing_(timing), phase_s_(phase_s), seed_(seed) {
  ST_CHECK(timing.camera_fps > 0) << "CameraClock for an ideal camera";
  period_s_ = 1.0 / timing.camera_fps;
}

bool CameraClock::Dropped(int64_t exposure) const {
  return timing_.drop_rate > 0 &&
         Draw(seed_, static_cast<uint64_t>(exposure), 1) < timing_.drop_rate;
}

CameraClock::Read CameraClock::Next(double now_s) {
  // The newest exposure readable at now_s.
  const int64_t newest =
      static_cast<int64_t>(std::floor((now_s - timing_.camera_latency_s - phase_s_) / period_s_));
  std::vector<int64_t> queued;  // newest first
  for (int64_t k = newest;
       (!any_ || k > last_) && static_cast<int>(queued.size()) < timing_.queue_frames &&
       k > newest - 64 * timing_.queue_frames;
       --k) {
    if (!Dropped(k)) queued.push_back(k);
  }
  Read read;
  if (!queued.empty()) {
    read.exposure = queued.back();
    read.ready_s = now_s;
  } else {
    int64_t k = std::max(newest + 1, any_ ? last_ + 1 : newest + 1);
    while (Dropped(k)) ++k;
    read.exposure = k;
    read.ready_s = std::max(now_s, Start(k) + timing_.camera_latency_s);
  }
  read.exposure_start_s = Start(read.exposure);
  read.repeat =
      reads_ > 0 && timing_.repeat_rate > 0 && Draw(seed_, reads_, 2) < timing_.repeat_rate;
  last_ = read.exposure;
  any_ = true;
  ++reads_;
  if (read.repeat) ++repeats_;
  return read;
}

}  // namespace sandtable::sim
