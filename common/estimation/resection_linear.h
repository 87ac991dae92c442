// Linear initialisers of the resection pipeline with known intrinsics (internal to
// common/estimation; the public entry point is EstimateResection in resection.h). Both take
// undistorted normalised image coordinates (x/z, y/z), i.e. K and the distortion already
// removed.
#pragma once

#include <span>

#include <Eigen/Core>

#include "common/base/status.h"
#include "common/geometry/rigid3.h"

namespace sandtable::internal {

// DLT of [R | t] up to scale from n >= 6 non-coplanar points, then R projected onto SO(3)
// (nearest rotation by SVD) and the scale taken from the mean singular value.
Expected<Rigid3d> CameraFromWorldDltKnownK(std::span<const Eigen::Vector3d> points_in_world,
                                           std::span<const Eigen::Vector2d> normalized);

// Pose from a homography between the best-fit plane of the points (SVD of the centred cloud)
// and the normalised image; exact for coplanar points, an approximation otherwise.
Expected<Rigid3d> CameraFromWorldPlanar(std::span<const Eigen::Vector3d> points_in_world,
                                        std::span<const Eigen::Vector2d> normalized);

// Minimal-solver start for 4 or 5 points in general 3D position: every triple is solved as a
// P3P problem (the depth equations reduced to one unknown, roots bracketed on a dense grid and
// bisected; no closed-form quartic), each candidate pose is scored by its reprojection error
// (normalised units) over all points, and the best is returned. DEGENERATE if no triple has a
// real solution with all points in front.
Expected<Rigid3d> CameraFromWorldP3p(std::span<const Eigen::Vector3d> points_in_world,
                                     std::span<const Eigen::Vector2d> normalized);

// The similarity that moves the centroid to the origin with mean distance sqrt(3) (Hartley's
// 3D normalisation), as a 4x4 matrix; ok = false when all points coincide.
struct Hartley3d {
  Eigen::Matrix4d t = Eigen::Matrix4d::Identity();
  bool ok = false;
};
Hartley3d ComputeHartley3d(std::span<const Eigen::Vector3d> points);

}  // namespace sandtable::internal
