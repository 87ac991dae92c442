// Sweeps of the camera model, GL projection, triangulation, plane fit, Umeyama and table
// frame. See numerics_sweep.cc and docs/numerics.md.
#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "common/base/units.h"
#include "common/camera/gl_projection.h"
#include "common/estimation/plane_fit.h"
#include "common/estimation/table_frame.h"
#include "common/estimation/triangulation.h"
#include "common/estimation/umeyama.h"
#include "tests/bench/sweep_csv.h"
#include "tests/bench/synthetic_scene.h"

namespace sandtable::bench {
namespace {

std::vector<uint64_t> Seeds(bool quick, int full) {
  std::vector<uint64_t> seeds;
  for (int i = 0; i < (quick ? 2 : full); ++i) seeds.push_back(2000 + i);
  return seeds;
}

double AngleBetween_deg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return RadToDeg(std::atan2(a.cross(b).norm(), a.dot(b)));
}

}  // namespace

// A wide 1280x800 camera (fx = 1000 px, corner at normalized radius 0.755); distortion grows
// along three families. Every 8th pixel plus the corners is unprojected and projected back.
void SweepUndistortion(const std::string& dir, bool quick) {
  CsvWriter csv(dir, "undistortion.csv",
                {"family", "k1", "k2", "k3", "pixels", "refused_pct", "first_refusal_radius_px",
                 "worst_round_trip_px", "wrong_rays", "time_ns_per_unproject", "status"});
  const int step_px = quick ? 32 : 8;
  struct Family {
    const char* name;
    double k2_per_k1, k3;
  };
  for (const Family& family : {Family{"k1_only", 0.0, 0.0}, Family{"k1_and_k2_negative", 0.5, 0.0},
                               Family{"k1_and_k3_positive", 0.0, 0.05}}) {
    for (double k1 = 0.0; k1 >= -0.801; k1 -= 0.05) {
      const BrownDistortion d{k1, family.k2_per_k1 * k1, 0.0, 0.0, k1 == 0.0 ? 0.0 : family.k3};
      const CameraModel cam(1280, 800, 1000.0, 1000.0, 639.5, 399.5, d);
      std::vector<Eigen::Vector2d> pixels;
      for (double v = -0.5; v <= 799.5; v += step_px) {
        for (double u = -0.5; u <= 1279.5; u += step_px) pixels.emplace_back(u, v);
      }
      for (const Eigen::Vector2d& c : {Eigen::Vector2d(1279.5, -0.5), Eigen::Vector2d(-0.5, 799.5),
                                       Eigen::Vector2d(1279.5, 799.5)}) {
        pixels.push_back(c);
      }
      int refused = 0, wrong = 0;
      double worst_px = 0.0, first_refusal_px = kNan;
      std::vector<Expected<Eigen::Vector3d>> rays;
      rays.reserve(pixels.size());
      const double ms = TimeMs([&] {
        for (const Eigen::Vector2d& p : pixels) rays.push_back(cam.Unproject(p));
      });
      for (size_t i = 0; i < pixels.size(); ++i) {
        const double radius_px = (pixels[i] - Eigen::Vector2d(cam.cx_px, cam.cy_px)).norm();
        if (!rays[i].ok()) {
          ++refused;
          if (!(first_refusal_px <= radius_px)) first_refusal_px = radius_px;
          continue;
        }
        const auto back = cam.Project(*rays[i]);
        // A wrong ray: accepted but not projecting back onto its pixel, or past the fold.
        if (!back.has_value() || (*back - pixels[i]).norm() > 1e-6) {
          ++wrong;
          continue;
        }
        worst_px = std::max(worst_px, (*back - pixels[i]).norm());
      }
      const std::string status = refused == 0 ? "ok" : "NOT_CONVERGED";
      csv.Row({family.name, d.k1, d.k2, d.k3, (long long)pixels.size(),
               100.0 * refused / pixels.size(), first_refusal_px, worst_px, (long long)wrong,
               1e6 * ms / pixels.size(), wrong > 0 ? std::string("WRONG_RAY") : status});
    }
  }
}

