#include "node/devices/video_camera_input.h"

#include <cmath>
#include <filesystem>

#include <opencv2/core/utils/logger.hpp>
#include <opencv2/imgproc.hpp>

#include "common/base/log.h"

namespace sandtable::node {
namespace {

bool IsIndex(const std::string& text) {
  return !text.empty() && text.size() <= 6 &&
         text.find_first_not_of("0123456789") == std::string::npos;
}

// V4L2 exposure_absolute counts 100 us.
constexpr double kV4l2ExposureUnit_s = 100e-6;
// OpenCV's V4L2 backend: CAP_PROP_AUTO_EXPOSURE 1 = manual, 3 = aperture priority (auto).
constexpr double kV4l2ManualExposure = 1.0;
constexpr double kV4l2AutoExposure = 3.0;

// OpenCV's backends print their own warnings while probing a device or stream that fails; we
// report one line of our own instead, so they are quiet during Open().
class QuietOpenCv {
 public:
  QuietOpenCv() : saved_(cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_ERROR)) {}
  ~QuietOpenCv() { cv::utils::logging::setLogLevel(saved_); }

 private:
  cv::utils::logging::LogLevel saved_;
};

}  // namespace

Status VideoCameraOptions::Check() const {
  if (device.empty()) return InvalidArgumentError("video: empty device (an index or a URL)");
  if (discard_frames < 0 || discard_frames > 16) {
    return InvalidArgumentError("video:" + device + ": discard_frames " +
                                std::to_string(discard_frames) + " must be in 0..16");
  }
  if (size_px && (size_px->width <= 0 || size_px->height <= 0)) {
    return InvalidArgumentError("video:" + device + ": requested size must be positive");
  }
  return OkStatus();
}

Expected<std::unique_ptr<VideoCameraInput>> VideoCameraInput::Open(
    const VideoCameraOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  std::unique_ptr<VideoCameraInput> camera(new VideoCameraInput());
  camera->options_ = options;
  camera->description_ = "video:" + options.device;
  const std::string& who = camera->description_;
  const QuietOpenCv quiet;
  std::error_code missing;
  try {
    if (IsIndex(options.device)) {
      const int index = std::stoi(options.device);
      const std::string node = "/dev/video" + options.device;
      std::error_code error;
      // Checked first: OpenCV would print its own warnings for a missing device.
      if (!std::filesystem::exists(node, error)) {
        return UnavailableError(who + ": no camera: " + node + " does not exist");
      }
      if (!camera->capture_.open(index, cv::CAP_V4L2)) {
        return UnavailableError(who + ": " + node +
                                " cannot be opened as a V4L2 capture device (busy, no "
                                "permission, or not a camera)");
      }
      camera->capture_.set(cv::CAP_PROP_BUFFERSIZE, 1);
    } else if (options.device.find("://") == std::string::npos &&
               !std::filesystem::exists(options.device, missing)) {
      return UnavailableError(who + ": no such file");
    } else if (!camera->capture_.open(options.device, cv::CAP_ANY)) {
      return UnavailableError(who + ": cannot open " + options.device +
                              " (no such file or host, or no OpenCV backend for it)");
    }
    if (options.size_px) {
      camera->capture_.set(cv::CAP_PROP_FRAME_WIDTH, options.size_px->width);
      camera->capture_.set(cv::CAP_PROP_FRAME_HEIGHT, options.size_px->height);
    }
  } catch (const cv::Exception& e) {
    return UnavailableError(who + ": OpenCV: " + e.what());
  }
  Expected<cv::Mat> first = camera->Read();
  if (!first.ok()) return first.status().WithContext("opened, but");
  camera->size_px_ = first->size();
  camera->bit_depth_ = first->depth() == CV_16U ? 16 : 8;
  ST_LOG(kInfo) << who << ": " << camera->size_px_.width << "x" << camera->size_px_.height << " "
                << camera->bit_depth_ << " bit";
  return camera;
}

Expected<cv::Mat> VideoCameraInput::Read() {
  cv::Mat raw;
  try {
    if (!capture_.read(raw) || raw.empty()) {
      return UnavailableError(description_ + ": no frame (unplugged, or the stream ended)");
    }
  } catch (const cv::Exception& e) {
    return UnavailableError(description_ + ": OpenCV: " + e.what());
  }
  if (raw.depth() != CV_8U && raw.depth() != CV_16U) {
    return UnavailableError(description_ + ": frames of OpenCV depth " +
                            std::to_string(raw.depth()) + " are not 8 or 16 bit");
  }
  cv::Mat gray;
  if (raw.channels() == 3) {
    cv::cvtColor(raw, gray, cv::COLOR_BGR2GRAY);
  } else if (raw.channels() == 4) {
    cv::cvtColor(raw, gray, cv::COLOR_BGRA2GRAY);
  } else {
    gray = raw.channels() == 1 ? raw.clone() : cv::Mat();
  }
  if (gray.empty()) {
    return UnavailableError(description_ + ": frames with " + std::to_string(raw.channels()) +
                            " channels are not gray or colour");
  }
  return gray;
}

void VideoCameraInput::SetExposure(Seconds exposure) {
  if (exposure == exposure_) return;
  bool ok = false;
  try {
    if (exposure.count() == 0.0) {
      ok = capture_.set(cv::CAP_PROP_AUTO_EXPOSURE, kV4l2AutoExposure);
    } else {
      ok = capture_.set(cv::CAP_PROP_AUTO_EXPOSURE, kV4l2ManualExposure) &&
           capture_.set(cv::CAP_PROP_EXPOSURE, exposure.count() / kV4l2ExposureUnit_s);
    }
  } catch (const cv::Exception&) {
    ok = false;
  }
  exposure_ = exposure;
  if (!ok && !exposure_warned_) {
    exposure_warned_ = true;
    ST_LOG(kWarning) << description_ << ": exposure control not supported; captures use the "
                     << "camera's own exposure";
  }
}

Expected<CapturedFrame> VideoCameraInput::Capture(Seconds exposure) {
  if (!std::isfinite(exposure.count()) || exposure.count() < 0.0) {
    return InvalidArgumentError(description_ + ": exposure must be finite and >= 0 s");
  }
  SetExposure(exposure);
  try {
    for (int i = 0; i < options_.discard_frames; ++i) capture_.grab();
  } catch (const cv::Exception& e) {
    return UnavailableError(description_ + ": OpenCV: " + e.what());
  }
  Expected<cv::Mat> image = Read();
  if (!image.ok()) return image.status();
  if (image->size() != size_px_ || image->depth() != (bit_depth_ > 8 ? CV_16U : CV_8U)) {
    return UnavailableError(description_ + ": frame format changed to " +
                            std::to_string(image->cols) + "x" + std::to_string(image->rows) +
                            (image->depth() == CV_16U ? " 16 bit" : " 8 bit"));
  }
  CapturedFrame frame;
  frame.capture_time = DeviceClock::now();
  frame.image = std::move(*image);
  frame.index = ++captures_;
  ST_LOG(kDebug) << description_ << ": capture " << frame.index;
  return frame;
}

}  // namespace sandtable::node
