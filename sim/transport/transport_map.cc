#include "sim/transport/transport_map.h"

#include <algorithm>
#include <cmath>
#include <thread>

namespace sandtable::sim {

namespace {

// Shadow rays start this far from the surface point and stop this far from the projector, so
// the point's own triangle (float rounding in Embree) never shadows it. 50 um is far below a
// projector pixel's footprint (~1 mm on the table).
constexpr double kShadowEpsilon_m = 5e-5;

// Overlaps of the box [centre - half, centre + half] with pixels x0 .. x0 + 3 (pixel i covers
// [i - 0.5, i + 0.5]), normalised to sum 1. Returns x0.
int BoxWeights(double centre, double half, double weights[4]) {
  half = std::clamp(half, 0.01, 0.5 * kMaxFootprint_px);
  const double lo = centre - half, hi = centre + half;
  const int x0 = static_cast<int>(std::floor(lo + 0.5));
  for (int i = 0; i < 4; ++i) {
    const double a = std::max(lo, x0 + i - 0.5), b = std::min(hi, x0 + i + 0.5);
    weights[i] = std::max(0.0, b - a) / (2 * half);
  }
  return x0;
}

}  // namespace

namespace {

// A projector's pose, precomputed once per map: the rotation as a matrix (a quaternion
// rotation costs about twice as much, and this runs for every pixel and projector).
struct ProjectorPose {
  Eigen::Matrix3d projector_from_table_rotation;
  Eigen::Vector3d centre_in_table_m;
  explicit ProjectorPose(const ProjectorSpec& projector)
      : projector_from_table_rotation(
            projector.table_from_projector.rotation.conjugate().toRotationMatrix()),
        centre_in_table_m(projector.table_from_projector.translation) {}
  Eigen::Vector3d ToProjector(const Eigen::Vector3d& point_in_table_m) const {
    return projector_from_table_rotation * (point_in_table_m - centre_in_table_m);
  }
};

// The projection of a point into the projector: `distance_m` (to the centre) always; on true
// (the point is projectable), projectable, pixel_px (maybe outside the image) and the blur.
bool ProjectionAt(const ProjectorSpec& projector, const ProjectorPose& pose,
                  const Eigen::Vector3d& point, double distance_m, ProjectorSample* out) {
  out->distance_m = distance_m;
  const Eigen::Vector3d x_in_projector = pose.ToProjector(point);
  const std::optional<Eigen::Vector2d> pixel = projector.model.Project(x_in_projector);
  if (!pixel) return false;
  out->projectable = true;
  out->pixel_px = *pixel;
  out->blur_px = 0.0;
  if (projector.aperture_diameter_m > 0 && projector.focus_distance_m > 0) {
    // Thin lens focused at s: the blur circle of a point at depth z (along the axis) on the
    // image side is A f |z - s| / (z (s - f)); in pixels (f / pitch = fx_px, s >> f) that is
    // fx_px A |z - s| / (z s).
    const double z = x_in_projector.z();
    const double s = projector.focus_distance_m;
    out->blur_px =
        projector.model.fx_px * projector.aperture_diameter_m * std::abs(z - s) / (z * s);
  }
  return true;
}

// Everything of SampleProjector except the shadow ray: false when the projector cannot light
// the point (behind the surface or the projector, outside its image). On true, *out holds the
// sample of a visible point (visible is set only then). The facing test comes first: it is
// cheap and rejects half of the candidates before their projection.
bool ProjectorGeometryAt(const ProjectorSpec& projector, const ProjectorPose& pose,
                         const Eigen::Vector3d& point, const Eigen::Vector3d& normal,
                         ProjectorSample* out) {
  const Eigen::Vector3d to_projector = pose.centre_in_table_m - point;
  const double d = to_projector.norm();
  if (!(d > 0)) return false;
  const double cos_theta = normal.dot(to_projector) / d;
  if (cos_theta <= 0.0) return false;
  if (!ProjectionAt(projector, pose, point, d, out) || !projector.model.InImage(out->pixel_px)) {
    return false;
  }
  out->visible = true;
  out->gain_per_m2 = cos_theta / (d * d);
  return true;
}

ProjectorSample SampleProjectorAt(const ProjectorSpec& projector, const ProjectorPose& pose,
                                  const RayCaster& caster, const Eigen::Vector3d& point,
                                  const Eigen::Vector3d& normal) {
  ProjectorSample lit;
  if (ProjectorGeometryAt(projector, pose, point, normal, &lit) &&
      !caster.Occluded(point, pose.centre_in_table_m, kShadowEpsilon_m)) {
    return lit;
  }
  // Not lit: the projection alone (also outside the image, grazing or shadowed).
  ProjectorSample unlit;
  ProjectionAt(projector, pose, point, (pose.centre_in_table_m - point).norm(), &unlit);
  return unlit;
}

// One view pixel's surface point and footprint (see BuildTransportMap).
struct PixelSurface {
  int x = 0;
  Eigen::Vector3d point, normal;
  double albedo = 0.0;
  Eigen::Vector3d footprint[2];
  bool has_footprint = false;
};

}  // namespace

ProjectorSample SampleProjector(const ProjectorSpec& projector, const RayCaster& caster,
                                const Eigen::Vector3d& point, const Eigen::Vector3d& normal) {
  return SampleProjectorAt(projector, ProjectorPose(projector), caster, point, normal);
}

ProjectorSample ProjectPoint(const ProjectorSpec& projector, const Eigen::Vector3d& point) {
  const ProjectorPose pose(projector);
  ProjectorSample out;
  ProjectionAt(projector, pose, point, (pose.centre_in_table_m - point).norm(), &out);
  return out;
}

size_t TransportMap::NumEntries() const {
  size_t n = 0;
  for (const auto& e : entries) n += e.size();
  return n;
}

Status TransportOptions::Check() const {
  if (num_threads < 0 || num_threads > 1024) {
    return InvalidArgumentError("transport: num_threads = " + std::to_string(num_threads) +
                                " must be in [0, 1024]");
  }
  return OkStatus();
}

Expected<TransportMap> BuildTransportMap(const Site& site, const RayCaster& caster,
                                         const View& view, const TransportOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  if (Status valid = view.Check(); !valid.ok()) return valid.WithContext("transport");
  const Scene& scene = caster.scene();
  const int width = view.width_px(), height = view.height_px();
  const size_t num_pixels = static_cast<size_t>(width) * height;
  const size_t num_units = site.units.size();
  TransportMap map;
  map.width_px = width;
  map.height_px = height;
  map.hit.assign(num_pixels, 0);
  map.albedo.assign(num_pixels, 0.0f);
  map.point_in_table_m.assign(num_pixels, Eigen::Vector3f::Zero());
  map.normal_in_table.assign(num_pixels, Eigen::Vector3f::Zero());

  int threads = options.num_threads > 0 ? options.num_threads
                                        : static_cast<int>(std::thread::hardware_concurrency());
  threads = std::clamp(threads, 1, height);
  // Each thread fills a contiguous band of rows into its own entry lists; concatenating the
  // bands in order gives the same map for any thread count.
  std::vector<std::vector<std::vector<TransportEntry>>> band_entries(
      threads, std::vector<std::vector<TransportEntry>>(num_units));
  Eigen::Vector3d origin_step_x, direction_step_x, origin_step_y, direction_step_y;
  view.RayStep(&origin_step_x, &direction_step_x, &origin_step_y, &direction_step_y);
  std::vector<ProjectorPose> poses;
  for (const UnitSpec& unit : site.units) poses.emplace_back(unit.projector);
  auto work = [&](int band) {
    const int y0 = static_cast<int>(static_cast<int64_t>(height) * band / threads);
    const int y1 = static_cast<int>(static_cast<int64_t>(height) * (band + 1) / threads);
    // At most one entry per pixel and projector: reserving that (untouched pages cost
    // nothing) avoids regrowing and copying the lists.
    for (auto& list : band_entries[band]) list.reserve(static_cast<size_t>(y1 - y0) * width);
    // Per row: first every pixel's surface point (primary rays, one coherent batch), then per
    // projector the candidates' shadow rays as one coherent batch (they all end at the
    // projector centre), then the entries in pixel order.
    std::vector<Ray> rays;  // the row's primary rays, one coherent batch
    std::vector<int> ray_x;
    std::vector<std::optional<RayHit>> hits;
    std::vector<PixelSurface> surfaces;
    std::vector<ProjectorSample> samples;
    std::vector<Eigen::Vector3d> shadow_from;
    std::vector<uint8_t> occluded;
    surfaces.reserve(width);
    for (int y = y0; y < y1; ++y) {
      surfaces.clear();
      rays.clear();
      ray_x.clear();
      for (int x = 0; x < width; ++x) {
        Ray ray;
        if (!view.Ray(x, y, &ray.origin_in_table_m, &ray.direction_in_table)) continue;
        rays.push_back(ray);
        ray_x.push_back(x);
      }
      caster.IntersectBatch(rays, &hits, /*coherent=*/true);
      for (size_t r = 0; r < rays.size(); ++r) {
        const std::optional<RayHit>& hit = hits[r];
        if (!hit) continue;
        const int x = ray_x[r];
        const size_t pixel = static_cast<size_t>(y) * width + x;
        const Eigen::Vector3d& origin = rays[r].origin_in_table_m;
        const Eigen::Vector3d& direction = rays[r].direction_in_table;
        PixelSurface surface;
        surface.x = x;
        surface.point = hit->point_in_table_m;
        // (direction keeps the scale of View::Ray so the ray steps above apply to it.)
        surface.normal = hit->normal_in_table;  // faces the view
        surface.albedo = scene.AlbedoAt(hit->triangle, hit->u, hit->v);
        map.hit[pixel] = 1;
        map.albedo[pixel] = static_cast<float>(surface.albedo);
        map.point_in_table_m[pixel] = surface.point.cast<float>();
        map.normal_in_table[pixel] = surface.normal.cast<float>();
        // The pixel's footprint on the surface's tangent plane: where the rays of the pixel's
        // edge midpoints (half a pixel step) meet the plane through `point` with `normal`.
        surface.has_footprint = true;
        for (int axis = 0; axis < 2; ++axis) {
          const Eigen::Vector3d o = origin + 0.5 * (axis == 0 ? origin_step_x : origin_step_y);
          const Eigen::Vector3d d =
              direction + 0.5 * (axis == 0 ? direction_step_x : direction_step_y);
          const double denominator = surface.normal.dot(d);
          if (std::abs(denominator) < 1e-12) {
            surface.has_footprint = false;
            break;
          }
          surface.footprint[axis] = o + surface.normal.dot(surface.point - o) / denominator * d;
        }
        surfaces.push_back(surface);
      }
      for (size_t p = 0; p < num_units; ++p) {
        const ProjectorSpec& projector = site.units[p].projector;
        const ProjectorPose& pose = poses[p];
        samples.assign(surfaces.size(), ProjectorSample());
        shadow_from.clear();
        for (size_t i = 0; i < surfaces.size(); ++i) {
          if (ProjectorGeometryAt(projector, pose, surfaces[i].point, surfaces[i].normal,
                                  &samples[i])) {
            shadow_from.push_back(surfaces[i].point);
          }
        }
        caster.OccludedToPoint(shadow_from, pose.centre_in_table_m, kShadowEpsilon_m, &occluded);
        size_t next_shadow = 0;
        for (size_t i = 0; i < surfaces.size(); ++i) {
          const ProjectorSample& s = samples[i];
          if (!s.visible || occluded[next_shadow++]) continue;
          const PixelSurface& surface = surfaces[i];
          const size_t pixel = static_cast<size_t>(y) * width + surface.x;
          // Half extents of the footprint box in projector pixels: twice the half-pixel
          // displacements give the per-pixel Jacobian; the box covers |du/dx| + |du/dy|.
          double half_u = 0.0, half_v = 0.0;
          if (surface.has_footprint) {
            for (int axis = 0; axis < 2; ++axis) {
              // The footprint points are within a pixel of the (in-domain, in-front) sample
              // point, so they are projected without Project()'s domain test.
              const Eigen::Vector3d f = pose.ToProjector(surface.footprint[axis]);
              if (!(f.z() > 0.0)) continue;
              const Eigen::Vector2d q =
                  projector.model.PixelFromNormalized(projector.model.Distort(f.head<2>() / f.z()));
              half_u += std::abs(q.x() - s.pixel_px.x());  // = 0.5 |du/d(axis)|
              half_v += std::abs(q.y() - s.pixel_px.y());
            }
          }
          // Defocus widens the box to the blur circle's diameter.
          half_u = std::max(half_u, 0.5 * s.blur_px);
          half_v = std::max(half_v, 0.5 * s.blur_px);
          double wu[4], wv[4];
          const int x0 = BoxWeights(s.pixel_px.x(), half_u, wu);
          const int v0 = BoxWeights(s.pixel_px.y(), half_v, wv);
          const int padded_width = projector.model.width_px + 2 * kFramePadding_px;
          TransportEntry e;
          e.pixel = static_cast<uint32_t>(pixel);
          e.frame_offset =
              static_cast<uint32_t>((v0 + kFramePadding_px) * padded_width + x0 + kFramePadding_px);
          const double gain = surface.albedo * projector.peak_luminance_at_1m_nits * s.gain_per_m2;
          for (int i4 = 0; i4 < 4; ++i4) {
            e.wu[i4] = static_cast<uint16_t>(std::lround(wu[i4] * 65535.0));
            e.wv[i4] = static_cast<float>(wv[i4] * gain);
          }
          band_entries[band][p].push_back(e);
        }
      }
    }
  };
  if (threads == 1) {
    work(0);
  } else {
    std::vector<std::thread> pool;
    for (int b = 0; b < threads; ++b) pool.emplace_back(work, b);
    for (std::thread& t : pool) t.join();
  }
  map.entries.resize(num_units);
  for (size_t p = 0; p < num_units; ++p) {
    if (threads == 1) {
      map.entries[p] = std::move(band_entries[0][p]);
      continue;
    }
    size_t total = 0;
    for (int b = 0; b < threads; ++b) total += band_entries[b][p].size();
    map.entries[p].reserve(total);
    for (int b = 0; b < threads; ++b) {
      map.entries[p].insert(map.entries[p].end(), band_entries[b][p].begin(),
                            band_entries[b][p].end());
    }
  }
  return map;
}

}  // namespace sandtable::sim
