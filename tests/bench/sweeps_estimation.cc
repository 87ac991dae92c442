// Sweeps of the estimators from 2D-3D and 2D-2D correspondences: resection, homography (DLT,
// refined, RANSAC), plane fit RANSAC. See numerics_sweep.cc and docs/numerics.md.
#include <cmath>
#include <string>
#include <vector>

#include "common/base/units.h"
#include "common/estimation/homography.h"
#include "common/estimation/plane_fit.h"
#include "common/estimation/resection.h"
#include "tests/bench/sweep_csv.h"
#include "tests/bench/synthetic_scene.h"

namespace sandtable::bench {
namespace {

constexpr double kTableDistance_m = 2.0;
constexpr double kTableTilt_deg = 25.0;

PointData Data(int n, double noise_px, double z_spread_m, uint64_t seed,
               double outlier_ratio = 0.0) {
  PointDataOptions options;
  options.num_points = n;
  options.noise_px = noise_px;
  options.z_spread_m = z_spread_m;
  options.outlier_ratio = outlier_ratio;
  options.seed = seed;
  return MakePointData(BenchCamera(), CameraLookingAtTable(kTableDistance_m, kTableTilt_deg),
                       options);
}

// Ground-truth error of a homography: transfer rms on the noise-free pixels.
double HomographyGtRms_px(const Eigen::Matrix3d& h, const PointData& data) {
  return HomographyTransferRms(h, XyOf(data.points_in_table_m), data.true_px);
}

struct ResectionOutcome {
  Status status;
  double time_ms = kNan, rms_px = kNan, gt_rms_px = kNan, focal_error_pct = kNan;
  double out_of_plane_ratio = kNan;
};

ResectionOutcome RunResection(const std::vector<Eigen::Vector3d>& world,
                              const std::vector<Eigen::Vector2d>& observed_px,
                              const std::vector<Eigen::Vector2d>& true_px,
                              const ResectionOptions& options = {}) {
  const CameraModel truth = BenchCamera();
  ResectionOutcome outcome;
  Expected<ResectionResult> result = InternalError("not run");
  outcome.time_ms = TimeMs([&] {
    result = EstimateResection(world, observed_px, truth.width_px, truth.height_px, options);
  });
  outcome.status = result.status();
  outcome.out_of_plane_ratio = OutOfPlaneRatio(world);
  if (!result.ok()) return outcome;
  outcome.rms_px = result->report.final_rms_px;
  outcome.gt_rms_px = ReprojectionRms_px(result->camera, result->camera_from_world, world, true_px);
  outcome.focal_error_pct = 100.0 * std::abs(result->camera.fx_px - truth.fx_px) / truth.fx_px;
  return outcome;
}

std::vector<uint64_t> Seeds(bool quick, int full) {
  std::vector<uint64_t> seeds;
  for (int i = 0; i < (quick ? 1 : full); ++i) seeds.push_back(1000 + i);
  return seeds;
}

}  // namespace

void SweepRuntimeVsError(const std::string& dir, bool quick) {
  CsvWriter csv(dir, "runtime_vs_error.csv",
                {"routine", "n", "noise_px", "seed", "time_ms", "rms_px", "gt_rms_px",
                 "focal_error_pct", "status"});
  std::vector<int> counts = {10, 30, 100, 300, 1000, 3000, 10000};
  if (quick) counts = {10, 100, 1000};
  for (int n : counts) {
    for (double noise_px : {0.0, 0.1, 0.5, 1.0, 2.0, 5.0}) {
      for (uint64_t seed : Seeds(quick, 3)) {
        const PointData volume = Data(n, noise_px, 0.3, seed);
        const ResectionOutcome r =
            RunResection(volume.points_in_table_m, volume.observed_px, volume.true_px);
        csv.Row({"resection", (long long)n, noise_px, (long long)seed, r.time_ms, r.rms_px,
                 r.gt_rms_px, r.focal_error_pct, StatusCell(r.status)});

        const PointData plane = Data(n, noise_px, 0.0, seed);
        const std::vector<Eigen::Vector2d> xy = XyOf(plane.points_in_table_m);
        Expected<Eigen::Matrix3d> dlt = InternalError("not run");
        const double dlt_ms = TimeMs([&] { dlt = EstimateHomographyDlt(xy, plane.observed_px); });
        csv.Row({"homography_dlt", (long long)n, noise_px, (long long)seed, dlt_ms,
                 dlt.ok() ? HomographyTransferRms(*dlt, xy, plane.observed_px) : kNan,
                 dlt.ok() ? HomographyGtRms_px(*dlt, plane) : kNan, kNan,
                 StatusCell(dlt.status())});
        if (!dlt.ok()) continue;
        Expected<RefinedHomography> refined = InternalError("not run");
        const double refine_ms =
            TimeMs([&] { refined = RefineHomography(xy, plane.observed_px, *dlt); });
        csv.Row({"homography_refined", (long long)n, noise_px, (long long)seed, dlt_ms + refine_ms,
                 refined.ok() ? refined->report.final_rms_px : kNan,
                 refined.ok() ? HomographyGtRms_px(refined->to_from_from, plane) : kNan, kNan,
                 StatusCell(refined.status())});
      }
    }
  }
}

void SweepCoordinateScale(const std::string& dir, bool quick) {
  CsvWriter csv(dir, "coordinate_scale.csv",
                {"routine", "scale", "seed", "time_ms", "gt_rms_px", "focal_error_pct", "status"});
  constexpr int kPoints = 100;
  constexpr double kNoise_px = 0.5;
  for (double scale = 1e-3; scale < 1.5e4; scale *= 10.0) {
    for (uint64_t seed : Seeds(quick, 3)) {
      // Homography: plane coordinates and pixels both multiplied by `scale`; the error is
      // divided by it again so it reads in original pixels.
      const PointData plane = Data(kPoints, kNoise_px, 0.0, seed);
      std::vector<Eigen::Vector2d> from = XyOf(plane.points_in_table_m), to = plane.observed_px;
      for (auto& p : from) p *= scale;
      for (auto& p : to) p *= scale;
      Expected<Eigen::Matrix3d> h = InternalError("not run");
      const double h_ms = TimeMs([&] { h = EstimateHomographyDlt(from, to); });
      double gt_px = kNan;
      if (h.ok()) {
        std::vector<Eigen::Vector2d> true_scaled = plane.true_px;
        for (auto& p : true_scaled) p *= scale;
        gt_px = HomographyTransferRms(*h, from, true_scaled) / scale;
      }
      csv.Row(
          {"homography_dlt", scale, (long long)seed, h_ms, gt_px, kNan, StatusCell(h.status())});
      // Resection: world coordinates multiplied by `scale` (the camera moves with them); the
      // pixels are unchanged.
      const PointData volume = Data(kPoints, kNoise_px, 0.3, seed);
      std::vector<Eigen::Vector3d> world = volume.points_in_table_m;
      for (auto& p : world) p *= scale;
      const ResectionOutcome r = RunResection(world, volume.observed_px, volume.true_px);
      csv.Row({"resection", scale, (long long)seed, r.time_ms, r.gt_rms_px, r.focal_error_pct,
               StatusCell(r.status)});
    }
  }
}

void SweepNearCoplanar(const std::string& dir, bool quick) {
  CsvWriter csv(dir, "near_coplanar.csv",
                {"routine", "spread_m", "out_of_plane_ratio", "seed", "time_ms", "gt_rms_px",
                 "focal_error_pct", "status"});
  constexpr int kPoints = 200;
  constexpr double kNoise_px = 0.5;
  for (double spread_m : {0.0, 1e-6, 1e-5, 1e-4, 3e-4, 1e-3, 3e-3, 1e-2, 3e-2, 0.1, 0.3}) {
    for (uint64_t seed : Seeds(quick, 3)) {
      const PointData data = Data(kPoints, kNoise_px, spread_m, seed);
      const ResectionOutcome free_k =
          RunResection(data.points_in_table_m, data.observed_px, data.true_px);
      csv.Row({"resection_free_intrinsics", spread_m, free_k.out_of_plane_ratio, (long long)seed,
               free_k.time_ms, free_k.gt_rms_px, free_k.focal_error_pct,
               StatusCell(free_k.status)});
      ResectionOptions fixed;
      fixed.fix_intrinsics = true;
      fixed.fix_distortion = true;
      fixed.initial_camera = BenchCamera();
      const ResectionOutcome fixed_k =
          RunResection(data.points_in_table_m, data.observed_px, data.true_px, fixed);
      csv.Row({"resection_fixed_intrinsics", spread_m, fixed_k.out_of_plane_ratio, (long long)seed,
               fixed_k.time_ms, fixed_k.gt_rms_px, fixed_k.focal_error_pct,
               StatusCell(fixed_k.status)});
    }
  }
}

void SweepGrazing(const std::string& dir, bool quick) {
  CsvWriter csv(dir, "grazing.csv",
                {"routine", "tilt_deg", "seed", "n", "time_ms", "gt_rms_px", "rotation_error_deg",
                 "translation_error_mm", "status"});
  constexpr int kPoints = 200;
  constexpr double kNoise_px = 0.5;
  constexpr double kMaxRange_m = 50.0;
  const CameraModel camera = BenchCamera();
  for (double tilt_deg : {0.0, 20.0, 40.0, 60.0, 70.0, 75.0, 80.0, 85.0, 88.0, 89.5}) {
    for (uint64_t seed : Seeds(quick, 3)) {
      const Rigid3d camera_from_table = CameraLookingAtTable(kTableDistance_m, tilt_deg);
      const PointData data =
          MakePlaneDataFromPixels(camera, camera_from_table, kPoints, kNoise_px, kMaxRange_m, seed);
      const std::vector<Eigen::Vector2d> xy = XyOf(data.points_in_table_m);
      Expected<Eigen::Matrix3d> h = InternalError("not run");
      Expected<RefinedHomography> refined = InternalError("not run");
      Expected<Rigid3d> pose = InternalError("not run");
      const double ms = TimeMs([&] {
        h = EstimateHomographyDlt(xy, data.observed_px);
        if (!h.ok()) return;
        refined = RefineHomography(xy, data.observed_px, *h);
        if (!refined.ok()) return;
        pose = CameraFromPlaneHomography(refined->to_from_from, camera.K(), xy);
      });
      const Status status = !h.ok() ? h.status() : !refined.ok() ? refined.status() : pose.status();
      double gt_px = kNan, rot_deg = kNan, trans_mm = kNan;
      if (refined.ok()) gt_px = HomographyGtRms_px(refined->to_from_from, data);
      if (pose.ok()) {
        rot_deg = RadToDeg(RotationAngleBetween_rad(*pose, camera_from_table));
        trans_mm =
            MToMm((pose->Inverse().translation - camera_from_table.Inverse().translation).norm());
      }
      csv.Row({"homography_pose", tilt_deg, (long long)seed, (long long)data.true_px.size(), ms,
               gt_px, rot_deg, trans_mm, StatusCell(status)});
    }
  }
}

void SweepRansacOutliers(const std::string& dir, bool quick) {
  CsvWriter csv(
      dir, "ransac_outliers.csv",
      {"routine", "outlier_pct", "seed", "n", "time_ms", "iterations", "inlier_ratio_found",
       "gt_rms_px", "normal_error_deg", "height_error_mm", "status"});
  constexpr int kHomographyPoints = 500;
  constexpr double kNoise_px = 0.5;
  constexpr int kPlanePoints = 2000;
  constexpr double kPlaneNoise_m = 0.001;
  constexpr double kTableHalf_m = 0.6;
  for (double outlier_pct : {0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0, 85.0, 90.0}) {
    for (uint64_t seed : Seeds(quick, 3)) {
      const PointData data = Data(kHomographyPoints, kNoise_px, 0.0, seed, outlier_pct / 100.0);
      const std::vector<Eigen::Vector2d> xy = XyOf(data.points_in_table_m);
      HomographyRansacOptions options;
      options.seed = seed;
      Expected<HomographyRansacResult> h = InternalError("not run");
      const double h_ms =
          TimeMs([&] { h = EstimateHomographyRansac(xy, data.observed_px, options); });
      double gt_px = kNan;
      if (h.ok()) {
        PointData inliers;  // ground truth error over the true inliers only
        for (size_t i = 0; i < data.true_px.size(); ++i) {
          if (data.is_outlier[i]) continue;
          inliers.points_in_table_m.push_back(data.points_in_table_m[i]);
          inliers.true_px.push_back(data.true_px[i]);
        }
        gt_px = HomographyGtRms_px(h->to_from_from, inliers);
      }
      csv.Row({"homography_ransac", outlier_pct, (long long)seed, (long long)kHomographyPoints,
               h_ms, h.ok() ? (long long)h->iterations : -1LL, h.ok() ? h->inlier_ratio : kNan,
               gt_px, kNan, kNan, StatusCell(h.status())});

      // Plane: table points with 1 mm noise, outliers uniform in the box above the table.
      std::mt19937_64 rng(seed);
      std::uniform_real_distribution<double> xy_m(-kTableHalf_m, kTableHalf_m), z_m(0.01, 0.5);
      std::uniform_real_distribution<double> unit(0.0, 1.0);
      std::normal_distribution<double> noise(0.0, kPlaneNoise_m);
      std::vector<Eigen::Vector3d> points;
      for (int i = 0; i < kPlanePoints; ++i) {
        const bool outlier = unit(rng) < outlier_pct / 100.0;
        points.emplace_back(xy_m(rng), xy_m(rng), outlier ? z_m(rng) : noise(rng));
      }
      PlaneFitOptions plane_options;
      plane_options.seed = seed;
      Expected<PlaneFitReport> plane = InternalError("not run");
      const double p_ms = TimeMs([&] { plane = FitPlaneRansac(points, plane_options); });
      double normal_deg = kNan, height_mm = kNan;
      if (plane.ok()) {
        const Plane oriented = plane->plane.OrientedToward(Eigen::Vector3d(0, 0, 10));
        normal_deg = RadToDeg(std::acos(std::min(1.0, oriented.normal.z())));
        height_mm = 0.0;  // worst |distance| of the true table corners to the fitted plane
        for (double sx : {-1.0, 1.0}) {
          for (double sy : {-1.0, 1.0}) {
            const Eigen::Vector3d corner(sx * kTableHalf_m, sy * kTableHalf_m, 0.0);
            height_mm = std::max(height_mm, MToMm(std::abs(oriented.SignedDistance_m(corner))));
          }
        }
      }
      csv.Row({"plane_ransac", outlier_pct, (long long)seed, (long long)kPlanePoints, p_ms,
               plane.ok() ? (long long)plane->ransac_iterations : -1LL,
               plane.ok() ? plane->inlier_ratio : kNan, kNan, normal_deg, height_mm,
               StatusCell(plane.status())});
    }
  }
}

}  // namespace sandtable::bench
