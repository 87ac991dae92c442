// VideoCameraInput: a real camera through OpenCV's cv::VideoCapture: a V4L2 device by index
// ("0" is /dev/video0) or anything OpenCV's backends open by name (a URL such as rtsp://...,
// http://..., a video file).
//
// Images are converted to gray (CV_8UC1, bit depth 8; a 16-bit source stays CV_16UC1, depth
// 16). Stale frames: a camera queues frames; the driver's queue is asked to hold one
// (CAP_PROP_BUFFERSIZE) and `discard_frames` grabbed frames are dropped before each capture,
// so the image returned was exposed after Capture() began (what the projector shows then).
// Exposure: Seconds(0) leaves the camera on its own (auto) exposure; > 0 sets manual exposure
// (V4L2 exposure_absolute, in units of 100 us). A camera without exposure control is told so
// once in the log (WARNING) and captures with its own.
// Failure behaviour, one line naming the device: no /dev/videoN, a device that cannot be
// opened, a stream that does not open or gives no frame: UNAVAILABLE. OpenCV exceptions are
// caught here.
#pragma once

#include <memory>
#include <optional>
#include <string>

#include <opencv2/videoio.hpp>

#include "node/devices/camera_input.h"

namespace sandtable::node {

struct VideoCameraOptions {
  std::string device;               // "N" (V4L2 index) or a URL / file name
  std::optional<cv::Size> size_px;  // asked of the device (it may give another; size() says)
  int discard_frames = 1;           // 0..16, dropped before each capture

  Status Check() const;
};

class VideoCameraInput : public CameraInput {
 public:
  // Opens the device and reads one frame to learn its size and depth.
  static Expected<std::unique_ptr<VideoCameraInput>> Open(const VideoCameraOptions& options);

  cv::Size size() const override { return size_px_; }
  int bit_depth() const override { return bit_depth_; }
  std::string description() const override { return description_; }
  Expected<CapturedFrame> Capture(Seconds exposure) override;

 private:
  VideoCameraInput() = default;
  // Grabs and converts one frame to the image contract.
  Expected<cv::Mat> Read();
  void SetExposure(Seconds exposure);

  VideoCameraOptions options_;
  cv::VideoCapture capture_;
  std::string description_;
  cv::Size size_px_;
  int bit_depth_ = 8;
  Seconds exposure_{0.0};  // the one last asked of the device
  bool exposure_warned_ = false;
  uint64_t captures_ = 0;
};

}  // namespace sandtable::node
