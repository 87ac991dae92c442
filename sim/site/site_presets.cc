#include "sim/site/site_presets.h"

#include <cmath>
#include <numbers>
#include <optional>
#include <string>

#include "common/base/units.h"
#include "common/scene/procedural_scene.h"
#include "common/scene/random_scene.h"
#include "sim/site/random_site.h"

namespace sandtable::sim {

namespace {

constexpr double kOverlap = 0.25;

// The camera exposure an installer sets for a throw: the presets' 5 ms suits throws of 1.6 to
// 2.6 m (sandtable-3 1.65 m, grid-8 2.54 m); the light on the table goes as 1 / throw^2, so a
// longer throw (grid-1, grid-2: 5.1 m, a white near 20 DN at 5 ms) gets a longer exposure and a
// shorter one (grid-16 and up: 1.3 m and less, white saturated at 5 ms) a shorter one, keeping
// the white in the camera's range.
double ExposureForThrow(double throw_m) {
  constexpr double kExposure_s = 0.005, kShort_m = 1.6, kLong_m = 2.6;
  if (throw_m < kShort_m) return kExposure_s * (throw_m / kShort_m) * (throw_m / kShort_m);
  if (throw_m > kLong_m) return kExposure_s * (throw_m / kLong_m) * (throw_m / kLong_m);
  return kExposure_s;
}

// The camera mount: 0.12 m right of the projector, rotated about the projector's y axis to look
// at the projector's axis point at `aim_distance_m`.
Rigid3d CameraMount(double aim_distance_m) {
  constexpr double kOffset_m = 0.12;
  const double toe_in_rad = std::atan2(kOffset_m, aim_distance_m);
  // Camera axes in the projector frame: rotated by -toe_in about y (turning its z towards -x).
  const Eigen::Matrix3d projector_from_camera_rotation =
      Eigen::AngleAxisd(-toe_in_rad, Eigen::Vector3d::UnitY()).toRotationMatrix();
  return Rigid3d(projector_from_camera_rotation, Eigen::Vector3d(kOffset_m, 0.0, 0.0));
}

UnitSpec MakeUnit(NodeId id, const Rigid3d& table_from_projector, double aim_distance_m) {
  UnitSpec unit;
  unit.id = id;
  unit.name = "unit-" + std::to_string(id);
  unit.projector = DefaultProjector();
  unit.projector.table_from_projector = table_from_projector;
  unit.camera = DefaultCamera();
  unit.camera->projector_from_camera = CameraMount(aim_distance_m);
  return unit;
}

Expected<Site> Sandtable3() {
  Site site;
  site.name = "sandtable-3";
  site.table.is_disc = true;
  site.table.diameter_m = kSandtableTableDiameter_m;
  constexpr double kHeight_m = 1.55;
  const double tilt_rad = DegToRad(20.0);
  constexpr double kAimPastCentre_m = 0.15;
  const double horizontal_m = kHeight_m * std::tan(tilt_rad);  // from the aim point
  for (int i = 0; i < 3; ++i) {
    const double azimuth_rad = DegToRad(90.0 + 120.0 * i);
    const Eigen::Vector3d outward(std::cos(azimuth_rad), std::sin(azimuth_rad), 0.0);
    const Eigen::Vector3d aim = -kAimPastCentre_m * outward;
    const Eigen::Vector3d eye = aim + horizontal_m * outward + Eigen::Vector3d(0, 0, kHeight_m);
    Expected<Rigid3d> table_from_projector =
        TableFromDeviceLookAt(eye, aim, Eigen::Vector3d::UnitZ());
    if (!table_from_projector.ok()) return table_from_projector.status();
    site.units.push_back(MakeUnit(i, *table_from_projector, (eye - aim).norm()));
  }
  return site;
}

// rows x cols projectors over a rectangle, each looking down (tilted by tilt_deg about the
// table's x axis alternately), footprints overlapping by kOverlap.
Expected<Site> Grid(const std::string& name, int n, const Eigen::Vector2d& table_size_m,
                    double tilt_deg) {
  Site site;
  site.name = name;
  site.table.is_disc = false;
  site.table.size_m = table_size_m;
  const int rows = std::max(1, static_cast<int>(std::floor(std::sqrt(static_cast<double>(n)))));
  const int cols = (n + rows - 1) / rows;
  const ProjectorSpec p = DefaultProjector();
  // Distance along the axis so that the footprint covers one cell plus the overlap.
  const double cell_x = table_size_m.x() / cols, cell_y = table_size_m.y() / rows;
  const double distance_x = cell_x * (1 + kOverlap) * p.model.fx_px / p.model.width_px;
  const double distance_y = cell_y * (1 + kOverlap) * p.model.fy_px / p.model.height_px;
  const double distance_m = std::max(distance_x, distance_y);
  int id = 0;
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols && id < n; ++c, ++id) {
      const Eigen::Vector3d centre((c + 0.5) * cell_x - 0.5 * table_size_m.x(),
                                   (r + 0.5) * cell_y - 0.5 * table_size_m.y(), 0.0);
      const double tilt_rad = DegToRad(tilt_deg) * (r % 2 == 0 ? 1 : -1);
      const Eigen::Vector3d eye =
          centre + distance_m * Eigen::Vector3d(0, -std::sin(tilt_rad), std::cos(tilt_rad));
      Expected<Rigid3d> table_from_projector =
          TableFromDeviceLookAt(eye, centre, Eigen::Vector3d::UnitY());
      if (!table_from_projector.ok()) return table_from_projector.status();
      site.units.push_back(MakeUnit(id, *table_from_projector, distance_m));
      site.units.back().camera->exposure_s = ExposureForThrow(distance_m);
    }
  }
  return site;
}

}  // namespace

