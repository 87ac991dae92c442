// Linear parts of resection: the normalized DLT of P, its RQ decomposition, the coplanarity
// measure, and the known-intrinsics initialisers.
#include "common/estimation/resection_linear.h"

#include <cmath>
#include <numbers>
#include <sstream>
#include <vector>

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
