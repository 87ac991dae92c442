// The Rigid3d and CameraModel JSON codec: property round trips (fixed seeds), the legacy forms
// older files hold, and errors that name the field.
#include "common/io/json_codec.h"

#include <random>
#include <string>

#include <gtest/gtest.h>

namespace sandtable::io {
namespace {

using nlohmann::json;

constexpr int kTrials = 200;
constexpr unsigned kSeed = 20261201;
// JSON numbers are written in shortest round-trip form, so a round trip is exact up to the
// quaternion normalisation on reading (a few ulp).
constexpr double kRoundTripTolerance_m = 1e-15;
constexpr double kRoundTripTolerance_rad = 1e-7;  // acos near 1: 1e-14 in w is ~1.4e-7 rad
constexpr double kPointTolerance_m = 1e-14;
constexpr double kIntrinsicsTolerance_px = 0.0;  // written and read back exactly

Rigid3d RandomRigid(std::mt19937& rng) {
  std::normal_distribution<double> normal(0.0, 1.0);
  const Eigen::Quaterniond q(normal(rng), normal(rng), normal(rng), normal(rng));
  return Rigid3d(q.normalized(), Eigen::Vector3d(normal(rng), normal(rng), normal(rng)) * 2.0);
}

CameraModel RandomModel(std::mt19937& rng) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const int width = 320 + static_cast<int>(u(rng) * 3000);
  const int height = 240 + static_cast<int>(u(rng) * 2000);
  return CameraModel(
      width, height, 500 + 3000 * u(rng), 500 + 3000 * u(rng), width * u(rng), height * u(rng),
      BrownDistortion{0.4 * (u(rng) - 0.5), 0.2 * (u(rng) - 0.5), 1e-3 * (u(rng) - 0.5),
                      1e-3 * (u(rng) - 0.5), 0.1 * (u(rng) - 0.5)});
}

// Through text, as a file does it.
json ThroughText(const json& j) { return json::parse(j.dump(2)); }

TEST(JsonCodec, RigidRoundTripMapsPointsAlike) {
  std::mt19937 rng(kSeed);
  std::normal_distribution<double> normal(0.0, 1.0);
  for (int i = 0; i < kTrials; ++i) {
    const Rigid3d b_from_a = RandomRigid(rng);
    Expected<Rigid3d> back = RigidFromJson(ThroughText(RigidToJson(b_from_a)), "t.json: pose");
    ASSERT_TRUE(back.ok()) << back.status().ToString();
    EXPECT_LT((back->translation - b_from_a.translation).norm(), kRoundTripTolerance_m);
    EXPECT_LT(RotationAngleBetween_rad(*back, b_from_a), kRoundTripTolerance_rad);
    const Eigen::Vector3d x_in_a(normal(rng), normal(rng), normal(rng));
    EXPECT_LT((*back * x_in_a - b_from_a * x_in_a).norm(), kPointTolerance_m);
  }
}

TEST(JsonCodec, RigidWrittenAsUnitQuaternionXyzwAndMetres) {
  const Rigid3d r(Eigen::Quaterniond(Eigen::AngleAxisd(0.5, Eigen::Vector3d::UnitZ())),
                  Eigen::Vector3d(0.1, -0.2, 1.5));
  const json j = RigidToJson(r);
  ASSERT_EQ(j.size(), 2u);
  ASSERT_TRUE(j.contains("rotation_xyzw") && j.contains("translation_m"));
  EXPECT_DOUBLE_EQ(j["rotation_xyzw"][2].get<double>(), std::sin(0.25));
  EXPECT_DOUBLE_EQ(j["rotation_xyzw"][3].get<double>(), std::cos(0.25));
  EXPECT_DOUBLE_EQ(j["translation_m"][2].get<double>(), 1.5);
}

TEST(JsonCodec, LegacyRotationFormsReadTheSameTransform) {
  std::mt19937 rng(kSeed + 1);
  std::normal_distribution<double> normal(0.0, 1.0);
  for (int i = 0; i < kTrials; ++i) {
    const Rigid3d b_from_a = RandomRigid(rng);
    const Eigen::Quaterniond& q = b_from_a.rotation;
    const Eigen::Vector3d& t = b_from_a.translation;
    const Eigen::Matrix3d m = b_from_a.RotationMatrix();
    const json wxyz = {{"rotation_wxyz", {q.w(), q.x(), q.y(), q.z()}},
                       {"translation_m", {t.x(), t.y(), t.z()}}};
    const json matrix = {
        {"rotation",
         {{m(0, 0), m(0, 1), m(0, 2)}, {m(1, 0), m(1, 1), m(1, 2)}, {m(2, 0), m(2, 1), m(2, 2)}}},
        {"translation_m", {t.x(), t.y(), t.z()}},
        {"convention", "x_in_b = rotation * x_in_a + translation_m"}};
    const Eigen::Vector3d x_in_a(normal(rng), normal(rng), normal(rng));
    for (const json& j : {wxyz, matrix}) {
      Expected<Rigid3d> back = RigidFromJson(ThroughText(j), "legacy");
      ASSERT_TRUE(back.ok()) << back.status().ToString();
      EXPECT_LT((*back * x_in_a - b_from_a * x_in_a).norm(), kPointTolerance_m) << j.dump();
    }
  }
}

TEST(JsonCodec, HandWrittenQuaternionsAreNormalised) {
  // Four decimals, as a person writes them: norm 0.99996.
  Expected<Rigid3d> r = RigidFromJson(
      json::parse(R"({"rotation_xyzw": [0, 0, 0.7071, 0.7071], "translation_m": [0, 0, 1]})"),
      "site.json: pose");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_NEAR(r->rotation.norm(), 1.0, 1e-15);
}

// Expects an error of `code` whose message contains every one of `parts`.
void ExpectError(const Status& s, StatusCode code, std::initializer_list<std::string> parts) {
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.code(), code) << s.ToString();
  for (const std::string& part : parts) {
    EXPECT_NE(s.message().find(part), std::string::npos)
        << "'" << part << "' not in " << s.ToString();
  }
}

