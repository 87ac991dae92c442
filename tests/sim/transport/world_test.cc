// Physics tests of the simulated world against independent, hand-derived geometry.
#include "sim/transport/world.h"

#include <algorithm>
#include <cmath>
#include <optional>

#include <Eigen/QR>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "common/base/units.h"
#include "common/scene/procedural_scene.h"
#include "sim/site/site_presets.h"
#include "sim/transport/capture.h"

namespace sandtable::sim {
namespace {

constexpr double kTableAlbedo = 0.8;

Scene FlatTable() {
  Scene scene = MakeRectangleMesh({2.0, 1.5}, 0);
  scene.materials = {Material{"table", {kTableAlbedo, kTableAlbedo, kTableAlbedo, 1.0}, -1}};
  return scene;
}

// One unit: a projector at `eye` looking at the origin, and a small camera beside it.
Site OneUnitSite(const Eigen::Vector3d& eye, int camera_width_px, int camera_height_px) {
  Site site;
  site.name = "test";
  site.table.is_disc = false;
  site.table.size_m = {2.0, 1.5};
  site.ambient_luminance_nits = 0.0;
  UnitSpec unit;
  unit.id = 0;
  unit.projector = DefaultProjector();
  unit.projector.black_level = 0.0;
  unit.projector.table_from_projector =
      *TableFromDeviceLookAt(eye, {0, 0, 0}, Eigen::Vector3d::UnitY());
  CameraSpec camera = DefaultCamera();
  const double fx_px = 0.5 * camera_width_px / std::tan(DegToRad(30.0));
  camera.model =
      CameraModel(camera_width_px, camera_height_px, fx_px, fx_px, 0.5 * (camera_width_px - 1),
                  0.5 * (camera_height_px - 1), camera.model.distortion);
  camera.projector_from_camera = Rigid3d(Eigen::Quaterniond::Identity(), {0.1, 0.0, 0.0});
  camera.bit_depth = 16;
  camera.saturation_nit_s = 20.0;  // full scale at 4000 nits with exposure 5 ms
  unit.camera = camera;
  site.units.push_back(unit);
  return site;
}

std::unique_ptr<World> MakeWorld(const Site& site, const Scene& scene,
                                 const WorldOptions& options = {}) {
  Expected<std::unique_ptr<World>> world = World::Create(site, scene, options);
  EXPECT_TRUE(world.ok()) << world.status().ToString();
  return world.ok() ? std::move(*world) : nullptr;
}

// Independent path: camera pixel -> table point on z = 0 (analytic plane intersection).
std::optional<Eigen::Vector3d> TablePointOfCameraPixel(const Site& site,
                                                       const Eigen::Vector2d& pixel) {
  const UnitSpec& unit = site.units[0];
  Expected<Eigen::Vector3d> ray = unit.camera->model.Unproject(pixel);
  if (!ray.ok()) return std::nullopt;
  const Rigid3d table_from_camera = site.TableFromCamera(unit);
  const Eigen::Vector3d origin = table_from_camera.translation;
  const Eigen::Vector3d direction = table_from_camera.rotation * *ray;
  if (direction.z() >= 0) return std::nullopt;
  return origin - origin.z() / direction.z() * direction;
}

// A 16-bit grey frame follows the same response over v / 65535: its codes that are 8-bit codes
// times 257 emit what the 8-bit codes emit, and a code between two 8-bit ones emits in between.
TEST(WorldPhysics, SixteenBitFrameFollowsTheSameResponse) {
  constexpr double kTolerance = 1e-6;
  ProjectorSpec projector = DefaultProjector();
  projector.black_level = 0.002;
  const int w = projector.model.width_px, h = projector.model.height_px;
  for (int v : {0, 1, 77, 128, 254, 255}) {
    Expected<LinearFrame> eight =
        DecodeProjectorFrame(projector, cv::Mat(h, w, CV_8UC1, cv::Scalar(v)));
    Expected<LinearFrame> sixteen =
        DecodeProjectorFrame(projector, cv::Mat(h, w, CV_16UC1, cv::Scalar(v * 257)));
    ASSERT_TRUE(eight.ok() && sixteen.ok());
    EXPECT_NEAR(sixteen->At(w / 2, h / 2), eight->At(w / 2, h / 2), kTolerance) << v;
    EXPECT_NEAR(sixteen->At(0, 0), eight->At(0, 0), kTolerance) << v;
  }
  Expected<LinearFrame> low =
      DecodeProjectorFrame(projector, cv::Mat(h, w, CV_16UC1, cv::Scalar(128 * 257)));
  Expected<LinearFrame> mid =
      DecodeProjectorFrame(projector, cv::Mat(h, w, CV_16UC1, cv::Scalar(128 * 257 + 128)));
  Expected<LinearFrame> high =
      DecodeProjectorFrame(projector, cv::Mat(h, w, CV_16UC1, cv::Scalar(129 * 257)));
  ASSERT_TRUE(low.ok() && mid.ok() && high.ok());
  EXPECT_GT(mid->At(1, 1), low->At(1, 1));
  EXPECT_LT(mid->At(1, 1), high->At(1, 1));
  EXPECT_FALSE(DecodeProjectorFrame(projector, cv::Mat(h, w, CV_32FC1, cv::Scalar(0.5))).ok());
}

TEST(WorldPhysics, WhiteFrameFollowsCosOverDistanceSquared) {
  constexpr double kRelativeTolerance = 0.01;
  const Site site = OneUnitSite({0.4, -0.2, 1.1}, 160, 120);
  auto world = MakeWorld(site, FlatTable());
  ASSERT_TRUE(world);
  ASSERT_TRUE(world->SetProjectorUniform(0, 255).ok());
  Expected<cv::Mat> image = world->Capture(0, {.enabled = false});
  ASSERT_TRUE(image.ok()) << image.status().ToString();
  const UnitSpec& unit = site.units[0];
  const CameraSpec& camera = *unit.camera;
  const Eigen::Vector3d projector_centre = unit.projector.table_from_projector.translation;
  int checked = 0;
  double min_gain = 1e9, max_gain = 0;
  for (int y = 0; y < image->rows; ++y) {
    for (int x = 0; x < image->cols; ++x) {
      const std::optional<Eigen::Vector3d> point = TablePointOfCameraPixel(site, {x, y});
      if (!point || std::abs(point->x()) > 0.99 || std::abs(point->y()) > 0.74) continue;
      const Eigen::Vector3d to_projector = projector_centre - *point;
      const double d = to_projector.norm();
      const double cos_theta = to_projector.z() / d;
      const std::optional<Eigen::Vector2d> projector_pixel =
          unit.projector.model.Project(unit.projector.table_from_projector.Inverse() * *point);
      if (!projector_pixel) continue;
      const Eigen::Vector2d& u = *projector_pixel;
      const bool inside = u.x() > 1 && u.y() > 1 && u.x() < unit.projector.model.width_px - 2 &&
                          u.y() < unit.projector.model.height_px - 2;
      const bool outside = !unit.projector.model.InImage(u) || u.x() < -1.5 || u.y() < -1.5;
      const double dn = image->at<uint16_t>(y, x);
      if (inside) {
        const double luminance_nits =
            kTableAlbedo * unit.projector.peak_luminance_at_1m_nits * cos_theta / (d * d);
        const double expected_dn =
            luminance_nits * camera.exposure_s / camera.saturation_nit_s * camera.MaxDn();
        ASSERT_LT(expected_dn, camera.MaxDn());
        EXPECT_NEAR(dn / expected_dn, 1.0, kRelativeTolerance) << "pixel " << x << "," << y;
        min_gain = std::min(min_gain, cos_theta / (d * d));
        max_gain = std::max(max_gain, cos_theta / (d * d));
        ++checked;
      } else if (outside) {
        EXPECT_EQ(dn, 0.0) << "unlit pixel " << x << "," << y;
      }
    }
  }
  EXPECT_GT(checked, 5000);
  EXPECT_GT(max_gain / min_gain, 1.2) << "the test must span a real range of cos/d^2";
}

TEST(WorldPhysics, BoxShadowMatchesHandComputedRegion) {
  // Projector 1 m straight above the origin; a 0.1 m x 0.1 m x 0.1 m box spanning
  // x in [0.2, 0.3], y in [-0.05, 0.05]. Its shadow on the table is the top face scaled by
  // H / (H - h) = 1 / 0.9 about the nadir: x in [0.2222, 0.3333], |y| <= 0.05556, minus the
  // footprint of the box itself.
  Scene scene = FlatTable();
  scene.Append(MakeBoxMesh({0.25, 0.0, 0.0}, {0.1, 0.1, 0.1}, 0.0, 0));
  const Site site = OneUnitSite({0.0, 0.0, 1.0}, 64, 48);
  auto world = MakeWorld(site, scene);
  ASSERT_TRUE(world);
  struct Case {
    double x, y;
    bool lit;
  };
  const Case cases[] = {
      {0.305, 0.0, false},   {0.330, 0.0, false},   {0.3370, 0.0, true}, {0.36, 0.0, true},
      {0.31, 0.053, false},  {0.31, -0.053, false}, {0.31, 0.058, true}, {0.25, 0.053, false},
      {0.25, 0.058, true},   {0.19, 0.0, true},     {0.25, 0.0, true},  // box top
      {0.30, 0.0555, false}, {0.333, 0.055, false}, {0.3336, 0.0, true},
  };
  for (const Case& c : cases) {
    Expected<SurfaceTruth> truth = world->TruthAtTableXY({c.x, c.y});
    ASSERT_TRUE(truth.ok());
    EXPECT_EQ(truth->projectors[0].sample.visible, c.lit) << "at " << c.x << ", " << c.y;
  }
  // The box top is hit from above at z = 0.1.
  EXPECT_NEAR(world->TruthAtTableXY({0.25, 0.0})->point_in_table_m.z(), 0.1,
              1e-6);  // float vertices
}

TEST(WorldPhysics, GammaRoundTrip) {
  constexpr double kRelativeTolerance = 0.002;
  Site site = OneUnitSite({0.2, 0.1, 1.0}, 64, 48);
  site.units[0].camera->gamma = 2.2;
  auto world = MakeWorld(site, FlatTable());
  ASSERT_TRUE(world);
  const CameraSpec& camera = *site.units[0].camera;
  auto linear_at_centre = [&](int value) {
    EXPECT_TRUE(world->SetProjectorUniform(0, value).ok());
    const cv::Mat image = *world->Capture(0, {.enabled = false});
    return std::pow(image.at<uint16_t>(24, 32) / camera.MaxDn(), camera.gamma);
  };
  const double white = linear_at_centre(255);
  ASSERT_GT(white, 0.05);
  for (int v : {32, 64, 128, 200}) {
    const double expected = std::pow(v / 255.0, site.units[0].projector.gamma);
    EXPECT_NEAR(linear_at_centre(v) / white / expected, 1.0, kRelativeTolerance) << "value " << v;
  }
}

// Measures a checkerboard corner from the image alone, more precisely than cv::cornerSubPix:
// each of the two checker edges through the corner is fitted with a straight line through
// many sub-pixel edge points, one per image column (for a mostly horizontal edge; rows for a
// mostly vertical one), taken away from the corner's own blur; the corner is the lines'
// intersection.
// Edge point of one profile (samples I_0 .. I_K across the edge, plateaus at both ends): with
// n_k = (I_k - I_0) / (I_K - I_0) rising from 0 to 1, the edge is at K + 1/2 - sum_k n_k (the
// area under the step). A pixel that integrates its footprint sees a step as a ramp of width
// w >= 1 px; the area estimate is exact when w is a whole number of pixels (w ~ 1 for an edge
// nearly parallel to the pixel grid, where the phase along the edge hardly changes), and its
// error for other w is periodic in the edge's sub-pixel phase and averages out along an
// oblique edge. (Linear interpolation of the 50 % level between the two straddling samples is
// biased by up to 0.08 px for w ~ 1, constantly along a grid-parallel edge; that, not the
// rendering, is what limits cornerSubPix here.)
// `start` is the initial guess; `arm1`, `arm2` point roughly along the two edges (length:
// the distance to the next corner). Within one square the edges are straight to far below
// 0.01 px for the lens distortions used here.
std::optional<Eigen::Vector2d> CornerFromEdgeLines(const cv::Mat& image,
                                                   const Eigen::Vector2d& start,
                                                   const Eigen::Vector2d& arm1,
                                                   const Eigen::Vector2d& arm2) {
  constexpr double kCornerClearance_px = 5.0;  // the other edge and the corner's blur
  constexpr int kHalfWindow_px = 3;            // profile half length across the edge
  Eigen::Vector2d line_point[2], line_direction[2];
  for (int line = 0; line < 2; ++line) {
    const Eigen::Vector2d arm = line == 0 ? arm1 : arm2;
    const double length = arm.norm();
    const Eigen::Vector2d d = arm / length;
    const bool horizontal = std::abs(d.x()) >= std::abs(d.y());
    std::vector<Eigen::Vector2d> points;  // (along, across)
    for (int side : {-1, 1}) {
      // Samples from kCornerClearance_px to length - clearance along the arm, one per column
      // (or row).
      const double step = 1.0 / std::max(std::abs(d.x()), std::abs(d.y()));
      for (double t = kCornerClearance_px; t <= length - kCornerClearance_px; t += step) {
        const Eigen::Vector2d guess = start + side * t * d;
        const int across0 = static_cast<int>(std::lround(horizontal ? guess.y() : guess.x()));
        const int along = static_cast<int>(std::lround(horizontal ? guess.x() : guess.y()));
        std::vector<double> profile;
        for (int k = -kHalfWindow_px; k <= kHalfWindow_px; ++k) {
          const int x = horizontal ? along : across0 + k;
          const int y = horizontal ? across0 + k : along;
          if (x < 0 || y < 0 || x >= image.cols || y >= image.rows) break;
          profile.push_back(image.at<float>(y, x));
        }
        if (profile.size() != 2 * kHalfWindow_px + 1) continue;
        const double contrast = profile.back() - profile.front();
        if (std::abs(contrast) < 1e-3) continue;
        double area = 0.0;
        for (double v : profile) area += (v - profile.front()) / contrast;
        points.emplace_back(along, across0 + kHalfWindow_px + 0.5 - area);
      }
    }
    if (points.size() < 6) return std::nullopt;
    // Least squares across = offset + slope along.
    Eigen::MatrixXd a(points.size(), 2);
    Eigen::VectorXd b(points.size());
    for (size_t i = 0; i < points.size(); ++i) {
      a.row(i) = Eigen::RowVector2d(1.0, points[i].x());
      b(i) = points[i].y();
    }
    const Eigen::Vector2d fit = a.colPivHouseholderQr().solve(b);
    line_point[line] = horizontal ? Eigen::Vector2d(0.0, fit(0)) : Eigen::Vector2d(fit(0), 0.0);
    line_direction[line] = horizontal ? Eigen::Vector2d(1.0, fit(1)) : Eigen::Vector2d(fit(1), 1.0);
  }
  // Intersect p0 + s d0 = p1 + t d1.
  Eigen::Matrix2d m;
  m << line_direction[0], -line_direction[1];
  if (std::abs(m.determinant()) < 1e-3) return std::nullopt;
  const Eigen::Vector2d st = m.colPivHouseholderQr().solve(line_point[1] - line_point[0]);
  return line_point[0] + st.x() * line_direction[0];
}

TEST(WorldPhysics, CheckerboardCornersLandWhereTrueModelsPredict) {
  // Every corner of a projected checkerboard, measured in the noise-free capture by fitting
  // lines to its two edges, lies within 0.05 px of where the true projector and camera
  // models put it. (cv::cornerSubPix is printed for comparison: it scatters by ~0.08 px rms on
  // this perspective, shaded board, so it cannot check 0.05 px.)
  constexpr double kPerCornerTolerance_px = 0.05;
  constexpr double kBias_px = 0.02;  // systematic offset over all corners
  constexpr int kSquare_px = 80;     // ~27 camera px: room for many edge points per corner
  const Site site = OneUnitSite({0.3, -0.2, 1.1}, 640, 480);
  auto world = MakeWorld(site, FlatTable());
  ASSERT_TRUE(world);
  const UnitSpec& unit = site.units[0];
  cv::Mat board(unit.projector.model.height_px, unit.projector.model.width_px, CV_8UC1);
  for (int y = 0; y < board.rows; ++y) {
    for (int x = 0; x < board.cols; ++x) {
      board.at<uint8_t>(y, x) = ((x / kSquare_px + y / kSquare_px) % 2) ? 230 : 25;
    }
  }
  ASSERT_TRUE(world->SetProjectorFrame(0, board).ok());
  const cv::Mat image = *world->Capture(0, {.enabled = false});
  cv::Mat image_f;
  image.convertTo(image_f, CV_32F, 1.0 / 65535.0);
  // Predict each corner: projector pixel (k s - 0.5, m s - 0.5) (pixel-centre convention),
  // its true ray onto z = 0, into the true camera.
  const Rigid3d table_from_camera = site.TableFromCamera(unit);
  auto predict = [&](int k, int m) -> std::optional<Eigen::Vector2d> {
    const Eigen::Vector2d corner(k * kSquare_px - 0.5, m * kSquare_px - 0.5);
    const Eigen::Vector3d ray =
        unit.projector.table_from_projector.rotation * *unit.projector.model.Unproject(corner);
    const Eigen::Vector3d origin = unit.projector.table_from_projector.translation;
    const Eigen::Vector3d point = origin - origin.z() / ray.z() * ray;
    return unit.camera->model.Project(table_from_camera.Inverse() * point);
  };
  const int corners_x = board.cols / kSquare_px, corners_y = board.rows / kSquare_px;
  std::vector<Eigen::Vector2d> predicted, measured;
  std::vector<cv::Point2f> subpix_start;
  int unmeasurable = 0;
  for (int m = 1; m < corners_y; ++m) {
    for (int k = 1; k < corners_x; ++k) {
      const std::optional<Eigen::Vector2d> pixel = predict(k, m);
      const std::optional<Eigen::Vector2d> right = predict(k + 1, m), down = predict(k, m + 1);
      if (!pixel || !right || !down || pixel->x() < 30 || pixel->y() < 30 ||
          pixel->x() > image.cols - 31 || pixel->y() > image.rows - 31) {
        continue;
      }
      // Start 0.6 px away from the prediction so the measurement has to find the corner.
      const Eigen::Vector2d start = *pixel + Eigen::Vector2d(0.6, -0.6);
      const std::optional<Eigen::Vector2d> corner =
          CornerFromEdgeLines(image_f, start, *right - *pixel, *down - *pixel);
      if (!corner) {
        ++unmeasurable;
        continue;
      }
      predicted.push_back(*pixel);
      measured.push_back(*corner);
      subpix_start.emplace_back(start.x(), start.y());
    }
  }
  ASSERT_GT(predicted.size(), 30u);
  EXPECT_LT(unmeasurable, static_cast<int>(predicted.size() / 10));
  double max_error_px = 0.0, sum_sq = 0.0;
  Eigen::Vector2d mean_offset = Eigen::Vector2d::Zero();
  for (size_t i = 0; i < predicted.size(); ++i) {
    const Eigen::Vector2d e = measured[i] - predicted[i];
    EXPECT_LT(e.norm(), kPerCornerTolerance_px) << "corner at " << predicted[i].transpose();
    max_error_px = std::max(max_error_px, e.norm());
    sum_sq += e.squaredNorm();
    mean_offset += e / predicted.size();
  }
  EXPECT_LT(mean_offset.norm(), kBias_px);
  cv::cornerSubPix(image_f, subpix_start, cv::Size(4, 4), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 100, 1e-4));
  double subpix_sum_sq = 0.0, subpix_max_px = 0.0;
  for (size_t i = 0; i < predicted.size(); ++i) {
    const double e =
        std::hypot(subpix_start[i].x - predicted[i].x(), subpix_start[i].y - predicted[i].y());
    subpix_sum_sq += e * e;
    subpix_max_px = std::max(subpix_max_px, e);
  }
  std::cout << "checkerboard: " << predicted.size() << " corners (" << unmeasurable
            << " not measurable); edge lines: rms " << std::sqrt(sum_sq / predicted.size())
            << " px, max " << max_error_px << " px, mean offset " << mean_offset.transpose()
            << " px; cornerSubPix: rms " << std::sqrt(subpix_sum_sq / predicted.size())
            << " px, max " << subpix_max_px << " px\n";
}

TEST(WorldPhysics, DeterministicForSeedAndThreadCount) {
  Site site = *MakeSitePreset("sandtable-3");
  for (UnitSpec& u : site.units)
    u.camera->model = CameraModel(96, 72, 90, 90, 47.5, 35.5, u.camera->model.distortion);
  ProceduralSceneOptions options;
  options.seed = 11;
  const Scene scene = MakeProceduralScene(options)->scene;
  WorldOptions one_thread, three_threads;
  one_thread.transport.num_threads = 1;
  three_threads.transport.num_threads = 3;
  auto a = MakeWorld(site, scene, one_thread);
  auto b = MakeWorld(site, scene, three_threads);
  ASSERT_TRUE(a && b);
  for (NodeId id : {0u, 1u, 2u}) {
    ASSERT_TRUE(a->SetProjectorUniform(id, 180).ok());
    ASSERT_TRUE(b->SetProjectorUniform(id, 180).ok());
  }
  const cv::Mat a1 = *a->Capture(1, {.enabled = true, .seed = 5});
  const cv::Mat b1 = *b->Capture(1, {.enabled = true, .seed = 5});
  const cv::Mat a2 = *a->Capture(1, {.enabled = true, .seed = 6});
  EXPECT_EQ(cv::norm(a1, b1, cv::NORM_INF), 0.0);
  EXPECT_GT(cv::norm(a1, a2, cv::NORM_INF), 0.0);
  EXPECT_GT(cv::mean(a1)[0], 10.0) << "the camera sees lit surfaces";
  // Shadows exist in the default scene: some surface pixels are lit by fewer than 3 projectors.
  const TransportMap& map = **a->CameraTransport(1);
  std::vector<int> count(map.width_px * map.height_px, 0);
  for (const auto& entries : map.entries)
    for (const TransportEntry& e : entries) ++count[e.pixel];
  int partially_lit = 0;
  for (size_t i = 0; i < count.size(); ++i)
    partially_lit += map.hit[i] && count[i] > 0 && count[i] < 3;
  EXPECT_GT(partially_lit, 0);
}

TEST(WorldPhysics, TransportMapAgreesWithPerPointTruth) {
  // The map's batched shadow rays give the same visibility as the single-ray ground truth
  // along each camera pixel's ray, on the default scene with real shadows.
  Site site = *MakeSitePreset("sandtable-3");
  for (UnitSpec& u : site.units)
    u.camera->model = CameraModel(96, 72, 90, 90, 47.5, 35.5, u.camera->model.distortion);
  ProceduralSceneOptions options;
  options.seed = 3;
  auto world = MakeWorld(site, MakeProceduralScene(options)->scene);
  ASSERT_TRUE(world);
  const UnitSpec& unit = site.units[2];
  const TransportMap& map = **world->CameraTransport(unit.id);
  std::vector<std::vector<bool>> lit(site.units.size(), std::vector<bool>(96 * 72, false));
  for (size_t p = 0; p < map.entries.size(); ++p)
    for (const TransportEntry& e : map.entries[p]) lit[p][e.pixel] = true;
  const Rigid3d table_from_camera = site.TableFromCamera(unit);
  int checked = 0, shadowed = 0;
  for (int y = 0; y < 72; ++y) {
    for (int x = 0; x < 96; ++x) {
      const Eigen::Vector3d ray =
          table_from_camera.rotation * *unit.camera->model.Unproject(Eigen::Vector2d(x, y));
      Expected<SurfaceTruth> truth = world->TruthAlongRay(table_from_camera.translation, ray);
      ASSERT_EQ(truth.ok(), map.hit[y * 96 + x] != 0) << x << "," << y;
      if (!truth.ok()) continue;
      for (size_t p = 0; p < site.units.size(); ++p) {
        EXPECT_EQ(truth->projectors[p].sample.visible, lit[p][y * 96 + x])
            << "pixel " << x << "," << y << " projector " << p;
        shadowed += !truth->projectors[p].sample.visible;
        ++checked;
      }
    }
  }
  EXPECT_GT(checked, 10000);
  EXPECT_GT(shadowed, 100) << "the check must include unlit points";
}

TEST(WorldPhysics, NoiseStatisticsMatchTheModel) {
  // Uniform grey: the spread of a flat patch matches Poisson + read noise.
  Site site = OneUnitSite({0.0, 0.0, 1.0}, 64, 48);
  CameraSpec& camera = *site.units[0].camera;
  camera.bit_depth = 12;
  camera.full_well_e = 2000;
  camera.read_noise_dn = 2.0;
  auto world = MakeWorld(site, FlatTable());
  ASSERT_TRUE(world->SetProjectorUniform(0, 255).ok());
  const cv::Mat clean = *world->Capture(0, {.enabled = false});
  const cv::Mat noisy = *world->Capture(0, {.enabled = true, .seed = 3});
  cv::Mat diff;
  cv::subtract(noisy, clean, diff, cv::noArray(), CV_64F);
  cv::Scalar mean, stddev;
  cv::meanStdDev(diff, mean, stddev);
  const double s = cv::mean(clean)[0] / camera.MaxDn();  // mean linear signal
  const double expected_sd =
      std::sqrt(s * camera.full_well_e) / camera.full_well_e * camera.MaxDn();
  const double expected_total = std::hypot(expected_sd, camera.read_noise_dn);
  // Standard error of a standard deviation from n = 3072 pixels: 1 / sqrt(2 n) = 1.3 %;
  // quantisation adds 1/12 DN^2 (included).
  constexpr double kSpreadRelativeTolerance = 0.05;
  const double expected_quantised = std::sqrt(expected_total * expected_total + 1.0 / 12.0);
  std::cout << "noise: measured sd " << stddev[0] << " DN, model " << expected_quantised << " DN\n";
  EXPECT_NEAR(stddev[0] / expected_quantised, 1.0, kSpreadRelativeTolerance);
  // Zero-mean noise: within 4 standard errors of the mean.
  EXPECT_NEAR(mean[0], 0.0, 4.0 * expected_total / std::sqrt(static_cast<double>(diff.total())));
}

}  // namespace
}  // namespace sandtable::sim
