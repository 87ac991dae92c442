#include "common/structured_light/opencv_peer.h"

#include <chrono>
#include <limits>
#include <string>

#include <opencv2/structured_light.hpp>

#include "common/structured_light/pattern_sequence.h"

namespace sandtable {

Status OpenCvPeerOptions::Check() const {
  if (projector_width_px < 2 || projector_height_px < 2) {
    return InvalidArgumentError("OpenCV peer: projector size must be at least 2x2 px");
  }
  if (black_threshold < 0 || black_threshold > 255 || white_threshold < 0 ||
      white_threshold > 255) {
    return InvalidArgumentError("OpenCV peer: thresholds must be in [0, 255]");
  }
  return OkStatus();
}

Expected<Decoding> DecodeWithOpenCvGrayCode(const std::vector<cv::Mat>& captures,
                                            const OpenCvPeerOptions& options, double* time_ms) {
  ST_RETURN_IF_ERROR(options.Check());
  const PatternOptions patterns =
      PatternOptions::OpenCvGrayCode(options.projector_width_px, options.projector_height_px);
  const PatternLayout layout = MakePatternLayout(patterns);
  if (static_cast<int>(captures.size()) != layout.frame_count) {
    return InvalidArgumentError("OpenCV peer: " + std::to_string(captures.size()) +
                                " captures given, OpenCV order needs " +
                                std::to_string(layout.frame_count));
  }
  for (const cv::Mat& m : captures) {
    if (m.empty() || m.type() != CV_8UC1 || m.size() != captures[0].size()) {
      return InvalidArgumentError(
          "OpenCV peer: captures must be non-empty CV_8UC1 images of one size");
    }
  }
  const cv::Mat& white = captures[layout.white_frame];
  const cv::Mat& black = captures[layout.black_frame];
  // getProjPixel reads the 2 * (bits_u + bits_v) code images only.
  std::vector<cv::Mat> code_images(captures.begin(), captures.begin() + layout.white_frame);

  Decoding out;
  const int rows = white.rows;
  const int cols = white.cols;
  out.projector_px.create(rows, cols, CV_32FC2);
  out.valid.create(rows, cols, CV_8UC1);
  out.confidence.create(rows, cols, CV_32FC1);
  out.flags.create(rows, cols, CV_8UC1);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  try {
    cv::structured_light::GrayCodePattern::Params params;
    params.width = options.projector_width_px;
    params.height = options.projector_height_px;
    cv::Ptr<cv::structured_light::GrayCodePattern> peer =
        cv::structured_light::GrayCodePattern::create(params);
    peer->setBlackThreshold(static_cast<size_t>(options.black_threshold));
    peer->setWhiteThreshold(static_cast<size_t>(options.white_threshold));
    const auto start = std::chrono::steady_clock::now();
    for (int y = 0; y < rows; ++y) {
      cv::Vec2f* uv = out.projector_px.ptr<cv::Vec2f>(y);
      uint8_t* valid = out.valid.ptr<uint8_t>(y);
      uint8_t* flags = out.flags.ptr<uint8_t>(y);
      float* confidence = out.confidence.ptr<float>(y);
      for (int x = 0; x < cols; ++x) {
        uv[x] = cv::Vec2f(nan, nan);
        valid[x] = 0;
        confidence[x] = 0.0f;
        if (static_cast<int>(white.at<uint8_t>(y, x)) - static_cast<int>(black.at<uint8_t>(y, x)) <=
            options.black_threshold) {
          flags[x] = kDecodeShadow;
          continue;
        }
        cv::Point projector;
        const bool error = peer->getProjPixel(code_images, x, y, projector);
        if (error) {
          flags[x] = kDecodeLowContrast;
          continue;
        }
        flags[x] = 0;
        valid[x] = 255;
        confidence[x] = 1.0f;
        uv[x] = cv::Vec2f(static_cast<float>(projector.x), static_cast<float>(projector.y));
      }
    }
    const auto stop = std::chrono::steady_clock::now();
    if (time_ms != nullptr) {
      *time_ms = std::chrono::duration<double, std::milli>(stop - start).count();
    }
  } catch (const cv::Exception& e) {
    return InternalError(std::string("OpenCV peer: GrayCodePattern threw: ") + e.what());
  }
  return out;
}

Expected<std::vector<cv::Mat>> GenerateOpenCvGrayCodePatterns(int width_px, int height_px) {
  if (width_px < 2 || height_px < 2) {
    return InvalidArgumentError("OpenCV peer: projector size must be at least 2x2 px");
  }
  try {
    cv::structured_light::GrayCodePattern::Params params;
    params.width = width_px;
    params.height = height_px;
    cv::Ptr<cv::structured_light::GrayCodePattern> peer =
        cv::structured_light::GrayCodePattern::create(params);
    std::vector<cv::Mat> frames;
    peer->generate(frames);
    cv::Mat black, white;
    peer->getImagesForShadowMasks(black, white);
    frames.push_back(white);
    frames.push_back(black);
    for (cv::Mat& f : frames) {
      if (f.channels() != 1) cv::extractChannel(f, f, 0);
    }
    return frames;
  } catch (const cv::Exception& e) {
    return InternalError(std::string("OpenCV peer: GrayCodePattern threw: ") + e.what());
  }
}

}  // namespace sandtable
