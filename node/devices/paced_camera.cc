#include "node/devices/paced_camera.h"

#include <algorithm>
#include <thread>

#include "common/base/log.h"

namespace sandtable::node {

namespace {

bool SamePicture(const cv::Mat& a, const cv::Mat& b) {
  return !a.empty() && a.size() == b.size() && a.type() == b.type() &&
         cv::norm(a, b, cv::NORM_INF) == 0.0;
}

double SecondsBetween(DeviceClock::time_point from, DeviceClock::time_point to) {
  return std::chrono::duration<double>(to - from).count();
}

}  // namespace

PacedCamera::PacedCamera(std::unique_ptr<CameraInput> camera, PacedCameraOptions options)
    : camera_(std::move(camera)), options_(options) {
  stats_.settle_s = options_.default_settle.count();
}

CaptureTimingStats PacedCamera::stats() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return stats_;
}

Expected<CapturedFrame> PacedCamera::Read(bool* repeat) {
  Expected<CapturedFrame> frame = camera_->Capture(Seconds(0));
  if (!frame.ok()) return frame;
  *repeat = SamePicture(previous_, frame->image);
  previous_ = frame->image;
  std::lock_guard<std::mutex> lock(mutex_);
  ++stats_.reads;
  return frame;
}

Expected<CapturedFrame> PacedCamera::CaptureAfter(DeviceClock::time_point since) {
  std::lock_guard<std::mutex> use(use_mutex_);
  return CaptureAfterLocked(since);
}

Expected<CapturedFrame> PacedCamera::CaptureAfterLocked(DeviceClock::time_point since) {
  double settle_s = 0;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    settle_s = stats_.settle_s;
  }
  const DeviceClock::time_point ready =
      since + std::chrono::duration_cast<DeviceClock::duration>(Seconds(settle_s));
  std::this_thread::sleep_until(ready);
  Expected<CapturedFrame> frame = InternalError("no picture read yet");
  for (int i = 0; i < options_.max_reads; ++i) {
    bool repeat = false;
    frame = Read(&repeat);
    if (!frame.ok()) return frame;
    const bool stale = frame->capture_time < ready;
    std::lock_guard<std::mutex> lock(mutex_);
    if (!stale && !repeat) {
      ++stats_.captures;
      return frame;
    }
    ++(stale ? stats_.stale : stats_.repeated);
  }
  std::lock_guard<std::mutex> lock(mutex_);
  ++stats_.gave_up;
  ++stats_.captures;
  return frame;
}

Expected<CapturedFrame> PacedCamera::CaptureFlash(DeviceClock::time_point since,
                                                  const std::function<bool(const cv::Mat&)>& lit) {
  std::lock_guard<std::mutex> use(use_mutex_);
  Expected<CapturedFrame> frame = InternalError("no picture read yet");
  DeviceClock::time_point previous_exposure{};
  double frame_s = 0.0;
  while (true) {
    bool repeat = false;
    frame = Read(&repeat);
    if (!frame.ok()) return frame;
    if (previous_exposure != DeviceClock::time_point{} && !repeat) {
      const double between = SecondsBetween(previous_exposure, frame->capture_time);
      if (between > 0) frame_s = frame_s > 0 ? std::min(frame_s, between) : between;
    }
    if (!repeat) previous_exposure = frame->capture_time;
    if (!repeat && frame->capture_time >= since && lit(frame->image)) break;
    if (DeviceClock::now() - since > options_.max_flash_wait) {
      ST_LOG(kWarning) << camera_->description() << ": the flash was not seen within "
                       << options_.max_flash_wait.count()
                       << " s; captures keep waiting the settle they had";
      std::lock_guard<std::mutex> lock(mutex_);
      ++stats_.captures;
      return frame;
    }
  }
  const double latency_s = std::max(0.0, SecondsBetween(since, frame->capture_time));
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stats_.latency_s = std::max(stats_.latency_s, latency_s);
    if (frame_s > 0) stats_.frame_s = std::max(stats_.frame_s, frame_s);
    ++stats_.flashes;
    stats_.settle_s = stats_.latency_s + stats_.frame_s;
    ST_LOG(kInfo) << camera_->description() << ": flash seen " << latency_s * 1e3
                  << " ms after it was asked for (frame " << stats_.frame_s * 1e3
                  << " ms); captures wait " << stats_.settle_s * 1e3 << " ms";
  }
  return CaptureAfterLocked(since);
}

}  // namespace sandtable::node
