#include "sim/transport/ray_caster.h"

#include <cmath>
#include <limits>

#include <embree3/rtcore.h>

namespace sandtable::sim {

struct RayCaster::Impl {
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  ~Impl() {
    if (scene) rtcReleaseScene(scene);
    if (device) rtcReleaseDevice(device);
  }
};

Expected<std::unique_ptr<RayCaster>> RayCaster::Create(const Scene& scene,
                                                       const std::string& embree_config) {
  if (scene.NumTriangles() == 0) return InvalidArgumentError("ray caster: scene has no triangles");
  std::unique_ptr<RayCaster> caster(new RayCaster(scene));
  caster->impl_ = std::make_unique<Impl>();
  Impl& impl = *caster->impl_;
  impl.device = rtcNewDevice(embree_config.empty() ? nullptr : embree_config.c_str());
  if (!impl.device) {
    return UnavailableError("ray caster: Embree device could not be created (error " +
                            std::to_string(rtcGetDeviceError(nullptr)) + ")");
  }
  impl.scene = rtcNewScene(impl.device);
  rtcSetSceneBuildQuality(impl.scene, RTC_BUILD_QUALITY_HIGH);
  RTCGeometry geometry = rtcNewGeometry(impl.device, RTC_GEOMETRY_TYPE_TRIANGLE);
  float* vertices = static_cast<float*>(
      rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                              3 * sizeof(float), scene.NumVertices()));
  unsigned* indices = static_cast<unsigned*>(
      rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                              3 * sizeof(unsigned), scene.NumTriangles()));
  if (!vertices || !indices) {
    rtcReleaseGeometry(geometry);
    return UnavailableError("ray caster: Embree could not allocate geometry buffers");
  }
  for (int i = 0; i < scene.NumVertices(); ++i) {
    for (int k = 0; k < 3; ++k) vertices[3 * i + k] = scene.positions_in_table_m[i][k];
  }
  for (int t = 0; t < scene.NumTriangles(); ++t) {
    for (int k = 0; k < 3; ++k) indices[3 * t + k] = static_cast<unsigned>(scene.triangles[t][k]);
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

RayCaster::RayCaster(const Scene& scene) : scene_(scene) {}
RayCaster::~RayCaster() = default;

RayHit RayCaster::Intersect(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction,
                            double near_m, double far_m) const {
  RayHit out;
  const double norm = direction.norm();
  if (!(norm > 0) || !origin.allFinite() || !direction.allFinite()) return out;
  const Eigen::Vector3d d = direction / norm;
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  RTCRayHit rh;
  rh.ray.org_x = static_cast<float>(origin.x());
  rh.ray.org_y = static_cast<float>(origin.y());
  rh.ray.org_z = static_cast<float>(origin.z());
  rh.ray.dir_x = static_cast<float>(d.x());
  rh.ray.dir_y = static_cast<float>(d.y());
  rh.ray.dir_z = static_cast<float>(d.z());
  rh.ray.tnear = static_cast<float>(near_m);
  rh.ray.tfar = static_cast<float>(std::min(far_m, 1e30));
  rh.ray.mask = 0xFFFFFFFFu;
  rh.ray.flags = 0;
  rh.ray.time = 0.0f;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(impl_->scene, &context, &rh);
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return out;
  out.hit = true;
  out.triangle = static_cast<int>(rh.hit.primID);
  out.distance_m = rh.ray.tfar;
  out.u = rh.hit.u;
  out.v = rh.hit.v;
  // Refine in double: intersect the exact ray with the triangle's plane, and recompute the
  // barycentrics there (Embree's float distance carries ~1e-7 relative error).
  const Eigen::Vector3i& tri = scene_.triangles[out.triangle];
  const Eigen::Vector3d p0 = scene_.positions_in_table_m[tri[0]].cast<double>();
  const Eigen::Vector3d e1 = scene_.positions_in_table_m[tri[1]].cast<double>() - p0;
  const Eigen::Vector3d e2 = scene_.positions_in_table_m[tri[2]].cast<double>() - p0;
  const Eigen::Vector3d n = e1.cross(e2);
  const double denominator = n.dot(d);
  if (std::abs(denominator) > 1e-12 * n.norm()) {
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
  return out;
}

namespace {

// The shadow ray of Occluded() from `from` to `to`; false when the segment is too short to
// be occluded.
bool MakeShadowRay(const Eigen::Vector3d& from, const Eigen::Vector3d& to, double epsilon_m,
                   RTCRay* ray) {
  const Eigen::Vector3d delta = to - from;
  const double length = delta.norm();
  if (!(length > 2 * epsilon_m)) return false;
  const Eigen::Vector3d d = delta / length;
  ray->org_x = static_cast<float>(from.x());
  ray->org_y = static_cast<float>(from.y());
  ray->org_z = static_cast<float>(from.z());
  ray->dir_x = static_cast<float>(d.x());
  ray->dir_y = static_cast<float>(d.y());
  ray->dir_z = static_cast<float>(d.z());
  ray->tnear = static_cast<float>(epsilon_m);
  ray->tfar = static_cast<float>(length - epsilon_m);
  ray->mask = 0xFFFFFFFFu;
  ray->flags = 0;
  ray->time = 0.0f;
  ray->id = 0;
  return true;
}

}  // namespace

bool RayCaster::Occluded(const Eigen::Vector3d& from, const Eigen::Vector3d& to,
                         double epsilon_m) const {
  RTCRay ray;
  if (!MakeShadowRay(from, to, epsilon_m, &ray)) return false;
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  rtcOccluded1(impl_->scene, &context, &ray);
  return ray.tfar == -std::numeric_limits<float>::infinity();
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
  for (size_t k = 0; k < rays.size(); ++k) {
    (*occluded)[index[k]] = rays[k].tfar == -std::numeric_limits<float>::infinity();
  }
}

}  // namespace sandtable::sim
