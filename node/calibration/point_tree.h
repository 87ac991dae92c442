// A k-d tree (nanoflann) over 3D points held elsewhere: nearest and k nearest neighbours, for the
// model's sampled surface in model registration (model_registration.h) and the per-building
// surfaces of the change report (model_changes.h).
#pragma once

#include <cstddef>
#include <limits>
#include <memory>
#include <vector>

#include <Eigen/Core>
#include <nanoflann.hpp>

namespace sandtable::node {

class PointTree {
 public:
  // `points` is not owned, must outlive the tree and not change after construction.
  explicit PointTree(const std::vector<Eigen::Vector3d>* points) : adaptor_{points} {
    index_ = std::make_unique<Index>(3, adaptor_, nanoflann::KDTreeSingleIndexAdaptorParams(16));
    index_->buildIndex();
  }
  PointTree(const PointTree&) = delete;
  PointTree& operator=(const PointTree&) = delete;

  bool empty() const { return adaptor_.points->empty(); }
  // The nearest point's index and squared distance (infinity, index 0, when empty).
  size_t Nearest(const Eigen::Vector3d& q, double* distance_sq) const {
    size_t i = 0;
    *distance_sq = std::numeric_limits<double>::infinity();
    if (!empty()) index_->knnSearch(q.data(), 1, &i, distance_sq);
    return i;
  }
  // The k nearest (fewer when there are fewer points), nearest first; returns how many.
  size_t Nearest(const Eigen::Vector3d& q, size_t k, size_t* indices, double* distances_sq) const {
    return empty() ? 0 : index_->knnSearch(q.data(), k, indices, distances_sq);
  }

 private:
  struct Adaptor {
    const std::vector<Eigen::Vector3d>* points;
    size_t kdtree_get_point_count() const { return points->size(); }
    double kdtree_get_pt(size_t i, size_t d) const { return (*points)[i][static_cast<int>(d)]; }
    template <class Box>
    bool kdtree_get_bbox(Box&) const {
      return false;
    }
  };
  using Index = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<double, Adaptor>,
                                                    Adaptor, 3, size_t>;
  Adaptor adaptor_;
  std::unique_ptr<Index> index_;
};

}  // namespace sandtable::node
