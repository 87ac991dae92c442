// SampleProjectorCells on synthetic decodings: an affine camera <- projector map, whole cells,
// cut cells at the edge, and stray decodes.
#include "common/structured_light/projector_cells.h"

#include <cmath>
#include <limits>

#include <Eigen/Dense>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

namespace sandtable {
namespace {

// A cell's camera pixels are whole pixels: its centroid differs from the image of the cell's
// centre by the quantization of its borders, at most half a pixel per axis (0.39 px rms was
// measured through the simulated world, against 0.034 px for the phase-shift grid: the reason
// the planar path decodes the phase frames too, docs/calibration.md). Over many cells the
// error averages out (no bias).
constexpr double kQuantizationBound_px = 0.5 * M_SQRT2;
constexpr double kBiasTolerance_px = 0.05;  // measured 0.026 px on this map
constexpr double kExactTolerance_px = 1e-4;

// Camera pixel (x, y) sees projector (u, v) = A (x, y) + b; decoded to the centre of its
// 16 px cell (a Gray code with 4 bits skipped, no sub-pixel edges).
Decoding SyntheticDecoding(const Eigen::Matrix2d& a, const Eigen::Vector2d& b, int cols, int rows,
                           int cell, int proj_w, int proj_h) {
  Decoding d;
  d.projector_px = cv::Mat(rows, cols, CV_32FC2, cv::Scalar(NAN, NAN));
  d.valid = cv::Mat::zeros(rows, cols, CV_8UC1);
  for (int y = 0; y < rows; ++y) {
    for (int x = 0; x < cols; ++x) {
      const Eigen::Vector2d p = a * Eigen::Vector2d(x, y) + b;
      // Pixel centres: projector pixel k covers [k - 0.5, k + 0.5).
      const int u = static_cast<int>(std::floor(p.x() + 0.5));
      const int v = static_cast<int>(std::floor(p.y() + 0.5));
      if (u < 0 || v < 0 || u >= proj_w || v >= proj_h) continue;
      const int i = u / cell, j = v / cell;
      d.projector_px.at<cv::Vec2f>(y, x) =
          cv::Vec2f(static_cast<float>(i * cell + (cell - 1) / 2.0),
                    static_cast<float>(j * cell + (cell - 1) / 2.0));
      d.valid.at<uint8_t>(y, x) = 255;
    }
  }
  return d;
}

TEST(ProjectorCells, CentroidsAreTheImagesOfTheCellCentres) {
  Eigen::Matrix2d a;
  a << 1.7, 0.2, -0.15, 1.6;  // ~1.7 projector px per camera px, sheared
  const Eigen::Vector2d b(-40.3, -25.7);
  const int proj_w = 1280, proj_h = 800;
  const Decoding d = SyntheticDecoding(a, b, 900, 620, 16, proj_w, proj_h);
  ProjectorCellOptions options;
  options.projector_width_px = proj_w;
  options.projector_height_px = proj_h;
  options.cell_px = 16;
  ProjectorCellReport report;
  Expected<std::vector<ProjectorGridPoint>> cells = SampleProjectorCells(d, options, &report);
  ASSERT_TRUE(cells.ok()) << cells.status().ToString();
  ASSERT_GT(cells->size(), 500u);
  const Eigen::Matrix2d inverse = a.inverse();
  double worst = 0.0;
  Eigen::Vector2d bias = Eigen::Vector2d::Zero();
  for (const ProjectorGridPoint& c : *cells) {
    // The cell's centre in the continuous projector plane is its pixel-centre midpoint.
    const Eigen::Vector2d expected = inverse * (c.projector_px.cast<double>() - b);
    const Eigen::Vector2d error = c.camera_px.cast<double>() - expected;
    worst = std::max(worst, error.norm());
    bias += error;
  }
  bias /= static_cast<double>(cells->size());
  EXPECT_LT(worst, kQuantizationBound_px);
  EXPECT_LT(bias.norm(), kBiasTolerance_px);
  // Cells cut by the camera's border were left out, and said so.
  EXPECT_GT(report.rejected_support + report.rejected_neighbours, 0);
  EXPECT_EQ(report.cells_kept, static_cast<int>(cells->size()));
}

TEST(ProjectorCells, StrayDecodesDoNotMoveACentroid) {
  Eigen::Matrix2d a = Eigen::Matrix2d::Identity() * 1.5;
  const Eigen::Vector2d b(0.0, 0.0);
  Decoding d = SyntheticDecoding(a, b, 400, 300, 16, 640, 480);
  // The centroid of cell (5, 5)'s own pixels, before a pixel far away decodes to it too.
  Eigen::Vector2d sum = Eigen::Vector2d::Zero();
  int count = 0;
  for (int y = 0; y < 300; ++y) {
    for (int x = 0; x < 400; ++x) {
      const cv::Vec2f p = d.projector_px.at<cv::Vec2f>(y, x);
      if (d.valid.at<uint8_t>(y, x) && p[0] == 87.5f && p[1] == 87.5f) {
        sum += Eigen::Vector2d(x, y);
        ++count;
      }
    }
  }
  ASSERT_GT(count, 50);
  const Eigen::Vector2d own_centroid = sum / count;
  d.projector_px.at<cv::Vec2f>(250, 350) = cv::Vec2f(5 * 16 + 7.5f, 5 * 16 + 7.5f);
  ProjectorCellOptions options;
  options.projector_width_px = 640;
  options.projector_height_px = 480;
  ProjectorCellReport report;
  Expected<std::vector<ProjectorGridPoint>> cells = SampleProjectorCells(d, options, &report);
  ASSERT_TRUE(cells.ok());
  EXPECT_EQ(report.stray_pixels, 1);
  bool found = false;
  for (const ProjectorGridPoint& c : *cells) {
    if (c.projector_px.x() != 87.5f || c.projector_px.y() != 87.5f) continue;
    found = true;
    EXPECT_NEAR(c.camera_px.x(), own_centroid.x(), kExactTolerance_px);
    EXPECT_NEAR(c.camera_px.y(), own_centroid.y(), kExactTolerance_px);
    EXPECT_NEAR(c.camera_px.x(), 87.5 / 1.5, kQuantizationBound_px);
  }
  EXPECT_TRUE(found);
}

TEST(ProjectorCells, RefusesBadInput) {
  Decoding d;
  d.projector_px = cv::Mat(4, 4, CV_32FC1);
  d.valid = cv::Mat::zeros(4, 4, CV_8UC1);
  EXPECT_FALSE(SampleProjectorCells(d, {}).ok());
  ProjectorCellOptions bad;
  bad.cell_px = 1;
  EXPECT_FALSE(bad.Check().ok());
}

}  // namespace
}  // namespace sandtable
