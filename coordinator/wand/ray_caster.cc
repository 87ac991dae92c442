#include "coordinator/wand/ray_caster.h"

#include <algorithm>
#include <limits>

#include "common/base/check.h"

namespace sandtable::coordinator {
namespace {

constexpr int kLeafTriangles = 4;

// Slab test; returns the entry distance or +inf when the box is missed within (t_min, t_max].
double BoxEntry(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, const Eigen::Vector3d& o,
                const Eigen::Vector3d& inv_d, double t_min, double t_max) {
  for (int a = 0; a < 3; ++a) {
    double t0 = (lo[a] - o[a]) * inv_d[a];
    double t1 = (hi[a] - o[a]) * inv_d[a];
    if (t0 > t1) std::swap(t0, t1);
    // NaN (0 * inf on a slab boundary) compares false and leaves the interval unchanged.
    if (t0 > t_min) t_min = t0;
    if (t1 < t_max) t_max = t1;
    if (t_min > t_max) return std::numeric_limits<double>::infinity();
  }
  return t_min;
}

}  // namespace

RayCaster::RayCaster(std::vector<Eigen::Vector3d> positions, std::vector<Eigen::Vector3i> triangles)
    : positions_(std::move(positions)), triangles_(std::move(triangles)) {
  for (const Eigen::Vector3i& t : triangles_) {
    for (int k = 0; k < 3; ++k) {
      ST_CHECK(t[k] >= 0 && t[k] < static_cast<int>(positions_.size()))
          << "RayCaster: triangle index out of range (validate the scene when loading it)";
    }
  }
  order_.resize(triangles_.size());
  for (size_t i = 0; i < order_.size(); ++i) order_[i] = static_cast<int>(i);
  if (!triangles_.empty()) Build(0, static_cast<int>(triangles_.size()));
}

int RayCaster::Build(int first, int count) {
  Node node;
  node.lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  node.hi = -node.lo;
  for (int i = first; i < first + count; ++i) {
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d& p = positions_[triangles_[order_[i]][k]];
      node.lo = node.lo.cwiseMin(p);
      node.hi = node.hi.cwiseMax(p);
    }
  }
  const int index = static_cast<int>(nodes_.size());
  nodes_.push_back(node);
  if (count <= kLeafTriangles) {
    nodes_[index].first = first;
    nodes_[index].count = count;
    return index;
  }
  int axis = 0;
  (node.hi - node.lo).maxCoeff(&axis);
  auto centroid = [&](int t) {
    const Eigen::Vector3i& tri = triangles_[t];
    return positions_[tri[0]][axis] + positions_[tri[1]][axis] + positions_[tri[2]][axis];
  };
  const int mid = first + count / 2;
  std::nth_element(order_.begin() + first, order_.begin() + mid, order_.begin() + first + count,
                   [&](int a, int b) { return centroid(a) < centroid(b); });
  const int left = Build(first, mid - first);
  const int right = Build(mid, first + count - mid);
  nodes_[index].left = left;
  nodes_[index].right = right;
  return index;
}

bool RayCaster::Intersect(int triangle, const Eigen::Vector3d& o, const Eigen::Vector3d& d,
                          double t_min, double* t) const {
  // Moller-Trumbore: solve o + t d = p0 + u e1 + v e2.
  const Eigen::Vector3i& tri = triangles_[triangle];
  const Eigen::Vector3d& p0 = positions_[tri[0]];
  const Eigen::Vector3d e1 = positions_[tri[1]] - p0;
  const Eigen::Vector3d e2 = positions_[tri[2]] - p0;
  const Eigen::Vector3d p = d.cross(e2);
  const double det = e1.dot(p);
  const double scale = e1.norm() * e2.norm();
  if (std::abs(det) <= 1e-14 * scale || scale == 0.0) return false;  // parallel or degenerate
  const double inv_det = 1.0 / det;
  const Eigen::Vector3d s = o - p0;
  const double u = s.dot(p) * inv_det;
  if (u < 0.0 || u > 1.0) return false;
  const Eigen::Vector3d q = s.cross(e1);
  const double v = d.dot(q) * inv_det;
  if (v < 0.0 || u + v > 1.0) return false;
  const double hit_t = e2.dot(q) * inv_det;
  if (hit_t <= t_min || hit_t >= *t) return false;
  *t = hit_t;
  return true;
}

RayHit RayCaster::MakeHit(int triangle, const Eigen::Vector3d& o, const Eigen::Vector3d& d,
                          double t) const {
  const Eigen::Vector3i& tri = triangles_[triangle];
  Eigen::Vector3d n = (positions_[tri[1]] - positions_[tri[0]])
                          .cross(positions_[tri[2]] - positions_[tri[0]])
                          .normalized();
  if (n.dot(d) > 0.0) n = -n;
  return RayHit{o + t * d, n, t, triangle};
}

std::optional<RayHit> RayCaster::Cast(const Eigen::Vector3d& origin,
                                      const Eigen::Vector3d& direction, double min_distance_m,
                                      double max_distance_m) const {
  if (nodes_.empty() || direction.squaredNorm() == 0.0 || !direction.allFinite() ||
      !origin.allFinite()) {
    return std::nullopt;
  }
  const Eigen::Vector3d d = direction.normalized();
  const Eigen::Vector3d inv_d = d.cwiseInverse();
  double best_t = std::nextafter(max_distance_m, std::numeric_limits<double>::infinity());
  int best = -1;
  int stack[128];
  int top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const Node& node = nodes_[stack[--top]];
    if (BoxEntry(node.lo, node.hi, origin, inv_d, min_distance_m, best_t) ==
        std::numeric_limits<double>::infinity()) {
      continue;
    }
    if (node.count > 0) {
      for (int i = node.first; i < node.first + node.count; ++i) {
        if (Intersect(order_[i], origin, d, min_distance_m, &best_t)) best = order_[i];
      }
    } else if (top + 2 <= 128) {
      stack[top++] = node.left;
      stack[top++] = node.right;
    }
  }
  if (best < 0) return std::nullopt;
  return MakeHit(best, origin, d, best_t);
}

std::optional<RayHit> RayCaster::CastBruteForce(const Eigen::Vector3d& origin,
                                                const Eigen::Vector3d& direction,
                                                double min_distance_m,
                                                double max_distance_m) const {
  if (direction.squaredNorm() == 0.0) return std::nullopt;
  const Eigen::Vector3d d = direction.normalized();
  double best_t = std::nextafter(max_distance_m, std::numeric_limits<double>::infinity());
  int best = -1;
  for (int i = 0; i < num_triangles(); ++i) {
    if (Intersect(i, origin, d, min_distance_m, &best_t)) best = i;
  }
  if (best < 0) return std::nullopt;
  return MakeHit(best, origin, d, best_t);
}

void AppendBox(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi,
               std::vector<Eigen::Vector3d>* positions, std::vector<Eigen::Vector3i>* triangles) {
  const int base = static_cast<int>(positions->size());
  for (int i = 0; i < 8; ++i) {
    positions->emplace_back((i & 1) ? hi.x() : lo.x(), (i & 2) ? hi.y() : lo.y(),
                            (i & 4) ? hi.z() : lo.z());
  }
  // Faces as quads (outward counter-clockwise), split into two triangles each.
  const int quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                           {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& q : quads) {
    triangles->emplace_back(base + q[0], base + q[1], base + q[2]);
    triangles->emplace_back(base + q[0], base + q[2], base + q[3]);
  }
}

}  // namespace sandtable::coordinator
