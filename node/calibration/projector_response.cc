#include "node/calibration/projector_response.h"

#include <algorithm>
#include <cmath>
#include <string>

namespace sandtable::node {

Expected<ProjectorResponse> FitProjectorResponse(const cv::Mat& black, const cv::Mat& white,
                                                 const cv::Mat& muted,
                                                 const std::vector<std::pair<int, cv::Mat>>& greys,
                                                 const cv::Mat& lit,
                                                 const ProjectorResponseOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  auto fits = [&](const cv::Mat& m) { return m.type() == CV_8UC1 && m.size() == white.size(); };
  if (white.empty() || !fits(black) || !fits(white) || (!muted.empty() && !fits(muted)) ||
      (!lit.empty() && !fits(lit))) {
    return InvalidArgumentError(
        "projector response: black, white, muted and the lit mask must be 8-bit captures of one "
        "size");
  }
  if (greys.empty()) return InvalidArgumentError("projector response: no grey levels");
  for (const auto& [level, image] : greys) {
    if (level < 1 || level > 254) {
      return InvalidArgumentError("projector response: grey level " + std::to_string(level) +
                                  " is not in 1..254");
    }
    if (!fits(image)) {
      return InvalidArgumentError("projector response: the capture of level " +
                                  std::to_string(level) + " is not an 8-bit capture of " +
                                  std::to_string(white.cols) + "x" + std::to_string(white.rows));
    }
  }
  // The usable pixels.
  std::vector<cv::Point> pixels;
  for (int y = 0; y < white.rows; ++y) {
    const uint8_t* w = white.ptr<uint8_t>(y);
    const uint8_t* b = black.ptr<uint8_t>(y);
    const uint8_t* m = lit.empty() ? nullptr : lit.ptr<uint8_t>(y);
    for (int x = 0; x < white.cols; ++x) {
      if ((m && !m[x]) || w[x] >= options.saturation_dn) continue;
      if (static_cast<int>(w[x]) - b[x] < options.min_signal_dn) continue;
      pixels.emplace_back(x, y);
    }
  }
  ProjectorResponse out;
  out.pixels = static_cast<int>(pixels.size());
  if (out.pixels < options.min_pixels) {
    return DegenerateError("projector response: " + std::to_string(out.pixels) +
                           " usable camera pixels (at least " + std::to_string(options.min_pixels) +
                           " must see the projector unsaturated)");
  }
  auto sum_difference = [&](const cv::Mat& a, const cv::Mat& b) {
    double sum = 0.0;
    for (const cv::Point& p : pixels) {
      sum += static_cast<double>(a.at<uint8_t>(p)) - static_cast<double>(b.at<uint8_t>(p));
    }
    return sum;
  };
  const double span = sum_difference(white, black);
  // log ratio = gamma log x, through the origin.
  std::vector<std::pair<double, double>> points;  // (x, ratio)
  double xx = 0.0, xy = 0.0;
  for (const auto& [level, image] : greys) {
    const double ratio = sum_difference(image, black) / span;
    if (!(ratio > 0.0 && ratio < 1.0)) {
      return DegenerateError("projector response: level " + std::to_string(level) + " gives " +
                             std::to_string(ratio) +
                             " of white above black (must be in (0, 1): the projector does not "
                             "respond as a display)");
    }
    const double lx = std::log(level / 255.0), ly = std::log(ratio);
    xx += lx * lx;
    xy += lx * ly;
    points.emplace_back(level / 255.0, ratio);
  }
  out.gamma = xy / xx;
  double sq = 0.0;
  for (const auto& [x, ratio] : points) sq += std::pow(ratio - std::pow(x, out.gamma), 2);
  out.fit_rms = std::sqrt(sq / static_cast<double>(points.size()));
  if (!muted.empty()) {
    const double over_muted = sum_difference(white, muted);
    if (!(over_muted > 0.0)) {
      return DegenerateError("projector response: white is not brighter than muted");
    }
    out.black_level = std::max(0.0, sum_difference(black, muted) / over_muted);
  }
  if (!(out.gamma >= kMinPlausibleGamma && out.gamma <= kMaxPlausibleGamma)) {
    return OutOfRangeError("projector response: fitted gamma " + std::to_string(out.gamma) +
                           " is not a projector's (" + std::to_string(kMinPlausibleGamma) + ".." +
                           std::to_string(kMaxPlausibleGamma) +
                           "): is the camera's auto exposure or its own gamma on?");
  }
  if (out.black_level > kMaxPlausibleBlackLevel) {
    return OutOfRangeError("projector response: black level " + std::to_string(out.black_level) +
                           " of peak is not a projector's (at most " +
                           std::to_string(kMaxPlausibleBlackLevel) +
                           "): did the muted capture see the projector's light?");
  }
  return out;
}

Status ProjectorResponseOptions::Check() const {
  if (saturation_dn < 1 || saturation_dn > 255 || min_signal_dn < 1 ||
      min_signal_dn >= saturation_dn || min_pixels < 1) {
    return InvalidArgumentError(
        "projector response: 0 < min_signal_dn < saturation_dn <= 255, min_pixels >= 1");
  }
  return OkStatus();
}

}  // namespace sandtable::node
