// Pinhole camera/projector model with Brown ("plumb bob", OpenCV order k1 k2 p1 p2 k3)
// distortion. One model serves cameras and projectors: a projector is a camera run backwards.
//
// Frames: x_in_camera is in the device's OpenCV frame (x right, y down, z forward), any length
// unit. Normalized coordinates are (x/z, y/z). Pixels follow OpenCV: pixel (0, 0) is centred at
// (0.0, 0.0), so the image covers [-0.5, width_px - 0.5] x [-0.5, height_px - 0.5].
//   u_px = fx_px * x_distorted + cx_px,  v_px = fy_px * y_distorted + cy_px.
// Failure: Project() of a point at or behind the camera plane, or past the fold of the
// distortion (see InDistortionDomain), returns nullopt; Unproject() returns NOT_CONVERGED when
// the distortion cannot be inverted at that pixel (past the fold of a strongly distorted lens),
// never a wrong ray.
//
// The fold: the radial map r -> r (1 + k1 r^2 + k2 r^4 + k3 r^6) is a valid lens model only
// while it increases; where its derivative first reaches zero (radius r_fold) the model folds
// back, and beyond it points land on pixels that belong to other rays (for barrel k1 = -0.5,
// k2 = -0.3 the ray at r = 1.33 lands on the opposite side of the image). The valid domain is
// r < r_fold; its image, distorted radius < g(r_fold), is the set of invertible pixels.
// tests/common/camera/camera_model_stress_test.cc and docs/numerics.md give measured numbers.
#pragma once

#include <array>
#include <optional>
#include <string>

#include <Eigen/Core>
#include <Eigen/LU>

#include "common/base/status.h"

namespace sandtable {

struct BrownDistortion {
  double k1 = 0.0, k2 = 0.0, p1 = 0.0, p2 = 0.0, k3 = 0.0;  // dimensionless, OpenCV order

  bool IsZero() const { return k1 == 0 && k2 == 0 && p1 == 0 && p2 == 0 && k3 == 0; }
  std::array<double, 5> ToArray() const { return {k1, k2, p1, p2, k3}; }
  static BrownDistortion FromArray(const double* k1_k2_p1_p2_k3);
  bool AllFinite() const;
};

// Applies Brown distortion to undistorted normalized coordinates (x, y). Templated so Ceres
// cost functions use the very same formula (T = double or ceres::Jet).
//   r2 = x^2 + y^2, radial = 1 + k1 r2 + k2 r2^2 + k3 r2^3
//   xd = x radial + 2 p1 x y + p2 (r2 + 2 x^2)
//   yd = y radial + p1 (r2 + 2 y^2) + 2 p2 x y
template <typename T>
inline void ApplyBrownDistortion(const T* k1_k2_p1_p2_k3, const T& x, const T& y, T* x_distorted,
                                 T* y_distorted) {
  const T& k1 = k1_k2_p1_p2_k3[0];
  const T& k2 = k1_k2_p1_p2_k3[1];
  const T& p1 = k1_k2_p1_p2_k3[2];
  const T& p2 = k1_k2_p1_p2_k3[3];
  const T& k3 = k1_k2_p1_p2_k3[4];
  const T xx = x * x;
  const T yy = y * y;
  const T xy = x * y;
  const T r2 = xx + yy;
  const T radial = T(1.0) + r2 * (k1 + r2 * (k2 + r2 * k3));
  *x_distorted = x * radial + T(2.0) * p1 * xy + p2 * (r2 + T(2.0) * xx);
  *y_distorted = y * radial + p1 * (r2 + T(2.0) * yy) + T(2.0) * p2 * xy;
}

struct UndistortOptions {
  int max_iterations = 30;
  // Convergence: |distort(x) - x_distorted| below this, in normalized units (1e-10 is about
  // 1e-7 px at fx = 1000 px).
  double tolerance = 1e-10;
  Status Check() const;
};

class CameraModel {
 public:
  int width_px = 0;
  int height_px = 0;
  double fx_px = 0.0, fy_px = 0.0;  // focal lengths
  double cx_px = 0.0, cy_px = 0.0;  // principal point (pixel-centre convention above)
  BrownDistortion distortion;

  CameraModel() = default;
  CameraModel(int width, int height, double fx, double fy, double cx, double cy,
              BrownDistortion dist = {})
      : width_px(width),
        height_px(height),
        fx_px(fx),
        fy_px(fy),
        cx_px(cx),
        cy_px(cy),
        distortion(dist) {}

  // A model from a throw ratio (throw distance / image width) and lens shift, as projector
  // data sheets give them. Square pixels; cx at the image centre; the principal point moves
  // vertically by lens_shift_v (fraction of the image height, + moves the image up, so
  // cy_px = (height_px - 1) / 2 + lens_shift_v * height_px).
  static CameraModel FromThrowRatio(int width, int height, double throw_ratio,
                                    double lens_shift_v = 0.0);

  // OK, or the first broken field named: "fx_px = -3 must be > 0".
  Status Check() const;

  Eigen::Matrix3d K() const;
  static CameraModel FromK(int width, int height, const Eigen::Matrix3d& k,
                           BrownDistortion dist = {});

  // Distortion in normalized coordinates. Defined everywhere; meaningful only inside
  // InDistortionDomain().
  Eigen::Vector2d Distort(const Eigen::Vector2d& undistorted) const;
  // True when the undistorted normalized point lies inside the fold of the radial distortion:
  // d/dr [r (1 + k1 r^2 + k2 r^4 + k3 r^6)] > 0 for every radius in [0, |undistorted|]
  // (exact: the minimum of a cubic in r^2 over an interval). Always true without distortion.
  // Tangential terms (p1, p2) are not part of this test; Undistort also checks the Jacobian.
  bool InDistortionDomain(const Eigen::Vector2d& undistorted) const;
  // Inverse of Distort by Newton's method from the distorted point as the first guess;
  // NOT_CONVERGED if the iteration does not reach `options.tolerance`, meets a singular
  // Jacobian, or converges to a point outside InDistortionDomain() (a wrong branch).
  Expected<Eigen::Vector2d> Undistort(const Eigen::Vector2d& distorted,
                                      const UndistortOptions& options = {}) const;

  Eigen::Vector2d PixelFromNormalized(const Eigen::Vector2d& distorted) const {
    return {fx_px * distorted.x() + cx_px, fy_px * distorted.y() + cy_px};
  }
  Eigen::Vector2d NormalizedFromPixel(const Eigen::Vector2d& pixel) const {
    return {(pixel.x() - cx_px) / fx_px, (pixel.y() - cy_px) / fy_px};
  }

  // Pixel of a point in the camera frame; nullopt when z <= 0, the input is not finite, the
  // point is past the fold (!InDistortionDomain(x/z, y/z)) or the pixel overflows.
  // The pixel may fall outside the image: check InImage().
  std::optional<Eigen::Vector2d> Project(const Eigen::Vector3d& x_in_camera) const;
  // The ray through a pixel, as a direction in the camera frame with z = 1.
  Expected<Eigen::Vector3d> Unproject(const Eigen::Vector2d& pixel,
                                      const UndistortOptions& options = {}) const;

  // True when the pixel lies on the sensor: [-0.5, width_px - 0.5) x [-0.5, height_px - 0.5).
  bool InImage(const Eigen::Vector2d& pixel) const;

  std::string ToString() const;
};

}  // namespace sandtable
