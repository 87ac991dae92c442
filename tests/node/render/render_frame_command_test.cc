// `sandtable-node render-frame` (node/render/render_frame_command.h), in process: a unit's frame
// written to a PNG, and bad usage named.
#include "node/render/render_frame_command.h"

#include <filesystem>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "common/io/unit_calibration_file.h"
#include "node/render/test_patterns.h"
#include "tests/node/render/render_test_scene.h"

namespace sandtable::node {
namespace {

std::filesystem::path Dir() {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() /
      ("render_frame_" + std::to_string(::testing::UnitTest::GetInstance()->random_seed()) + "_" +
       ::testing::UnitTest::GetInstance()->current_test_info()->name());
  std::filesystem::create_directories(dir);
  return dir;
}

std::string WriteCalibration(const std::filesystem::path& dir) {
  UnitCalibration c;
  c.unit_id = 4;
  c.source = kSourceStructuredLight;
  c.projector = testing::RenderTestProjector(320, 200, true);
  c.camera = testing::RenderTestProjector(320, 200, false);
  c.table_from_projector = testing::RenderTestProjectorFromTable().Inverse();
  const std::string path = (dir / "unit-4.json").string();
  EXPECT_TRUE(SaveUnitCalibration(c, path).ok());
  return path;
}

TEST(RenderFrameCommandTest, WritesTheFrameAndAPatternExactly) {
  const std::filesystem::path dir = Dir();
  const std::string calibration = WriteCalibration(dir);
  const std::string png = (dir / "bars.png").string();
  ASSERT_EQ(RunRenderFrame({"--calibration", calibration, "-o", png, "--pattern", "bars"}), 0);
  cv::Mat read = cv::imread(png, cv::IMREAD_COLOR);
  ASSERT_FALSE(read.empty());
  cv::cvtColor(read, read, cv::COLOR_BGR2RGB);
  cv::Mat diff;
  cv::absdiff(read, ColourBarsPattern(read.size()), diff);
  EXPECT_EQ(cv::countNonZero(diff.reshape(1)), 0);
  // The table grid on the table plane (no model given): some lines lit, most pixels dark.
  const std::string grid = (dir / "grid.png").string();
  ASSERT_EQ(RunRenderFrame({"--calibration", calibration, "-o", grid, "--pattern", "grid"}), 0);
  const cv::Mat lines = cv::imread(grid, cv::IMREAD_GRAYSCALE);
  ASSERT_EQ(lines.size(), cv::Size(320, 200));
  const int lit = cv::countNonZero(lines > 128);
  EXPECT_GT(lit, 320 * 200 / 50);
  EXPECT_LT(lit, 320 * 200 / 2);
  std::filesystem::remove_all(dir);
}

TEST(RenderFrameCommandTest, BadUsageExitsTwoNamingIt) {
  const std::filesystem::path dir = Dir();
  EXPECT_EQ(RunRenderFrame({"-o", (dir / "x.png").string()}), 2);  // no --calibration
  const std::string calibration = WriteCalibration(dir);
  EXPECT_EQ(RunRenderFrame({"--calibration", calibration, "-o", (dir / "x.png").string(),
                            "--pattern", "plaid"}),
            2);
  // A factory calibration (no table_from_projector) is not a site calibration.
  UnitCalibration factory;
  factory.unit_id = 4;
  factory.source = kSourceFactory;
  factory.projector = testing::RenderTestProjector(320, 200, false);
  factory.camera = factory.projector;
  const std::string factory_path = (dir / "factory.json").string();
  ASSERT_TRUE(SaveUnitCalibration(factory, factory_path).ok());
  EXPECT_EQ(RunRenderFrame({"--calibration", factory_path, "-o", (dir / "x.png").string()}), 2);
  EXPECT_FALSE(std::filesystem::exists(dir / "x.png"));
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace sandtable::node
