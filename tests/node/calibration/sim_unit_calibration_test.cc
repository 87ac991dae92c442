// Unit calibration of ONE simulated unit (sandtable-3, unit 0) compared with the site's truth.
//
// A flat white board (the 9x7 inner-corner grid of 75 mm squares plus one square of margin) is
// placed at six poses in front of the unit; the scene is the board alone. Per pose:
//   - camera "corners": SYNTHESISED, not detected. The world has no printed chessboard
//     texture, so each inner corner is projected through the site's TRUE camera model and
//     Gaussian noise of kCornerNoise_px is added (a sub-pixel detector's typical error);
//   - dense correspondences: the real structured-light path. The OpenCV Gray-code sequence is
//     shown on the unit's projector, captured through the World (light transport, projector
//     blur and distortion, camera noise), decoded by DecodeStructuredLight and sampled inside
//     the corner hull, exactly as ObservePose does on real captures.
// CalibrateUnit then runs with the default options (those of the real-data path) and the
// result is compared with the true camera, projector and projector_from_camera.
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "common/base/units.h"
#include "common/scene/scene.h"
#include "common/structured_light/decoder.h"
#include "common/structured_light/pattern_sequence.h"
#include "node/calibration/board_observation.h"
#include "node/calibration/unit_calibrator.h"
#include "sim/site/site_presets.h"
#include "sim/transport/world.h"

