// Unit calibration file (version 2): round trip, named errors on untrusted input, and the older
// files that must still load (version 1 of calibrate-unit; make-site's factory files before
// they carried format/version).
#include "common/io/unit_calibration_file.h"

#include <filesystem>
#include <functional>
#include <random>

#include <unistd.h>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

namespace sandtable {
namespace {

using nlohmann::json;

constexpr double kRoundTripTolerance_px = 0.0;  // shortest round-trip numbers: exact
constexpr double kRoundTripTolerance_m = 1e-15;
constexpr double kRoundTripTolerance_rad = 1e-7;  // acos near 1 (see rigid3_test)
constexpr double kLegacyTolerance_m = 1e-12;
constexpr double kLegacyTolerance_rad = 1e-7;
constexpr unsigned kSeed = 20261202;

UnitCalibration Example() {
  UnitCalibration c;
  c.unit_id = 3;
  c.source = kSourceFactoryTruePose;
  c.camera = CameraModel(1280, 1024, 3452.4, 3449.9, 587.2, 521.4,
                         BrownDistortion{-0.22, -0.87, -7e-4, -1.7e-3, 3.1});
  c.projector = CameraModel(1024, 768, 1950.0, 1940.0, 450.0, 730.0);
  c.projector_from_camera = Rigid3d(
      Eigen::Quaterniond(Eigen::AngleAxisd(0.2, Eigen::Vector3d(0.3, -1.0, 0.1).normalized())),
      Eigen::Vector3d(0.0067, -0.0478, -0.0113));
  c.table_from_projector = Rigid3d(
      Eigen::Quaterniond(Eigen::AngleAxisd(2.9, Eigen::Vector3d(1.0, 0.1, 0.0).normalized())),
      Eigen::Vector3d(0.3, -0.8, 1.4));
  c.table_from_model = Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitZ())),
                               Eigen::Vector3d(0.01, 0.02, 0.0));
  c.camera_rms_px = 0.12;
  c.projector_rms_px = 0.31;
  c.poses_used = {"capture_0", "capture_1"};
  return c;
}

void ExpectSameRigid(const Rigid3d& a, const Rigid3d& b, double tolerance_m, double tolerance_rad) {
  EXPECT_LT((a.translation - b.translation).norm(), tolerance_m);
  EXPECT_LT(RotationAngleBetween_rad(a, b), tolerance_rad);
}

TEST(UnitCalibrationFile, RoundTripKeepsEveryField) {
  const UnitCalibration c = Example();
  Expected<UnitCalibration> parsed = ParseUnitCalibration(UnitCalibrationToJson(c), "unit-3.json");
  ASSERT_TRUE(parsed.ok()) << parsed.status().ToString();
  EXPECT_EQ(parsed->unit_id, 3u);
  EXPECT_EQ(parsed->source, kSourceFactoryTruePose);
  EXPECT_NEAR((parsed->camera.K() - c.camera.K()).norm(), 0.0, kRoundTripTolerance_px);
  EXPECT_EQ(parsed->camera.distortion.k3, c.camera.distortion.k3);
  EXPECT_NEAR((parsed->projector.K() - c.projector.K()).norm(), 0.0, kRoundTripTolerance_px);
  EXPECT_EQ(parsed->projector.width_px, 1024);
  EXPECT_EQ(parsed->camera.height_px, 1024);
  ExpectSameRigid(parsed->projector_from_camera, c.projector_from_camera, kRoundTripTolerance_m,
                  kRoundTripTolerance_rad);
  ASSERT_TRUE(parsed->table_from_projector && parsed->table_from_model);
  ExpectSameRigid(*parsed->table_from_projector, *c.table_from_projector, kRoundTripTolerance_m,
                  kRoundTripTolerance_rad);
  ExpectSameRigid(*parsed->table_from_model, *c.table_from_model, kRoundTripTolerance_m,
                  kRoundTripTolerance_rad);
  EXPECT_EQ(parsed->poses_used, c.poses_used);
  EXPECT_EQ(parsed->camera_rms_px, c.camera_rms_px);
  EXPECT_EQ(parsed->projector_rms_px, c.projector_rms_px);
}

