// Reading a numbered capture sequence from a folder, as laid out by procam-kamino410
// (capture_0/graycode_00.png ... graycode_41.png) and by our own capture tools.
#pragma once

#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "common/base/status.h"

namespace sandtable {

// The most frames one capture sequence may hold.
inline constexpr int kMaxCaptureFrames = 4096;

struct CaptureSequenceNames {
  std::string prefix = "graycode_";
  int digits = 2;  // zero-padded index width
  std::string suffix = ".png";
  // "<folder>/<prefix><index zero-padded to digits><suffix>".
  std::string PathOf(const std::string& folder, int index) const;
};

// Reads frames 0..count-1 as 8-bit grayscale (cv::IMREAD_GRAYSCALE), each through
// io::ReadImageFile (regular files only; a directory, FIFO or /dev/zero is refused by name; the
// header's size bounded by kMaxImageSide_px / kMaxImagePixels before decoding).
// Errors: INVALID_ARGUMENT for count < 1 or count > kMaxCaptureFrames; IO_ERROR naming the first
// file that is missing, not a regular file, too large or undecodable; INVALID_ARGUMENT naming a
// frame whose size differs from frame 0's.
Expected<std::vector<cv::Mat>> LoadCaptureSequence(const std::string& folder, int count,
                                                   const CaptureSequenceNames& names = {});

}  // namespace sandtable