TEST(JsonCodec, BadRigidsNameTheField) {
  const std::string w = "unit-3.json: projector_from_camera";
  auto parse = [&](const char* text) { return RigidFromJson(json::parse(text), w).status(); };
  ExpectError(parse(R"({"rotation_xyzw": [0, 0, 1], "translation_m": [0, 0, 0]})"),
              StatusCode::kParseError, {w + ".rotation_xyzw", "array of 4 numbers"});
  ExpectError(parse(R"({"rotation_xyzw": [2, 0, 0, 0], "translation_m": [0, 0, 0]})"),
              StatusCode::kInvalidArgument, {w + ".rotation_xyzw", "norm 2"});
  ExpectError(parse(R"({"rotation_wxyz": [0, 0, 0, 0], "translation_m": [0, 0, 0]})"),
              StatusCode::kInvalidArgument, {w + ".rotation_wxyz", "norm 0"});
  ExpectError(parse(R"({"rotation_xyzw": [0, 0, 0, 1], "translation_m": [0, "x", 0]})"),
              StatusCode::kParseError, {w + ".translation_m[1]", "must be a number"});
  ExpectError(parse(R"({"rotation_xyzw": [0, 0, 0, 1]})"), StatusCode::kParseError,
              {w + ".translation_m is missing"});
  ExpectError(parse(R"({"translation_m": [0, 0, 0]})"), StatusCode::kParseError,
              {w + ".rotation_xyzw is missing"});
  ExpectError(
      parse(R"({"rotation": [[2, 0, 0], [0, 1, 0], [0, 0, 1]], "translation_m": [0, 0, 0]})"),
      StatusCode::kInvalidArgument, {w + ".rotation is not a rotation"});
  ExpectError(
      parse(R"({"rotation": [[-1, 0, 0], [0, 1, 0], [0, 0, 1]], "translation_m": [0, 0, 0]})"),
      StatusCode::kInvalidArgument, {w + ".rotation is not a rotation", "det = -1"});
  ExpectError(parse(R"({"rotation_xyzw": [0, 0, 0, 1], "rotation_wxyz": [1, 0, 0, 0],
                        "translation_m": [0, 0, 0]})"),
              StatusCode::kParseError, {w, "more than one"});
  ExpectError(parse(R"({"rotation_xyzw": [0, 0, 0, 1], "translation_mm": [0, 0, 0],
                        "translation_m": [0, 0, 0]})"),
              StatusCode::kParseError, {w + " has unknown key 'translation_mm'"});
  ExpectError(parse(R"([0, 0, 0, 1])"), StatusCode::kParseError, {w + " must be a JSON object"});
}

TEST(JsonCodec, CameraModelRoundTripIsExact) {
  std::mt19937 rng(kSeed + 2);
  for (int i = 0; i < kTrials; ++i) {
    const CameraModel m = RandomModel(rng);
    Expected<CameraModel> back = CameraModelFromJson(ThroughText(CameraModelToJson(m)), "cam");
    ASSERT_TRUE(back.ok()) << back.status().ToString();
    EXPECT_EQ(back->width_px, m.width_px);
    EXPECT_EQ(back->height_px, m.height_px);
    EXPECT_NEAR((back->K() - m.K()).norm(), 0.0, kIntrinsicsTolerance_px);
    for (int k = 0; k < 5; ++k) {
      EXPECT_EQ(back->distortion.ToArray()[k], m.distortion.ToArray()[k]);
    }
    // Same pixels for the same rays.
    const Eigen::Vector3d x(0.1, -0.05, 1.0);
    EXPECT_EQ(*back->Project(x), *m.Project(x));
  }
}