namespace sandtable::node {
namespace {

constexpr double kCornerNoise_px = 0.15;
constexpr double kBoardMargin_m = 0.075;  // white border around the inner-corner grid
constexpr uint64_t kSeed = 7;
// Tolerances (measured values in docs/unit-calibration.md, "Simulated unit").
constexpr double kCameraFocalTolerance = 0.005;  // relative
constexpr double kCameraPrincipalTolerance_px = 3.0;
constexpr double kProjectorFocalTolerance = 0.01;  // relative
constexpr double kProjectorPrincipalTolerance_px = 4.0;
constexpr double kRotationTolerance_deg = 0.1;
constexpr double kTranslationTolerance_mm = 2.0;
constexpr double kMaxCameraRms_px = 0.3;
constexpr double kMaxProjectorRms_px = 1.0;

struct BoardPose {
  double about_x_deg, about_y_deg, about_z_deg;
  Eigen::Vector3d centre_in_projector_m;
};

// Board centre along the projector axis at 1.25-1.45 m, tilted up to 30 degrees.
const std::vector<BoardPose>& Poses() {
  static const std::vector<BoardPose> poses = {
      {0.0, 0.0, 0.0, {0.03, 0.0, 1.35}},      {0.0, 28.0, 3.0, {0.05, 0.01, 1.30}},
      {0.0, -28.0, -4.0, {0.02, -0.01, 1.40}}, {25.0, 0.0, 5.0, {0.04, 0.02, 1.35}},
      {-25.0, 5.0, 0.0, {0.03, -0.02, 1.30}},  {18.0, 18.0, -6.0, {0.05, 0.0, 1.45}},
  };
  return poses;
}

Rigid3d ProjectorFromBoard(const BoardPose& p, const BoardSpec& board) {
  const Eigen::Matrix3d r = (Eigen::AngleAxisd(DegToRad(p.about_x_deg), Eigen::Vector3d::UnitX()) *
                             Eigen::AngleAxisd(DegToRad(p.about_y_deg), Eigen::Vector3d::UnitY()) *
                             Eigen::AngleAxisd(DegToRad(p.about_z_deg), Eigen::Vector3d::UnitZ()))
                                .toRotationMatrix();
  const Eigen::Vector3d centre_in_board(0.5 * (board.inner_cols - 1) * board.square_m,
                                        0.5 * (board.inner_rows - 1) * board.square_m, 0.0);
  return Rigid3d(r, p.centre_in_projector_m - r * centre_in_board);
}

// The white board as a two-triangle scene in the table frame, facing the unit (board -z).
Scene BoardScene(const Rigid3d& table_from_board, const BoardSpec& board) {
  Scene scene;
  const double x1 = (board.inner_cols - 1) * board.square_m + kBoardMargin_m;
  const double y1 = (board.inner_rows - 1) * board.square_m + kBoardMargin_m;
  const double x0 = -kBoardMargin_m, y0 = -kBoardMargin_m;
  for (const Eigen::Vector3d& c : {Eigen::Vector3d(x0, y0, 0), Eigen::Vector3d(x1, y0, 0),
                                   Eigen::Vector3d(x1, y1, 0), Eigen::Vector3d(x0, y1, 0)}) {
    scene.positions_in_table_m.push_back((table_from_board * c).cast<float>());
  }
  // (p1 - p0) x (p2 - p0) = -z_board for these windings: the front faces the devices.
  scene.triangles = {{0, 2, 1}, {0, 3, 2}};
  scene.triangle_material = {0, 0};
  Material white;
  white.name = "board";
  white.base_color_factor = Eigen::Vector4d(0.8, 0.8, 0.8, 1.0);
  scene.materials.push_back(white);
  return scene;
}

TEST(SimUnitCalibration, MatchesTheSiteTruth) {
  Expected<sim::Site> preset = sim::MakeSitePreset("sandtable-3");
  ASSERT_TRUE(preset.ok()) << preset.status().ToString();
  sim::Site site = *preset;
  site.units.resize(1);  // unit 0 alone: no other projector's black level on the board
  const sim::UnitSpec unit = site.units[0];
  const CameraModel& true_camera = unit.camera->model;
  const CameraModel& true_projector = unit.projector.model;
  const Rigid3d& true_projector_from_camera = unit.camera->projector_from_camera;

  UnitCalibrationOptions options;  // the real-data defaults
  options.projector_width_px = true_projector.width_px;
  options.projector_height_px = true_projector.height_px;
  ObservationOptions observation;
  observation.patterns =
      PatternOptions::OpenCvGrayCode(true_projector.width_px, true_projector.height_px);
  observation.decoder.num_threads = 1;
  ASSERT_TRUE(observation.Check().ok()) << observation.Check().ToString();
  Expected<std::vector<cv::Mat>> frames = GeneratePatterns(observation.patterns);
  ASSERT_TRUE(frames.ok()) << frames.status().ToString();

  std::mt19937_64 rng(kSeed);
  std::normal_distribution<double> corner_noise(0.0, kCornerNoise_px);
  std::vector<PoseObservation> poses;
  for (size_t p = 0; p < Poses().size(); ++p) {
    const Rigid3d projector_from_board = ProjectorFromBoard(Poses()[p], options.board);
    const Rigid3d camera_from_board = true_projector_from_camera.Inverse() * projector_from_board;
    PoseObservation obs;
    obs.name = "sim_pose_" + std::to_string(p);
    obs.camera_size = cv::Size(true_camera.width_px, true_camera.height_px);
    std::vector<cv::Point> hull_in;
    for (int k = 0; k < options.board.corner_count(); ++k) {
      const std::optional<Eigen::Vector2d> px =
          true_camera.Project(camera_from_board * options.board.CornerInBoard_m(k));
      ASSERT_TRUE(px.has_value()) << obs.name << " corner " << k;
      ASSERT_TRUE(px->x() > 0 && px->y() > 0 && px->x() < true_camera.width_px - 1 &&
                  px->y() < true_camera.height_px - 1)
          << obs.name << " corner " << k << " outside the camera";
      obs.corners_in_camera_px.emplace_back(px->x() + corner_noise(rng),
                                            px->y() + corner_noise(rng));
      hull_in.emplace_back(cvRound(obs.corners_in_camera_px.back().x()),
                           cvRound(obs.corners_in_camera_px.back().y()));
    }

    Expected<std::unique_ptr<sim::World>> world = sim::World::Create(
        site,
        BoardScene(unit.projector.table_from_projector * projector_from_board, options.board));
    ASSERT_TRUE(world.ok()) << world.status().ToString();
    std::vector<cv::Mat> captures;
    for (size_t k = 0; k < frames->size(); ++k) {
      ASSERT_TRUE((*world)->SetProjectorFrame(unit.id, (*frames)[k]).ok());
      Expected<cv::Mat> image = (*world)->Capture(
          unit.id, sim::CaptureNoise{.enabled = true, .seed = kSeed * 1000 + p * 100 + k});
      ASSERT_TRUE(image.ok()) << image.status().ToString();
      captures.push_back(std::move(*image));
    }
    Expected<Decoding> decoded =
        DecodeStructuredLight(captures, observation.patterns, observation.decoder);
    ASSERT_TRUE(decoded.ok()) << decoded.status().ToString();

    // Dense samples inside the corner hull, as ObservePose collects them.
    std::vector<cv::Point> hull;
    cv::convexHull(hull_in, hull);
    cv::Mat board_mask = cv::Mat::zeros(obs.camera_size, CV_8UC1);
    cv::fillConvexPoly(board_mask, hull, cv::Scalar(255));
    for (int y = 0; y < board_mask.rows; ++y) {
      for (int x = 0; x < board_mask.cols; ++x) {
        if (board_mask.at<uint8_t>(y, x) == 0) continue;
        ++obs.board_pixels;
        if (decoded->valid.at<uint8_t>(y, x) == 0) continue;
        ++obs.decoded_board_pixels;
        if (x % observation.dense_stride_px != 0 || y % observation.dense_stride_px != 0) continue;
        const cv::Vec2f uv = decoded->projector_px.at<cv::Vec2f>(y, x);
        obs.dense_in_camera_px.emplace_back(x, y);
        obs.dense_in_projector_px.emplace_back(uv[0], uv[1]);
      }
    }
    std::printf("%s: %lld of %lld board px decoded, %zu dense samples\n", obs.name.c_str(),
                static_cast<long long>(obs.decoded_board_pixels),
                static_cast<long long>(obs.board_pixels), obs.dense_in_camera_px.size());
    poses.push_back(std::move(obs));
  }

  Expected<UnitCalibrationResult> result = CalibrateUnit(poses, options);
  ASSERT_TRUE(result.ok()) << result.status().ToString();
  const UnitCalibration& c = result->calibration;
  const UnitCalibrationReport& r = result->report;

  const double camera_fx_rel = std::abs(c.camera.fx_px / true_camera.fx_px - 1.0);
  const double camera_fy_rel = std::abs(c.camera.fy_px / true_camera.fy_px - 1.0);
  const double camera_cx_px = std::abs(c.camera.cx_px - true_camera.cx_px);
  const double camera_cy_px = std::abs(c.camera.cy_px - true_camera.cy_px);
  const double projector_fx_rel = std::abs(c.projector.fx_px / true_projector.fx_px - 1.0);
  const double projector_fy_rel = std::abs(c.projector.fy_px / true_projector.fy_px - 1.0);
  const double projector_cx_px = std::abs(c.projector.cx_px - true_projector.cx_px);
  const double projector_cy_px = std::abs(c.projector.cy_px - true_projector.cy_px);
  const double rotation_deg =
      RadToDeg(RotationAngleBetween_rad(c.projector_from_camera, true_projector_from_camera));
  const double translation_mm =
      (c.projector_from_camera.translation - true_projector_from_camera.translation).norm() *
      kMmPerM;
  std::printf(
      "camera fx %.2f (true %.2f, %.3f %%) fy %.2f (%.3f %%) cx %.2f (err %.2f px) cy %.2f "
      "(err %.2f px) k1 %.4f (true %.4f) k2 %.4f (true %.4f)\n",
      c.camera.fx_px, true_camera.fx_px, 100 * camera_fx_rel, c.camera.fy_px, 100 * camera_fy_rel,
      c.camera.cx_px, camera_cx_px, c.camera.cy_px, camera_cy_px, c.camera.distortion.k1,
      true_camera.distortion.k1, c.camera.distortion.k2, true_camera.distortion.k2);
  std::printf(
      "projector fx %.2f (true %.2f, %.3f %%) fy %.2f (%.3f %%) cx %.2f (true %.2f, err %.2f px) "
      "cy %.2f (true %.2f, err %.2f px) k1 %.4f (true %.4f) k2 %.4f (true %.4f)\n",
      c.projector.fx_px, true_projector.fx_px, 100 * projector_fx_rel, c.projector.fy_px,
      100 * projector_fy_rel, c.projector.cx_px, true_projector.cx_px, projector_cx_px,
      c.projector.cy_px, true_projector.cy_px, projector_cy_px, c.projector.distortion.k1,
      true_projector.distortion.k1, c.projector.distortion.k2, true_projector.distortion.k2);
  std::printf(
      "projector_from_camera: rotation err %.4f deg, translation err %.3f mm (t (%.4f %.4f "
      "%.4f) m, true (%.4f %.4f %.4f) m); rms camera %.3f projector %.3f px; %s, %d it, %.2f s\n",
      rotation_deg, translation_mm, c.projector_from_camera.translation.x(),
      c.projector_from_camera.translation.y(), c.projector_from_camera.translation.z(),
      true_projector_from_camera.translation.x(), true_projector_from_camera.translation.y(),
      true_projector_from_camera.translation.z(), r.camera_rms_px, r.projector_rms_px,
      r.termination.c_str(), r.iterations, r.compute_time.count());

  EXPECT_LT(r.camera_rms_px, kMaxCameraRms_px);
  EXPECT_LT(r.projector_rms_px, kMaxProjectorRms_px);
  EXPECT_LT(camera_fx_rel, kCameraFocalTolerance);
  EXPECT_LT(camera_fy_rel, kCameraFocalTolerance);
  EXPECT_LT(camera_cx_px, kCameraPrincipalTolerance_px);
  EXPECT_LT(camera_cy_px, kCameraPrincipalTolerance_px);
  EXPECT_LT(projector_fx_rel, kProjectorFocalTolerance);
  EXPECT_LT(projector_fy_rel, kProjectorFocalTolerance);
  EXPECT_LT(projector_cx_px, kProjectorPrincipalTolerance_px);
  EXPECT_LT(projector_cy_px, kProjectorPrincipalTolerance_px);
  EXPECT_LT(rotation_deg, kRotationTolerance_deg);
  EXPECT_LT(translation_mm, kTranslationTolerance_mm);
}

}  // namespace
}  // namespace sandtable::node
