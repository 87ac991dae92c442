#include "node/devices/projector_output.h"

#include <opencv2/core/utility.hpp>

namespace sandtable::node {

std::string FrameTypeName(const cv::Mat& frame) {
  if (frame.type() == CV_8UC1) return "GRAY8";
  if (frame.type() == CV_8UC3) return "RGB8";
  return cv::typeToString(frame.type()).substr(3);  // "CV_16UC1" -> "16UC1"
}

Status CheckProjectorFrame(const cv::Mat& frame, cv::Size size, const std::string& who) {
  const std::string shape = std::to_string(frame.cols) + "x" + std::to_string(frame.rows);
  const std::string projector = std::to_string(size.width) + "x" + std::to_string(size.height);
  if (frame.empty()) return InvalidArgumentError(who + ": empty frame, projector is " + projector);
  if (frame.dims != 2 || (frame.type() != CV_8UC1 && frame.type() != CV_8UC3)) {
    return InvalidArgumentError(who + ": frame is " + FrameTypeName(frame) +
                                ", expected GRAY8 (CV_8UC1) or RGB8 (CV_8UC3)");
  }
  if (frame.size() != size) {
    return InvalidArgumentError(who + ": frame is " + shape + " " + FrameTypeName(frame) +
                                ", projector is " + projector);
  }
  return OkStatus();
}

}  // namespace sandtable::node