// The renderer's float chain (projection * view * vertex, divide, viewport) against
// CameraModel::Project in double, for scenes at several distances and far from the origin.
void SweepGlFloat(const std::string& dir, bool quick) {
  CsvWriter csv(dir, "gl_float.csv",
                {"routine", "distance_m", "offset_m", "vertices", "worst_px", "mean_px", "status"});
  const CameraModel cam = CameraModel::FromThrowRatio(1280, 800, 1.27, 0.35);
  const int vertices = quick ? 500 : 5000;
  auto run = [&](const char* routine, double distance_m, double offset_m) {
    // Camera distance_m from a scene centred at (offset, offset, 0), tilted 30 degrees.
    const Rigid3d camera_from_scene = CameraLookingAtTable(distance_m, 30.0);
    const Rigid3d scene_from_table(Eigen::Matrix3d::Identity(),
                                   -Eigen::Vector3d(offset_m, offset_m, 0.0));
    const Rigid3d camera_from_table = camera_from_scene * scene_from_table;
    const Expected<Eigen::Matrix4d> proj =
        GlProjectionFromCamera(cam, 0.05 * distance_m, 20.0 * distance_m);
    if (!proj.ok()) {
      csv.Row({routine, distance_m, offset_m, 0LL, kNan, kNan, StatusCell(proj.status())});
      return;
    }
    const Eigen::Matrix4f clip_from_table_f =
        (*proj * GlEyeFromTable(camera_from_table)).cast<float>();
    std::mt19937_64 rng(7);
    std::uniform_real_distribution<double> unit(0.0, 1.0);
    const Rigid3d table_from_camera = camera_from_table.Inverse();
    double worst_px = 0.0, sum_px = 0.0;
    for (int i = 0; i < vertices; ++i) {
      const Eigen::Vector2d pixel(unit(rng) * (cam.width_px - 1), unit(rng) * (cam.height_px - 1));
      const Eigen::Vector3d x_in_camera =
          *cam.Unproject(pixel) * distance_m * (0.8 + 0.4 * unit(rng));
      const Eigen::Vector3d x_in_table = table_from_camera * x_in_camera;
      const Eigen::Vector2d expected = *cam.Project(camera_from_table * x_in_table);
      const Eigen::Vector4f clip = clip_from_table_f * x_in_table.cast<float>().homogeneous();
      const Eigen::Vector2f ndc = clip.head<2>() / clip.w();
      const Eigen::Vector2d gl((ndc.x() + 1.0f) * 0.5f * cam.width_px - 0.5,
                               cam.height_px - (ndc.y() + 1.0f) * 0.5f * cam.height_px - 0.5);
      const double e = (gl - expected).norm();
      worst_px = std::max(worst_px, e);
      sum_px += e;
    }
    csv.Row(
        {routine, distance_m, offset_m, (long long)vertices, worst_px, sum_px / vertices, "ok"});
  };
  for (double distance_m : {0.5, 1.0, 2.0, 3.0, 5.0, 10.0, 20.0, 50.0, 100.0}) {
    run("distance", distance_m, 0.0);
  }
  for (double offset_m : {0.0, 1.0, 10.0, 100.0, 1000.0, 10000.0}) run("offset", 3.0, offset_m);
}

// Two cameras 2 m from the table centre, tilted 45 degrees from vertical, turned apart by
// yaw_deg about the vertical axis (180: opposite sides, rays 90 degrees apart). The true angle
// between their rays at the point is written as ray_angle_deg.
void SweepTriangulation(const std::string& dir, bool quick) {
  CsvWriter csv(dir, "triangulation.csv",
                {"routine", "yaw_deg", "ray_angle_deg", "noise_px", "seed", "time_us", "error_mm",
                 "rms_px", "status"});
  const CameraModel cam = BenchCamera();
  auto run = [&](const char* routine, double yaw_apart_deg, double noise_px, uint64_t seed) {
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> noise(0.0, noise_px);
    std::uniform_real_distribution<double> jitter(-0.1, 0.1);
    const Eigen::Vector3d x_in_table(jitter(rng), jitter(rng), 0.1 + jitter(rng));
    std::vector<TriangulationView> views;
    std::vector<Eigen::Vector3d> rays_in_table;  // camera centre -> point
    for (double yaw_deg : {-0.5 * yaw_apart_deg, 0.5 * yaw_apart_deg}) {
      const Eigen::Matrix3d about_z =
          Eigen::AngleAxisd(DegToRad(yaw_deg), Eigen::Vector3d::UnitZ()).toRotationMatrix();
      // camera_from_table = camera_from_turned * turned_from_table (turned = table rotated).
      const Rigid3d camera_from_table =
          CameraLookingAtTable(2.0, 45.0) * Rigid3d(about_z.transpose(), Eigen::Vector3d::Zero());
      const auto pixel = cam.Project(camera_from_table * x_in_table);
      rays_in_table.push_back(x_in_table - camera_from_table.Inverse().translation);
      views.push_back({cam, camera_from_table, *pixel + Eigen::Vector2d(noise(rng), noise(rng))});
    }
    Expected<TriangulationReport> result = InternalError("not run");
    const double ms = TimeMs([&] { result = TriangulatePoint(views); });
    csv.Row({routine, yaw_apart_deg, AngleBetween_deg(rays_in_table[0], rays_in_table[1]), noise_px,
             (long long)seed, 1000.0 * ms,
             result.ok() ? MToMm((result->point_in_world - x_in_table).norm()) : kNan,
             result.ok() ? result->rms_px : kNan, StatusCell(result.status())});
  };
  for (double yaw_deg :
       {0.0, 0.5, 1.0, 1.5, 2.0, 3.0, 5.0, 10.0, 20.0, 40.0, 60.0, 90.0, 120.0, 180.0}) {
    for (uint64_t seed : Seeds(quick, 10)) run("angle", yaw_deg, 0.5, seed);
  }
  for (double noise_px : {0.0, 0.1, 0.5, 1.0, 2.0, 5.0}) {
    for (uint64_t seed : Seeds(quick, 10)) run("noise", 40.0, noise_px, seed);
  }
}

