// The report's pictures for people: the steps picture keeps the view's pixels where they were,
// paints the steps red, outlines the footprints and adds a legend with a scale bar below.
#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "sim/lab/lab_pictures.h"

namespace sandtable::sim {
namespace {

TEST(LabPicturesTest, StepsPictureMarksStepsOutlinesFootprintsAndAddsALegend) {
  // A 2 m x 1 m view, 200 x 100 px (10 mm per pixel), mid-grey.
  const cv::Mat picture(100, 200, CV_8UC1, cv::Scalar(128));
  cv::Mat over = cv::Mat::zeros(100, 200, CV_8UC1);
  over.at<uint8_t>(20, 30) = 255;
  PictureArea area;
  area.min_m = {-1.0, -0.5};
  area.max_m = {1.0, 0.5};
  // Unit 3's footprint: the square x, y in [0, 0.4] (pixels 100..140 wide, rows 10..50).
  const PictureFootprint square{3, {{0.0, 0.0}, {0.4, 0.0}, {0.4, 0.4}, {0.0, 0.4}}};
  const cv::Mat out = StepsPicture(picture, over, area, {square});
  ASSERT_EQ(out.type(), CV_8UC3);
  EXPECT_EQ(out.cols, 200);
  EXPECT_GT(out.rows, 100 + 2 * 20) << "a scale bar row and two legend rows below the view";
  const cv::Vec3b step = out.at<cv::Vec3b>(20, 30);
  EXPECT_GT(step[2], 200);  // red (BGR)
  EXPECT_LT(step[1], 80);
  // The footprint's west edge (x = 0 m: column 100) between its rows, in unit 3's colour.
  const cv::Scalar c = UnitColour(3);
  const cv::Vec3b edge = out.at<cv::Vec3b>(30, 100);
  EXPECT_NEAR(edge[0], c[0], 40);
  EXPECT_NEAR(edge[1], c[1], 40);
  EXPECT_NEAR(edge[2], c[2], 40);
  // Elsewhere the view is kept, dimmed towards white (grey, not coloured).
  const cv::Vec3b plain = out.at<cv::Vec3b>(80, 10);
  EXPECT_EQ(plain[0], plain[1]);
  EXPECT_EQ(plain[1], plain[2]);
  EXPECT_NEAR(plain[0], 0.55 * 128 + 90, 1.0);
}

TEST(LabPicturesTest, ScaleBarIsARoundLength) {
  const cv::Mat image(50, 400, CV_8UC3, cv::Scalar(255, 255, 255));
  // 2.5 mm per pixel: a fifth of the width is 200 mm, so the bar is 200 mm = 80 px long.
  const cv::Mat out = WithLegend(image, 2.5, {});
  const int bar_row = 50 + 22 - 6 - 5;
  for (int x = 10; x <= 86; ++x) {
    EXPECT_LT(out.at<cv::Vec3b>(bar_row, x)[0], 100) << "the bar at x = " << x;
  }
  EXPECT_GT(out.at<cv::Vec3b>(bar_row, 93)[0], 200) << "the bar ends at 8 + 80 px";
}

}  // namespace
}  // namespace sandtable::sim
