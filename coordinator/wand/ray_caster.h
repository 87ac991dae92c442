// RayCaster: closest-hit ray casting against a triangle mesh in the table frame (the scene the
// wand points at), with a bounding volume hierarchy of our own (median split on the longest
// axis, 4 triangles per leaf) and Moller-Trumbore intersection in double precision.
//
// Frame and units: table frame, metres. Normals: the triangle's geometric normal from its
// counter-clockwise winding, flipped to face the ray (the wand can hit either side).
// Cost: build O(T log T); a query visits O(log T) nodes on typical scenes. Degenerate
// triangles never hit. Not thread-safe for building; queries are const.
#pragma once

#include <optional>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace sandtable::coordinator {

struct RayHit {
  Eigen::Vector3d point_in_table_m;
  Eigen::Vector3d normal_in_table;  // unit, facing the ray origin
  double distance_m = 0.0;          // along the unit direction
  int triangle = -1;
};

class RayCaster {
 public:
  RayCaster(std::vector<Eigen::Vector3d> positions_in_table_m,
            std::vector<Eigen::Vector3i> triangles);

  // Closest hit with distance in (min_distance_m, max_distance_m]; `direction` need not be
  // unit (it is normalised; a zero direction never hits).
  std::optional<RayHit> Cast(const Eigen::Vector3d& origin_in_table_m,
                             const Eigen::Vector3d& direction_in_table,
                             double min_distance_m = 1e-9, double max_distance_m = 1e9) const;
  // Same, testing every triangle (reference for tests).
  std::optional<RayHit> CastBruteForce(const Eigen::Vector3d& origin_in_table_m,
                                       const Eigen::Vector3d& direction_in_table,
                                       double min_distance_m = 1e-9,
                                       double max_distance_m = 1e9) const;
  int num_triangles() const { return static_cast<int>(triangles_.size()); }

 private:
  struct Node {
    Eigen::Vector3d lo, hi;
    int left = -1, right = -1;  // children (internal)
    int first = 0, count = 0;   // range in order_ (leaf when count > 0)
  };
  int Build(int first, int count);
  bool Intersect(int triangle, const Eigen::Vector3d& o, const Eigen::Vector3d& d, double t_min,
                 double* t) const;
  RayHit MakeHit(int triangle, const Eigen::Vector3d& o, const Eigen::Vector3d& d, double t) const;

  std::vector<Eigen::Vector3d> positions_;
  std::vector<Eigen::Vector3i> triangles_;
  std::vector<int> order_;
  std::vector<Node> nodes_;
};

// Axis-aligned box as 12 triangles (outward counter-clockwise), appended to the lists: for
// tests and the lab's simple scenes.
void AppendBox(const Eigen::Vector3d& lo_m, const Eigen::Vector3d& hi_m,
               std::vector<Eigen::Vector3d>* positions, std::vector<Eigen::Vector3i>* triangles);

}  // namespace sandtable::coordinator
