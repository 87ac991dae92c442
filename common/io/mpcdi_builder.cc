#include "common/io/mpcdi_builder.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <set>

namespace sandtable {

namespace {

constexpr double kDegFromRad = 180.0 / M_PI;

// The MPCDI viewer frame is the OpenCV device frame, so world_from_viewer is table_from_projector's
// rotation as it stands.
Eigen::Matrix3d TableFromViewer(const Rigid3d& table_from_projector) {
  return table_from_projector.RotationMatrix();
}

}  // namespace

Status MpcdiBuildOptions::Check() const {
  if (warp_step_px < 1) {
    return InvalidArgumentError(
        "MpcdiBuildOptions: warp_step_px = " + std::to_string(warp_step_px) + " must be >= 1");
  }
  if (buffer_id.empty()) return InvalidArgumentError("MpcdiBuildOptions: buffer_id is empty");
  return OkStatus();
}

MpcdiCoordinateFrame MpcdiTableCoordinateFrame(const Eigen::Vector3d& projector_centre_in_table_m) {
  MpcdiCoordinateFrame frame;  // the defaults are the table's axes (mpcdi.h)
  frame.position = projector_centre_in_table_m;
  frame.yaw_axis = Eigen::Vector3d(0.0, 0.0, -1.0);
  frame.pitch_axis = Eigen::Vector3d(1.0, 0.0, 0.0);
  frame.roll_axis = Eigen::Vector3d(0.0, 1.0, 0.0);
  return frame;
}

MpcdiFrustum MpcdiFrustumFromProjector(const CameraModel& projector,
                                       const Rigid3d& table_from_projector) {
  MpcdiFrustum frustum;
  // Image edges at -0.5 and size - 0.5 px (pixel centres at integers); normalized x = tan of the
  // angle from the optical axis, y down.
  frustum.right_angle_deg =
      std::atan((projector.width_px - 0.5 - projector.cx_px) / projector.fx_px) * kDegFromRad;
  frustum.left_angle_deg = -std::atan((projector.cx_px + 0.5) / projector.fx_px) * kDegFromRad;
  frustum.up_angle_deg = std::atan((projector.cy_px + 0.5) / projector.fy_px) * kDegFromRad;
  frustum.down_angle_deg =
      -std::atan((projector.height_px - 0.5 - projector.cy_px) / projector.fy_px) * kDegFromRad;
  SetMpcdiOrientation(TableFromViewer(table_from_projector),
                      MpcdiTableCoordinateFrame(table_from_projector.translation), &frustum);
  return frustum;
}

Expected<MpcdiWarp> ComputeMpcdiWarp(const CameraModel& projector,
                                     const Rigid3d& table_from_projector, const RayCaster& caster,
                                     int warp_step_px) {
  ST_RETURN_IF_ERROR(projector.Check().WithContext("MPCDI warp: projector"));
  if (!table_from_projector.AllFinite()) {
    return InvalidArgumentError("MPCDI warp: table_from_projector is not finite");
  }
  if (warp_step_px < 1) {
    return InvalidArgumentError("MPCDI warp: warp_step_px = " + std::to_string(warp_step_px) +
                                " must be >= 1");
  }
  MpcdiWarp warp;
  warp.samples_x = std::max(2, (projector.width_px + warp_step_px - 1) / warp_step_px);
  warp.samples_y = std::max(2, (projector.height_px + warp_step_px - 1) / warp_step_px);
  warp.interpolation = "linear";
  warp.geometric_unit = "m";
  warp.origin_of_3d_data = "unknown";
  if (warp.samples_x > kMaxMpcdiWarpSide || warp.samples_y > kMaxMpcdiWarpSide ||
      int64_t{warp.samples_x} * warp.samples_y > kMaxMpcdiWarpSamples) {
    return InvalidArgumentError("MPCDI warp: a " + std::to_string(warp.samples_x) + "x" +
                                std::to_string(warp.samples_y) +
                                " grid is over kMaxMpcdiWarpSide or kMaxMpcdiWarpSamples");
  }
  const size_t count = static_cast<size_t>(warp.samples_x) * warp.samples_y;
  const Eigen::Matrix3d table_from_projector_rotation = table_from_projector.RotationMatrix();
  std::vector<Ray> rays(count);
  std::vector<uint8_t> cast(count, 0);
  for (int j = 0; j < warp.samples_y; ++j) {
    for (int i = 0; i < warp.samples_x; ++i) {
      // Fill layout: the grid covers the image [-0.5, size - 0.5]; sample centres in between.
      const Eigen::Vector2d pixel((i + 0.5) * projector.width_px / warp.samples_x - 0.5,
                                  (j + 0.5) * projector.height_px / warp.samples_y - 0.5);
      const Expected<Eigen::Vector3d> direction_in_projector = projector.Unproject(pixel);
      const size_t k = static_cast<size_t>(j) * warp.samples_x + i;
      if (!direction_in_projector.ok()) continue;  // past the lens model's fold: NaN
      rays[k].origin_in_table_m = table_from_projector.translation;
      rays[k].direction_in_table = table_from_projector_rotation * *direction_in_projector;
      cast[k] = 1;
    }
  }
  std::vector<std::optional<RayHit>> hits;
  caster.IntersectBatch(rays, &hits, /*coherent=*/true);
  constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
  warp.samples.assign(count, Eigen::Vector3f(kNaN, kNaN, kNaN));
  for (size_t k = 0; k < count; ++k) {
    if (cast[k] && hits[k]) warp.samples[k] = hits[k]->point_in_table_m.cast<float>();
  }
  return warp;
}

Expected<MpcdiSite> BuildMpcdiSite(const std::vector<MpcdiUnit>& units, const RayCaster& caster,
                                   const MpcdiBuildOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  MpcdiSite site;
  site.profile = kMpcdiProfileShaderLamps;
  site.level = 1;
  site.version = "1.0";
  site.date = options.date;
  site.buffer_id = options.buffer_id;
  std::set<std::pair<int, int>> resolutions;
  for (size_t u = 0; u < units.size(); ++u) {
    const MpcdiUnit& unit = units[u];
    const UnitCalibration& calibration = unit.calibration;
    const std::string what = "MPCDI unit " + std::to_string(u) +
                             (calibration.unit_id != kInvalidNodeId
                                  ? " (unit_id " + std::to_string(calibration.unit_id) + ")"
                                  : std::string());
    ST_RETURN_IF_ERROR(calibration.Check().WithContext(what));
    if (!calibration.table_from_projector) {
      return InvalidArgumentError(what + ": no table_from_projector (the unit is not registered " +
                                  "in the site)");
    }
    const CameraModel& projector = calibration.projector;
    const Rigid3d& table_from_projector = *calibration.table_from_projector;
    MpcdiRegion region;
    region.id = unit.region_id;
    if (region.id.empty()) {
      if (calibration.unit_id == kInvalidNodeId) {
        return InvalidArgumentError(what + ": neither a region id nor a unit_id");
      }
      region.id = "unit-" + std::to_string(calibration.unit_id);
    }
    region.x_resolution_px = projector.width_px;
    region.y_resolution_px = projector.height_px;
    resolutions.insert({projector.width_px, projector.height_px});
    region.frustum = MpcdiFrustumFromProjector(projector, table_from_projector);
    region.coordinate_frame = MpcdiTableCoordinateFrame(table_from_projector.translation);
    Expected<MpcdiWarp> warp =
        ComputeMpcdiWarp(projector, table_from_projector, caster, options.warp_step_px);
    if (!warp.ok()) return warp.status().WithContext(what);
    region.warp = std::move(*warp);
    if (unit.alpha) {
      region.alpha = *unit.alpha;
    } else {
      MpcdiBlendMap alpha;
      alpha.width_px = projector.width_px;
      alpha.height_px = projector.height_px;
      alpha.values.assign(static_cast<size_t>(alpha.width_px) * alpha.height_px, 255);
      alpha.gamma_embedded = 1.0;
      region.alpha = std::move(alpha);
    }
    site.regions.push_back(std::move(region));
  }
  if (resolutions.size() == 1) {
    site.buffer_x_resolution_px = resolutions.begin()->first;
    site.buffer_y_resolution_px = resolutions.begin()->second;
  }
  ST_RETURN_IF_ERROR(site.CheckForWriting());
  return site;
}

Expected<MpcdiSite> BuildMpcdiSite(const std::vector<MpcdiUnit>& units,
                                   std::shared_ptr<const Scene> scene,
                                   const MpcdiBuildOptions& options) {
  Expected<std::unique_ptr<RayCaster>> caster = RayCaster::Create(std::move(scene));
  if (!caster.ok()) return caster.status().WithContext("MPCDI");
  return BuildMpcdiSite(units, **caster, options);
}

}  // namespace sandtable