// Least-squares plane of n points on a 1.2 m table with Gaussian height noise.
void SweepPlaneFitNoise(const std::string& dir, bool quick) {
  CsvWriter csv(dir, "plane_fit_noise.csv",
                {"routine", "n", "noise_mm", "seed", "time_ms", "normal_error_deg",
                 "height_error_mm", "status"});
  constexpr double kHalf_m = 0.6;
  for (int n : {10, 100, 2000}) {
    for (double noise_mm : {0.0, 0.1, 0.5, 1.0, 2.0, 5.0, 10.0}) {
      for (uint64_t seed : Seeds(quick, 5)) {
        std::mt19937_64 rng(seed);
        std::uniform_real_distribution<double> xy(-kHalf_m, kHalf_m);
        std::normal_distribution<double> noise(0.0, MmToM(noise_mm));
        std::vector<Eigen::Vector3d> points;
        for (int i = 0; i < n; ++i) points.emplace_back(xy(rng), xy(rng), noise(rng));
        Expected<Plane> plane = InternalError("not run");
        const double ms = TimeMs([&] { plane = FitPlaneLeastSquares(points); });
        double normal_deg = kNan, height_mm = kNan;
        if (plane.ok()) {
          const Plane up = plane->OrientedToward(Eigen::Vector3d(0, 0, 10));
          normal_deg = RadToDeg(std::acos(std::min(1.0, up.normal.z())));
          height_mm = 0.0;
          for (double sx : {-1.0, 1.0}) {
            for (double sy : {-1.0, 1.0}) {
              height_mm = std::max(height_mm, MToMm(std::abs(up.SignedDistance_m(Eigen::Vector3d(
                                                  sx * kHalf_m, sy * kHalf_m, 0)))));
            }
          }
        }
        csv.Row({"plane_least_squares", (long long)n, noise_mm, (long long)seed, ms, normal_deg,
                 height_mm, StatusCell(plane.status())});
      }
    }
  }
}

