// OpenCV YAML export: written, then read back THROUGH cv::FileStorage (as a renderer or a ROS
// camera_info reader would), and through ReadOpenCvYaml.
#include "common/io/opencv_yaml.h"

#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>

#include <unistd.h>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

namespace sandtable {
namespace {

// 17 significant digits are written: a round trip is exact to the last bit or two.
constexpr double kIntrinsicsTolerance_px = 1e-9;
constexpr double kDistortionTolerance = 1e-15;
constexpr double kRotationTolerance = 1e-15;  // per matrix entry
constexpr double kTranslationTolerance_m = 1e-15;
constexpr double kPointTolerance_m = 1e-14;
constexpr unsigned kSeed = 20261203;

UnitCalibration Example() {
  UnitCalibration c;
  c.unit_id = 3;
  c.source = kSourceFactoryTruePose;
  c.camera = CameraModel(1024, 768, 1098.3, 1097.1, 511.2, 383.9,
                         BrownDistortion{-0.08, 0.02, 1e-4, -2e-4, 0.001});
  c.projector = CameraModel(1280, 800, 1625.6, 1624.9, 639.5, 420.25,
                            BrownDistortion{0.02, -0.005, 3e-4, 1e-4, 0.0});
  c.projector_from_camera = Rigid3d(
      Eigen::Quaterniond(Eigen::AngleAxisd(0.072, Eigen::Vector3d(0.1, -1.0, 0.05).normalized())),
      Eigen::Vector3d(0.12, 0.001, -0.002));
  c.table_from_projector = Rigid3d(
      Eigen::Quaterniond(Eigen::AngleAxisd(2.8, Eigen::Vector3d(1.0, 0.2, 0.1).normalized())),
      Eigen::Vector3d(0.4, -0.7, 1.5));
  c.table_from_model = Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ())),
                               Eigen::Vector3d(0.02, -0.01, 0.0));
  return c;
}

class OpenCvYamlTest : public ::testing::Test {
 protected:
  void SetUp() override {
    path_ = (std::filesystem::temp_directory_path() /
             ("sandtable_unit_" + std::to_string(::getpid()) + ".yaml"))
                .string();
  }
  void TearDown() override { std::filesystem::remove(path_); }
  std::string path_;
};

TEST_F(OpenCvYamlTest, RoundTripThroughCvFileStorage) {
  const UnitCalibration c = Example();
  ASSERT_TRUE(WriteOpenCvYaml(c, path_).ok());

  cv::FileStorage fs(path_, cv::FileStorage::READ);
  ASSERT_TRUE(fs.isOpened());
  EXPECT_EQ(static_cast<int>(fs["image_width"]), 1280);
  EXPECT_EQ(static_cast<int>(fs["image_height"]), 800);
  EXPECT_EQ(static_cast<std::string>(fs["distortion_model"]), "plumb_bob");
  cv::Mat k, d, r, t;
  fs["camera_matrix"] >> k;
  fs["distortion_coefficients"] >> d;
  fs["R"] >> r;
  fs["T"] >> t;
  ASSERT_EQ(k.rows, 3);
  ASSERT_EQ(k.cols, 3);
  ASSERT_EQ(d.total(), 5u);
  ASSERT_EQ(r.rows, 3);
  ASSERT_EQ(r.cols, 3);
  ASSERT_EQ(t.rows, 3);
  ASSERT_EQ(t.cols, 1);
  const Eigen::Matrix3d k_expected = c.projector.K();
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      EXPECT_NEAR(k.at<double>(i, j), k_expected(i, j), kIntrinsicsTolerance_px);
    }
  }
  const std::array<double, 5> d_expected = c.projector.distortion.ToArray();
  for (int i = 0; i < 5; ++i) EXPECT_NEAR(d.at<double>(i), d_expected[i], kDistortionTolerance);

  // x_in_projector = R x_in_model + T, with projector_from_model =
  // table_from_projector^-1 * table_from_model.
  const Rigid3d projector_from_model = c.table_from_projector->Inverse() * *c.table_from_model;
  const Eigen::Matrix3d r_expected = projector_from_model.RotationMatrix();
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j)
      EXPECT_NEAR(r.at<double>(i, j), r_expected(i, j), kRotationTolerance);
    EXPECT_NEAR(t.at<double>(i), projector_from_model.translation[i], kTranslationTolerance_m);
  }
  // The meaning, on points of the model: R x + T is the point in the projector frame.
  std::mt19937 rng(kSeed);
  std::uniform_real_distribution<double> u(-0.5, 0.5);
  for (int trial = 0; trial < 100; ++trial) {
    const Eigen::Vector3d x_in_model(u(rng), u(rng), 0.3 * (u(rng) + 0.5));
    const Eigen::Vector3d x_in_projector =
        c.table_from_projector->Inverse() * (*c.table_from_model * x_in_model);
    cv::Mat x = (cv::Mat_<double>(3, 1) << x_in_model.x(), x_in_model.y(), x_in_model.z());
    const cv::Mat y = r * x + t;
    for (int i = 0; i < 3; ++i) EXPECT_NEAR(y.at<double>(i), x_in_projector[i], kPointTolerance_m);
  }
  // The unit's camera as a second section.
  const cv::FileNode camera = fs["camera"];
  ASSERT_TRUE(camera.isMap());
  EXPECT_EQ(static_cast<int>(camera["image_width"]), 1024);
  cv::Mat camera_k;
  camera["camera_matrix"] >> camera_k;
  EXPECT_NEAR(camera_k.at<double>(0, 0), c.camera.fx_px, kIntrinsicsTolerance_px);
  // What ROS's camera_info reader needs.
  cv::Mat rectification, projection;
  fs["rectification_matrix"] >> rectification;
  fs["projection_matrix"] >> projection;
  EXPECT_EQ(rectification.rows, 3);
  EXPECT_EQ(projection.cols, 4);
  EXPECT_EQ(static_cast<std::string>(fs["camera_name"]), "unit-3-projector");
}

