// Unit calibration file: round trip and named errors on untrusted input.
#include "node/calibration/unit_calibration.h"

#include <functional>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

namespace sandtable::node {
namespace {

constexpr double kRoundTripTolerance = 1e-9;

UnitCalibration Example() {
  UnitCalibration c;
  c.camera = CameraModel(1280, 1024, 3452.4, 3449.9, 587.2, 521.4,
                         BrownDistortion{-0.22, -0.87, -7e-4, -1.7e-3, 3.1});
  c.projector = CameraModel(1024, 768, 1950.0, 1940.0, 450.0, 730.0);
  c.projector_from_camera = Rigid3d(
      Eigen::Quaterniond(Eigen::AngleAxisd(0.2, Eigen::Vector3d(0.3, -1.0, 0.1).normalized())),
      Eigen::Vector3d(0.0067, -0.0478, -0.0113));
  c.camera_rms_px = 0.12;
  c.projector_rms_px = 0.31;
  c.poses_used = {"capture_0", "capture_1"};
  return c;
}

TEST(UnitCalibrationFile, RoundTrip) {
  const UnitCalibration c = Example();
  auto parsed = ParseUnitCalibration(UnitCalibrationToJson(c), "unit.json");
  ASSERT_TRUE(parsed.ok()) << parsed.status().ToString();
  EXPECT_NEAR((parsed->camera.K() - c.camera.K()).norm(), 0.0, kRoundTripTolerance);
  EXPECT_NEAR(parsed->camera.distortion.k3, c.camera.distortion.k3, kRoundTripTolerance);
  EXPECT_NEAR((parsed->projector.K() - c.projector.K()).norm(), 0.0, kRoundTripTolerance);
  EXPECT_EQ(parsed->projector.width_px, 1024);
  EXPECT_EQ(parsed->camera.height_px, 1024);
  EXPECT_NEAR(
      (parsed->projector_from_camera.translation - c.projector_from_camera.translation).norm(), 0.0,
      kRoundTripTolerance);
  EXPECT_NEAR(RotationAngleBetween_rad(parsed->projector_from_camera, c.projector_from_camera), 0.0,
              kRoundTripTolerance);
  EXPECT_EQ(parsed->poses_used, c.poses_used);
  EXPECT_NEAR(parsed->projector_rms_px, c.projector_rms_px, kRoundTripTolerance);
}

// Applies `edit` to the JSON of Example() and expects an error whose message contains `field`.
void ExpectError(const std::function<void(nlohmann::json&)>& edit, StatusCode code,
                 const std::string& field) {
  nlohmann::json j = nlohmann::json::parse(UnitCalibrationToJson(Example()));
  edit(j);
  auto parsed = ParseUnitCalibration(j.dump(), "unit.json");
  ASSERT_FALSE(parsed.ok()) << "accepted: " << field;
  EXPECT_EQ(parsed.status().code(), code) << parsed.status().ToString();
  EXPECT_NE(parsed.status().message().find(field), std::string::npos) << parsed.status().ToString();
  EXPECT_NE(parsed.status().message().find("unit.json"), std::string::npos);
}

TEST(UnitCalibrationFile, ErrorsNameTheField) {
  using J = nlohmann::json;
  ExpectError([](J& j) { j["projector"]["camera_matrix"][0][0] = -3.0; },
              StatusCode::kInvalidArgument, "projector");
  ExpectError([](J& j) { j["camera"].erase("distortion_coefficients"); }, StatusCode::kParseError,
              "camera.distortion_coefficients");
  ExpectError(
      [](J& j) {
        j["camera"]["distortion_coefficients"] = {1, 2, 3};
      },
      StatusCode::kParseError, "camera.distortion_coefficients");
  ExpectError([](J& j) { j["projector_from_camera"]["rotation"][0][0] = 2.0; },
              StatusCode::kInvalidArgument, "projector_from_camera.rotation");
  ExpectError([](J& j) { j["projector_from_camera"]["translation_m"][1] = "x"; },
              StatusCode::kParseError, "projector_from_camera.translation_m[1]");
  ExpectError([](J& j) { j["projector"]["image_width_px"] = 0; }, StatusCode::kInvalidArgument,
              "projector.image_width_px");
  ExpectError([](J& j) { j["camera"]["camera_matrix"][0][1] = 1.0; }, StatusCode::kInvalidArgument,
              "camera.camera_matrix");
  ExpectError([](J& j) { j["version"] = 99; }, StatusCode::kParseError, "version");
  ExpectError([](J& j) { j["poses_used"][0] = 3; }, StatusCode::kParseError, "poses_used[0]");
}

TEST(UnitCalibrationFile, MalformedTextAndMissingFile) {
  auto parsed = ParseUnitCalibration("{not json", "unit.json");
  ASSERT_FALSE(parsed.ok());
  EXPECT_EQ(parsed.status().code(), StatusCode::kParseError);
  auto missing = LoadUnitCalibration("/nonexistent/unit.json");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), StatusCode::kIoError);
  EXPECT_NE(missing.status().message().find("/nonexistent/unit.json"), std::string::npos);
}

}  // namespace
}  // namespace sandtable::node
