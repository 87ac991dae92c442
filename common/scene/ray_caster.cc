#include "common/scene/ray_caster.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include <embree3/rtcore.h>

#include "common/base/check.h"

namespace sandtable {

struct RayCaster::Impl {
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  ~Impl() {
    if (scene) rtcReleaseScene(scene);
    if (device) rtcReleaseDevice(device);
  }
};

namespace {

// Embree's float range stops here (a ray "without far end" ends at 1e30 m).
constexpr double kMaxFar_m = 1e30;

// Fills an Embree ray for origin + s unit_dir, s in [near_m, far_m]; false (a miss) when the
// ray is not castable: zero or non-finite direction, non-finite origin, empty range.
bool MakeRay(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, double near_m,
             double far_m, RTCRay* ray, Eigen::Vector3d* unit_dir) {
  const double norm = direction.norm();
  if (!(norm > 0) || !std::isfinite(norm) || !origin.allFinite()) return false;
  if (origin.cwiseAbs().maxCoeff() > kMaxRayOrigin_m) return false;
  near_m = std::max(0.0, near_m);
  far_m = std::min(far_m, kMaxFar_m);
  if (!(far_m >= near_m)) return false;  // also false for NaN
  *unit_dir = direction / norm;
  ray->org_x = static_cast<float>(origin.x());
  ray->org_y = static_cast<float>(origin.y());
  ray->org_z = static_cast<float>(origin.z());
  ray->dir_x = static_cast<float>(unit_dir->x());
  ray->dir_y = static_cast<float>(unit_dir->y());
  ray->dir_z = static_cast<float>(unit_dir->z());
  ray->tnear = static_cast<float>(near_m);
  ray->tfar = static_cast<float>(far_m);
  ray->mask = 0xFFFFFFFFu;
  ray->flags = 0;
  ray->time = 0.0f;
  ray->id = 0;
  return true;
}

void ClearHit(RTCHit* hit) {
  hit->geomID = RTC_INVALID_GEOMETRY_ID;
  hit->primID = RTC_INVALID_GEOMETRY_ID;
  hit->instID[0] = RTC_INVALID_GEOMETRY_ID;
}

// The shadow ray of Occluded() from `from` to `to`; false when the segment is too short to
// be occluded (or not finite).
bool MakeShadowRay(const Eigen::Vector3d& from, const Eigen::Vector3d& to, double epsilon_m,
                   RTCRay* ray) {
  const Eigen::Vector3d delta = to - from;
  const double length = delta.norm();
  if (!(length > 2 * epsilon_m) || !std::isfinite(length)) return false;
  Eigen::Vector3d unit_dir;
  return MakeRay(from, delta, epsilon_m, length - epsilon_m, ray, &unit_dir);
}

bool WasOccluded(const RTCRay& ray) { return ray.tfar == -std::numeric_limits<float>::infinity(); }

}  // namespace

Expected<std::unique_ptr<RayCaster>> RayCaster::Create(std::shared_ptr<const Scene> scene,
                                                       const std::string& embree_config) {
  if (!scene) return InvalidArgumentError("ray caster: no scene");
  if (scene->NumTriangles() == 0) return InvalidArgumentError("ray caster: scene has no triangles");
  for (int i = 0; i < scene->NumVertices(); ++i) {
    const Eigen::Vector3f& p = scene->positions_in_table_m[i];
    if (!p.allFinite()) {
      return InvalidArgumentError("ray caster: vertex " + std::to_string(i) + " is not finite");
    }
    if (p.cwiseAbs().maxCoeff() > kMaxSceneCoordinate_m) {
      std::ostringstream s;
      s << "ray caster: vertex " << i << " at (" << p.x() << ", " << p.y() << ", " << p.z()
        << ") m is outside |x|, |y|, |z| <= kMaxSceneCoordinate_m = " << kMaxSceneCoordinate_m
        << " m";
      return InvalidArgumentError(s.str());
    }
  }
  for (int t = 0; t < scene->NumTriangles(); ++t) {
    for (int k = 0; k < 3; ++k) {
      const int index = scene->triangles[t][k];
      if (index < 0 || index >= scene->NumVertices()) {
        return InvalidArgumentError("ray caster: triangle " + std::to_string(t) + " vertex " +
                                    std::to_string(index) + " is out of range [0, " +
                                    std::to_string(scene->NumVertices()) + ")");
      }
    }
  }
  std::unique_ptr<RayCaster> caster(new RayCaster(std::move(scene)));
  const Scene& s = *caster->scene_;
  caster->impl_ = std::make_unique<Impl>();
  Impl& impl = *caster->impl_;
  impl.device = rtcNewDevice(embree_config.empty() ? nullptr : embree_config.c_str());
  if (!impl.device) {
    return UnavailableError("ray caster: Embree device could not be created (config '" +
                            embree_config + "', error " +
                            std::to_string(rtcGetDeviceError(nullptr)) + ")");
  }
  impl.scene = rtcNewScene(impl.device);
  rtcSetSceneBuildQuality(impl.scene, RTC_BUILD_QUALITY_HIGH);
  RTCGeometry geometry = rtcNewGeometry(impl.device, RTC_GEOMETRY_TYPE_TRIANGLE);
  float* vertices = static_cast<float*>(rtcSetNewGeometryBuffer(
      geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), s.NumVertices()));
  unsigned* indices = static_cast<unsigned*>(
      rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                              3 * sizeof(unsigned), s.NumTriangles()));
  if (!vertices || !indices) {
    rtcReleaseGeometry(geometry);
    return UnavailableError("ray caster: Embree could not allocate geometry buffers");
  }
  for (int i = 0; i < s.NumVertices(); ++i) {
    for (int k = 0; k < 3; ++k) vertices[3 * i + k] = s.positions_in_table_m[i][k];
  }
  for (int t = 0; t < s.NumTriangles(); ++t) {
    for (int k = 0; k < 3; ++k) indices[3 * t + k] = static_cast<unsigned>(s.triangles[t][k]);
  }
  rtcCommitGeometry(geometry);
  rtcAttachGeometry(impl.scene, geometry);
  rtcReleaseGeometry(geometry);
  rtcCommitScene(impl.scene);
  if (rtcGetDeviceError(impl.device) != RTC_ERROR_NONE) {
    return UnavailableError("ray caster: Embree failed to build the scene");
  }
  return caster;
}