TEST_F(OpenCvYamlTest, PlainYamlForOtherReaders) {
  ASSERT_TRUE(WriteOpenCvYaml(Example(), path_).ok());
  std::ifstream in(path_);
  std::stringstream text;
  text << in.rdbuf();
  EXPECT_EQ(text.str().rfind("%YAML 1.0\n", 0), 0u) << text.str().substr(0, 20);
  EXPECT_EQ(text.str().find("!!opencv-matrix"), std::string::npos);
}

TEST_F(OpenCvYamlTest, ReadOpenCvYamlGivesTheCalibrationBack) {
  const UnitCalibration c = Example();
  ASSERT_TRUE(WriteOpenCvYaml(c, path_).ok());
  Expected<OpenCvYamlCalibration> back = ReadOpenCvYaml(path_);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(back->unit_id, 3u);
  EXPECT_EQ(back->source, kSourceFactoryTruePose);
  EXPECT_NEAR((back->projector.K() - c.projector.K()).norm(), 0.0, kIntrinsicsTolerance_px);
  EXPECT_NEAR(back->projector.distortion.p1, c.projector.distortion.p1, kDistortionTolerance);
  const Rigid3d projector_from_model = c.table_from_projector->Inverse() * *c.table_from_model;
  EXPECT_LT((back->projector_from_model.translation - projector_from_model.translation).norm(),
            kTranslationTolerance_m * 10);
  ASSERT_TRUE(back->camera && back->projector_from_camera);
  EXPECT_NEAR(back->camera->distortion.k3, c.camera.distortion.k3, kDistortionTolerance);
  EXPECT_LT((back->projector_from_camera->translation - c.projector_from_camera.translation).norm(),
            kTranslationTolerance_m * 10);
}

TEST_F(OpenCvYamlTest, NeedsAPoseOnTheTable) {
  UnitCalibration c = Example();
  c.table_from_model.reset();
  Status s = WriteOpenCvYaml(c, path_);
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("table_from_model"), std::string::npos) << s.ToString();
  c = Example();
  c.table_from_projector.reset();
  s = WriteOpenCvYaml(c, path_);
  EXPECT_NE(s.message().find("table_from_projector"), std::string::npos) << s.ToString();
  EXPECT_FALSE(std::filesystem::exists(path_));
  c = Example();
  c.projector.fx_px = 0.0;
  EXPECT_EQ(WriteOpenCvYaml(c, path_).code(), StatusCode::kInvalidArgument);
}

TEST_F(OpenCvYamlTest, BadFilesNameTheKey) {
  EXPECT_EQ(ReadOpenCvYaml("/nonexistent/unit.yaml").status().code(), StatusCode::kIoError);
  std::ofstream(path_) << "%YAML 1.0\n---\nformat: \"sandtable.unit_calibration.opencv\"\n"
                          "version: 1\nimage_width: 1280\nimage_height: 800\n";
  Expected<OpenCvYamlCalibration> r = ReadOpenCvYaml(path_);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kParseError);
  EXPECT_NE(r.status().message().find("camera_matrix is missing"), std::string::npos)
      << r.status().ToString();
  std::ofstream(path_) << "not: [yaml";
  EXPECT_FALSE(ReadOpenCvYaml(path_).ok());
}

}  // namespace
}  // namespace sandtable
