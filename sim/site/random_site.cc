#include "sim/site/random_site.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <optional>
#include <sstream>

#include <Eigen/Geometry>

#include "common/base/units.h"
#include "common/scene/mesh_builder.h"
#include "common/scene/random_scene.h"

namespace sandtable::sim {

namespace {

// The ranges a random site draws from.
constexpr int kMinUnits = 3, kMaxUnits = 8;
constexpr int kProjectorSizes[][2] = {{1024, 768}, {1280, 800}, {1920, 1080}, {1920, 1200}};
constexpr double kMinThrow = 0.8, kMaxThrow = 1.6;
constexpr double kMaxLensShift = 0.5;  // of the image height
constexpr double kMaxTilt_deg = 60.0;  // the image centre's ray from vertical
constexpr double kMinHeight_m = 0.6;   // projector above the table
constexpr int kCameraSizes[][2] = {{1024, 768}, {1280, 960}, {1280, 1024}, {1600, 1200}};
constexpr int kCameraBits[] = {8, 10, 12, 14, 16};
constexpr double kMinCameraFocal_px = 700.0, kMaxCameraFocal_px = 1100.0;
constexpr double kMinMount_m = 0.05, kMaxMount_m = 0.20;
constexpr double kMaxMountTurn_deg = 8.0;
// Footprints: the image's short side on the table spans this many layout cells (the rest of
// the cell's neighbours' overlap).
constexpr double kFootprintCells = 1.4;
// The camera's white: this share of full scale on the table at the aim point (albedo 0.8).
constexpr double kWhiteShare = 0.35;
constexpr int kMaxDraws = 200;

// Table points lit by a projector, on a 32 x 20 grid of its image (z = 0 plane).
std::vector<Eigen::Vector2d> LitTable(const TableSpec& table, const ProjectorSpec& projector,
                                      int* samples) {
  std::vector<Eigen::Vector2d> out;
  constexpr int kNx = 32, kNy = 20;
  *samples = 0;
  for (int j = 0; j < kNy; ++j) {
    for (int i = 0; i < kNx; ++i) {
      ++*samples;
      const Eigen::Vector2d pixel((i + 0.5) * projector.model.width_px / kNx - 0.5,
                                  (j + 0.5) * projector.model.height_px / kNy - 0.5);
      Expected<Eigen::Vector3d> ray = projector.model.Unproject(pixel);
      if (!ray.ok()) continue;
      const Eigen::Vector3d origin = projector.table_from_projector.translation;
      const Eigen::Vector3d dir = projector.table_from_projector.rotation * *ray;
      if (!(dir.z() < -1e-9)) continue;
      const double t = -origin.z() / dir.z();
      const Eigen::Vector2d xy = (origin + t * dir).head<2>();
      if (table.Contains(xy)) out.push_back(xy);
    }
  }
  return out;
}

bool SeenBy(const CameraModel& model, const Rigid3d& device_from_table, const Eigen::Vector2d& xy) {
  const std::optional<Eigen::Vector2d> pixel =
      model.Project(device_from_table * Eigen::Vector3d(xy.x(), xy.y(), 0.0));
  return pixel && model.InImage(*pixel);
}

bool CornersInvertible(const CameraModel& model) {
  for (const Eigen::Vector2d& corner :
       {Eigen::Vector2d(-0.5, -0.5), Eigen::Vector2d(model.width_px - 0.5, -0.5),
        Eigen::Vector2d(-0.5, model.height_px - 0.5),
        Eigen::Vector2d(model.width_px - 0.5, model.height_px - 0.5)}) {
    if (!model.Unproject(corner).ok()) return false;
  }
  return true;
}

std::string Percent(double share) {
  std::ostringstream s;
  s.precision(3);
  s << 100.0 * share << " %";
  return s.str();
}

// n layout centres spread over the table: Lloyd's relaxation of random starts over a 48 x 48
// sampling of the table.
std::vector<Eigen::Vector2d> Layout(const RandomTable& table, int n, SceneRng* rng) {
  const Eigen::Vector2d half = table.is_disc ? Eigen::Vector2d::Constant(0.5 * table.diameter_m)
                                             : Eigen::Vector2d(0.5 * table.size_m);
  std::vector<Eigen::Vector2d> samples;
  constexpr int kGrid = 48;
  for (int j = 0; j < kGrid; ++j) {
    for (int i = 0; i < kGrid; ++i) {
      const Eigen::Vector2d xy(-half.x() + (i + 0.5) * 2 * half.x() / kGrid,
                               -half.y() + (j + 0.5) * 2 * half.y() / kGrid);
      if (table.Contains(xy)) samples.push_back(xy);
    }
  }
  std::vector<Eigen::Vector2d> centres;
  while (static_cast<int>(centres.size()) < n) {
    centres.push_back(samples[rng->Index(static_cast<int>(samples.size()))]);
  }
  for (int iteration = 0; iteration < 30; ++iteration) {
    std::vector<Eigen::Vector2d> sum(n, Eigen::Vector2d::Zero());
    std::vector<int> count(n, 0);
    for (const Eigen::Vector2d& xy : samples) {
      int best = 0;
      for (int k = 1; k < n; ++k) {
        if ((xy - centres[k]).squaredNorm() < (xy - centres[best]).squaredNorm()) best = k;
      }
      sum[best] += xy;
      ++count[best];
    }
    for (int k = 0; k < n; ++k) {
      if (count[k] > 0) centres[k] = sum[k] / count[k];
    }
  }
  return centres;
}

ProjectorSpec DrawProjector(SceneRng* rng) {
  ProjectorSpec p;
  const auto& size = kProjectorSizes[rng->Index(4)];
  p.model = CameraModel::FromThrowRatio(size[0], size[1], rng->Uniform(kMinThrow, kMaxThrow),
                                        rng->Uniform(0.0, kMaxLensShift));
  p.model.distortion.k1 = rng->Uniform(-0.1, 0.05);
  p.model.distortion.k2 = rng->Uniform(-0.02, 0.02);
  p.model.distortion.p1 = rng->Uniform(-0.002, 0.002);
  p.model.distortion.p2 = rng->Uniform(-0.002, 0.002);
  p.model.distortion.k3 = rng->Uniform(-0.01, 0.01);
  p.gamma = rng->Uniform(1.8, 2.6);
  p.black_level = rng->Uniform(0.001, 0.005);
  p.peak_luminance_at_1m_nits = rng->Uniform(1500.0, 3000.0);
  return p;
}

CameraSpec DrawCamera(SceneRng* rng) {
  CameraSpec c;
  const auto& size = kCameraSizes[rng->Index(4)];
  const double f = rng->Uniform(kMinCameraFocal_px, kMaxCameraFocal_px);
  c.model = CameraModel(size[0], size[1], f, f * rng->Uniform(0.998, 1.002),
                        0.5 * (size[0] - 1) + rng->Uniform(-8.0, 8.0),
                        0.5 * (size[1] - 1) + rng->Uniform(-8.0, 8.0));
  c.model.distortion.k1 = rng->Uniform(-0.25, -0.02);
  c.model.distortion.k2 = rng->Uniform(0.0, 0.1);
  c.model.distortion.p1 = rng->Uniform(-0.001, 0.001);
  c.model.distortion.p2 = rng->Uniform(-0.001, 0.001);
  c.model.distortion.k3 = rng->Uniform(-0.02, 0.0);
  c.bit_depth = kCameraBits[rng->Index(5)];
  // Read noise of a sensor: about half an 8-bit DN, in the camera's own DN.
  c.read_noise_dn = rng->Uniform(0.3, 0.8) * std::ldexp(1.0, c.bit_depth - 8);
  c.full_well_e = rng->Uniform(6000.0, 20000.0);
  return c;
}

// One draw: a site that passes Site::Check, not yet checked for soundness.
Expected<Site> DrawSite(uint64_t seed, uint64_t draw) {
  SceneRng rng(seed * 1000003ULL + draw * 7919ULL + 0x5349544555ULL);
  const RandomTable table = RandomTableForSeed(seed);
  Site site;
  site.name = "random-" + std::to_string(seed);
  site.table.is_disc = table.is_disc;
  if (table.is_disc) {
    site.table.diameter_m = table.diameter_m;
  } else {
    site.table.size_m = table.size_m;
  }
  site.ambient_luminance_nits = rng.Uniform(2.0, 10.0);
  const int n = kMinUnits + rng.Index(kMaxUnits - kMinUnits + 1);
  const std::vector<Eigen::Vector2d> centres = Layout(table, n, &rng);
  const double cell_m = std::sqrt(table.Area_m2() / n);
  for (int k = 0; k < n; ++k) {
    UnitSpec unit;
    unit.id = static_cast<NodeId>(k);
    unit.name = "unit-" + std::to_string(k);
    unit.projector = DrawProjector(&rng);
    const CameraModel& pm = unit.projector.model;
    // The ray through the image centre, in the projector frame.
    const Eigen::Vector3d centre_ray =
        Eigen::Vector3d((0.5 * (pm.width_px - 1) - pm.cx_px) / pm.fx_px,
                        (0.5 * (pm.height_px - 1) - pm.cy_px) / pm.fy_px, 1.0)
            .normalized();
    const double image_width_m = kFootprintCells * cell_m * pm.width_px / pm.height_px;
    const double distance_m = image_width_m * pm.fx_px / pm.width_px / centre_ray.z();
    double tilt_rad = DegToRad(rng.Uniform(0.0, kMaxTilt_deg));
    tilt_rad = std::min(tilt_rad, std::acos(std::min(1.0, kMinHeight_m / distance_m)));
    const double azimuth_rad = rng.Uniform(0.0, 2 * std::numbers::pi);
    const double roll_rad = rng.Uniform(0.0, 2 * std::numbers::pi);
    const Eigen::Vector3d aim(centres[k].x(), centres[k].y(), 0.0);
    const Eigen::Vector3d eye =
        aim + distance_m * Eigen::Vector3d(std::sin(tilt_rad) * std::cos(azimuth_rad),
                                           std::sin(tilt_rad) * std::sin(azimuth_rad),
                                           std::cos(tilt_rad));
    // Any image "up": a horizontal hint (never parallel to a view at most 60 degrees off
    // vertical).
    Expected<Rigid3d> look = TableFromDeviceLookAt(
        eye, aim, Eigen::Vector3d(std::cos(roll_rad), std::sin(roll_rad), 0.0));
    if (!look.ok()) return look.status();
    // Turn the device so that its image centre's ray (not its optical axis) meets the aim.
    const Eigen::Matrix3d axis_from_centre_ray =
        Eigen::Quaterniond::FromTwoVectors(centre_ray, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    unit.projector.table_from_projector =
        Rigid3d(look->rotation * axis_from_centre_ray, look->translation);

    CameraSpec camera = DrawCamera(&rng);
    const double mount_m = rng.Uniform(kMinMount_m, kMaxMount_m);
    const double mount_dir_rad = rng.Uniform(0.0, 2 * std::numbers::pi);
    const Eigen::Vector3d camera_in_projector_m(mount_m * std::cos(mount_dir_rad),
                                                mount_m * std::sin(mount_dir_rad), 0.0);
    Expected<Rigid3d> toe_in = TableFromDeviceLookAt(camera_in_projector_m, distance_m * centre_ray,
                                                     Eigen::Vector3d(0.0, -1.0, 0.0));
    if (!toe_in.ok()) return toe_in.status();
    const double turn = DegToRad(kMaxMountTurn_deg);
    const Eigen::Matrix3d mount_turn =
        (Eigen::AngleAxisd(rng.Uniform(-turn, turn), Eigen::Vector3d::UnitY()) *
         Eigen::AngleAxisd(rng.Uniform(-0.5 * turn, 0.5 * turn), Eigen::Vector3d::UnitX()) *
         Eigen::AngleAxisd(rng.Uniform(-0.1, 0.1), Eigen::Vector3d::UnitZ()))
            .toRotationMatrix();
    camera.projector_from_camera = Rigid3d(toe_in->rotation * mount_turn, toe_in->translation);
    // Exposure for a white at kWhiteShare of full scale on the table at the aim point.
    const double luminance_nits = unit.projector.peak_luminance_at_1m_nits * 0.8 *
                                  std::cos(tilt_rad) / (distance_m * distance_m);
    camera.exposure_s = kWhiteShare * camera.saturation_nit_s / luminance_nits;
    unit.camera = camera;
    site.units.push_back(unit);
  }
  ST_RETURN_IF_ERROR(site.Check());
  return site;
}

}  // namespace

Status CheckSiteSoundness(const Site& site) {
  ST_RETURN_IF_ERROR(site.Check());
  const size_t n = site.units.size();
  std::vector<std::vector<Eigen::Vector2d>> lit(n);
  for (size_t i = 0; i < n; ++i) {
    const UnitSpec& unit = site.units[i];
    const std::string label = "unit " + std::to_string(unit.id);
    if (!CornersInvertible(unit.projector.model)) {
      return InvalidArgumentError(label +
                                  ": the projector's image corners are past the fold "
                                  "of its distortion");
    }
    int samples = 0;
    lit[i] = LitTable(site.table, unit.projector, &samples);
    const double lit_share = static_cast<double>(lit[i].size()) / samples;
    if (lit_share < kMinLitTableShare) {
      return InvalidArgumentError(label + ": " + Percent(lit_share) +
                                  " of its image lands on the table (at least " +
                                  Percent(kMinLitTableShare) + ")");
    }
    if (!unit.camera) return InvalidArgumentError(label + ": no camera");
    if (!CornersInvertible(unit.camera->model)) {
      return InvalidArgumentError(label +
                                  ": the camera's image corners are past the fold "
                                  "of its distortion");
    }
    const Rigid3d camera_from_table = site.TableFromCamera(unit).Inverse();
    int seen = 0;
    for (const Eigen::Vector2d& xy : lit[i])
      seen += SeenBy(unit.camera->model, camera_from_table, xy);
    const double seen_share = static_cast<double>(seen) / lit[i].size();
    if (seen_share < kMinOwnLightSeen) {
      return InvalidArgumentError(label + ": its camera sees " + Percent(seen_share) +
                                  " of its projector's light on the table (at least " +
                                  Percent(kMinOwnLightSeen) + ")");
    }
  }
  // Overlaps, and the group they connect.
  std::vector<std::vector<size_t>> neighbours(n);
  for (size_t i = 0; i < n; ++i) {
    double best = 0.0;
    for (size_t j = 0; j < n; ++j) {
      if (j == i) continue;
      const Rigid3d projector_from_table = site.units[j].projector.table_from_projector.Inverse();
      int shared = 0;
      for (const Eigen::Vector2d& xy : lit[i])
        shared += SeenBy(site.units[j].projector.model, projector_from_table, xy);
      const double share = static_cast<double>(shared) / lit[i].size();
      best = std::max(best, share);
      if (share >= kMinNeighbourOverlap) neighbours[i].push_back(j);
    }
    if (n > 1 && best < kMinNeighbourOverlap) {
      return InvalidArgumentError(
          "unit " + std::to_string(site.units[i].id) + ": overlaps no neighbour (at most " +
          Percent(best) + " of its footprint, at least " + Percent(kMinNeighbourOverlap) + ")");
    }
  }
  std::vector<bool> reached(n, false);
  std::vector<size_t> stack = {0};
  reached[0] = true;
  while (!stack.empty()) {
    const size_t i = stack.back();
    stack.pop_back();
    for (size_t j : neighbours[i]) {
      if (!reached[j]) {
        reached[j] = true;
        stack.push_back(j);
      }
    }
  }
  for (size_t i = 0; i < n; ++i) {
    if (!reached[i]) {
      return InvalidArgumentError("unit " + std::to_string(site.units[i].id) +
                                  ": its overlaps do not connect it to unit " +
                                  std::to_string(site.units[0].id));
    }
  }
  return OkStatus();
}

Expected<Site> MakeRandomSite(uint64_t seed, RandomSiteReport* report) {
  RandomSiteReport local;
  for (int draw = 0; draw < kMaxDraws; ++draw) {
    ++local.draws;
    Expected<Site> site = DrawSite(seed, static_cast<uint64_t>(draw));
    Status sound = site.ok() ? CheckSiteSoundness(*site) : site.status();
    if (sound.ok()) {
      if (report) *report = local;
      return site;
    }
    local.rejections.push_back(sound.message());
  }
  if (report) *report = local;
  return InternalError("random site " + std::to_string(seed) + ": no sound site in " +
                       std::to_string(kMaxDraws) + " draws (last: " + local.rejections.back() +
                       ")");
}

}  // namespace sandtable::sim