RayCaster::RayCaster(std::shared_ptr<const Scene> scene) : scene_(std::move(scene)) {}
RayCaster::~RayCaster() = default;

RayHit RayCaster::FinishHit(const Eigen::Vector3d& origin, const Eigen::Vector3d& d, int triangle,
                            double distance_m, double u, double v) const {
  RayHit out;
  out.triangle = triangle;
  out.distance_m = distance_m;
  out.u = u;
  out.v = v;
  // Refine in double: intersect the exact ray with the triangle's plane, and recompute the
  // barycentrics there (Embree's float distance carries ~1e-7 relative error).
  const Eigen::Vector3i& tri = scene_->triangles[triangle];
  const Eigen::Vector3d p0 = scene_->positions_in_table_m[tri[0]].cast<double>();
  const Eigen::Vector3d e1 = scene_->positions_in_table_m[tri[1]].cast<double>() - p0;
  const Eigen::Vector3d e2 = scene_->positions_in_table_m[tri[2]].cast<double>() - p0;
  const Eigen::Vector3d n = e1.cross(e2);
  const double n_norm = n.norm();
  const double denominator = n.dot(d);
  if (std::abs(denominator) > 1e-12 * n_norm) {
    const double s = n.dot(p0 - origin) / denominator;
    if (std::isfinite(s) && std::abs(s - out.distance_m) < 1e-3 * (1 + out.distance_m)) {
      out.distance_m = s;
      const Eigen::Vector3d w = origin + s * d - p0;
      // Solve w = u e1 + v e2 in the plane (least squares via the Gram matrix).
      const double a = e1.dot(e1), b = e1.dot(e2), c = e2.dot(e2);
      const double det = a * c - b * b;
      if (det > 0) {
        out.u = (c * w.dot(e1) - b * w.dot(e2)) / det;
        out.v = (a * w.dot(e2) - b * w.dot(e1)) / det;
      }
    }
  }
  out.point_in_table_m = origin + out.distance_m * d;
  // Same arithmetic as Scene::FaceNormal, so both give the same bits.
  const Eigen::Vector3d face_normal =
      n_norm > 0.0 ? Eigen::Vector3d(n / n_norm) : Eigen::Vector3d::Zero();
  out.front_face = !(face_normal.dot(d) > 0);
  out.normal_in_table = out.front_face ? face_normal : Eigen::Vector3d(-face_normal);
  return out;
}

