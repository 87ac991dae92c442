#include "common/structured_light/capture_io.h"

#include <filesystem>
#include <string>

#include <opencv2/imgcodecs.hpp>

#include "common/io/image_file.h"

namespace sandtable {

std::string CaptureSequenceNames::PathOf(const std::string& folder, int index) const {
  std::string number = std::to_string(index);
  if (static_cast<int>(number.size()) < digits) {
    number.insert(0, static_cast<size_t>(digits) - number.size(), '0');
  }
  return (std::filesystem::path(folder) / (prefix + number + suffix)).string();
}

Expected<std::vector<cv::Mat>> LoadCaptureSequence(const std::string& folder, int count,
                                                   const CaptureSequenceNames& names) {
  if (count < 1 || count > kMaxCaptureFrames) {
    return InvalidArgumentError(
        "capture sequence: count " + std::to_string(count) +
        " is outside [1, kMaxCaptureFrames = " + std::to_string(kMaxCaptureFrames) + "]");
  }
  std::vector<cv::Mat> frames;
  frames.reserve(static_cast<size_t>(count));
  for (int i = 0; i < count; ++i) {
    const std::string path = names.PathOf(folder, i);
    // Regular files only, the size in the header bounded before decoding (image_file.h).
    Expected<cv::Mat> read = io::ReadImageFile(path, cv::IMREAD_GRAYSCALE);
    if (!read.ok()) {
      return IoError("capture sequence: cannot read " + read.status().message() +
                     (read.status().code() == StatusCode::kNotFound ? " (missing)" : ""));
    }
    cv::Mat image = std::move(*read);
    if (!frames.empty() && image.size() != frames[0].size()) {
      return InvalidArgumentError("capture sequence: " + path + " is " +
                                  std::to_string(image.cols) + "x" + std::to_string(image.rows) +
                                  " px, frame 0 is " + std::to_string(frames[0].cols) + "x" +
                                  std::to_string(frames[0].rows));
    }
    frames.push_back(std::move(image));
  }
  return frames;
}

}  // namespace sandtable
