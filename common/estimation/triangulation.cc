#include "common/estimation/triangulation.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <vector>

#include <ceres/jet.h>
#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

#include "common/base/units.h"

namespace sandtable {
namespace {

// One view prepared for the refinement: rotation matrix, translation and intrinsics.
struct PreparedView {
  Eigen::Matrix3d camera_r_world;
  Eigen::Vector3d camera_t_world;
  const CameraModel* camera;
  Eigen::Vector2d observed_px;
};

// Depth (camera z) of a world point.
double Depth(const PreparedView& view, const Eigen::Vector3d& point_in_world) {
  return view.camera_r_world.row(2).dot(point_in_world) + view.camera_t_world.z();
}

// Reprojection residual (projected - observed, px) of a world point; templated so the
// refinement gets its exact Jacobian from ceres::Jet. Assumes positive depth.
template <typename T>
void Residual(const PreparedView& view, const T* point_in_world, T* residual_px) {
  T x[3];
  for (int r = 0; r < 3; ++r) {
    x[r] = T(view.camera_r_world(r, 0)) * point_in_world[0] +
           T(view.camera_r_world(r, 1)) * point_in_world[1] +
           T(view.camera_r_world(r, 2)) * point_in_world[2] + T(view.camera_t_world[r]);
  }
  const T xn = x[0] / x[2];
  const T yn = x[1] / x[2];
  const std::array<double, 5> k = view.camera->distortion.ToArray();
  const T kt[5] = {T(k[0]), T(k[1]), T(k[2]), T(k[3]), T(k[4])};
  T xd, yd;
  ApplyBrownDistortion(kt, xn, yn, &xd, &yd);
  residual_px[0] = T(view.camera->fx_px) * xd + T(view.camera->cx_px) - T(view.observed_px.x());
  residual_px[1] = T(view.camera->fy_px) * yd + T(view.camera->cy_px) - T(view.observed_px.y());
}

// Sum of squared residuals (px^2); +inf when the point is at or behind a camera.
double Cost(std::span<const PreparedView> views, const Eigen::Vector3d& point) {
  double cost = 0.0;
  for (const PreparedView& view : views) {
    if (!(Depth(view, point) > 0.0)) return std::numeric_limits<double>::infinity();
    double r[2];
    Residual(view, point.data(), r);
    cost += r[0] * r[0] + r[1] * r[1];
  }
  return cost;
}

// Levenberg-Marquardt on the 3 coordinates (Marquardt's diagonal scaling). Returns the number
// of iterations; *point is only ever replaced by a point of lower cost and positive depths.
int Refine(std::span<const PreparedView> views, const TriangulationOptions& options, double scale,
           Eigen::Vector3d* point, double* cost) {
  using Jet = ceres::Jet<double, 3>;
  double lambda = 1e-3;
  int iteration = 0;
  for (; iteration < options.max_iterations; ++iteration) {
    Eigen::Matrix3d jtj = Eigen::Matrix3d::Zero();
    Eigen::Vector3d jtr = Eigen::Vector3d::Zero();
    const Jet x[3] = {Jet((*point)[0], 0), Jet((*point)[1], 1), Jet((*point)[2], 2)};
    for (const PreparedView& view : views) {
      Jet r[2];
      Residual(view, x, r);
      for (const Jet& ri : r) {
        jtj += ri.v * ri.v.transpose();
        jtr += ri.v * ri.a;
      }
    }
    bool stepped = false;
    // Raise lambda until a step lowers the cost (at most 10 tries per iteration).
    for (int attempt = 0; attempt < 10 && !stepped; ++attempt) {
      Eigen::Matrix3d damped = jtj;
      damped.diagonal() += lambda * jtj.diagonal().cwiseMax(1e-12 * jtj.diagonal().maxCoeff());
      const Eigen::Vector3d step = damped.ldlt().solve(-jtr);
      if (!step.allFinite()) break;
      const Eigen::Vector3d candidate = *point + step;
      const double candidate_cost = Cost(views, candidate);
      if (candidate_cost < *cost) {
        *point = candidate;
        *cost = candidate_cost;
        lambda = std::max(lambda / 10.0, 1e-12);
        stepped = true;
        if (step.norm() < options.relative_step_tolerance * scale) return iteration + 1;
      } else {
        lambda *= 10.0;
      }
    }
    if (!stepped) return iteration + 1;  // no step lowers the cost: at a minimum
  }
  return iteration;
}

}  // namespace

Status TriangulationOptions::Check() const {
  if (!(min_angle_deg >= 0.0 && min_angle_deg < 180.0)) {
    return InvalidArgumentError("TriangulationOptions: min_angle_deg must be in [0, 180)");
  }
  if (max_iterations < 1) {
    return InvalidArgumentError("TriangulationOptions: max_iterations must be >= 1");
  }
  if (!(relative_step_tolerance > 0.0) || !std::isfinite(relative_step_tolerance)) {
    return InvalidArgumentError(
        "TriangulationOptions: relative_step_tolerance must be finite and > 0");
  }
  return undistort.Check();
}

Expected<WorldRay> RayThroughPixel(const CameraModel& camera, const Rigid3d& camera_from_world,
                                   const Eigen::Vector2d& pixel, const UndistortOptions& options) {
  if (!camera_from_world.AllFinite()) {
    return InvalidArgumentError("ray through pixel: camera_from_world is not finite");
  }
  Expected<Eigen::Vector3d> ray_in_camera = camera.Unproject(pixel, options);
  if (!ray_in_camera.ok()) return ray_in_camera.status();
  const Rigid3d world_from_camera = camera_from_world.Inverse();
  WorldRay ray;
  ray.origin_in_world = world_from_camera.translation;
  ray.direction_in_world = (world_from_camera.rotation * *ray_in_camera).normalized();
  return ray;
}

double MaxRayAngle_deg(std::span<const WorldRay> rays) {
  double max_rad = 0.0;
  for (size_t i = 0; i < rays.size(); ++i) {
    for (size_t j = i + 1; j < rays.size(); ++j) {
      const Eigen::Vector3d& a = rays[i].direction_in_world;
      const Eigen::Vector3d& b = rays[j].direction_in_world;
      // atan2(|a x b|, a . b) keeps full precision at small angles, where acos does not.
      max_rad = std::max(max_rad, std::atan2(a.cross(b).norm(), a.dot(b)));
    }
  }
  return RadToDeg(max_rad);
}

Expected<Eigen::Vector3d> MidpointOfRays(std::span<const WorldRay> rays) {
  if (rays.size() < 2) {
    std::ostringstream m;
    m << "midpoint: " << rays.size() << " rays given, at least 2 needed";
    return DegenerateError(m.str());
  }
  Eigen::Vector3d mean_origin = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < rays.size(); ++i) {
    const WorldRay& ray = rays[i];
    if (!ray.origin_in_world.allFinite() || !ray.direction_in_world.allFinite() ||
        !(ray.direction_in_world.norm() > 0.0)) {
      std::ostringstream m;
      m << "midpoint: ray " << i << " has a non-finite origin or a zero/non-finite direction";
      return InvalidArgumentError(m.str());
    }
    mean_origin += ray.origin_in_world;
  }
  mean_origin /= static_cast<double>(rays.size());
  // Minimise sum_i |(I - d_i d_i^T)(x - c_i)|^2 (squared distance of x to ray i, unit d_i):
  //   sum_i (I - d_i d_i^T) x = sum_i (I - d_i d_i^T) c_i.
  // Origins are taken relative to their mean so that far-away coordinates keep precision.
  // For two rays at angle theta the eigenvalues of the matrix are 1 and 1 +- cos(theta): its
  // conditioning degrades as theta^2 / 2, hence the check below.
  Eigen::Matrix3d a = Eigen::Matrix3d::Zero();
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
  for (const WorldRay& ray : rays) {
    const Eigen::Vector3d d = ray.direction_in_world.normalized();
    const Eigen::Matrix3d p = Eigen::Matrix3d::Identity() - d * d.transpose();
    a += p;
    b += p * (ray.origin_in_world - mean_origin);
  }
  const Eigen::Vector3d eigenvalues =
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(a, Eigen::EigenvaluesOnly).eigenvalues();
  constexpr double kMinRelativeEigenvalue = 1e-14;  // about theta = 1.4e-7 rad for two rays
  if (!(eigenvalues[0] > kMinRelativeEigenvalue * eigenvalues[2])) {
    std::ostringstream m;
    m << "midpoint: the rays are parallel (normal-matrix eigenvalues " << eigenvalues[0] << " of "
      << eigenvalues[2] << "); they do not meet";
    return DegenerateError(m.str());
  }
  return Eigen::Vector3d(a.ldlt().solve(b) + mean_origin);
}