TEST(JsonCodec, CameraModelOtherForms) {
  // Throw ratio (site files), distortion optional.
  Expected<CameraModel> thrown = CameraModelFromJson(
      json::parse(R"({"width_px": 1280, "height_px": 800, "throw_ratio": 1.27})"), "p");
  ASSERT_TRUE(thrown.ok()) << thrown.status().ToString();
  EXPECT_DOUBLE_EQ(thrown->fx_px, CameraModel::FromThrowRatio(1280, 800, 1.27).fx_px);
  EXPECT_TRUE(thrown->distortion.IsZero());
  // Version-1 unit calibration form.
  Expected<CameraModel> v1 = CameraModelFromJson(json::parse(R"({
      "image_width_px": 1024, "image_height_px": 768,
      "camera_matrix": [[1950, 0, 450], [0, 1940, 730], [0, 0, 1]],
      "distortion_coefficients": [0.1, -0.2, 0.001, 0.002, 0.3],
      "distortion_model": "opencv k1 k2 p1 p2 k3"})"),
                                                 "p");
  ASSERT_TRUE(v1.ok()) << v1.status().ToString();
  EXPECT_EQ(v1->fy_px, 1940);
  EXPECT_EQ(v1->cy_px, 730);
  EXPECT_EQ(v1->distortion.k3, 0.3);
}

TEST(JsonCodec, BadCameraModelsNameTheField) {
  const std::string w = "unit-3.json: projector";
  json good = CameraModelToJson(CameraModel(1280, 800, 1600, 1600, 639.5, 399.5));
  auto with = [&](const char* key, json value) {
    json j = good;
    j[key] = std::move(value);
    return CameraModelFromJson(j, w).status();
  };
  ExpectError(with("fx_px", -3), StatusCode::kInvalidArgument,
              {"unit-3.json: projector.fx_px = -3 must be finite and > 0"});
  ExpectError(with("fy_px", "big"), StatusCode::kParseError, {w + ".fy_px must be a number"});
  ExpectError(with("width_px", 0), StatusCode::kInvalidArgument,
              {w + ".width_px = 0 must be in [1, 65536]"});
  ExpectError(with("height_px", 1.5), StatusCode::kParseError,
              {w + ".height_px must be an integer"});
  ExpectError(with("distortion_k1_k2_p1_p2_k3", json::array({1, 2, 3})), StatusCode::kParseError,
              {w + ".distortion_k1_k2_p1_p2_k3 must be an array of 5 numbers"});
  ExpectError(with("fx", 10), StatusCode::kParseError, {w + " has unknown key 'fx'"});
  ExpectError(with("throw_ratio", 1.2), StatusCode::kParseError, {w, "both throw_ratio and fx_px"});
  json missing = good;
  missing.erase("cy_px");
  ExpectError(CameraModelFromJson(missing, w).status(), StatusCode::kParseError,
              {w + ".cy_px is missing"});
  ExpectError(CameraModelFromJson(json::parse(R"({
      "image_width_px": 1024, "image_height_px": 768,
      "camera_matrix": [[1950, 1, 450], [0, 1940, 730], [0, 0, 1]],
      "distortion_coefficients": [0, 0, 0, 0, 0]})"),
                                  w)
                  .status(),
              StatusCode::kInvalidArgument, {w + ".camera_matrix", "no skew"});
}

TEST(JsonReader, JoinsPaths) {
  EXPECT_EQ(JoinField("unit-3.json: projector", "fx_px"), "unit-3.json: projector.fx_px");
  EXPECT_EQ(JoinField("unit-3.json:", "camera"), "unit-3.json: camera");
  EXPECT_EQ(JoinField("", "camera"), "camera");
  EXPECT_EQ(JoinIndex("units", 2), "units[2]");
}

TEST(JsonReader, FormatAndVersionAreChecked) {
  auto check = [](const char* text) {
    const json j = json::parse(text);
    ObjectReader r(j, "f.json:");
    return ReadFormatVersion(&r, "sandtable.thing", 1, 2);
  };
  Expected<int> ok = check(R"({"format": "sandtable.thing", "version": 2})");
  ASSERT_TRUE(ok.ok()) << ok.status().ToString();
  EXPECT_EQ(*ok, 2);
  ExpectError(check(R"({"version": 2})").status(), StatusCode::kParseError,
              {"f.json: format is missing"});
  ExpectError(check(R"({"format": "other", "version": 2})").status(), StatusCode::kParseError,
              {"f.json: format = \"other\" must be \"sandtable.thing\""});
  ExpectError(check(R"({"format": "sandtable.thing", "version": 3})").status(),
              StatusCode::kParseError, {"f.json: version = 3 is not supported"});
  ExpectError(check(R"({"format": "sandtable.thing"})").status(), StatusCode::kParseError,
              {"f.json: version is missing"});
}

TEST(JsonReader, MalformedTextAndMissingFile) {
  ExpectError(ParseJsonText("{not json", "a.json").status(), StatusCode::kParseError,
              {"a.json: not valid JSON"});
  ExpectError(ReadJsonFile("/nonexistent/a.json").status(), StatusCode::kIoError,
              {"/nonexistent/a.json"});
  ExpectError(WriteJsonFile(json::object(), "/nonexistent/dir/a.json"), StatusCode::kIoError,
              {"/nonexistent/dir/a.json"});
}

}  // namespace
}  // namespace sandtable::io
