#include "node/render/test_patterns.h"

#include <string>

#include <opencv2/imgproc.hpp>

namespace sandtable::node {

cv::Mat ProjectorIdPattern(cv::Size size_px, uint32_t id) {
  cv::Mat image(size_px, CV_8UC3, cv::Scalar::all(0));
  const std::string text = std::to_string(id);
  const int font = cv::FONT_HERSHEY_SIMPLEX;
  const int base_thickness = 2;
  int baseline = 0;
  const cv::Size unit = cv::getTextSize(text, font, 1.0, base_thickness, &baseline);
  const double scale = std::min(0.6 * size_px.height / std::max(unit.height, 1),
                                0.8 * size_px.width / std::max(unit.width, 1));
  const int thickness = std::max(2, static_cast<int>(scale * base_thickness * 0.8));
  const cv::Size text_size = cv::getTextSize(text, font, scale, thickness, &baseline);
  const cv::Point origin((size_px.width - text_size.width) / 2,
                         (size_px.height + text_size.height) / 2);
  cv::putText(image, text, origin, font, scale, cv::Scalar::all(255), thickness, cv::LINE_AA);
  cv::rectangle(image, cv::Rect(0, 0, size_px.width, size_px.height), cv::Scalar::all(255), 1);
  return image;
}

cv::Mat ColourBarsPattern(cv::Size size_px) {
  static const cv::Vec3b kBars[8] = {{255, 255, 255}, {255, 255, 0}, {0, 255, 255}, {0, 255, 0},
                                     {255, 0, 255},   {255, 0, 0},   {0, 0, 255},   {0, 0, 0}};
  cv::Mat image(size_px, CV_8UC3);
  for (int x = 0; x < size_px.width; ++x) {
    const cv::Vec3b colour = kBars[std::min(7, x * 8 / std::max(size_px.width, 1))];
    image.col(x).setTo(cv::Scalar(colour[0], colour[1], colour[2]));
  }
  return image;
}

}  // namespace sandtable::node
