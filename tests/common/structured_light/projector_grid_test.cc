// SampleProjectorGrid: the camera position of projector grid nodes from a dense decoding.
#include "common/structured_light/projector_grid.h"

#include <cmath>
#include <random>

#include <gtest/gtest.h>
#include <Eigen/LU>

namespace sandtable {
namespace {

constexpr double kExactTolerance_px = 1e-3;  // noise-free affine map: exact up to float
constexpr double kNoisyTolerance_px = 0.05;  // 0.1 px decode noise averaged over the support

// A decoding of a camera that sees the projector through an affine map:
// projector = a * camera + b (so camera = a^-1 (projector - b)), with optional noise.
Decoding AffineDecoding(int width, int height, const Eigen::Matrix2d& a, const Eigen::Vector2d& b,
                        double noise_px, uint64_t seed) {
  Decoding d;
  d.projector_px = cv::Mat(height, width, CV_32FC2);
  d.valid = cv::Mat(height, width, CV_8UC1, cv::Scalar(255));
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> n(0.0, noise_px);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const Eigen::Vector2d p = a * Eigen::Vector2d(x, y) + b;
      d.projector_px.at<cv::Vec2f>(y, x) =
          cv::Vec2f(static_cast<float>(p.x() + (noise_px > 0 ? n(rng) : 0.0)),
                    static_cast<float>(p.y() + (noise_px > 0 ? n(rng) : 0.0)));
    }
  }
  return d;
}

ProjectorGridOptions Options() {
  ProjectorGridOptions o;
  o.projector_width_px = 400;
  o.projector_height_px = 300;
  o.step_px = 16;
  o.offset_px = 8;
  o.support_radius_px = 3;
  return o;
}

TEST(ProjectorGrid, RecoversTheInverseOfAnAffineMapExactly) {
  Eigen::Matrix2d a;
  a << 1.3, 0.2, -0.1, 1.2;  // 1.3 projector px per camera px, slightly sheared
  const Eigen::Vector2d b(-20.0, -15.0);
  const Decoding d = AffineDecoding(320, 260, a, b, 0.0, 1);
  ProjectorGridReport report;
  Expected<std::vector<ProjectorGridPoint>> points = SampleProjectorGrid(d, Options(), &report);
  ASSERT_TRUE(points.ok()) << points.status().ToString();
  ASSERT_GT(points->size(), 200u);
  EXPECT_EQ(report.nodes_kept, static_cast<int>(points->size()));
  for (const ProjectorGridPoint& p : *points) {
    const Eigen::Vector2d expected = a.inverse() * (p.projector_px.cast<double>() - b);
    EXPECT_NEAR(p.camera_px.x(), expected.x(), kExactTolerance_px);
    EXPECT_NEAR(p.camera_px.y(), expected.y(), kExactTolerance_px);
    EXPECT_GE(p.support, Options().min_support);
  }
}

TEST(ProjectorGrid, AveragesDecodeNoise) {
  Eigen::Matrix2d a;
  a << 1.5, 0.0, 0.0, 1.5;
  const Eigen::Vector2d b(5.0, 3.0);
  const Decoding d = AffineDecoding(300, 220, a, b, 0.1, 7);
  Expected<std::vector<ProjectorGridPoint>> points = SampleProjectorGrid(d, Options());
  ASSERT_TRUE(points.ok());
  double sum_sq = 0;
  for (const ProjectorGridPoint& p : *points) {
    const Eigen::Vector2d expected = a.inverse() * (p.projector_px.cast<double>() - b);
    sum_sq += (p.camera_px.cast<double>() - expected).squaredNorm();
  }
  const double rms = std::sqrt(sum_sq / points->size());
  // Per camera pixel the noise is 0.1 / 1.5 = 0.067 camera px per axis; ~16 pixels per node.
  EXPECT_LT(rms, kNoisyTolerance_px);
}

