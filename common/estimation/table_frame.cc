#include "common/estimation/table_frame.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <sstream>
#include <vector>

#include "common/base/units.h"

namespace sandtable {
namespace {

using Vec2 = Eigen::Vector2d;

double Cross(const Vec2& o, const Vec2& a, const Vec2& b) {
  return (a - o).x() * (b - o).y() - (a - o).y() * (b - o).x();
}

// Andrew's monotone chain: the hull counter-clockwise, without collinear vertices. The input
// is sorted first, so the hull does not depend on the order of the points.
std::vector<Vec2> ConvexHull(std::vector<Vec2> points) {
  std::sort(points.begin(), points.end(), [](const Vec2& a, const Vec2& b) {
    return a.x() < b.x() || (a.x() == b.x() && a.y() < b.y());
  });
  const int n = static_cast<int>(points.size());
  std::vector<Vec2> hull(2 * n);
  int k = 0;
  for (int i = 0; i < n; ++i) {  // lower hull
    while (k >= 2 && Cross(hull[k - 2], hull[k - 1], points[i]) <= 0.0) --k;
    hull[k++] = points[i];
  }
  for (int i = n - 2, lower = k + 1; i >= 0; --i) {  // upper hull
    while (k >= lower && Cross(hull[k - 2], hull[k - 1], points[i]) <= 0.0) --k;
    hull[k++] = points[i];
  }
  hull.resize(std::max(k - 1, 0));  // the last point repeats the first
  return hull;
}

struct Candidate {
  Vec2 x_axis;       // unit, in the plane basis (u, v)
  double angle_rad;  // signed angle from the reference direction u, in (-pi, pi]
};

}  // namespace

Status TableFrameOptions::Check() const {
  if (!(tie_relative_tolerance >= 0.0 && tie_relative_tolerance < 1.0)) {
    return InvalidArgumentError("TableFrameOptions: tie_relative_tolerance must be in [0, 1)");
  }
  if (!(min_hint_height_m > 0.0) || !std::isfinite(min_hint_height_m)) {
    return InvalidArgumentError("TableFrameOptions: min_hint_height_m must be finite and > 0");
  }
  return OkStatus();
}

Expected<TableFrameReport> BuildTableFrame(const Plane& plane_in_source,
                                           std::span<const Eigen::Vector3d> points_in_source_m,
                                           const Eigen::Vector3d& up_hint_in_source_m,
                                           const TableFrameOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  if (!plane_in_source.AllFinite() || !up_hint_in_source_m.allFinite()) {
    return InvalidArgumentError("table frame: the plane or the up hint is not finite");
  }
  if (std::abs(plane_in_source.normal.norm() - 1.0) > 1e-6) {
    std::ostringstream m;
    m << "table frame: the plane normal has length " << plane_in_source.normal.norm()
      << ", expected 1";
    return InvalidArgumentError(m.str());
  }
  for (size_t i = 0; i < points_in_source_m.size(); ++i) {
    if (!points_in_source_m[i].allFinite()) {
      std::ostringstream m;
      m << "table frame: point " << i << " is not finite";
      return InvalidArgumentError(m.str());
    }
  }
  const int n = static_cast<int>(points_in_source_m.size());
  if (n < 3) {
    std::ostringstream m;
    m << "table frame: " << n << " points given, at least 3 needed";
    return DegenerateError(m.str());
  }
  const double hint_height_m = plane_in_source.SignedDistance_m(up_hint_in_source_m);
  if (std::abs(hint_height_m) < options.min_hint_height_m) {
    std::ostringstream m;
    m << "table frame: the up hint is " << hint_height_m << " m from the plane (minimum "
      << options.min_hint_height_m << " m); give a point above the table, e.g. a camera centre";
    return DegenerateError(m.str());
  }
  const Plane plane = plane_in_source.OrientedToward(up_hint_in_source_m);
  const Eigen::Vector3d z = plane.normal;

  // In-plane basis (u, v, z right-handed) with u the reference direction of the tie rule:
  // the source +x projected on the plane, or +y when +x is within 1 degree of the normal.
  Eigen::Vector3d reference = Eigen::Vector3d::UnitX() - z.x() * z;
  if (reference.norm() < std::sin(DegToRad(1.0))) reference = Eigen::Vector3d::UnitY() - z.y() * z;
  const Eigen::Vector3d u = reference.normalized();
  const Eigen::Vector3d v = z.cross(u);

  // 2D coordinates relative to an anchor that does not depend on the point order (the
  // lexicographically smallest point, projected), so that far-away coordinates keep their
  // precision and a permutation of the input gives bit-identical coordinates.
  const Eigen::Vector3d anchor_point = *std::min_element(
      points_in_source_m.begin(), points_in_source_m.end(),
      [](const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
        return std::lexicographical_compare(a.data(), a.data() + 3, b.data(), b.data() + 3);
      });
  const Eigen::Vector3d anchor = plane.Project(anchor_point);
  std::vector<Vec2> planar(n);
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d d = points_in_source_m[i] - anchor;
    planar[i] = Vec2(u.dot(d), v.dot(d));
  }
  const std::vector<Vec2> hull = ConvexHull(planar);
  const int h = static_cast<int>(hull.size());
  double spread_sq = 0.0;  // squared largest distance from the first point
  for (const Vec2& p : planar) spread_sq = std::max(spread_sq, (p - planar[0]).squaredNorm());
  double area = 0.0;
  for (int i = 0; i < h; ++i) area += Cross(Vec2::Zero(), hull[i], hull[(i + 1) % h]);
  area *= 0.5;
  if (h < 3 || !(area > kCollinearRelativeTolerance * spread_sq)) {
    std::ostringstream m;
    m << "table frame: the " << n << " points projected on the plane are "
      << (spread_sq > 0.0 ? "collinear" : "coincident") << " (hull area " << area << " m^2, spread "
      << std::sqrt(spread_sq) << " m); give points spread over the table";
    return DegenerateError(m.str());
  }

