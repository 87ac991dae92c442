// Google Benchmark timings of the estimators at several correspondence counts.
//   build-c/tests/bench/bench_estimation [--benchmark_filter=Resection]
// Synthetic data from synthetic_scene.h, 0.5 px noise. A benchmark whose estimator returns an
// error reports it with SkipWithError (so a broken estimator is visible, not timed).
#include <benchmark/benchmark.h>

#include <vector>

#include "common/estimation/homography.h"
#include "common/estimation/resection.h"
#include "common/estimation/triangulation.h"
#include "tests/bench/synthetic_scene.h"

namespace sandtable::bench {
namespace {

constexpr double kNoise_px = 0.5;

PointData ResectionData(int n) {
  PointDataOptions options;
  options.num_points = n;
  options.noise_px = kNoise_px;
  options.seed = 1;
  return MakePointData(BenchCamera(), CameraLookingAtTable(2.0, 25.0), options);
}

// Full pipeline: validation, DLT, RQ, Ceres refinement of intrinsics, distortion and pose.
void BM_ResectionFull(benchmark::State& state) {
  const PointData data = ResectionData(static_cast<int>(state.range(0)));
  const CameraModel cam = BenchCamera();
  for (auto _ : state) {
    auto result =
        EstimateResection(data.points_in_table_m, data.observed_px, cam.width_px, cam.height_px);
    if (!result.ok()) {
      state.SkipWithError(result.status().ToString().c_str());
      break;
    }
    benchmark::DoNotOptimize(result->camera.fx_px);
  }
  state.SetItemsProcessed(state.iterations() * state.range(0));
}
BENCHMARK(BM_ResectionFull)
    ->Arg(10)
    ->Arg(100)
    ->Arg(1000)
    ->Arg(10000)
    ->Unit(benchmark::kMillisecond);

// Refinement alone: the initial camera and pose are given (perturbed ground truth), so only
// the Ceres problem runs.
void BM_ResectionRefineOnly(benchmark::State& state) {
  const PointData data = ResectionData(static_cast<int>(state.range(0)));
  CameraModel initial = BenchCamera();
  initial.fx_px *= 1.02;
  initial.fy_px *= 0.99;
  initial.cx_px += 5.0;
  Rigid3d initial_pose = CameraLookingAtTable(2.0, 25.0);
  initial_pose.translation += Eigen::Vector3d(0.01, -0.02, 0.03);
  ResectionOptions options;
  options.initial_camera = initial;
  options.initial_camera_from_world = initial_pose;
  for (auto _ : state) {
    auto result = EstimateResection(data.points_in_table_m, data.observed_px, initial.width_px,
                                    initial.height_px, options);
    if (!result.ok()) {
      state.SkipWithError(result.status().ToString().c_str());
      break;
    }
    benchmark::DoNotOptimize(result->camera.fx_px);
  }
  state.SetItemsProcessed(state.iterations() * state.range(0));
}
BENCHMARK(BM_ResectionRefineOnly)
    ->Arg(10)
    ->Arg(100)
    ->Arg(1000)
    ->Arg(10000)
    ->Unit(benchmark::kMillisecond);

PointData PlaneData(int n, double outlier_ratio) {
  PointDataOptions options;
  options.num_points = n;
  options.noise_px = kNoise_px;
  options.z_spread_m = 0.0;
  options.outlier_ratio = outlier_ratio;
  options.seed = 2;
  return MakePointData(BenchCamera(), CameraLookingAtTable(2.0, 25.0), options);
}

void BM_HomographyDlt(benchmark::State& state) {
  const PointData data = PlaneData(static_cast<int>(state.range(0)), 0.0);
  const std::vector<Eigen::Vector2d> plane = XyOf(data.points_in_table_m);
  for (auto _ : state) {
    auto h = EstimateHomographyDlt(plane, data.observed_px);
    if (!h.ok()) {
      state.SkipWithError(h.status().ToString().c_str());
      break;
    }
    benchmark::DoNotOptimize(h->data());
  }
  state.SetItemsProcessed(state.iterations() * state.range(0));
}
BENCHMARK(BM_HomographyDlt)
    ->Arg(10)
    ->Arg(100)
    ->Arg(1000)
    ->Arg(10000)
    ->Unit(benchmark::kMicrosecond);

// RANSAC with 30% outliers, refinement on the inliers included.
void BM_HomographyRansac(benchmark::State& state) {
  const PointData data = PlaneData(static_cast<int>(state.range(0)), 0.3);
  const std::vector<Eigen::Vector2d> plane = XyOf(data.points_in_table_m);
  HomographyRansacOptions options;
  options.seed = 3;
  for (auto _ : state) {
    auto result = EstimateHomographyRansac(plane, data.observed_px, options);
    if (!result.ok()) {
      state.SkipWithError(result.status().ToString().c_str());
      break;
    }
    benchmark::DoNotOptimize(result->to_from_from.data());
  }
  state.SetItemsProcessed(state.iterations() * state.range(0));
}
BENCHMARK(BM_HomographyRansac)
    ->Arg(10)
    ->Arg(100)
    ->Arg(1000)
    ->Arg(10000)
    ->Unit(benchmark::kMillisecond);

// One point seen by range(0) cameras on a ring around the table, refinement on.
void BM_Triangulation(benchmark::State& state) {
  const int num_views = static_cast<int>(state.range(0));
  const CameraModel cam = BenchCamera();
  const Eigen::Vector3d x_in_table(0.05, -0.1, 0.12);
  std::vector<TriangulationView> views;
  std::mt19937_64 rng(4);
  std::normal_distribution<double> noise(0.0, kNoise_px);
  for (int i = 0; i < num_views; ++i) {
    const Rigid3d tilted = CameraLookingAtTable(2.0, 30.0);
    const Eigen::AngleAxisd about_z(2.0 * M_PI * i / num_views, Eigen::Vector3d::UnitZ());
    // camera_from_table = camera_from_rotated_table * rotated_table_from_table.
    const Rigid3d camera_from_table =
        tilted * Rigid3d(about_z.toRotationMatrix().transpose(), Eigen::Vector3d::Zero());
    const auto pixel = cam.Project(camera_from_table * x_in_table);
    views.push_back({cam, camera_from_table, *pixel + Eigen::Vector2d(noise(rng), noise(rng))});
  }
  for (auto _ : state) {
    auto result = TriangulatePoint(views);
    if (!result.ok()) {
      state.SkipWithError(result.status().ToString().c_str());
      break;
    }
    benchmark::DoNotOptimize(result->point_in_world.data());
  }
}
BENCHMARK(BM_Triangulation)->Arg(2)->Arg(3)->Arg(8)->Arg(32)->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace sandtable::bench

BENCHMARK_MAIN();