// Tracker calibration: 16 points in a 1.2 m box with noise; and points along a 1 m line with a
// shrinking perpendicular spread (the rotation about the line becomes undetermined).
void SweepUmeyama(const std::string& dir, bool quick) {
  CsvWriter csv(dir, "umeyama.csv",
                {"routine", "noise_mm", "spread_mm", "seed", "time_us", "rms_mm", "gt_error_mm",
                 "rotation_error_deg", "status"});
  const Rigid3d target_from_source(
      Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix(),
      Eigen::Vector3d(0.3, -1.2, 0.8));
  auto run = [&](const char* routine, double noise_mm, double spread_mm, uint64_t seed) {
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> box(-0.6, 0.6), along(-0.5, 0.5);
    std::normal_distribution<double> noise(0.0, MmToM(noise_mm)), perp(0.0, MmToM(spread_mm));
    std::vector<Eigen::Vector3d> source, target;
    for (int i = 0; i < 16; ++i) {
      const Eigen::Vector3d x = spread_mm < 0.0 ? Eigen::Vector3d(box(rng), box(rng), box(rng))
                                                : Eigen::Vector3d(along(rng), perp(rng), perp(rng));
      source.push_back(x);
      target.push_back(target_from_source * x +
                       Eigen::Vector3d(noise(rng), noise(rng), noise(rng)));
    }
    Expected<RigidFitReport> fit = InternalError("not run");
    const double ms = TimeMs([&] { fit = FitRigidUmeyama(source, target); });
    double gt_mm = kNan, rot_deg = kNan;
    if (fit.ok()) {
      gt_mm = 0.0;  // worst error over the corners of the 1.2 m box
      for (double sx : {-0.6, 0.6}) {
        for (double sy : {-0.6, 0.6}) {
          for (double sz : {-0.6, 0.6}) {
            const Eigen::Vector3d c(sx, sy, sz);
            gt_mm = std::max(gt_mm,
                             MToMm((fit->target_from_source * c - target_from_source * c).norm()));
          }
        }
      }
      rot_deg = RadToDeg(RotationAngleBetween_rad(fit->target_from_source, target_from_source));
    }
    csv.Row({routine, noise_mm, spread_mm < 0.0 ? kNan : spread_mm, (long long)seed, 1000.0 * ms,
             fit.ok() ? MToMm(fit->rms_m) : kNan, gt_mm, rot_deg, StatusCell(fit.status())});
  };
  for (double noise_mm : {0.0, 0.1, 0.5, 1.0, 2.0, 5.0, 10.0}) {
    for (uint64_t seed : Seeds(quick, 10)) run("box_noise", noise_mm, -1.0, seed);
  }
  for (double spread_mm : {0.0, 1e-9, 1e-6, 1e-3, 0.01, 0.1, 1.0, 10.0, 100.0}) {
    for (uint64_t seed : Seeds(quick, 10)) run("line_spread", 0.1, spread_mm, seed);
  }
}

// A rectangular table a x b (a = 1.2 m) sampled by 400 points with 1 mm noise in x, y; as b/a
// approaches 1 the longer side, hence +x, is decided by noise.
void SweepTableFrame(const std::string& dir, bool quick) {
  CsvWriter csv(dir, "table_frame.csv",
                {"routine", "aspect", "noise_mm", "seed", "time_us", "x_axis_error_deg", "flipped",
                 "status"});
  constexpr double kLong_m = 1.2;
  const Rigid3d source_from_true(
      Eigen::AngleAxisd(0.4, Eigen::Vector3d(0.2, -1.0, 0.3).normalized()).toRotationMatrix(),
      Eigen::Vector3d(0.1, 0.2, 2.0));
  for (double aspect : {0.5, 0.8, 0.9, 0.95, 0.98, 0.99, 0.995, 0.999, 1.0}) {
    for (uint64_t seed : Seeds(quick, 10)) {
      std::mt19937_64 rng(seed);
      std::uniform_real_distribution<double> x(0.0, kLong_m), y(0.0, aspect * kLong_m);
      std::normal_distribution<double> noise(0.0, 0.001);
      std::vector<Eigen::Vector3d> points;
      for (int i = 0; i < 400; ++i) {
        points.push_back(source_from_true *
                         Eigen::Vector3d(x(rng) + noise(rng), y(rng) + noise(rng), 0.0));
      }
      // The four corners, so the hull is the rectangle (a marked table outline).
      for (double cx : {0.0, kLong_m}) {
        for (double cy : {0.0, aspect * kLong_m}) {
          points.push_back(source_from_true *
                           Eigen::Vector3d(cx + noise(rng), cy + noise(rng), 0.0));
        }
      }
      Plane plane_in_source;
      plane_in_source.normal = source_from_true.rotation * Eigen::Vector3d::UnitZ();
      plane_in_source.offset_m = -plane_in_source.normal.dot(source_from_true.translation);
      const Eigen::Vector3d up_in_source = source_from_true * Eigen::Vector3d(0.6, 0.6, 2.0);
      Expected<TableFrameReport> frame = InternalError("not run");
      const double ms =
          TimeMs([&] { frame = BuildTableFrame(plane_in_source, points, up_in_source); });
      double error_deg = kNan;
      long long flipped = -1;
      if (frame.ok()) {
        const Eigen::Vector3d x_in_source =
            frame->table_from_source.Inverse().rotation * Eigen::Vector3d::UnitX();
        const Eigen::Vector3d true_x = source_from_true.rotation * Eigen::Vector3d::UnitX();
        const double a = AngleBetween_deg(x_in_source, true_x);
        error_deg = std::min(a, 180.0 - a);  // the sign of +x is the rule's choice
        flipped = error_deg > 45.0 ? 1 : 0;
      }
      csv.Row({"table_frame", aspect, 1.0, (long long)seed, 1000.0 * ms, error_deg, flipped,
               StatusCell(frame.status())});
    }
  }
}

}  // namespace sandtable::bench
