// ProjectorOutput: what a node shows through its projector. The simulated world
// (world_projector_output.h) and a real fullscreen window (window_projector_output.h)
// implement it; nothing above this interface knows which one it has (device_factory.h picks).
//
// Frames: a cv::Mat of exactly size() pixels (width x height, row 0 at the top, pixel (0,0)
// centred at (0.0, 0.0) as in docs/frames.md), either
//   GRAY8  CV_8UC1, or
//   RGB8   CV_8UC3 with channel 0 = red (the wire's PIXEL_ENCODING_RGB8 and OpenGL's GL_RGB;
//          an image read with cv::imread is BGR: convert it with cv::COLOR_BGR2RGB first).
// Values are the projector's input levels (0..255), before its own gamma. The frame need not
// be continuous (a ROI of a larger image is fine); it is copied before Show() returns.
//
// Failure behaviour: a frame of the wrong size or type is INVALID_ARGUMENT naming both sizes;
// a device that went away is UNAVAILABLE. Neither aborts, and the output stays usable.
// Show() is a per-frame path: implementations log nothing above DEBUG there.
// Threading: one thread at a time (implementations do not lock, except the world's link).
#pragma once

#include <chrono>
#include <cstdint>
#include <string>

#include <opencv2/core.hpp>

#include "common/base/status.h"

namespace sandtable::node {

using DeviceClock = std::chrono::steady_clock;

// What Show() reports about one frame.
struct ShownFrame {
  uint64_t frame_index = 0;  // 1, 2, 3 ... per output, in Show() order
  // When the frame was on the output, on this process's steady clock: the world's
  // acknowledgement (the frame is in effect from then on), or a window's completed buffer
  // swap. The projector's own input lag (typically one to two refreshes) is not included.
  DeviceClock::time_point shown_time{};
};

class ProjectorOutput {
 public:
  virtual ~ProjectorOutput() = default;

  // The projector's resolution in px (width, height); fixed for the output's lifetime.
  virtual cv::Size size() const = 0;
  // Which device this is, for messages: "world tcp://127.0.0.1:5555 projector 3".
  virtual std::string description() const = 0;

  // Shows `frame` from now on (see the frame contract above) and says when it was shown.
  // Returns once the frame is on the output (a world's reply, a window's swap), so a capture
  // started after Show() returns sees this frame.
  virtual Expected<ShownFrame> Show(const cv::Mat& frame) = 0;
  // Cuts the light altogether (an AV mute or shutter: not even the black level a black frame
  // emits) until the next Show(). The self-calibration measures the black level against it.
  // UNAVAILABLE where the device has no such control (a window); the output stays usable.
  virtual Expected<ShownFrame> Mute() {
    return UnavailableError(description() + ": no way to cut the light (no AV mute)");
  }
};

// OK when `frame` is GRAY8 or RGB8 of exactly `size`; INVALID_ARGUMENT naming `who`, the
// frame's size and type and the projector's size otherwise. For implementations.
Status CheckProjectorFrame(const cv::Mat& frame, cv::Size size, const std::string& who);

// "GRAY8", "RGB8", or the OpenCV type name ("16UC1") of anything else.
std::string FrameTypeName(const cv::Mat& frame);

}  // namespace sandtable::node
