// Linear parts of resection: the normalized DLT of P, its RQ decomposition, the coplanarity
// measure, and the known-intrinsics initialisers.
#include "common/estimation/resection_linear.h"

#include <array>
#include <cmath>
#include <limits>
#include <numbers>
#include <optional>
#include <sstream>
#include <vector>

#include <Eigen/Geometry>
#include <Eigen/QR>
#include <Eigen/SVD>

#include "common/estimation/homography.h"
#include "common/estimation/homography_hartley.h"
#include "common/estimation/resection.h"

namespace sandtable {
namespace internal {

Hartley3d ComputeHartley3d(std::span<const Eigen::Vector3d> points) {
  Hartley3d h;
  if (points.empty()) return h;
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& p : points) c += p;
  c /= static_cast<double>(points.size());
  double mean_distance = 0.0;
  for (const Eigen::Vector3d& p : points) mean_distance += (p - c).norm();
  mean_distance /= static_cast<double>(points.size());
  if (!(mean_distance > 0.0) || !std::isfinite(mean_distance)) return h;
  const double s = std::sqrt(3.0) / mean_distance;
  h.t.topLeftCorner<3, 3>() = s * Eigen::Matrix3d::Identity();
  h.t.topRightCorner<3, 1>() = -s * c;
  h.ok = true;
  return h;
}

namespace {

// Smallest right singular vector of the 2n x 12 DLT system for [u; 1] ~ P [X; 1] (Hartley &
// Zisserman eq. 7.2), in the normalised coordinates of both sides, undone at the end.
// Rows: [X^T 0 -u X^T] and [0 X^T -v X^T].
Expected<Eigen::Matrix<double, 3, 4>> DltP(std::span<const Eigen::Vector3d> world,
                                           std::span<const Eigen::Vector2d> image) {
  const int n = static_cast<int>(world.size());
  const Hartley3d n3 = ComputeHartley3d(world);
  const Hartley2d n2 = ComputeHartley2d(image);
  if (!n3.ok || !n2.ok) return DegenerateError("DLT: all points coincide");
  Eigen::MatrixXd a(2 * n, 12);
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector4d x = n3.t * world[i].homogeneous();
    const Eigen::Vector2d u = n2.Apply(image[i]);
    a.row(2 * i) << x.transpose(), Eigen::RowVector4d::Zero(), -u.x() * x.transpose();
    a.row(2 * i + 1) << Eigen::RowVector4d::Zero(), x.transpose(), -u.y() * x.transpose();
  }
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(a, Eigen::ComputeFullV);
  Eigen::Matrix<double, 12, 1> sv = Eigen::Matrix<double, 12, 1>::Zero();
  sv.head(svd.singularValues().size()) = svd.singularValues();
  // Rank 11 is needed for a unique P; below that the points do not determine it.
  if (!(sv(10) > 1e-9 * sv(0))) {
    std::ostringstream s;
    s << "DLT: the linear system is rank-deficient (s11/s1 = " << sv(10) / sv(0)
      << "); the points do not determine a projection matrix";
    return DegenerateError(s.str());
  }
  const Eigen::Matrix<double, 12, 1> p = svd.matrixV().col(11);
  Eigen::Matrix<double, 3, 4> pn;
  pn.row(0) = p.segment<4>(0).transpose();
  pn.row(1) = p.segment<4>(4).transpose();
  pn.row(2) = p.segment<4>(8).transpose();
  Eigen::Matrix<double, 3, 4> out = n2.t.inverse() * pn * n3.t;
  out /= out.norm();
  // Sign: the majority of the points in front (depth = row 2 . [X; 1] > 0).
  int in_front = 0;
  for (const Eigen::Vector3d& x : world) in_front += out.row(2).dot(x.homogeneous()) > 0.0;
  if (2 * in_front < n) out = -out;
  return out;
}

Rigid3d NearestRigid(const Eigen::Matrix<double, 3, 4>& scaled_rt) {
  const Eigen::Matrix3d m = scaled_rt.leftCols<3>();
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(m, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
  d(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0.0 ? -1.0 : 1.0;
  const Eigen::Matrix3d r = svd.matrixU() * d * svd.matrixV().transpose();
  const double scale = svd.singularValues().mean();
  return Rigid3d(r, Eigen::Vector3d(scaled_rt.col(3) / scale));
}

}  // namespace

Expected<Rigid3d> CameraFromWorldDltKnownK(std::span<const Eigen::Vector3d> points_in_world,
                                           std::span<const Eigen::Vector2d> normalized) {
  Expected<Eigen::Matrix<double, 3, 4>> p = DltP(points_in_world, normalized);
  if (!p.ok()) return p.status();
  // P ~ [R | t] with a positive scale (sign fixed by the depths); the left block may be a
  // reflection only when the data are not a camera view, which the depth check later catches.
  return NearestRigid(*p);
}

Expected<Rigid3d> CameraFromWorldPlanar(std::span<const Eigen::Vector3d> points_in_world,
                                        std::span<const Eigen::Vector2d> normalized) {
  // plane_from_world: rows of R are the principal axes of the centred cloud (largest first),
  // so the fitted plane is z = 0 of the frame "plane".
  const int n = static_cast<int>(points_in_world.size());
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& p : points_in_world) c += p;
  c /= n;
  Eigen::MatrixXd centred(3, n);
  for (int i = 0; i < n; ++i) centred.col(i) = points_in_world[i] - c;
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(centred, Eigen::ComputeThinU);
  Eigen::Matrix3d axes = svd.matrixU();
  if (axes.determinant() < 0.0) axes.col(2) = -axes.col(2);
  const Rigid3d plane_from_world(Eigen::Matrix3d(axes.transpose()), -axes.transpose() * c);
  std::vector<Eigen::Vector2d> on_plane(n);
  for (int i = 0; i < n; ++i) on_plane[i] = (plane_from_world * points_in_world[i]).head<2>();
  Expected<Eigen::Matrix3d> h = EstimateHomographyDlt(on_plane, normalized);
  if (!h.ok()) return h.status();
  Expected<Rigid3d> camera_from_plane =
      CameraFromPlaneHomography(*h, Eigen::Matrix3d::Identity(), on_plane);
  if (!camera_from_plane.ok()) return camera_from_plane.status();
  return *camera_from_plane * plane_from_world;
}

namespace {

// All solutions of P3P for one triple. Unknown depths s1, s2, s3 > 0 along unit bearings
// f1, f2, f3 satisfy the law of cosines for the three world distances:
//   s1^2 + s2^2 - 2 s1 s2 cos_12 = d12^2,  s1^2 + s3^2 - 2 s1 s3 cos_13 = d13^2,
//   s2^2 + s3^2 - 2 s2 s3 cos_23 = d23^2.
// For a given s1 the first two give s2 = s1 cos_12 +- sqrt(d12^2 - s1^2 sin^2_12) and likewise
// s3 (two branches each); the third equation is then a function of s1 alone on four branches,
// whose roots are bracketed on a grid over the admissible s1 and bisected. Roots where the
// function only touches zero can be missed; the caller tries every triple, so one miss is
// covered by another triple.
std::vector<Rigid3d> SolveP3p(const std::array<Eigen::Vector3d, 3>& world,
                              const std::array<Eigen::Vector3d, 3>& bearing) {
  const double d12 = (world[0] - world[1]).norm();
  const double d13 = (world[0] - world[2]).norm();
  const double d23 = (world[1] - world[2]).norm();
  const double c12 = bearing[0].dot(bearing[1]);
  const double c13 = bearing[0].dot(bearing[2]);
  const double c23 = bearing[1].dot(bearing[2]);
  const double sin12_sq = std::max(0.0, 1.0 - c12 * c12);
  const double sin13_sq = std::max(0.0, 1.0 - c13 * c13);
  // s1 is limited by the discriminants (s1 sin <= d) when the sines are not zero.
  double s1_max = std::numeric_limits<double>::infinity();
  if (sin12_sq > 0.0) s1_max = std::min(s1_max, d12 / std::sqrt(sin12_sq));
  if (sin13_sq > 0.0) s1_max = std::min(s1_max, d13 / std::sqrt(sin13_sq));
  if (!std::isfinite(s1_max) || !(s1_max > 0.0)) return {};

  // Returns the residual of the third equation on `branch` (bit 0: sign for s2, bit 1: s3),
  // or NaN where a depth is not real or not positive.
  auto depths = [&](double s1, int branch, double* s2, double* s3) {
    const double r2 = d12 * d12 - s1 * s1 * sin12_sq;
    const double r3 = d13 * d13 - s1 * s1 * sin13_sq;
    if (r2 < 0.0 || r3 < 0.0) return false;
    *s2 = s1 * c12 + ((branch & 1) ? -1.0 : 1.0) * std::sqrt(r2);
    *s3 = s1 * c13 + ((branch & 2) ? -1.0 : 1.0) * std::sqrt(r3);
    return *s2 > 0.0 && *s3 > 0.0;
  };
  auto f = [&](double s1, int branch) {
    double s2, s3;
    if (!depths(s1, branch, &s2, &s3)) return std::numeric_limits<double>::quiet_NaN();
    return (s2 * s2 + s3 * s3 - 2.0 * s2 * s3 * c23 - d23 * d23) / (d23 * d23);
  };

  constexpr int kGrid = 2000;
  constexpr int kBisections = 100;
  std::vector<Rigid3d> poses;
  for (int branch = 0; branch < 4; ++branch) {
    double prev_s1 = 0.0, prev_f = std::numeric_limits<double>::quiet_NaN();
    for (int g = 1; g <= kGrid; ++g) {
      const double s1 = s1_max * g / kGrid;
      const double value = f(s1, branch);
      if (std::isfinite(prev_f) && std::isfinite(value) && (prev_f < 0.0) != (value < 0.0)) {
        double lo = prev_s1, hi = s1, f_lo = prev_f;
        for (int b = 0; b < kBisections; ++b) {
          const double mid = 0.5 * (lo + hi);
          const double f_mid = f(mid, branch);
          if (!std::isfinite(f_mid)) break;
          if ((f_mid < 0.0) == (f_lo < 0.0)) {
            lo = mid;
            f_lo = f_mid;
          } else {
            hi = mid;
          }
        }
        const double root = 0.5 * (lo + hi);
        double s2, s3;
        if (depths(root, branch, &s2, &s3)) {
          // Camera-frame points, then the rigid alignment camera_from_world (Kabsch/Umeyama
          // without scale) of the triple.
          Eigen::Matrix3d in_camera, in_world;
          in_camera << root * bearing[0], s2 * bearing[1], s3 * bearing[2];
          in_world << world[0], world[1], world[2];
          const Eigen::Matrix4d t = Eigen::umeyama(in_world, in_camera, false);
          poses.emplace_back(Eigen::Matrix3d(t.topLeftCorner<3, 3>()),
                             Eigen::Vector3d(t.topRightCorner<3, 1>()));
        }
      }
      prev_s1 = s1;
      prev_f = value;
    }
  }
  return poses;
}

}  // namespace

Expected<Rigid3d> CameraFromWorldP3p(std::span<const Eigen::Vector3d> points_in_world,
                                     std::span<const Eigen::Vector2d> normalized) {
  const int n = static_cast<int>(points_in_world.size());
  double best_error = std::numeric_limits<double>::infinity();
  std::optional<Rigid3d> best;
  for (int i = 0; i < n; ++i) {
    for (int j = i + 1; j < n; ++j) {
      for (int k = j + 1; k < n; ++k) {
        const std::array<Eigen::Vector3d, 3> world = {points_in_world[i], points_in_world[j],
                                                      points_in_world[k]};
        const std::array<Eigen::Vector3d, 3> bearing = {normalized[i].homogeneous().normalized(),
                                                        normalized[j].homogeneous().normalized(),
                                                        normalized[k].homogeneous().normalized()};
        for (const Rigid3d& pose : SolveP3p(world, bearing)) {
          double error = 0.0;
          for (int m = 0; m < n && std::isfinite(error); ++m) {
            const Eigen::Vector3d x = pose * points_in_world[m];
            error = x.z() > 0.0 ? error + (x.head<2>() / x.z() - normalized[m]).squaredNorm()
                                : std::numeric_limits<double>::infinity();
          }
          if (error < best_error) {
            best_error = error;
            best = pose;
          }
        }
      }
    }
  }
  if (!best) {
    return DegenerateError(
        "P3P: no triple of points has a real solution with all points in front of the camera");
  }
  return *best;
}

}  // namespace internal

