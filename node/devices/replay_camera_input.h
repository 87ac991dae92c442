// ReplayCameraInput: a recorded capture folder played back as if it were a live camera, e.g.
// ../shared/data/procam-kamino410/capture_0 (graycode_00.png ... graycode_41.png, 1280x1024
// 8-bit gray, captured while the projector showed pattern_00 ... pattern_41).
//
// The recording: every image file of the folder (.png .jpg .jpeg .tif .tiff .bmp .pgm .ppm),
// in natural name order (frame_2 before frame_10; at most kMaxReplayFrames), read through
// io::ReadImageFile (regular files only, the size in the header bounded by kMaxImageSide_px and
// kMaxImagePixels before decoding; common/io/image_file.h) with IMREAD_UNCHANGED so
// that 16-bit captures keep their depth (OpenCV's VideoCapture image-sequence backend would
// give 8-bit BGR). Colour images are converted to gray. The first image sets size() and
// bit_depth() (8 for 8-bit files, 16 for 16-bit ones); every later one must match.
// Capture(i) returns frame i in order; `exposure` is ignored (the recording has its own);
// capture_time is when Capture() read it. After the last frame, OUT_OF_RANGE "end of
// recording" (every later call too); a file that cannot be read, or that does not match, is
// IO_ERROR / INVALID_ARGUMENT naming the file, and counts as a dropped frame (the next call
// returns the next file, so CapturedFrame::index is always the file's 1-based position). A missing
// or empty folder fails Open() with NOT_FOUND naming it.
#pragma once

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "node/devices/camera_input.h"

namespace sandtable::node {

// The most image files one recording folder may hold.
inline constexpr size_t kMaxReplayFrames = 100000;

class ReplayCameraInput : public CameraInput {
 public:
  static Expected<std::unique_ptr<ReplayCameraInput>> Open(const std::string& directory);

  cv::Size size() const override { return size_px_; }
  int bit_depth() const override { return bit_depth_; }
  std::string description() const override { return "replay " + directory_; }
  Expected<CapturedFrame> Capture(Seconds exposure) override;

  // Frames in the recording, and how many were taken (returned or dropped) so far.
  size_t frame_count() const { return files_.size(); }
  size_t frames_captured() const { return next_; }
  const std::vector<std::filesystem::path>& files() const { return files_; }

 private:
  ReplayCameraInput() = default;
  Expected<cv::Mat> Load(const std::filesystem::path& file) const;

  std::string directory_;
  std::vector<std::filesystem::path> files_;
  size_t next_ = 0;
  cv::Size size_px_;
  int bit_depth_ = 8;
};

// True when `a` comes before `b` in natural order: digit runs compare as numbers.
bool NaturalLess(const std::string& a, const std::string& b);

}  // namespace sandtable::node
