// RayCaster: closest-hit and shadow ray queries over a Scene, with Embree 3. The one ray caster
// of the project: the world's light transport and ground truth, the coordinator's wand, the
// lab's registration metric and the node's blending all cast through it.
//
// Frame and units: the scene's table frame, metres. Directions need not be unit; distances are
// along the normalised direction.
// Precision: Embree traverses and tests in float; Intersect() then refines the hit distance in
// double against the hit triangle's plane (vertices as stored, float), so a hit point lies on
// that plane to double rounding. Whether a ray passing within ~1e-7 relative of a triangle edge
// hits it is decided in float.
// Normals: the triangle's geometric normal from its counter-clockwise winding (Scene::FaceNormal)
// turned to face the ray's origin; front_face says which side was hit. Degenerate triangles
// (zero area) never hit.
// Threading: every const query may run concurrently from any number of threads once Create()
// has returned (Embree's committed scenes are read-only); the caster is immutable.
// Failure: Create() returns INVALID_ARGUMENT for a scene without triangles, a vertex index out
// of range, a non-finite vertex or one outside |x|, |y|, |z| <= kMaxSceneCoordinate_m (scene.h),
// before Embree sees it, and UNAVAILABLE when Embree cannot start or build. Queries never fail:
// a zero or non-finite direction, a non-finite origin or one outside |x|, |y|, |z| <=
// kMaxRayOrigin_m, or an empty [near, far] range, is a miss.
// Cost: build O(T log T) (Embree's high-quality BVH); a query visits O(log T) nodes.
#pragma once

#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "common/base/status.h"
#include "common/scene/scene.h"

namespace sandtable {

// The farthest ray origin cast, each coordinate, m (100 x kMaxSceneCoordinate_m): beyond it the
// float ray would lose all precision at the scene, so such a ray is a miss.
inline constexpr double kMaxRayOrigin_m = 1e6;

// The far end of a ray that has none.
inline constexpr double kRayNoFar_m = std::numeric_limits<double>::infinity();

struct Ray {
  Eigen::Vector3d origin_in_table_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d direction_in_table = Eigen::Vector3d::UnitX();  // need not be unit
  double near_m = 0.0;         // hits with distance in [near_m, far_m] (near_m < 0 counts as 0,
  double far_m = kRayNoFar_m;  // far_m is capped at Embree's 1e30 m)
};

// The closest hit of a ray.
struct RayHit {
  double distance_m = 0.0;                                     // along the unit direction
  Eigen::Vector3d point_in_table_m = Eigen::Vector3d::Zero();  // origin + distance * unit dir.
  Eigen::Vector3d normal_in_table = Eigen::Vector3d::UnitZ();  // unit, facing the ray origin
  bool front_face = true;   // the ray met the counter-clockwise side (FaceNormal . dir < 0)
  int triangle = -1;        // index into Scene::triangles
  double u = 0.0, v = 0.0;  // barycentrics: point = (1-u-v) p0 + u p1 + v p2 (Scene::AlbedoAt)
};

class RayCaster {
 public:
  // `embree_config` is passed to rtcNewDevice ("threads=1" for one core; "" = Embree default).
  // The caster shares ownership of `scene` (whose geometry must not change afterwards).
  static Expected<std::unique_ptr<RayCaster>> Create(std::shared_ptr<const Scene> scene,
                                                     const std::string& embree_config = "");
  ~RayCaster();
  RayCaster(const RayCaster&) = delete;
  RayCaster& operator=(const RayCaster&) = delete;

  // Closest hit of origin + s direction / |direction| for s in [near_m, far_m]; nullopt when
  // the ray hits nothing there.
  std::optional<RayHit> Intersect(const Eigen::Vector3d& origin_in_table_m,
                                  const Eigen::Vector3d& direction_in_table, double near_m = 0.0,
                                  double far_m = kRayNoFar_m) const;
  std::optional<RayHit> Intersect(const Ray& ray) const;
  // Intersect() of every ray as one Embree batch (rtcIntersect1M); the same hits as the
  // single-ray calls. `coherent`: the rays are coherent (neighbouring pixels of one view, or
  // rays sharing an origin) and traverse the tree together.
  void IntersectBatch(const std::vector<Ray>& rays, std::vector<std::optional<RayHit>>* hits,
                      bool coherent = false) const;

  // True when any triangle lies on the open segment from `from` to `to`, ignoring `epsilon_m`
  // at both ends (so a surface point is not shadowed by its own triangle). Cast shadows: a
  // surface point is visible to a projector when the segment to its centre is not occluded.
  bool Occluded(const Eigen::Vector3d& from_in_table_m, const Eigen::Vector3d& to_in_table_m,
                double epsilon_m = 1e-5) const;
  // Occluded(from[i], to, epsilon_m) for every i, as one coherent batch (rtcOccluded1M: shadow
  // rays that share an end point, e.g. a projector's centre, traverse the tree together). Same
  // result as the single-ray calls. (*occluded)[i] is 1 when occluded.
  void OccludedToPoint(const std::vector<Eigen::Vector3d>& from_in_table_m,
                       const Eigen::Vector3d& to_in_table_m, double epsilon_m,
                       std::vector<uint8_t>* occluded) const;

  // The plane of a triangle, n . x + offset = 0 with n = Scene::FaceNormal (counter-clockwise,
  // unit); zero normal for a degenerate triangle. CHECKs the index.
  Eigen::Hyperplane<double, 3> TrianglePlane(int triangle) const;

  const Scene& scene() const { return *scene_; }
  int num_triangles() const { return scene_->NumTriangles(); }

 private:
  explicit RayCaster(std::shared_ptr<const Scene> scene);
  RayHit FinishHit(const Eigen::Vector3d& origin, const Eigen::Vector3d& unit_dir, int triangle,
                   double distance_m, double u, double v) const;

  std::shared_ptr<const Scene> scene_;
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace sandtable
