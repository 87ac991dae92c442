#include "sim/lab/lab_pictures.h"

#include <algorithm>
#include <cmath>

#include <opencv2/imgproc.hpp>

namespace sandtable::sim {
namespace {

constexpr int kLegendRowPx = 22;
constexpr double kFontScale = 0.45;
const cv::Scalar kInk(30, 30, 30), kPaper(250, 250, 250), kOverRed(40, 40, 225);

cv::Point ToPixel(const Eigen::Vector2d& p, const PictureArea& area, cv::Size size) {
  const double u = (p.x() - area.min_m.x()) / (area.max_m.x() - area.min_m.x()) * size.width;
  const double v = (area.max_m.y() - p.y()) / (area.max_m.y() - area.min_m.y()) * size.height;
  return {static_cast<int>(std::lround(u)), static_cast<int>(std::lround(v))};
}

// 1, 2 or 5 times a power of ten, the largest not over `mm`.
double RoundLength(double mm) {
  const double decade = std::pow(10.0, std::floor(std::log10(std::max(mm, 1e-3))));
  for (const double f : {5.0, 2.0, 1.0}) {
    if (f * decade <= mm) return f * decade;
  }
  return decade;
}

}  // namespace

cv::Scalar UnitColour(int id) {
  static const cv::Scalar kPalette[] = {{214, 120, 31}, {44, 160, 44},  {180, 60, 200},
                                        {30, 140, 240}, {160, 160, 20}, {200, 80, 120},
                                        {90, 90, 230},  {20, 190, 190}};
  return kPalette[static_cast<size_t>(std::abs(id)) % (sizeof(kPalette) / sizeof(kPalette[0]))];
}

cv::Mat WithLegend(const cv::Mat& image, double mm_per_px,
                   const std::vector<std::pair<cv::Scalar, std::string>>& entries) {
  // Text and rows grow with pictures wider than 800 px, so they read the same when shown small.
  const double grow = std::max(1.0, image.cols / 800.0);
  const int row_px = static_cast<int>(std::lround(kLegendRowPx * grow));
  const double font = kFontScale * grow;
  const int thick = grow >= 1.75 ? 2 : 1;
  const int rows = 1 + static_cast<int>(entries.size());
  cv::Mat out(image.rows + rows * row_px + 8, image.cols, CV_8UC3, kPaper);
  image.copyTo(out(cv::Rect(0, 0, image.cols, image.rows)));
  int y = image.rows + row_px - 6;
  // The scale bar: a round length near a fifth of the width.
  const double bar_mm = RoundLength(0.2 * image.cols * mm_per_px);
  const int bar_px = static_cast<int>(std::lround(bar_mm / mm_per_px));
  cv::line(out, {8, y - 5}, {8 + bar_px, y - 5}, kInk, 2);
  cv::line(out, {8, y - 10}, {8, y}, kInk, 2);
  cv::line(out, {8 + bar_px, y - 10}, {8 + bar_px, y}, kInk, 2);
  const std::string scale = bar_mm >= 1000.0
                                ? std::to_string(static_cast<int>(bar_mm / 1000.0)) + " m"
                                : std::to_string(static_cast<int>(bar_mm)) + " mm";
  cv::putText(out, scale + " (table frame, seen from above)", {16 + bar_px, y},
              cv::FONT_HERSHEY_SIMPLEX, font, kInk, thick, cv::LINE_AA);
  const int swatch = static_cast<int>(std::lround(12 * grow));
  for (const auto& [colour, words] : entries) {
    y += row_px;
    cv::rectangle(out, cv::Rect(8, y - swatch, 2 * swatch, swatch), colour, cv::FILLED);
    cv::putText(out, words, {16 + 2 * swatch, y}, cv::FONT_HERSHEY_SIMPLEX, font, kInk, thick,
                cv::LINE_AA);
  }
  return out;
}

cv::Mat StepsPicture(const cv::Mat& picture, const cv::Mat& over, const PictureArea& area,
                     const std::vector<PictureFootprint>& footprints) {
  cv::Mat grey;
  picture.convertTo(grey, CV_8UC1, 0.55, 90.0);  // dimmed, so the red and outlines stand out
  cv::Mat image;
  cv::cvtColor(grey, image, cv::COLOR_GRAY2BGR);
  int over_px = 0;
  if (!over.empty() && over.size() == picture.size()) {
    cv::Mat marks;
    cv::dilate(over != 0, marks, cv::Mat::ones(3, 3, CV_8UC1));
    image.setTo(kOverRed, marks);
    over_px = cv::countNonZero(over);
  }
  std::vector<std::pair<cv::Scalar, std::string>> legend = {
      {kOverRed,
       "a step over 1 % between samples 5 mm apart (" + std::to_string(over_px) + " samples)"}};
  for (const PictureFootprint& f : footprints) {
    if (f.polygon_m.size() < 3) continue;
    std::vector<cv::Point> polygon;
    Eigen::Vector2d centre = Eigen::Vector2d::Zero();
    for (const Eigen::Vector2d& p : f.polygon_m) {
      polygon.push_back(ToPixel(p, area, picture.size()));
      centre += p / static_cast<double>(f.polygon_m.size());
    }
    cv::polylines(image, polygon, true, UnitColour(f.id), 2, cv::LINE_AA);
    cv::putText(image, std::to_string(f.id), ToPixel(centre, area, picture.size()),
                cv::FONT_HERSHEY_SIMPLEX, 0.8 * std::max(1.0, picture.cols / 800.0),
                UnitColour(f.id), 2, cv::LINE_AA);
    legend.push_back(
        {UnitColour(f.id), "projector " + std::to_string(f.id) + "'s footprint (its true pose)"});
  }
  const double mm_per_px = 1e3 * (area.max_m.x() - area.min_m.x()) / std::max(1, picture.cols);
  return WithLegend(image, mm_per_px, legend);
}

}  // namespace sandtable::sim