TEST(ProjectorGrid, RefusesSupportAcrossADepthEdge) {
  Eigen::Matrix2d a = Eigen::Matrix2d::Identity() * 1.4;
  Decoding d = AffineDecoding(300, 220, a, Eigen::Vector2d(0, 0), 0.0, 3);
  // Columns x >= 146 see the projector through another map (a step in depth): the decoded
  // projector x jumps back by 6 px there, so nodes near the seam get pixels from both sides.
  for (int y = 0; y < d.projector_px.rows; ++y) {
    for (int x = 146; x < d.projector_px.cols; ++x) d.projector_px.at<cv::Vec2f>(y, x)[0] -= 6.0f;
  }
  ProjectorGridReport report;
  Expected<std::vector<ProjectorGridPoint>> points = SampleProjectorGrid(d, Options(), &report);
  ASSERT_TRUE(points.ok());
  EXPECT_GT(report.rejected_fit, 0);
  for (const ProjectorGridPoint& p : *points) {
    // Every kept node is explained by one side's map.
    const double left = p.projector_px.x() / 1.4, right = (p.projector_px.x() + 6.0) / 1.4;
    EXPECT_TRUE(std::abs(p.camera_px.x() - left) < 0.01 || std::abs(p.camera_px.x() - right) < 0.01)
        << p.projector_px.transpose() << " -> " << p.camera_px.transpose();
  }
}

TEST(ProjectorGrid, ACoarseCameraStillGivesEveryNodeItSees) {
  // The unseen site of issue 34: a 1920-wide projector seen by a 700 px camera, 3 projector px
  // per camera px. Inside the small support (6 x 6 projector px) a node gets ~4 camera pixels,
  // under min_support: with the small support alone 3 of ~350 nodes survived.
  Eigen::Matrix2d a;
  a << 3.0, 0.3, -0.2, 2.9;
  const Eigen::Vector2d b(-30.0, -20.0);
  const Decoding d = AffineDecoding(150, 110, a, b, 0.1, 11);
  ProjectorGridOptions small = Options();
  small.wide_support_radius_px = 0.0;
  ProjectorGridReport small_report;
  Expected<std::vector<ProjectorGridPoint>> few = SampleProjectorGrid(d, small, &small_report);
  ASSERT_TRUE(few.ok());
  EXPECT_LT(few->size(), 20u) << "the small support alone loses the coarse camera's nodes";

  ProjectorGridReport report;
  Expected<std::vector<ProjectorGridPoint>> points = SampleProjectorGrid(d, Options(), &report);
  ASSERT_TRUE(points.ok());
  // Nodes whose whole wide support lies in the decoded area: (150 x 110 camera px) x 3 = a
  // 450 x 320 projector region, clipped to the 400 x 300 image, 16 px apart.
  EXPECT_GT(points->size(), 300u);
  EXPECT_EQ(report.nodes_on_wide_support,
            static_cast<int>(points->size()) - static_cast<int>(few->size()));
  double sum_sq = 0;
  for (const ProjectorGridPoint& p : *points) {
    const Eigen::Vector2d expected = a.inverse() * (p.projector_px.cast<double>() - b);
    sum_sq += (p.camera_px.cast<double>() - expected).squaredNorm();
  }
  // 0.1 projector px of noise is 0.033 camera px per pixel, averaged over ~25 pixels.
  EXPECT_LT(std::sqrt(sum_sq / points->size()), kNoisyTolerance_px);
}

TEST(ProjectorGrid, AFineCameraKeepsTheSmallSupport) {
  Eigen::Matrix2d a = Eigen::Matrix2d::Identity() * 1.2;
  const Decoding d = AffineDecoding(320, 250, a, Eigen::Vector2d(2.0, 1.0), 0.1, 5);
  ProjectorGridOptions small = Options();
  small.wide_support_radius_px = 0.0;
  Expected<std::vector<ProjectorGridPoint>> without = SampleProjectorGrid(d, small);
  ProjectorGridReport report;
  Expected<std::vector<ProjectorGridPoint>> with = SampleProjectorGrid(d, Options(), &report);
  ASSERT_TRUE(without.ok() && with.ok());
  ASSERT_EQ(without->size(), with->size());
  EXPECT_EQ(report.nodes_on_wide_support, 0);
  for (size_t i = 0; i < with->size(); ++i) {
    EXPECT_EQ((*with)[i].camera_px, (*without)[i].camera_px);
  }
}

TEST(ProjectorGrid, RefusesBadInput) {
  Decoding d;
  d.projector_px = cv::Mat(10, 10, CV_32FC1);
  d.valid = cv::Mat(10, 10, CV_8UC1);
  EXPECT_FALSE(SampleProjectorGrid(d, Options()).ok());
  ProjectorGridOptions bad = Options();
  bad.support_radius_px = 20;  // >= step
  EXPECT_FALSE(bad.Check().ok());
  bad = Options();
  bad.wide_support_radius_px = -1;
  EXPECT_FALSE(bad.Check().ok());
}

}  // namespace
}  // namespace sandtable