std::optional<RayHit> RayCaster::Intersect(const Eigen::Vector3d& origin,
                                           const Eigen::Vector3d& direction, double near_m,
                                           double far_m) const {
  RTCRayHit rh;
  Eigen::Vector3d d;
  if (!MakeRay(origin, direction, near_m, far_m, &rh.ray, &d)) return std::nullopt;
  ClearHit(&rh.hit);
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  rtcIntersect1(impl_->scene, &context, &rh);
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return std::nullopt;
  return FinishHit(origin, d, static_cast<int>(rh.hit.primID), rh.ray.tfar, rh.hit.u, rh.hit.v);
}

std::optional<RayHit> RayCaster::Intersect(const Ray& ray) const {
  return Intersect(ray.origin_in_table_m, ray.direction_in_table, ray.near_m, ray.far_m);
}

void RayCaster::IntersectBatch(const std::vector<Ray>& rays,
                               std::vector<std::optional<RayHit>>* hits, bool coherent) const {
  hits->assign(rays.size(), std::nullopt);
  std::vector<RTCRayHit> batch;
  std::vector<Eigen::Vector3d> unit_dirs;
  std::vector<size_t> index;
  batch.reserve(rays.size());
  unit_dirs.reserve(rays.size());
  index.reserve(rays.size());
  for (size_t i = 0; i < rays.size(); ++i) {
    RTCRayHit rh;
    Eigen::Vector3d d;
    if (!MakeRay(rays[i].origin_in_table_m, rays[i].direction_in_table, rays[i].near_m,
                 rays[i].far_m, &rh.ray, &d)) {
      continue;
    }
    ClearHit(&rh.hit);
    batch.push_back(rh);
    unit_dirs.push_back(d);
    index.push_back(i);
  }
  if (batch.empty()) return;
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  if (coherent) context.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  rtcIntersect1M(impl_->scene, &context, batch.data(), static_cast<unsigned>(batch.size()),
                 sizeof(RTCRayHit));
  for (size_t k = 0; k < batch.size(); ++k) {
    const RTCRayHit& rh = batch[k];
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) continue;
    (*hits)[index[k]] = FinishHit(rays[index[k]].origin_in_table_m, unit_dirs[k],
                                  static_cast<int>(rh.hit.primID), rh.ray.tfar, rh.hit.u, rh.hit.v);
  }
}

bool RayCaster::Occluded(const Eigen::Vector3d& from, const Eigen::Vector3d& to,
                         double epsilon_m) const {
  RTCRay ray;
  if (!MakeShadowRay(from, to, epsilon_m, &ray)) return false;
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  rtcOccluded1(impl_->scene, &context, &ray);
  return WasOccluded(ray);
}

void RayCaster::OccludedToPoint(const std::vector<Eigen::Vector3d>& from, const Eigen::Vector3d& to,
                                double epsilon_m, std::vector<uint8_t>* occluded) const {
  occluded->assign(from.size(), 0);
  std::vector<RTCRay> rays;
  std::vector<size_t> index;
  rays.reserve(from.size());
  index.reserve(from.size());
  for (size_t i = 0; i < from.size(); ++i) {
    RTCRay ray;
    if (!MakeShadowRay(from[i], to, epsilon_m, &ray)) continue;
    rays.push_back(ray);
    index.push_back(i);
  }
  if (rays.empty()) return;
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  context.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  rtcOccluded1M(impl_->scene, &context, rays.data(), static_cast<unsigned>(rays.size()),
                sizeof(RTCRay));
  for (size_t k = 0; k < rays.size(); ++k) (*occluded)[index[k]] = WasOccluded(rays[k]);
}

Eigen::Hyperplane<double, 3> RayCaster::TrianglePlane(int triangle) const {
  ST_CHECK(triangle >= 0 && triangle < scene_->NumTriangles())
      << "RayCaster::TrianglePlane: triangle " << triangle << " of " << scene_->NumTriangles();
  const Eigen::Vector3d normal = scene_->FaceNormal(triangle);
  const Eigen::Vector3d p0 =
      scene_->positions_in_table_m[scene_->triangles[triangle][0]].cast<double>();
  return Eigen::Hyperplane<double, 3>(normal, p0);
}

}  // namespace sandtable
