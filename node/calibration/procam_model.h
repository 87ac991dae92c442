// The projector-camera-board measurement model shared by the joint refinement (Ceres, T = Jet)
// and by the held-out prediction (T = double), so both evaluate the same formula.
//
// Parameter blocks (all double arrays):
//   intrinsics[4]   fx_px, fy_px, cx_px, cy_px
//   distortion[5]   k1 k2 p1 p2 k3 (OpenCV order; common/camera/camera_model.h)
//   pose[6]         angle-axis (rad) then translation (m): target_from_source, x_t = R x_s + t
//
// Corner model: board point (x, y, 0) -> camera_from_board -> Brown -> camera px.
// Dense model: camera px -> undistort (fixed-point iteration, converged to CameraModel's
// tolerance or the sample is refused) -> camera ray -> intersect the board plane
// (camera_from_board) -> projector_from_camera -> Brown -> projector px. The camera pixel is the
// sample position (exact); the decoded projector pixel is the noisy measurement, so the residual
// lives in the projector.
#pragma once

#include <cmath>

#include <ceres/jet.h>
#include <ceres/rotation.h>

#include "common/camera/camera_model.h"

namespace sandtable::node {

// Undistortion of normalized coordinates for the Ceres cost functions (T = double or Jet), where
// CameraModel::Undistort (double only) cannot serve: the fixed point
// x = (x_d - tangential(x)) / radial(x), which contracts by about |k1| r^2 per step (at the
// camera's board radii, r < 0.25 and |k1| < 0.3, 12 steps reach 1e-12). It runs at least
// kUndistortIterations steps, then on until the residual |distort(x) - x_d| (of the values, not
// the derivatives) is below UndistortOptions' tolerance, the test CameraModel::Undistort uses, at
// most kMaxUndistortIterations steps. Returns false when it does not get there (past the fold
// of a strong lens the iteration diverges or cycles): a sample is refused, never a wrong ray.
constexpr int kUndistortIterations = 12;
constexpr int kMaxUndistortIterations = 100;

inline double ScalarPart(double x) { return x; }
template <typename T, int N>
double ScalarPart(const ceres::Jet<T, N>& x) {
  return x.a;
}

template <typename T>
bool UndistortNormalized(const T* d, const T& xd, const T& yd, T* x, T* y) {
  const double tolerance = UndistortOptions{}.tolerance;
  T xu = xd;
  T yu = yd;
  for (int i = 1; i <= kMaxUndistortIterations; ++i) {
    const T xx = xu * xu, yy = yu * yu, xy = xu * yu;
    const T r2 = xx + yy;
    const T radial = T(1.0) + r2 * (d[0] + r2 * (d[1] + r2 * d[4]));
    const T dx = T(2.0) * d[2] * xy + d[3] * (r2 + T(2.0) * xx);
    const T dy = d[2] * (r2 + T(2.0) * yy) + T(2.0) * d[3] * xy;
    xu = (xd - dx) / radial;
    yu = (yd - dy) / radial;
    if (i < kUndistortIterations) continue;
    T xr, yr;
    ApplyBrownDistortion(d, xu, yu, &xr, &yr);
    const double ex = ScalarPart(xr) - ScalarPart(xd);
    const double ey = ScalarPart(yr) - ScalarPart(yd);
    if (std::sqrt(ex * ex + ey * ey) < tolerance) {  // NaN compares false: not converged
      *x = xu;
      *y = yu;
      return true;
    }
  }
  return false;
}

// Projects a point in the device frame to pixels. Returns false when z <= 0.
template <typename T>
bool ProjectToPixel(const T* k, const T* d, const T* x_in_device, T* pixel) {
  if (!(x_in_device[2] > T(0.0))) return false;
  const T xn = x_in_device[0] / x_in_device[2];
  const T yn = x_in_device[1] / x_in_device[2];
  T xd, yd;
  ApplyBrownDistortion(d, xn, yn, &xd, &yd);
  pixel[0] = k[0] * xd + k[2];
  pixel[1] = k[1] * yd + k[3];
  return true;
}

// Camera pixel of a board point.
template <typename T>
bool CornerPixel(const T* camera_k, const T* camera_d, const T* camera_from_board,
                 const T* x_in_board, T* pixel) {
  T x_in_camera[3];
  ceres::AngleAxisRotatePoint(camera_from_board, x_in_board, x_in_camera);
  for (int i = 0; i < 3; ++i) x_in_camera[i] += camera_from_board[3 + i];
  return ProjectToPixel(camera_k, camera_d, x_in_camera, pixel);
}

// The board point seen at camera pixel `camera_px`, in the camera frame. False when the pixel
// cannot be undistorted (UndistortNormalized), or the ray is parallel to the board or meets it
// behind the camera.
template <typename T>
bool BoardPointInCamera(const T* camera_k, const T* camera_d, const T* camera_from_board,
                        const T* camera_px, T* x_in_camera) {
  const T xd = (camera_px[0] - camera_k[2]) / camera_k[0];
  const T yd = (camera_px[1] - camera_k[3]) / camera_k[1];
  T ray[3];
  if (!UndistortNormalized(camera_d, xd, yd, &ray[0], &ray[1])) return false;
  ray[2] = T(1.0);
  // Board plane in the camera: normal n = R e_z, through the board origin t; depth s with
  // n . (s ray) = n . t.
  const T ez[3] = {T(0.0), T(0.0), T(1.0)};
  T n[3];
  ceres::AngleAxisRotatePoint(camera_from_board, ez, n);
  const T* t = camera_from_board + 3;
  const T n_dot_ray = n[0] * ray[0] + n[1] * ray[1] + n[2] * ray[2];
  const T n_dot_t = n[0] * t[0] + n[1] * t[1] + n[2] * t[2];
  using std::abs;
  if (!(abs(n_dot_ray) > T(1e-12))) return false;
  const T s = n_dot_t / n_dot_ray;
  if (!(s > T(0.0))) return false;
  for (int i = 0; i < 3; ++i) x_in_camera[i] = s * ray[i];
  return true;
}

// Projector pixel predicted for a decoded camera pixel on the board.
template <typename T>
bool DenseProjectorPixel(const T* camera_k, const T* camera_d, const T* camera_from_board,
                         const T* projector_from_camera, const T* projector_k, const T* projector_d,
                         const T* camera_px, T* projector_px) {
  T x_in_camera[3];
  if (!BoardPointInCamera(camera_k, camera_d, camera_from_board, camera_px, x_in_camera)) {
    return false;
  }
  T x_in_projector[3];
  ceres::AngleAxisRotatePoint(projector_from_camera, x_in_camera, x_in_projector);
  for (int i = 0; i < 3; ++i) x_in_projector[i] += projector_from_camera[3 + i];
  return ProjectToPixel(projector_k, projector_d, x_in_projector, projector_px);
}

}  // namespace sandtable::node