  // Rotating calipers: for each hull edge (direction e, inward normal w = rot90(e)), the
  // bounding rectangle with a side on that edge. Three pointers (max along e, min along e,
  // max along w) only move forward as the edges turn counter-clockwise, so this is O(h).
  struct Rectangle {
    Vec2 e;
    double length_e, length_w, area;
  };
  std::vector<Rectangle> rectangles(h);
  auto next = [h](int i) { return (i + 1) % h; };
  int i_max = 0, i_min = 0, i_far = 0;
  for (int i = 0; i < h; ++i) {
    const Vec2 e = (hull[next(i)] - hull[i]).normalized();
    const Vec2 w(-e.y(), e.x());
    if (i == 0) {
      for (int j = 1; j < h; ++j) {
        if (hull[j].dot(e) > hull[i_max].dot(e)) i_max = j;
        if (hull[j].dot(e) < hull[i_min].dot(e)) i_min = j;
        if (hull[j].dot(w) > hull[i_far].dot(w)) i_far = j;
      }
    } else {
      // Each projection is unimodal around a convex polygon; bounded loops as a guard.
      for (int s = 0; s < h && hull[next(i_max)].dot(e) > hull[i_max].dot(e); ++s)
        i_max = next(i_max);
      for (int s = 0; s < h && hull[next(i_min)].dot(e) < hull[i_min].dot(e); ++s)
        i_min = next(i_min);
      for (int s = 0; s < h && hull[next(i_far)].dot(w) > hull[i_far].dot(w); ++s)
        i_far = next(i_far);
    }
    const double length_e = hull[i_max].dot(e) - hull[i_min].dot(e);
    const double length_w = hull[i_far].dot(w) - hull[i].dot(w);
    rectangles[i] = {e, length_e, length_w, length_e * length_w};
  }
  double min_area = rectangles[0].area;
  for (const Rectangle& r : rectangles) min_area = std::min(min_area, r.area);

  // Candidate +x directions: along the longer side of every (tied) minimum rectangle, both
  // senses; both sides when their lengths tie.
  const double tol = options.tie_relative_tolerance;
  std::vector<Candidate> candidates;
  for (const Rectangle& r : rectangles) {
    if (r.area > min_area * (1.0 + tol)) continue;
    const Vec2 w(-r.e.y(), r.e.x());
    std::vector<Vec2> axes;
    if (r.length_e >= r.length_w * (1.0 - tol)) axes.push_back(r.e);
    if (r.length_w >= r.length_e * (1.0 - tol)) axes.push_back(w);
    for (const Vec2& a : axes) {
      for (const Vec2& x_axis : {a, Vec2(-a)}) {
        candidates.push_back({x_axis, std::atan2(x_axis.y(), x_axis.x())});
      }
    }
  }
  // Smallest |angle| to the reference; equal (within 1e-12 rad) ones: the more negative angle.
  constexpr double kAngleTie_rad = 1e-12;
  const Candidate best = *std::min_element(
      candidates.begin(), candidates.end(), [&](const Candidate& a, const Candidate& b) {
        const double da = std::abs(a.angle_rad), db = std::abs(b.angle_rad);
        if (std::abs(da - db) > kAngleTie_rad) return da < db;
        return a.angle_rad < b.angle_rad;
      });

  const Vec2 x2 = best.x_axis;
  const Vec2 y2(-x2.y(), x2.x());
  double min_x = hull[0].dot(x2), max_x = min_x, min_y = hull[0].dot(y2), max_y = min_y;
  for (const Vec2& p : hull) {
    min_x = std::min(min_x, p.dot(x2));
    max_x = std::max(max_x, p.dot(x2));
    min_y = std::min(min_y, p.dot(y2));
    max_y = std::max(max_y, p.dot(y2));
  }
  const Eigen::Vector3d x_axis = x2.x() * u + x2.y() * v;
  const Eigen::Vector3d y_axis = z.cross(x_axis);
  const Vec2 origin2 = min_x * x2 + min_y * y2;
  const Eigen::Vector3d origin_in_source = anchor + origin2.x() * u + origin2.y() * v;
  Eigen::Matrix3d table_r_source;
  table_r_source.row(0) = x_axis.transpose();
  table_r_source.row(1) = y_axis.transpose();
  table_r_source.row(2) = z.transpose();

  TableFrameReport report;
  report.table_from_source = Rigid3d(table_r_source, -(table_r_source * origin_in_source));
  report.extent_x_m = max_x - min_x;
  report.extent_y_m = max_y - min_y;
  report.num_points = n;
  report.num_hull_vertices = h;
  for (const Eigen::Vector3d& p : points_in_source_m) {
    report.max_abs_height_m =
        std::max(report.max_abs_height_m, std::abs(z.dot(p - origin_in_source)));
  }
  return report;
}

}  // namespace sandtable
