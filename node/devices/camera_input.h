// CameraInput: how a node takes pictures with its camera. The simulated world
// (world_camera_input.h), a real camera through OpenCV (video_camera_input.h) and a recorded
// capture folder replayed as if it were live (replay_camera_input.h) implement it; nothing
// above this interface knows which one it has (device_factory.h picks).
//
// Images: single channel, size() pixels (row 0 at the top, pixel (0,0) centred at (0.0, 0.0)),
//   CV_8UC1  when bit_depth() <= 8, or
//   CV_16UC1 otherwise, values in [0, 2^bit_depth - 1] (not rescaled to 16 bits).
// A colour camera's frames are converted to gray (cv::COLOR_BGR2GRAY) by the implementation.
//
// Failure behaviour: a device that is gone is UNAVAILABLE, the end of a recording OUT_OF_RANGE,
// a bad exposure INVALID_ARGUMENT; never an abort. Capture() is a per-frame path:
// implementations log nothing above DEBUG there.
// Threading: one thread at a time.
#pragma once

#include <chrono>
#include <cstdint>
#include <string>

#include <opencv2/core.hpp>

#include "common/base/status.h"
#include "common/base/units.h"
#include "node/devices/projector_output.h"

namespace sandtable::node {

struct CapturedFrame {
  cv::Mat image;       // see the image contract above; owns its pixels
  uint64_t index = 0;  // 1, 2, 3 ... per input, in Capture() order
  // When the image was exposed, on this process's steady clock: never before Capture() was
  // called and never after it returned (so it is after the ShownFrame::shown_time of a frame
  // shown before the call).
  DeviceClock::time_point capture_time{};
};

class CameraInput {
 public:
  virtual ~CameraInput() = default;

  // Image size in px (width, height) and bits per pixel of every capture.
  virtual cv::Size size() const = 0;
  virtual int bit_depth() const = 0;
  // Which device this is, for messages: "replay ../shared/data/procam-kamino410/capture_0".
  virtual std::string description() const = 0;

  // Takes one picture exposed for `exposure` (Seconds(0): the camera's own setting; a
  // recording ignores it). The image is exposed after the call begins, so it shows what the
  // projectors showed when Capture() was called.
  virtual Expected<CapturedFrame> Capture(Seconds exposure) = 0;
};

}  // namespace sandtable::node