ProjectorSpec DefaultProjector() {
  ProjectorSpec p;
  p.model = CameraModel::FromThrowRatio(1280, 800, 1.27);
  p.model.distortion.k1 = 0.02;
  p.model.distortion.k2 = -0.005;
  return p;
}

CameraSpec DefaultCamera() {
  CameraSpec c;
  const double fx_px = 512.0 / std::tan(DegToRad(25.0));
  c.model = CameraModel(1024, 768, fx_px, fx_px, 511.5, 383.5);
  c.model.distortion.k1 = -0.08;
  c.model.distortion.k2 = 0.02;
  return c;
}

namespace {

Status ScaleModel(double factor, const std::string& what, CameraModel* model) {
  const int width = static_cast<int>(std::lround(model->width_px * factor));
  const int height = static_cast<int>(std::lround(model->height_px * factor));
  if (width < 32 || height < 32) {
    return InvalidArgumentError(what + ": " + std::to_string(model->width_px) + "x" +
                                std::to_string(model->height_px) + " at " + std::to_string(factor) +
                                " would be under 32 px");
  }
  const double sx = static_cast<double>(width) / model->width_px;
  const double sy = static_cast<double>(height) / model->height_px;
  model->fx_px *= sx;
  model->fy_px *= sy;
  model->cx_px = (model->cx_px + 0.5) * sx - 0.5;
  model->cy_px = (model->cy_px + 0.5) * sy - 0.5;
  model->width_px = width;
  model->height_px = height;
  return OkStatus();
}

}  // namespace

Status ScaleSiteResolution(double factor, Site* site) {
  if (!(factor > 0.0 && factor <= 1.0)) {
    return InvalidArgumentError("resolution scale " + std::to_string(factor) + " is not in (0, 1]");
  }
  if (factor == 1.0) return OkStatus();
  for (UnitSpec& unit : site->units) {
    ST_RETURN_IF_ERROR(ScaleModel(factor, unit.name + ".projector", &unit.projector.model));
    if (unit.camera)
      ST_RETURN_IF_ERROR(ScaleModel(factor, unit.name + ".camera", &unit.camera->model));
  }
  return site->Check();
}

Expected<Site> MakeSitePreset(std::string_view name) {
  Expected<Site> site =
      InvalidArgumentError("unknown site preset '" + std::string(name) +
                           "' (use sandtable-3, grid-N with N in 1..64, flat-4, random:SEED)");
  if (std::optional<uint64_t> seed = ParseRandomSeedName(std::string(name))) {
    site = MakeRandomSite(*seed);
  } else if (name == "sandtable-3") {
    site = Sandtable3();
  } else if (name == "flat-4") {
    site = Grid("flat-4", 4, {2.0, 1.5}, 10.0);
  } else if (name.substr(0, 5) == "grid-") {
    const std::string digits(name.substr(5));
    int n = 0;
    try {
      size_t used = 0;
      n = std::stoi(digits, &used);
      if (used != digits.size()) n = 0;
    } catch (const std::exception&) {
      n = 0;
    }
    if (n < 1 || n > 64) {
      return InvalidArgumentError("site preset '" + std::string(name) + "': N must be in 1..64");
    }
    site = Grid(std::string(name), n, {3.0, 2.0}, 0.0);
  }
  if (!site.ok()) return site;
  ST_RETURN_IF_ERROR(site->Check());
  return site;
}

}  // namespace sandtable::sim