TEST(UnitCalibrationFile, PredictedErrorRoundTripsAndIsChecked) {
  UnitCalibration c = Example();
  PredictedErrorRecord p;
  p.rms_px = 0.042;
  p.rms_mm = 0.081;
  p.samples = 180;
  p.sigma_px = 0.051;
  p.weak_direction = "the image grows or shrinks, 71 % of it: focal fx";
  p.weak_share = 0.64;
  p.undetermined = "";
  c.predicted_error = p;
  Expected<UnitCalibration> parsed = ParseUnitCalibration(UnitCalibrationToJson(c), "unit-3.json");
  ASSERT_TRUE(parsed.ok()) << parsed.status().ToString();
  ASSERT_TRUE(parsed->predicted_error.has_value());
  EXPECT_EQ(parsed->predicted_error->rms_px, p.rms_px);
  EXPECT_EQ(parsed->predicted_error->rms_mm, p.rms_mm);
  EXPECT_EQ(parsed->predicted_error->samples, p.samples);
  EXPECT_EQ(parsed->predicted_error->weak_direction, p.weak_direction);
  EXPECT_EQ(parsed->predicted_error->weak_share, p.weak_share);
  // Not predicted on the table: rms_mm is left out and reads back as not predicted.
  c.predicted_error->rms_mm = -1.0;
  const json j = json::parse(UnitCalibrationToJson(c));
  EXPECT_FALSE(j["predicted_error"].contains("rms_mm"));
  parsed = ParseUnitCalibration(j.dump(), "unit-3.json");
  ASSERT_TRUE(parsed.ok()) << parsed.status().ToString();
  EXPECT_LT(parsed->predicted_error->rms_mm, 0.0);
  // A negative spread is refused, naming the field.
  json bad = j;
  bad["predicted_error"]["rms_px"] = -0.1;
  parsed = ParseUnitCalibration(bad.dump(), "unit-3.json");
  ASSERT_FALSE(parsed.ok());
  EXPECT_NE(parsed.status().message().find("predicted_error"), std::string::npos);
  bad = j;
  bad["predicted_error"]["colour"] = 1;
  parsed = ParseUnitCalibration(bad.dump(), "unit-3.json");
  ASSERT_FALSE(parsed.ok());
  EXPECT_NE(parsed.status().message().find("colour"), std::string::npos);
}

TEST(UnitCalibrationFile, WritesFormatVersionAndTheCodecForms) {
  const json j = json::parse(UnitCalibrationToJson(Example()));
  EXPECT_EQ(j["format"], "sandtable.unit_calibration");
  EXPECT_EQ(j["version"], 2);
  EXPECT_TRUE(j["projector_from_camera"].contains("rotation_xyzw"));
  EXPECT_TRUE(j["projector"].contains("fx_px"));
  // A factory calibration (no poses): no rms, no optional poses.
  UnitCalibration factory = Example();
  factory.source = kSourceFactory;
  factory.table_from_projector.reset();
  factory.table_from_model.reset();
  factory.camera_rms_px = factory.projector_rms_px = 0.0;
  factory.poses_used.clear();
  const json f = json::parse(UnitCalibrationToJson(factory));
  EXPECT_FALSE(f.contains("camera_rms_px") || f.contains("poses_used") ||
               f.contains("table_from_projector") || f.contains("table_from_model"));
  Expected<UnitCalibration> back = ParseUnitCalibration(f.dump(), "unit-3.factory.json");
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_FALSE(back->table_from_projector.has_value());
  EXPECT_EQ(back->source, kSourceFactory);
}

TEST(UnitCalibrationFile, PropertyRoundTripOfRandomCalibrations) {
  std::mt19937 rng(kSeed);
  std::normal_distribution<double> normal(0.0, 1.0);
  for (int trial = 0; trial < 50; ++trial) {
    UnitCalibration c = Example();
    c.unit_id = static_cast<NodeId>(trial);
    c.camera.fx_px *= 1.0 + 0.1 * std::abs(normal(rng));
    c.projector.distortion.k1 = 0.1 * normal(rng);
    c.projector_from_camera =
        Rigid3d(Eigen::Quaterniond(normal(rng), normal(rng), normal(rng), normal(rng)).normalized(),
                Eigen::Vector3d(normal(rng), normal(rng), normal(rng)) * 0.1);
    const Eigen::Vector3d x_in_camera(normal(rng), normal(rng), 2.0 + std::abs(normal(rng)));
    Expected<UnitCalibration> back = ParseUnitCalibration(UnitCalibrationToJson(c), "u.json");
    ASSERT_TRUE(back.ok()) << back.status().ToString();
    EXPECT_EQ(back->unit_id, c.unit_id);
    EXPECT_LT(
        (back->projector_from_camera * x_in_camera - c.projector_from_camera * x_in_camera).norm(),
        1e-14);
    EXPECT_EQ(back->camera.fx_px, c.camera.fx_px);
    EXPECT_EQ(back->projector.distortion.k1, c.projector.distortion.k1);
  }
}

// Applies `edit` to the JSON of Example() and expects an error whose message contains `field`.
void ExpectError(const std::function<void(json&)>& edit, StatusCode code,
                 const std::string& field) {
  json j = json::parse(UnitCalibrationToJson(Example()));
  edit(j);
  Expected<UnitCalibration> parsed = ParseUnitCalibration(j.dump(), "unit-3.json");
  ASSERT_FALSE(parsed.ok()) << "accepted: " << field;
  EXPECT_EQ(parsed.status().code(), code) << parsed.status().ToString();
  EXPECT_NE(parsed.status().message().find(field), std::string::npos) << parsed.status().ToString();
  EXPECT_EQ(parsed.status().message().rfind("unit-3.json", 0), 0u) << parsed.status().ToString();
}