Expected<TriangulationReport> TriangulatePoint(std::span<const TriangulationView> views,
                                               const TriangulationOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  for (size_t i = 0; i < views.size(); ++i) {
    const TriangulationView& view = views[i];
    if (Status s = view.camera.Check(); !s.ok()) {
      return s.WithContext("triangulation: view " + std::to_string(i));
    }
    if (!view.camera_from_world.AllFinite() || !view.observed_px.allFinite()) {
      std::ostringstream m;
      m << "triangulation: view " << i << " has a non-finite pose or pixel ("
        << view.observed_px.transpose() << ")";
      return InvalidArgumentError(m.str());
    }
  }
  if (views.size() < 2) {
    std::ostringstream m;
    m << "triangulation: " << views.size() << " views given, at least 2 needed";
    return DegenerateError(m.str());
  }

  std::vector<WorldRay> rays;
  rays.reserve(views.size());
  for (size_t i = 0; i < views.size(); ++i) {
    Expected<WorldRay> ray = RayThroughPixel(views[i].camera, views[i].camera_from_world,
                                             views[i].observed_px, options.undistort);
    if (!ray.ok()) return ray.status().WithContext("triangulation: view " + std::to_string(i));
    rays.push_back(*ray);
  }

  TriangulationReport report;
  report.num_views = static_cast<int>(views.size());
  report.angle_deg = MaxRayAngle_deg(rays);
  if (!(report.angle_deg >= options.min_angle_deg)) {
    std::ostringstream m;
    m << "triangulation: the rays meet at " << report.angle_deg << " deg, below the "
      << options.min_angle_deg
      << " deg minimum; the depth along them is not determined (wider baseline needed)";
    return DegenerateError(m.str());
  }
  Expected<Eigen::Vector3d> midpoint = MidpointOfRays(rays);
  if (!midpoint.ok()) return midpoint.status().WithContext("triangulation");

  std::vector<PreparedView> prepared(views.size());
  double nearest_centre = std::numeric_limits<double>::infinity();
  for (size_t i = 0; i < views.size(); ++i) {
    prepared[i] = {views[i].camera_from_world.RotationMatrix(),
                   views[i].camera_from_world.translation, &views[i].camera, views[i].observed_px};
    nearest_centre = std::min(nearest_centre, (*midpoint - rays[i].origin_in_world).norm());
    const double depth = Depth(prepared[i], *midpoint);
    if (!(depth > 0.0)) {
      std::ostringstream m;
      m << "triangulation: the point is behind camera " << i << " (depth " << depth
        << "); the rays diverge: check the correspondence";
      return OutOfRangeError(m.str());
    }
  }

  Eigen::Vector3d point = *midpoint;
  double cost = Cost(prepared, point);
  report.midpoint_rms_px = std::sqrt(cost / static_cast<double>(views.size()));
  if (options.refine) {
    const double midpoint_cost = cost;
    report.iterations = Refine(prepared, options, nearest_centre, &point, &cost);
    report.refined = cost < midpoint_cost;
  }
  report.point_in_world = point;
  report.rms_px = std::sqrt(cost / static_cast<double>(views.size()));
  report.min_depth_m = std::numeric_limits<double>::infinity();
  for (const PreparedView& view : prepared) {
    report.min_depth_m = std::min(report.min_depth_m, Depth(view, point));
    double r[2];
    Residual(view, point.data(), r);
    report.max_px = std::max(report.max_px, std::hypot(r[0], r[1]));
  }
  if (!point.allFinite() || !std::isfinite(report.rms_px)) {
    return InternalError("triangulation: the estimate is not finite (a bug: please report)");
  }
  return report;
}

}  // namespace sandtable
