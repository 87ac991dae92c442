#include "sim/site/site.h"

#include <cmath>
#include <set>
#include <sstream>

namespace sandtable::sim {

namespace {

std::string UnitLabel(const UnitSpec& unit, size_t index) {
  std::ostringstream s;
  if (unit.id == kInvalidNodeId) {
    s << "units[" << index << "]";
  } else {
    s << "unit " << unit.id;
  }
  if (!unit.name.empty()) s << " (" << unit.name << ")";
  return s.str();
}

Status FieldError(const std::string& unit, const std::string& field, double value,
                  const std::string& rule) {
  std::ostringstream s;
  s << unit << ": " << field << " = " << value << " " << rule;
  return InvalidArgumentError(s.str());
}

// True when some point of the table top projects into the projector's image. Samples a 65 x 65
// grid over the table's bounding square and keeps the points on the table.
bool SeesTable(const TableSpec& table, const ProjectorSpec& projector) {
  const Rigid3d projector_from_table = projector.table_from_projector.Inverse();
  const double half_x = table.is_disc ? 0.5 * table.diameter_m : 0.5 * table.size_m.x();
  const double half_y = table.is_disc ? 0.5 * table.diameter_m : 0.5 * table.size_m.y();
  constexpr int kSteps = 64;
  for (int j = 0; j <= kSteps; ++j) {
    for (int i = 0; i <= kSteps; ++i) {
      const Eigen::Vector2d xy(-half_x + 2 * half_x * i / kSteps,
                               -half_y + 2 * half_y * j / kSteps);
      if (!table.Contains(xy)) continue;
      const std::optional<Eigen::Vector2d> pixel =
          projector.model.Project(projector_from_table * Eigen::Vector3d(xy.x(), xy.y(), 0.0));
      if (pixel && projector.model.InImage(*pixel)) return true;
    }
  }
  return false;
}

// The image size and pose limits of one device (kMaxSiteImageSide_px, kMaxSiteImagePixels,
// kMaxSiteCoordinate_m); `field` is "projector" or "camera".
Status CheckDeviceLimits(const std::string& label, const std::string& field,
                         const CameraModel& model, const Rigid3d& pose, const char* pose_name) {
  const std::string size = std::to_string(model.width_px) + "x" + std::to_string(model.height_px);
  if (model.width_px > kMaxSiteImageSide_px || model.height_px > kMaxSiteImageSide_px) {
    return InvalidArgumentError(
        label + ": " + field + " image " + size +
        " px has a side over kMaxSiteImageSide_px = " + std::to_string(kMaxSiteImageSide_px));
  }
  if (int64_t{model.width_px} * model.height_px > kMaxSiteImagePixels) {
    return InvalidArgumentError(
        label + ": " + field + " image " + size +
        " px is more than kMaxSiteImagePixels = " + std::to_string(kMaxSiteImagePixels));
  }
  if (!pose.AllFinite()) {
    return InvalidArgumentError(label + ": " + field + "." + pose_name + " is not finite");
  }
  if (pose.translation.cwiseAbs().maxCoeff() > kMaxSiteCoordinate_m) {
    std::ostringstream s;
    s << label << ": " << field << "." << pose_name << ".translation_m = (" << pose.translation.x()
      << ", " << pose.translation.y() << ", " << pose.translation.z()
      << ") is outside |x|, |y|, |z| <= kMaxSiteCoordinate_m = " << kMaxSiteCoordinate_m << " m";
    return InvalidArgumentError(s.str());
  }
  return OkStatus();
}

}  // namespace

bool TableSpec::Contains(const Eigen::Vector2d& xy) const {
  if (is_disc) return xy.norm() <= 0.5 * diameter_m + 1e-12;
  return std::abs(xy.x()) <= 0.5 * size_m.x() + 1e-12 &&
         std::abs(xy.y()) <= 0.5 * size_m.y() + 1e-12;
}

const UnitSpec* Site::FindUnit(NodeId id) const {
  for (const UnitSpec& u : units) {
    if (u.id == id) return &u;
  }
  return nullptr;
}

Status Site::Check() const {
  if (table.is_disc && !(table.diameter_m > 0 && std::isfinite(table.diameter_m))) {
    return FieldError("table", "diameter_m", table.diameter_m, "must be > 0");
  }
  if (!table.is_disc && !(table.size_m.minCoeff() > 0 && table.size_m.allFinite())) {
    return FieldError("table", "size_m", table.size_m.minCoeff(), "must be > 0");
  }
  if (!(ambient_luminance_nits >= 0) || !std::isfinite(ambient_luminance_nits)) {
    return FieldError("site", "ambient_luminance_nits", ambient_luminance_nits, "must be >= 0");
  }
  if (units.empty()) return InvalidArgumentError("site: no units");
  if (units.size() > kMaxSiteUnits) {
    return InvalidArgumentError(
        "site: " + std::to_string(units.size()) +
        " units, more than kMaxSiteUnits = " + std::to_string(kMaxSiteUnits));
  }
  std::set<NodeId> ids;
  for (size_t i = 0; i < units.size(); ++i) {
    const UnitSpec& unit = units[i];
    const std::string label = UnitLabel(unit, i);
    if (unit.id == kInvalidNodeId) return InvalidArgumentError(label + ": id missing or invalid");
    if (!ids.insert(unit.id).second) {
      return InvalidArgumentError("units[" + std::to_string(i) + "]: duplicate id " +
                                  std::to_string(unit.id));
    }
    const ProjectorSpec& p = unit.projector;
    if (Status s = p.model.Check(); !s.ok()) {
      return InvalidArgumentError(label + ": projector." + s.message());
    }
    ST_RETURN_IF_ERROR(CheckDeviceLimits(label, "projector", p.model, p.table_from_projector,
                                         "table_from_projector"));
    if (!(p.gamma > 0) || !std::isfinite(p.gamma)) {
      return FieldError(label, "projector.gamma", p.gamma, "must be > 0");
    }
    if (!(p.peak_luminance_at_1m_nits > 0) || !std::isfinite(p.peak_luminance_at_1m_nits)) {
      return FieldError(label, "projector.peak_luminance_at_1m_nits", p.peak_luminance_at_1m_nits,
                        "must be > 0");
    }
    if (!(p.black_level >= 0 && p.black_level < 1)) {
      return FieldError(label, "projector.black_level", p.black_level, "must be in [0, 1)");
    }
    if (!(p.focus_distance_m >= 0) || !(p.aperture_diameter_m >= 0)) {
      return FieldError(label, "projector.focus_distance_m/aperture_diameter_m",
                        std::min(p.focus_distance_m, p.aperture_diameter_m), "must be >= 0");
    }
    if (p.aperture_diameter_m > 0 && p.focus_distance_m <= 0) {
      return FieldError(label, "projector.focus_distance_m", p.focus_distance_m,
                        "must be > 0 when aperture_diameter_m > 0");
    }
    if (!SeesTable(table, p)) {
      return InvalidArgumentError(label +
                                  ": projector sees nothing of the table (no table point "
                                  "projects into its " +
                                  std::to_string(p.model.width_px) + "x" +
                                  std::to_string(p.model.height_px) +
                                  " image); check projector.table_from_projector");
    }
    if (Status s = unit.timing.Check(); !s.ok()) {
      return InvalidArgumentError(label + ": " + s.message());
    }
    if (unit.camera) {
      const CameraSpec& c = *unit.camera;
      if (Status s = c.model.Check(); !s.ok()) {
        return InvalidArgumentError(label + ": camera." + s.message());
      }
      ST_RETURN_IF_ERROR(CheckDeviceLimits(label, "camera", c.model, c.projector_from_camera,
                                           "projector_from_camera"));
      if (!(c.read_noise_dn >= 0))
        return FieldError(label, "camera.read_noise_dn", c.read_noise_dn, "must be >= 0");
      if (!(c.exposure_s > 0))
        return FieldError(label, "camera.exposure_s", c.exposure_s, "must be > 0");
      if (!(c.saturation_nit_s > 0)) {
        return FieldError(label, "camera.saturation_nit_s", c.saturation_nit_s, "must be > 0");
      }
      if (!(c.full_well_e >= 0))
        return FieldError(label, "camera.full_well_e", c.full_well_e, "must be >= 0");
      if (!(c.gamma > 0)) return FieldError(label, "camera.gamma", c.gamma, "must be > 0");
      if (c.bit_depth < 1 || c.bit_depth > 16) {
        return FieldError(label, "camera.bit_depth", c.bit_depth, "must be in [1, 16]");
      }
    }
  }
  return OkStatus();
}

Expected<Rigid3d> TableFromDeviceLookAt(const Eigen::Vector3d& eye, const Eigen::Vector3d& target,
                                        const Eigen::Vector3d& up_hint) {
  const Eigen::Vector3d forward = target - eye;
  if (!(forward.norm() > 0)) return InvalidArgumentError("look-at: eye equals target");
  const Eigen::Vector3d z = forward.normalized();
  Eigen::Vector3d x = z.cross(up_hint);  // right = forward x up
  if (!(x.norm() > 1e-9)) return InvalidArgumentError("look-at: view direction parallel to up");
  x.normalize();
  const Eigen::Vector3d y = z.cross(x);  // down
  Eigen::Matrix3d table_from_device_rotation;
  table_from_device_rotation << x, y, z;
  return Rigid3d(table_from_device_rotation, eye);
}

}  // namespace sandtable::sim
