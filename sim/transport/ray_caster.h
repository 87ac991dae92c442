// RayCaster: exact ray/triangle visibility over a Scene with Embree 3.
//
// Frame: the scene's table frame, metres. Rays are cast in float (Embree); Intersect() refines
// the hit distance in double against the hit triangle's plane, so hit points are exact to
// double rounding for planar faces. Thread-safe for concurrent queries after construction.
// Failure: Create() returns UNAVAILABLE when Embree cannot start and INVALID_ARGUMENT for an
// empty scene.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "common/base/status.h"
#include "common/scene/scene.h"

namespace sandtable::sim {

struct RayHit {
  bool hit = false;
  double distance_m = 0.0;  // along the unit direction
  int triangle = -1;
  double u = 0.0, v = 0.0;  // barycentrics: point = (1-u-v) p0 + u p1 + v p2
};

class RayCaster {
 public:
  // `embree_config` is passed to rtcNewDevice ("threads=1" for one core; "" = Embree default).
  static Expected<std::unique_ptr<RayCaster>> Create(const Scene& scene,
                                                     const std::string& embree_config = "");
  ~RayCaster();
  RayCaster(const RayCaster&) = delete;
  RayCaster& operator=(const RayCaster&) = delete;

  // Nearest hit of origin + s direction for s in [near_m, far_m]; direction need not be unit
  // (distance_m is along the normalised direction).
  RayHit Intersect(const Eigen::Vector3d& origin_in_table_m, const Eigen::Vector3d& direction,
                   double near_m = 0.0, double far_m = 1e30) const;
  // True when any triangle lies on the open segment from `from` to `to`, ignoring `epsilon_m`
  // at both ends (so a surface point is not shadowed by its own triangle).
  bool Occluded(const Eigen::Vector3d& from_in_table_m, const Eigen::Vector3d& to_in_table_m,
                double epsilon_m = 1e-5) const;

  // Occluded(from[i], to, epsilon_m) for every i, as one coherent batch (rays that share an
  // end point, e.g. shadow rays to a projector centre, traverse the tree together). Same
  // result as the single-ray calls. (*occluded)[i] is 1 when occluded.
  void OccludedToPoint(const std::vector<Eigen::Vector3d>& from_in_table_m,
                       const Eigen::Vector3d& to_in_table_m, double epsilon_m,
                       std::vector<uint8_t>* occluded) const;

  const Scene& scene() const { return scene_; }

 private:
  explicit RayCaster(const Scene& scene);
  const Scene& scene_;  // must outlive the caster
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace sandtable::sim
