// The report's pictures made for people: what is shown, where the table's projectors fall, a
// legend and a scale bar drawn into the picture itself.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

namespace sandtable::sim {

// A projector's footprint on the table (common/estimation/footprint.h), table frame, metres;
// the lab draws the truth's.
struct PictureFootprint {
  int id = 0;
  std::vector<Eigen::Vector2d> polygon_m;
};

// A top view's extent on the table: row 0 at the north edge (area_max_m.y), column 0 at the
// west edge (area_min_m.x), as the world's top views (render_metrics.h TopView).
struct PictureArea {
  Eigen::Vector2d min_m = Eigen::Vector2d::Zero(), max_m = Eigen::Vector2d::Zero();
};

// The blend's steps on the table: the blended white top view (`picture`, CV_8UC1 grey) dimmed,
// the pixels of `over` (CV_8UC1, non-zero where a step over 5 mm exceeds 1 %) in red, every
// footprint outlined in its colour with its unit's id, and below the view a legend and a scale
// bar in millimetres. CV_8UC3 (BGR).
cv::Mat StepsPicture(const cv::Mat& picture, const cv::Mat& over, const PictureArea& area,
                     const std::vector<PictureFootprint>& footprints);

// The colour of unit `id`'s outline (BGR), the same in every picture.
cv::Scalar UnitColour(int id);

// Below `image` (CV_8UC3): a strip with a scale bar of a round length (mm) for `mm_per_px`
// and the legend's entries, each a colour swatch and its words.
cv::Mat WithLegend(const cv::Mat& image, double mm_per_px,
                   const std::vector<std::pair<cv::Scalar, std::string>>& entries);

}  // namespace sandtable::sim