TEST(UnitCalibrationFile, ErrorsNameTheField) {
  ExpectError([](json& j) { j["projector"]["fx_px"] = -3.0; }, StatusCode::kInvalidArgument,
              "unit-3.json: projector.fx_px = -3 must be finite and > 0");
  ExpectError(
      [](json& j) {
        j["camera"].erase("distortion_k1_k2_p1_p2_k3");
        j["camera"]["k1"] = 0;
      },
      StatusCode::kParseError, "unit-3.json: camera has unknown key 'k1'");
  ExpectError(
      [](json& j) {
        j["camera"]["distortion_k1_k2_p1_p2_k3"] = {1, 2, 3};
      },
      StatusCode::kParseError, "camera.distortion_k1_k2_p1_p2_k3");
  ExpectError(
      [](json& j) {
        j["projector_from_camera"]["rotation_xyzw"] = {0, 0, 0, 3};
      },
      StatusCode::kInvalidArgument, "projector_from_camera.rotation_xyzw has norm 3");
  ExpectError([](json& j) { j["projector_from_camera"]["translation_m"][1] = "x"; },
              StatusCode::kParseError, "projector_from_camera.translation_m[1]");
  ExpectError([](json& j) { j["table_from_model"].erase("translation_m"); },
              StatusCode::kParseError, "table_from_model.translation_m is missing");
  ExpectError([](json& j) { j["projector"]["width_px"] = 0; }, StatusCode::kInvalidArgument,
              "projector.width_px");
  ExpectError([](json& j) { j["version"] = 99; }, StatusCode::kParseError, "version = 99");
  ExpectError([](json& j) { j["format"] = "sandtable.site"; }, StatusCode::kParseError,
              "format = \"sandtable.site\"");
  ExpectError([](json& j) { j["poses_used"][0] = 3; }, StatusCode::kParseError, "poses_used[0]");
  ExpectError([](json& j) { j["camera_rms_px"] = -1; }, StatusCode::kInvalidArgument,
              "camera_rms_px");
  ExpectError([](json& j) { j["unit_id"] = -1; }, StatusCode::kInvalidArgument, "unit_id");
  ExpectError([](json& j) { j["unit_id"] = 4294967290u; }, StatusCode::kInvalidArgument, "unit_id");
  ExpectError([](json& j) { j["table_from_projecter"] = j["table_from_projector"]; },
              StatusCode::kParseError, "unknown key 'table_from_projecter'");
  ExpectError([](json& j) { j.erase("camera"); }, StatusCode::kParseError, "camera is missing");
  ExpectError(
      [](json& j) {
        j.erase("format");
        j.erase("unit_id");
      },
      StatusCode::kParseError, "format is missing");
}

// What calibrate-unit wrote before the common codec (node/calibration/unit_calibration.cc,
// format version 1): 3x3 rotation, camera_matrix intrinsics.
constexpr char kVersion1File[] = R"({
  "camera": {
    "camera_matrix": [[3452.4, 0.0, 587.2], [0.0, 3449.9, 521.4], [0.0, 0.0, 1.0]],
    "distortion_coefficients": [-0.22, -0.87, -0.0007, -0.0017, 3.1],
    "distortion_model": "opencv k1 k2 p1 p2 k3",
    "image_height_px": 1024, "image_width_px": 1280
  },
  "camera_rms_px": 0.12,
  "format": "sandtable-unit-calibration",
  "poses_used": ["capture_0", "capture_1"],
  "projector": {
    "camera_matrix": [[1950.0, 0.0, 450.0], [0.0, 1940.0, 730.0], [0.0, 0.0, 1.0]],
    "distortion_coefficients": [0.0, 0.0, 0.0, 0.0, 0.0],
    "distortion_model": "opencv k1 k2 p1 p2 k3",
    "image_height_px": 768, "image_width_px": 1024
  },
  "projector_from_camera": {
    "convention": "x_in_projector = rotation * x_in_camera + translation_m",
    "rotation": [[0.980066577841242, 0.0, 0.198669330795061],
                 [0.0, 1.0, 0.0],
                 [-0.198669330795061, 0.0, 0.980066577841242]],
    "translation_m": [0.0067, -0.0478, -0.0113]
  },
  "projector_rms_px": 0.31,
  "version": 1
})";

