#include "sim/site/factory_calibration.h"

#include <cmath>
#include <random>

#include "common/base/units.h"

namespace sandtable::sim {

namespace {

// Standard normal from mt19937_64 by Box-Muller (portable: std::normal_distribution is not).
class Gaussian {
 public:
  explicit Gaussian(uint64_t seed) : engine_(seed) {}
  double Next() {
    const double u1 = (static_cast<double>(engine_() >> 11) + 0.5) * 0x1.0p-53;
    const double u2 = static_cast<double>(engine_() >> 11) * 0x1.0p-53;
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * std::numbers::pi * u2);
  }

 private:
  std::mt19937_64 engine_;
};

CameraModel Perturb(const CameraModel& truth, const FactoryCalibrationError& e, Gaussian* g) {
  CameraModel m = truth;
  m.fx_px *= 1.0 + e.focal_relative_sigma * g->Next();
  m.fy_px *= 1.0 + e.focal_relative_sigma * g->Next();
  m.cx_px += e.principal_point_sigma_px * g->Next();
  m.cy_px += e.principal_point_sigma_px * g->Next();
  m.distortion.k1 += e.distortion_sigma * g->Next();
  m.distortion.k2 += e.distortion_sigma / 3.0 * g->Next();
  m.distortion.p1 += e.distortion_sigma / 10.0 * g->Next();
  m.distortion.p2 += e.distortion_sigma / 10.0 * g->Next();
  return m;
}

}  // namespace

Status FactoryCalibrationError::Check() const {
  for (double s : {focal_relative_sigma, principal_point_sigma_px, distortion_sigma,
                   rotation_sigma_deg, translation_sigma_m}) {
    if (!(s >= 0.0) || !std::isfinite(s)) {
      return InvalidArgumentError("factory calibration error: every sigma must be finite and >= 0");
    }
  }
  return OkStatus();
}

Expected<FactoryCalibration> MakeFactoryCalibration(const UnitSpec& unit,
                                                    const FactoryCalibrationError& error,
                                                    uint64_t seed) {
  ST_RETURN_IF_ERROR(error.Check());
  if (!unit.camera) {
    return InvalidArgumentError("unit " + std::to_string(unit.id) + ": has no camera to calibrate");
  }
  // Distinct stream per unit: mix the id into the seed (splitmix64 constant).
  Gaussian g(seed ^ (0x9E3779B97F4A7C15ull * (static_cast<uint64_t>(unit.id) + 1)));
  FactoryCalibration out;
  out.unit_id = unit.id;
  out.camera = Perturb(unit.camera->model, error, &g);
  out.projector = Perturb(unit.projector.model, error, &g);
  Eigen::Vector3d axis(g.Next(), g.Next(), g.Next());
  if (axis.norm() < 1e-12) axis = Eigen::Vector3d::UnitZ();
  const double angle_rad = DegToRad(error.rotation_sigma_deg) * g.Next();
  const Eigen::Quaterniond delta(Eigen::AngleAxisd(angle_rad, axis.normalized()));
  const Rigid3d& truth = unit.camera->projector_from_camera;
  const Eigen::Vector3d dt(g.Next(), g.Next(), g.Next());
  out.projector_from_camera =
      Rigid3d(delta * truth.rotation, truth.translation + error.translation_sigma_m * dt);
  return out;
}

UnitCalibration ToUnitCalibration(const FactoryCalibration& c) {
  UnitCalibration out;
  out.unit_id = c.unit_id;
  out.source = kSourceFactory;
  out.camera = c.camera;
  out.projector = c.projector;
  out.projector_from_camera = c.projector_from_camera;
  return out;
}

nlohmann::json FactoryCalibrationToJson(const FactoryCalibration& c) {
  return UnitCalibrationToJsonValue(ToUnitCalibration(c));
}

}  // namespace sandtable::sim