double OutOfPlaneRatio(std::span<const Eigen::Vector3d> points) {
  if (points.size() < 3) return 0.0;
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& p : points) c += p;
  c /= static_cast<double>(points.size());
  // Singular values of the 3 x n centred matrix = square roots of the scatter's eigenvalues;
  // the 3x3 scatter resolves ratios down to ~1e-8, ample for thresholds near 1e-3.
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
  for (const Eigen::Vector3d& p : points) scatter += (p - c) * (p - c).transpose();
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(scatter);
  const Eigen::Vector3d s = svd.singularValues();
  if (!(s(0) > 0.0)) return 0.0;
  return std::sqrt(std::max(0.0, s(2)) / s(0));
}

Expected<Eigen::Matrix<double, 3, 4>> EstimateProjectionMatrixDlt(
    std::span<const Eigen::Vector3d> points_in_world,
    std::span<const Eigen::Vector2d> points_in_image_px, double coplanar_ratio_threshold) {
  if (points_in_world.size() != points_in_image_px.size()) {
    return InvalidArgumentError("DLT: 3D and 2D point counts differ");
  }
  for (size_t i = 0; i < points_in_world.size(); ++i) {
    if (!points_in_world[i].allFinite() || !points_in_image_px[i].allFinite()) {
      std::ostringstream s;
      s << "DLT: point " << i << " has a non-finite coordinate (NaN or Inf)";
      return InvalidArgumentError(s.str());
    }
  }
  if (points_in_world.size() < 6) {
    std::ostringstream s;
    s << "DLT: " << points_in_world.size() << " points given, at least 6 needed";
    return DegenerateError(s.str());
  }
  const double ratio = OutOfPlaneRatio(points_in_world);
  if (ratio < coplanar_ratio_threshold) {
    std::ostringstream s;
    s << "DLT: the 3D points are coplanar (out-of-plane ratio " << ratio << " < "
      << coplanar_ratio_threshold << "); a projection matrix needs off-plane points";
    return DegenerateError(s.str());
  }
  if (internal::CollinearityRatio(points_in_image_px) < kHomographyCollinearRatio) {
    return DegenerateError("DLT: the image points are collinear");
  }
  return internal::DltP(points_in_world, points_in_image_px);
}

