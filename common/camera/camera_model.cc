#include "common/camera/camera_model.h"

#include <cmath>
#include <sstream>

namespace sandtable {

BrownDistortion BrownDistortion::FromArray(const double* c) {
  return BrownDistortion{c[0], c[1], c[2], c[3], c[4]};
}

bool BrownDistortion::AllFinite() const {
  return std::isfinite(k1) && std::isfinite(k2) && std::isfinite(p1) && std::isfinite(p2) &&
         std::isfinite(k3);
}

Status UndistortOptions::Check() const {
  if (max_iterations < 1) {
    return InvalidArgumentError("UndistortOptions: max_iterations must be >= 1");
  }
  if (!(tolerance > 0.0)) return InvalidArgumentError("UndistortOptions: tolerance must be > 0");
  return OkStatus();
}

CameraModel CameraModel::FromThrowRatio(int width, int height, double throw_ratio,
                                        double lens_shift_v) {
  // Throw ratio D / W: an image W wide at distance D, so fx = width_px * D / W.
  const double f = width * throw_ratio;
  return CameraModel(width, height, f, f, 0.5 * (width - 1),
                     0.5 * (height - 1) + lens_shift_v * height);
}

Status CameraModel::Check() const {
  auto bad = [](const std::string& field, double value, const char* rule) {
    std::ostringstream s;
    s << field << " = " << value << " " << rule;
    return InvalidArgumentError(s.str());
  };
  if (width_px <= 0) return bad("width_px", width_px, "must be > 0");
  if (height_px <= 0) return bad("height_px", height_px, "must be > 0");
  if (!std::isfinite(fx_px) || fx_px <= 0) return bad("fx_px", fx_px, "must be finite and > 0");
  if (!std::isfinite(fy_px) || fy_px <= 0) return bad("fy_px", fy_px, "must be finite and > 0");
  if (!std::isfinite(cx_px)) return bad("cx_px", cx_px, "must be finite");
  if (!std::isfinite(cy_px)) return bad("cy_px", cy_px, "must be finite");
  if (!distortion.AllFinite()) {
    return InvalidArgumentError("distortion coefficients (k1 k2 p1 p2 k3) must be finite");
  }
  return OkStatus();
}

Eigen::Matrix3d CameraModel::K() const {
  Eigen::Matrix3d k;
  k << fx_px, 0.0, cx_px, 0.0, fy_px, cy_px, 0.0, 0.0, 1.0;
  return k;
}

CameraModel CameraModel::FromK(int width, int height, const Eigen::Matrix3d& k,
                               BrownDistortion dist) {
  return CameraModel(width, height, k(0, 0), k(1, 1), k(0, 2), k(1, 2), dist);
}

Eigen::Vector2d CameraModel::Distort(const Eigen::Vector2d& undistorted) const {
  const std::array<double, 5> c = distortion.ToArray();
  Eigen::Vector2d out;
  ApplyBrownDistortion(c.data(), undistorted.x(), undistorted.y(), &out.x(), &out.y());
  return out;
}

bool CameraModel::InDistortionDomain(const Eigen::Vector2d& undistorted) const {
  if (!undistorted.allFinite()) return false;
  // With s = r^2, d/dr [r (1 + k1 s + k2 s^2 + k3 s^3)] = h(s) = 1 + 3 k1 s + 5 k2 s^2 + 7 k3 s^3.
  // h(0) = 1, so h > 0 on [0, s_max] iff h > 0 at s_max and at every critical point of h
  // inside (0, s_max): the roots of h'(s) = 3 k1 + 10 k2 s + 21 k3 s^2.
  const double a = 3.0 * distortion.k1, b = 5.0 * distortion.k2, c = 7.0 * distortion.k3;
  auto h = [&](double s) { return 1.0 + s * (a + s * (b + s * c)); };
  const double s_max = undistorted.squaredNorm();
  if (!(h(s_max) > 0.0)) return false;
  auto critical_ok = [&](double s) { return !(s > 0.0 && s < s_max) || h(s) > 0.0; };
  if (c == 0.0) {
    return b == 0.0 || critical_ok(-a / (2.0 * b));
  }
  const double discriminant = 4.0 * b * b - 12.0 * a * c;  // of 3c s^2 + 2b s + a
  if (discriminant < 0.0) return true;
  const double root = std::sqrt(discriminant);
  return critical_ok((-2.0 * b + root) / (6.0 * c)) && critical_ok((-2.0 * b - root) / (6.0 * c));
}

Expected<Eigen::Vector2d> CameraModel::Undistort(const Eigen::Vector2d& distorted,
                                                 const UndistortOptions& options) const {
  if (!distorted.allFinite()) return InvalidArgumentError("undistort: input is not finite");
  if (distortion.IsZero()) return distorted;
  const double k1 = distortion.k1, k2 = distortion.k2, k3 = distortion.k3;
  const double p1 = distortion.p1, p2 = distortion.p2;
  // Newton on f(x) = Distort(x) - distorted. The Jacobian below is the analytic derivative of
  // ApplyBrownDistortion. Starting from the distorted point is good while the map is close to
  // the identity; a determinant that approaches zero means we are near the fold where the
  // model stops being invertible, and we refuse rather than return a wrong branch.
  //
  // Converging is not enough: past the fold the map has other preimages, and Newton can land
  // on one of them (measured before this check: barrel k1 = -0.5, k2 = -0.3 with p1 = p2 =
  // 1e-3 returned a ray on the opposite side of the axis at distorted radius 1.08; k1 = -0.5,
  // k3 = +0.05 returned rays beyond the fold for every distorted radius past 0.5628). A
  // solution is accepted only inside InDistortionDomain() with a positive Jacobian.
  auto jacobian_at = [&](const Eigen::Vector2d& x) {
    const double xx = x.x() * x.x(), yy = x.y() * x.y(), xy = x.x() * x.y();
    const double r2 = xx + yy;
    const double radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
    const double dradial_dr2 = k1 + r2 * (2.0 * k2 + 3.0 * r2 * k3);
    Eigen::Matrix2d jacobian;
    jacobian(0, 0) = radial + 2.0 * xx * dradial_dr2 + 2.0 * p1 * x.y() + 6.0 * p2 * x.x();
    jacobian(0, 1) = 2.0 * xy * dradial_dr2 + 2.0 * p1 * x.x() + 2.0 * p2 * x.y();
    jacobian(1, 0) = 2.0 * xy * dradial_dr2 + 2.0 * p1 * x.x() + 2.0 * p2 * x.y();
    jacobian(1, 1) = radial + 2.0 * yy * dradial_dr2 + 6.0 * p1 * x.y() + 2.0 * p2 * x.x();
    return jacobian;
  };
  auto wrong_branch = [&](const Eigen::Vector2d& x) {
    std::ostringstream s;
    s << "undistort: normalized (" << distorted.x() << ", " << distorted.y()
      << ") is past the fold of the distortion (the only solution found, (" << x.x() << ", "
      << x.y() << "), lies outside the lens model's valid domain)";
    return NotConvergedError(s.str());
  };
  Eigen::Vector2d x = distorted;
  for (int iteration = 0; iteration < options.max_iterations; ++iteration) {
    const Eigen::Vector2d residual = Distort(x) - distorted;
    if (residual.norm() < options.tolerance) {
      if (!InDistortionDomain(x) || !(jacobian_at(x).determinant() > 0.0)) return wrong_branch(x);
      return x;
    }
    const Eigen::Matrix2d jacobian = jacobian_at(x);
    const double det = jacobian.determinant();
    if (!(det > 1e-6)) {
      std::ostringstream s;
      s << "undistort: distortion is not invertible near normalized (" << distorted.x() << ", "
        << distorted.y() << ") (Jacobian determinant " << det << ")";
      return NotConvergedError(s.str());
    }
    x -= jacobian.inverse() * residual;
    if (!x.allFinite()) break;
  }
  const Eigen::Vector2d residual = Distort(x) - distorted;
  if (x.allFinite() && residual.norm() < options.tolerance) {
    if (!InDistortionDomain(x) || !(jacobian_at(x).determinant() > 0.0)) return wrong_branch(x);
    return x;
  }
  std::ostringstream s;
  s << "undistort: no convergence within " << options.max_iterations
    << " iterations at normalized (" << distorted.x() << ", " << distorted.y() << ")";
  return NotConvergedError(s.str());
}

std::optional<Eigen::Vector2d> CameraModel::Project(const Eigen::Vector3d& x_in_camera) const {
  if (!x_in_camera.allFinite() || !(x_in_camera.z() > 0.0)) return std::nullopt;
  const Eigen::Vector2d normalized = x_in_camera.head<2>() / x_in_camera.z();
  if (!InDistortionDomain(normalized)) return std::nullopt;
  const Eigen::Vector2d pixel = PixelFromNormalized(Distort(normalized));
  if (!pixel.allFinite()) return std::nullopt;  // overflow of a huge x/z
  return pixel;
}

Expected<Eigen::Vector3d> CameraModel::Unproject(const Eigen::Vector2d& pixel,
                                                 const UndistortOptions& options) const {
  if (!pixel.allFinite()) return InvalidArgumentError("unproject: pixel is not finite");
  Expected<Eigen::Vector2d> undistorted = Undistort(NormalizedFromPixel(pixel), options);
  if (!undistorted.ok()) return undistorted.status();
  return Eigen::Vector3d(undistorted->x(), undistorted->y(), 1.0);
}

bool CameraModel::InImage(const Eigen::Vector2d& pixel) const {
  return pixel.x() >= -0.5 && pixel.x() < width_px - 0.5 && pixel.y() >= -0.5 &&
         pixel.y() < height_px - 0.5;
}

std::string CameraModel::ToString() const {
  std::ostringstream s;
  s << width_px << "x" << height_px << " fx=" << fx_px << " fy=" << fy_px << " cx=" << cx_px
    << " cy=" << cy_px << " k1=" << distortion.k1 << " k2=" << distortion.k2
    << " p1=" << distortion.p1 << " p2=" << distortion.p2 << " k3=" << distortion.k3;
  return s.str();
}

}  // namespace sandtable
