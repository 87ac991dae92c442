#include "common/structured_light/capture_io.h"

#include <filesystem>
#include <string>

#include <opencv2/imgcodecs.hpp>

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
  if (count < 1) {
    return InvalidArgumentError("capture sequence: count " + std::to_string(count) + " < 1");
  }
  std::vector<cv::Mat> frames;
  frames.reserve(static_cast<size_t>(count));
  for (int i = 0; i < count; ++i) {
    const std::string path = names.PathOf(folder, i);
    cv::Mat image;
    try {
      image = cv::imread(path, cv::IMREAD_GRAYSCALE);
    } catch (const cv::Exception& e) {
      return IoError("capture sequence: cannot read " + path + ": " + e.what());
    }
    if (image.empty()) {
      return IoError("capture sequence: cannot read " + path +
                     (std::filesystem::exists(path) ? " (not a decodable image)" : " (missing)"));
    }
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
