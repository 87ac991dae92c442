#include "common/structured_light/pattern_sequence.h"

#include <cmath>
#include <filesystem>
#include <string>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "common/structured_light/capture_io.h"
#include "common/structured_light/decoder.h"
#include "common/structured_light/opencv_peer.h"

namespace sandtable {
namespace {

// Projecting the patterns straight into the "camera" (identity map, no noise): Gray code is
// exact; the phase only suffers from rounding the sinusoid to 8 bits.
constexpr double kExact_px = 0.0;
constexpr double kPhaseRounding_px = 0.03;

TEST(GrayCode, RoundTripsEvery16BitValue) {
  for (uint32_t v = 0; v < 65536; ++v) {
    ASSERT_EQ(BinaryFromGray(GrayFromBinary(v)), v);
    if (v > 0) {  // neighbours differ in exactly one bit
      ASSERT_EQ(__builtin_popcount(GrayFromBinary(v) ^ GrayFromBinary(v - 1)), 1);
    }
  }
}

TEST(PatternLayout, CountsAndOrders) {
  EXPECT_EQ(GrayBitsFor(1024), 10);
  EXPECT_EQ(GrayBitsFor(768), 10);
  EXPECT_EQ(GrayBitsFor(1025), 11);
  EXPECT_EQ(GrayBitsFor(2), 1);

  const PatternLayout opencv = MakePatternLayout(PatternOptions::OpenCvGrayCode(1024, 768));
  EXPECT_EQ(opencv.frame_count, 42);
  EXPECT_EQ(opencv.columns.gray_frame[0], 0);
  EXPECT_EQ(opencv.columns.gray_inverse_frame[0], 1);
  EXPECT_EQ(opencv.rows.gray_frame[0], 20);
  EXPECT_EQ(opencv.rows.gray_inverse_frame[9], 39);
  EXPECT_EQ(opencv.white_frame, 40);
  EXPECT_EQ(opencv.black_frame, 41);

  PatternOptions o;
  o.projector_width_px = 1280;
  o.projector_height_px = 800;
  o.phase_steps = 6;
  o.gray_lsb_skip = 2;
  const PatternLayout ours = MakePatternLayout(o);
  EXPECT_EQ(ours.white_frame, 0);
  EXPECT_EQ(ours.black_frame, 1);
  EXPECT_EQ(ours.columns.projected_bits, 9);  // 11 bits for 1280, 2 skipped
  EXPECT_EQ(ours.rows.projected_bits, 8);     // 10 bits for 800, 2 skipped
  EXPECT_EQ(ours.columns.gray_frame[0], 2);
  EXPECT_EQ(ours.rows.gray_frame[0], 2 + 2 * 9);
  EXPECT_EQ(ours.columns.phase_frame[0], 2 + 2 * 9 + 2 * 8);
  EXPECT_EQ(ours.rows.phase_frame[5], ours.frame_count - 1);
  EXPECT_EQ(ours.frame_count, 2 + 2 * 9 + 2 * 8 + 2 * 6);
}

TEST(PatternOptions, CheckNamesTheBadField) {
  auto message_of = [](PatternOptions o) { return o.Check().message(); };
  PatternOptions o;
  EXPECT_TRUE(o.Check().ok());
  o.projector_width_px = 1;
  EXPECT_NE(message_of(o).find("projector size"), std::string::npos);
  o = PatternOptions();
  o.encode_columns = o.encode_rows = false;
  EXPECT_NE(message_of(o).find("neither"), std::string::npos);
  o = PatternOptions();
  o.gray_lsb_skip = 10;  // 768 rows have 10 bits
  EXPECT_NE(message_of(o).find("gray_lsb_skip"), std::string::npos);
  o = PatternOptions();
  o.phase_steps = 2;
  EXPECT_NE(message_of(o).find("phase_steps"), std::string::npos);
  o = PatternOptions();
  o.phase_period_px = std::nan("");
  EXPECT_NE(message_of(o).find("phase_period_px"), std::string::npos);
  o = PatternOptions();
  o.low_level = 200;
  o.high_level = 100;
  EXPECT_NE(message_of(o).find("levels"), std::string::npos);
  EXPECT_FALSE(GeneratePatterns(o).ok());
}

TEST(GeneratePatterns, OpenCvOrderEqualsOpenCvGrayCodePattern) {
  const auto ours = GeneratePatterns(PatternOptions::OpenCvGrayCode(1024, 768));
  const auto peer = GenerateOpenCvGrayCodePatterns(1024, 768);
  ASSERT_TRUE(ours.ok()) << ours.status().ToString();
  ASSERT_TRUE(peer.ok()) << peer.status().ToString();
  ASSERT_EQ(ours->size(), peer->size());
  for (size_t i = 0; i < ours->size(); ++i) {
    ASSERT_EQ((*ours)[i].size(), (*peer)[i].size()) << "frame " << i;
    EXPECT_EQ(cv::norm((*ours)[i], (*peer)[i], cv::NORM_INF), 0.0) << "frame " << i;
  }
}

TEST(GeneratePatterns, OpenCvOrderEqualsTheDatasetPatterns) {
  const std::string folder = "../shared/data/procam-kamino410/graycode_pattern";
  if (!std::filesystem::exists(folder))
    GTEST_SKIP() << folder << " not found (run from the project root)";
  const auto dataset = LoadCaptureSequence(folder, 42, {.prefix = "pattern_"});
  ASSERT_TRUE(dataset.ok()) << dataset.status().ToString();
  const auto ours = GeneratePatterns(PatternOptions::OpenCvGrayCode(1024, 768));
  ASSERT_TRUE(ours.ok());
  for (size_t i = 0; i < ours->size(); ++i) {
    EXPECT_EQ(cv::norm((*ours)[i], (*dataset)[i], cv::NORM_INF), 0.0) << "pattern_" << i;
  }
}

// Decoding the projector's own frames must give back every projector pixel.
void ExpectIdentityDecode(const PatternOptions& o, double tolerance_px) {
  const auto frames = GeneratePatterns(o);
  ASSERT_TRUE(frames.ok());
  DecoderOptions d;
  d.saturation_level = 256;  // the frames use the full 0..255 range
  d.min_contrast = 1;
  DecodeReport report;
  const auto decoded = DecodeStructuredLight(*frames, o, d, &report);
  ASSERT_TRUE(decoded.ok()) << decoded.status().ToString();
  EXPECT_EQ(report.decoded_pixels, report.camera_pixels) << report.ToString();
  double worst_px = 0.0;
  for (int v = 0; v < o.projector_height_px; ++v) {
    for (int u = 0; u < o.projector_width_px; ++u) {
      const cv::Vec2f uv = decoded->projector_px.at<cv::Vec2f>(v, u);
      worst_px = std::max({worst_px, std::abs(double{uv[0]} - u), std::abs(double{uv[1]} - v)});
    }
  }
  EXPECT_LE(worst_px, tolerance_px);
}

TEST(GeneratePatterns, GrayCodeDecodesToItselfAtOddSizes) {
  PatternOptions o;
  o.projector_width_px = 1000;
  o.projector_height_px = 613;
  o.phase_steps = 0;
  ExpectIdentityDecode(o, kExact_px);
}

TEST(GeneratePatterns, PhaseShiftDecodesToItself) {
  PatternOptions o;
  o.projector_width_px = 640;
  o.projector_height_px = 400;
  o.phase_steps = 4;
  o.phase_period_px = 12.5;  // need not divide the size
  ExpectIdentityDecode(o, kPhaseRounding_px);
  o.gray_lsb_skip = 2;
  o.phase_steps = 7;
  o.phase_period_px = 32.0;
  ExpectIdentityDecode(o, kPhaseRounding_px);
}

TEST(GeneratePatterns, OneAxisOnly) {
  PatternOptions o;
  o.projector_width_px = 300;
  o.projector_height_px = 20;
  o.encode_rows = false;
  o.phase_steps = 0;
  const PatternLayout layout = MakePatternLayout(o);
  EXPECT_EQ(layout.frame_count, 2 + 2 * 9);
  const auto frames = GeneratePatterns(o);
  ASSERT_TRUE(frames.ok());
  const auto decoded =
      DecodeStructuredLight(*frames, o, {.min_contrast = 1, .saturation_level = 256});
  ASSERT_TRUE(decoded.ok());
  const cv::Vec2f uv = decoded->projector_px.at<cv::Vec2f>(7, 123);
  EXPECT_EQ(uv[0], 123.0f);
  EXPECT_TRUE(std::isnan(uv[1]));
}

}  // namespace
}  // namespace sandtable