Expected<DecomposedProjection> DecomposeProjectionMatrix(const Eigen::Matrix<double, 3, 4>& p) {
  if (!p.allFinite()) return InvalidArgumentError("decompose P: non-finite entry");
  Eigen::Matrix<double, 3, 4> pp = p;
  Eigen::Matrix3d m = pp.leftCols<3>();
  const Eigen::JacobiSVD<Eigen::Matrix3d> msvd(m);
  if (!(msvd.singularValues()(2) > 1e-12 * msvd.singularValues()(0))) {
    return DegenerateError("decompose P: the left 3x3 block is singular (camera at infinity)");
  }
  // P and -P are the same camera; det M > 0 makes det R = +1 with a positive-diagonal K.
  if (m.determinant() < 0.0) {
    pp = -pp;
    m = -m;
  }
  // RQ from QR: with the exchange matrix J, QR of (J M)^T = Q U gives M = (J U^T J)(J Q^T),
  // an upper triangular times an orthogonal matrix.
  Eigen::Matrix3d j = Eigen::Matrix3d::Zero();
  j(0, 2) = j(1, 1) = j(2, 0) = 1.0;
  const Eigen::HouseholderQR<Eigen::Matrix3d> qr((j * m).transpose());
  const Eigen::Matrix3d q = qr.householderQ();
  const Eigen::Matrix3d u = qr.matrixQR().triangularView<Eigen::Upper>();
  Eigen::Matrix3d k = j * u.transpose() * j;
  Eigen::Matrix3d r = j * q.transpose();
  // Make the diagonal of K positive: K D D R with D = diag(sign(K_ii)).
  const Eigen::Vector3d signs(k(0, 0) < 0 ? -1.0 : 1.0, k(1, 1) < 0 ? -1.0 : 1.0,
                              k(2, 2) < 0 ? -1.0 : 1.0);
  k = k * signs.asDiagonal();
  r = signs.asDiagonal() * r;
  const Eigen::Vector3d t = k.inverse() * pp.col(3);
  DecomposedProjection out;
  out.k = k / k(2, 2);
  out.skew_px = out.k(0, 1);
  out.camera_from_world = Rigid3d(r, t);
  if (r.determinant() < 0.0) {
    return DegenerateError("decompose P: the rotation is a reflection");
  }
  return out;
}

}  // namespace sandtable
