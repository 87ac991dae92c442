// Construction of the table frame from a fitted table plane (TR09-017: the plane normal
// becomes z, and the points on the plane are placed in the positive x, y quadrant).
//
// Input: the table plane and points on it (e.g. the triangulated table surface, the plane
// fit's inliers), both in a source frame (e.g. the first camera's), metres; and an "up hint",
// a point known to be above the table in the source frame (a camera centre).
// Output: table_from_source (Rigid3d, x_in_table = R x_in_source + t), such that
//   - the plane becomes z = 0 and the up hint has z > 0;
//   - the origin and the x axis follow this deterministic rule:
//     1. Project the points onto the plane; take their 2D convex hull.
//     2. Take the minimum-area bounding rectangle of the hull (rotating calipers: one side of
//        the optimal rectangle lies along a hull edge).
//     3. +x runs along the rectangle's longer side; +y = z x x (right-handed); the origin is
//        the rectangle corner from which every point has x >= 0 and y >= 0. So the points lie
//        in [0, extent_x_m] x [0, extent_y_m] with extent_x_m >= extent_y_m.
//     4. Ties: rectangles whose areas agree within options.tie_relative_tolerance, and sides
//        whose lengths agree within it, give several candidate +x directions (at least two:
//        +x and -x along the longer side). The candidate chosen is the one at the smallest
//        angle to the reference direction: the source frame's +x axis projected onto the plane
//        (its +y axis if +x is within 1 degree of the normal). Candidates at equal angles are
//        broken by the smaller atan2 angle measured from the reference toward +y.
//   The rule depends only on the set of points, not on their order.
//   Near-ties are inherently unstable: noise that flips which side is longer, or which hull
//   edge gives the smallest rectangle, flips the frame by 90 or 180 degrees about z. Mark the
//   table (a corner, an asymmetric outline) if the frame must survive re-calibration.
//
// Failure (never aborts): INVALID_ARGUMENT for non-finite input, a plane normal that is not
// unit length (|1 - |n|| > 1e-6), or options out of range; DEGENERATE for fewer than 3 points,
// points whose projections are collinear or coincident (hull area below
// kCollinearRelativeTolerance times the squared spread of the points), or an up hint within
// options.min_hint_height_m of the plane.
// Cost: O(N log N) for the hull, O(H) for the calipers (H hull vertices).
#pragma once

#include <span>

#include <Eigen/Core>

#include "common/base/status.h"
#include "common/estimation/plane_fit.h"
#include "common/geometry/rigid3.h"

namespace sandtable {

struct TableFrameOptions {
  // Relative tolerance that makes two rectangle areas or side lengths equal (ties), in [0, 1).
  double tie_relative_tolerance = 1e-9;
  // The up hint must be at least this far from the plane (> 0).
  double min_hint_height_m = 1e-6;
  Status Check() const;
};

struct TableFrameReport {
  Rigid3d table_from_source;
  double extent_x_m = 0.0;        // bounding rectangle side along +x (the longer one)
  double extent_y_m = 0.0;        // along +y
  double max_abs_height_m = 0.0;  // largest |z| of the input points in the table frame
  int num_points = 0;
  int num_hull_vertices = 0;
};

Expected<TableFrameReport> BuildTableFrame(const Plane& plane_in_source,
                                           std::span<const Eigen::Vector3d> points_in_source_m,
                                           const Eigen::Vector3d& up_hint_in_source_m,
                                           const TableFrameOptions& options = {});

}  // namespace sandtable