TEST(UnitCalibrationFile, Version1FilesStillLoad) {
  Expected<UnitCalibration> c = ParseUnitCalibration(kVersion1File, "unit.json");
  ASSERT_TRUE(c.ok()) << c.status().ToString();
  EXPECT_EQ(c->source, kSourceUnitCalibration);
  EXPECT_EQ(c->unit_id, kInvalidNodeId);
  EXPECT_EQ(c->camera.fx_px, 3452.4);
  EXPECT_EQ(c->camera.cy_px, 521.4);
  EXPECT_EQ(c->camera.distortion.k3, 3.1);
  EXPECT_EQ(c->projector.width_px, 1024);
  const Rigid3d expected(Eigen::Quaterniond(Eigen::AngleAxisd(0.2, Eigen::Vector3d::UnitY())),
                         Eigen::Vector3d(0.0067, -0.0478, -0.0113));
  ExpectSameRigid(c->projector_from_camera, expected, kLegacyTolerance_m, kLegacyTolerance_rad);
  EXPECT_EQ(c->poses_used.size(), 2u);
  EXPECT_EQ(c->projector_rms_px, 0.31);
  // Saved again, it is a version-2 file.
  const json again = json::parse(UnitCalibrationToJson(*c));
  EXPECT_EQ(again["version"], kUnitCalibrationVersion);

  json bad = json::parse(kVersion1File);
  bad["projector_from_camera"]["rotation"][0][0] = 2.0;
  Expected<UnitCalibration> e = ParseUnitCalibration(bad.dump(), "unit.json");
  ASSERT_FALSE(e.ok());
  EXPECT_EQ(e.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(
      e.status().message().find("unit.json: projector_from_camera.rotation is not a rotation"),
      std::string::npos)
      << e.status().ToString();
  bad = json::parse(kVersion1File);
  bad["version"] = 2;  // version 2 under the old format name
  EXPECT_EQ(ParseUnitCalibration(bad.dump(), "unit.json").status().code(), StatusCode::kParseError);
}

// What `sandtable-world make-site --factory-dir` wrote before files carried format/version.
constexpr char kOldFactoryFile[] = R"({
  "camera": {"cx_px": 511.9, "cy_px": 383.1, "distortion_k1_k2_p1_p2_k3": [-0.081, 0.021, 0.0001, -0.0002, 0.0],
             "fx_px": 1101.2, "fy_px": 1097.5, "height_px": 768, "width_px": 1024},
  "projector": {"cx_px": 640.3, "cy_px": 398.2, "distortion_k1_k2_p1_p2_k3": [0.021, -0.004, 0.0, 0.0, 0.0],
                "fx_px": 1630.1, "fy_px": 1621.9, "height_px": 800, "width_px": 1280},
  "projector_from_camera": {"rotation_xyzw": [0.0001, -0.0359, 0.0002, 0.99935], "translation_m": [0.1203, 0.0004, -0.0007]},
  "unit_id": 2
})";

TEST(UnitCalibrationFile, OldFactoryFilesStillLoad) {
  Expected<UnitCalibration> c = ParseUnitCalibration(kOldFactoryFile, "unit-2.factory.json");
  ASSERT_TRUE(c.ok()) << c.status().ToString();
  EXPECT_EQ(c->unit_id, 2u);
  EXPECT_EQ(c->source, kSourceFactory);
  EXPECT_EQ(c->camera.fx_px, 1101.2);
  EXPECT_EQ(c->projector.height_px, 800);
  EXPECT_NEAR(c->projector_from_camera.translation.x(), 0.1203, kLegacyTolerance_m);
  EXPECT_FALSE(c->table_from_projector.has_value());
}

TEST(UnitCalibrationFile, SaveAndLoadFiles) {
  const std::string path = (std::filesystem::temp_directory_path() /
                            ("sandtable_unit_" + std::to_string(::getpid()) + ".json"))
                               .string();
  ASSERT_TRUE(SaveUnitCalibration(Example(), path).ok());
  Expected<UnitCalibration> back = LoadUnitCalibration(path);
  std::filesystem::remove(path);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(back->poses_used, Example().poses_used);

  UnitCalibration bad = Example();
  bad.projector.fx_px = -1.0;
  const Status refused = SaveUnitCalibration(bad, path);
  EXPECT_EQ(refused.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(refused.message().find("projector: fx_px"), std::string::npos) << refused.ToString();
  EXPECT_FALSE(std::filesystem::exists(path));

  Expected<UnitCalibration> missing = LoadUnitCalibration("/nonexistent/unit.json");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), StatusCode::kIoError);
  EXPECT_NE(missing.status().message().find("/nonexistent/unit.json"), std::string::npos);
  Expected<UnitCalibration> malformed = ParseUnitCalibration("{not json", "unit.json");
  EXPECT_EQ(malformed.status().code(), StatusCode::kParseError);
}

}  // namespace
}  // namespace sandtable
