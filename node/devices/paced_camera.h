// PacedCamera: captures that show what the projectors show now, on devices with real timing
// (docs/devices.md, "Timing"). A projector puts a frame on the table some refreshes after it
// is sent; a camera delivers an exposure some time after it began, and its driver queues
// frames, so a read right after a pattern was shown may return a picture from before it; a
// driver may also hand the same picture twice, or lose one.
//
// Each capture is asked for with the moment its pattern was asked for (`since`): the camera
// waits until `since + settle`, then reads until a picture exposed after that moment comes
// that is not the previous read's picture again (bit-identical: two exposures always differ
// by their noise), at most max_reads reads. `settle` is measured: at a flash (a projector
// turning white, `since` when it was asked) the camera reads until it sees the light; the
// first lit picture's exposure minus `since` is the latency, and settle the largest latency
// seen plus the time between two exposures (the camera's frame, or the read's own time for
// a camera that exposes when asked). Until measured, settle is default_settle.
// Threading: thread-safe; captures from several threads (a round's step and a saved
// calibration's check on two workers) take the camera one after the other. stats() may be read
// from any thread.
#pragma once

#include <functional>
#include <memory>
#include <mutex>

#include "node/devices/camera_input.h"

namespace sandtable::node {

struct PacedCameraOptions {
  Seconds default_settle{0.2};
  int max_reads = 12;           // per capture, stale and repeated reads included
  Seconds max_flash_wait{2.0};  // a flash not seen in this long is not measured
};

// What the camera's timing has been so far (for logs and the report).
struct CaptureTimingStats {
  double latency_s = -1.0;  // the largest flash latency measured; < 0: none yet
  double frame_s = 0.0;     // the time between two exposures, as measured at a flash
  double settle_s = 0.0;    // what captures wait for now
  int flashes = 0;          // flashes measured
  uint64_t captures = 0;    // pictures kept
  uint64_t reads = 0;       // pictures read (kept, stale and repeated)
  uint64_t stale = 0;       // exposed before their pattern was surely on: read again
  uint64_t repeated = 0;    // the previous read's picture again: read again
  uint64_t gave_up = 0;     // captures that kept a picture after max_reads unfit reads
};

class PacedCamera {
 public:
  PacedCamera(std::unique_ptr<CameraInput> camera, PacedCameraOptions options = {});

  CameraInput& camera() { return *camera_; }
  cv::Size size() const { return camera_->size(); }
  int bit_depth() const { return camera_->bit_depth(); }

  // A picture exposed after since + settle that repeats no earlier read (the camera's own
  // exposure). Errors: the camera's.
  Expected<CapturedFrame> CaptureAfter(DeviceClock::time_point since);
  // At a flash asked for at `since`: reads until `lit` says the light is seen (measuring the
  // latency), then returns a picture as CaptureAfter does. A flash not seen within
  // max_flash_wait leaves settle as it was and returns the last picture read.
  Expected<CapturedFrame> CaptureFlash(DeviceClock::time_point since,
                                       const std::function<bool(const cv::Mat&)>& lit);
  CaptureTimingStats stats() const;

 private:
  // One read, counted; `repeat` when bit-identical to the previous read. Holds use_mutex_.
  Expected<CapturedFrame> Read(bool* repeat);
  Expected<CapturedFrame> CaptureAfterLocked(DeviceClock::time_point since);

  std::unique_ptr<CameraInput> camera_;
  PacedCameraOptions options_;
  std::mutex use_mutex_;      // held while the camera is used
  cv::Mat previous_;          // the last picture read
  mutable std::mutex mutex_;  // stats_
  CaptureTimingStats stats_;
};

}  // namespace sandtable::node
