// ComputeDistanceField (blend_field.h): the distance along the surface from each grid point of a
// projector's image to the nearest surface point it cannot light.
#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <queue>
#include <utility>
#include <vector>

#include "common/base/units.h"
#include "node/blend/blend_field.h"
#include "node/blend/projector_rays.h"

namespace sandtable::node {
namespace {

using blend_internal::Cast;
using blend_internal::CastPixels;
using blend_internal::RayTable;

// The eight grid directions, and each one's opposite.
constexpr int kDc[8] = {1, -1, 0, 0, 1, 1, -1, -1};
constexpr int kDr[8] = {0, 0, 1, -1, 1, -1, 1, -1};
constexpr int kOpposite[8] = {1, 0, 3, 2, 7, 6, 5, 4};
// Rays cast between two grid points suspected of a break, less one.
constexpr int kSubsamples = 8;
// Bisection steps locating where the lit surface ends between two grid points.
constexpr int kBisections = 5;

// Where the lit surface ends between a lit grid point i and a neighbour j that is unlit or
// across a break.
struct Crossing {
  size_t i, j;
  double lo = 0.0, hi = 1.0;  // lit and near i at lo, not at hi
  bool rim = false;           // j: a ray past the model's rim
};

// One field's computation: the grid's casts, its breaks and crossings, and the Dijkstra spread.
class FieldBuilder {
 public:
  FieldBuilder(const DistanceField& f, const RayCaster& caster, const BlendOptions& options)
      : f_(f),
        caster_(caster),
        options_(options),
        rays_(f.projector, std::max(1, f.step_px)),
        min_cos_(std::cos(DegToRad(options.max_incidence_deg))),
        focal_px_(0.5 * (f.projector.fx_px + f.projector.fy_px)),
        n_(static_cast<size_t>(f.cols) * f.rows) {
    pixels_.resize(n_);
    for (int r = 0; r < f.rows; ++r) {
      for (int c = 0; c < f.cols; ++c)
        pixels_[static_cast<size_t>(r) * f.cols + c] = f.GridPixel(c, r);
    }
    casts_ = CastAll(pixels_);
    d_.assign(n_, std::numeric_limits<double>::infinity());
    outside_.assign(n_, -std::numeric_limits<double>::infinity());
  }

  void FindBreaks();
  void FindCrossings();
  void LocateCrossings();
  // Seeds the crossings `take` accepts, then spreads the distances along the surface.
  void Spread(const std::function<bool(const Crossing&)>& take);
  bool Unreached(size_t i) const { return Lit(i) && !std::isfinite(d_[i]); }
  std::vector<float> Distances() const;

 private:
  bool Lit(size_t i) const { return casts_[i].range_m > 0; }
  std::vector<Cast> CastAll(const std::vector<Eigen::Vector2d>& pixels) const {
    return CastPixels(pixels, rays_, f_.projector_from_table, caster_, min_cos_);
  }
  // The neighbour of grid point i in direction k; false past the grid.
  bool Neighbour(size_t i, int k, size_t* j) const {
    const int cc = static_cast<int>(i % f_.cols) + kDc[k];
    const int rr = static_cast<int>(i / f_.cols) + kDr[k];
    if (cc < 0 || rr < 0 || cc >= f_.cols || rr >= f_.rows) return false;
    *j = static_cast<size_t>(rr) * f_.cols + cc;
    return true;
  }
  bool OnImageEdge(size_t i) const {
    const int c = static_cast<int>(i % f_.cols), r = static_cast<int>(i / f_.cols);
    return c == 0 || r == 0 || c == f_.cols - 1 || r == f_.rows - 1;
  }
  void Seed(size_t i, double value) {
    if (value < d_[i]) {
      d_[i] = value;
      queue_.emplace(value, i);
    }
  }

  const DistanceField& f_;
  const RayCaster& caster_;
  const BlendOptions& options_;
  const RayTable rays_;
  const double min_cos_, focal_px_;
  const size_t n_;
  std::vector<Eigen::Vector2d> pixels_;
  std::vector<Cast> casts_;
  std::vector<uint8_t> broken_;  // per point and direction: a break between the two
  std::vector<Crossing> crossings_;
  std::vector<double> d_, outside_;
  using Item = std::pair<double, size_t>;
  std::priority_queue<Item, std::vector<Item>, std::greater<Item>> queue_;
};

// Breaks between lit neighbours: points farther apart than break_ratio times what the pixel
// step spans at their range are suspect (a silhouette, or a surface met obliquely); the
// pixels between them are cast (kSubsamples rays): a continuous surface spreads the distance
// over the sub-steps, a silhouette puts most of it into one jump (or a sub-step misses).
void FieldBuilder::FindBreaks() {
  broken_.assign(n_ * 8, 0);
  struct Suspect {
    size_t i, j;
    int k;
  };
  std::vector<Suspect> suspects;
  std::vector<Eigen::Vector2d> sub_pixels;
  for (size_t i = 0; i < n_; ++i) {
    if (!Lit(i)) continue;
    for (int k : {0, 2, 4, 5}) {
      size_t j = 0;
      if (!Neighbour(i, k, &j) || !Lit(j)) continue;
      const double spacing_m = (casts_[i].point - casts_[j].point).norm();
      const double expected_m = (pixels_[j] - pixels_[i]).norm() *
                                std::min(casts_[i].range_m, casts_[j].range_m) / focal_px_;
      if (spacing_m <= options_.break_ratio * expected_m) continue;
      suspects.push_back({i, j, k});
      for (int q = 1; q < kSubsamples; ++q) {
        sub_pixels.push_back(pixels_[i] + (pixels_[j] - pixels_[i]) * (double(q) / kSubsamples));
      }
    }
  }
  const std::vector<Cast> sub = CastAll(sub_pixels);
  for (size_t s = 0; s < suspects.size(); ++s) {
    const auto [i, j, k] = suspects[s];
    const double spacing_m = (casts_[i].point - casts_[j].point).norm();
    bool is_break = false;
    Eigen::Vector3d previous = casts_[i].point;
    double largest_jump_m = 0.0;
    for (int q = 1; q <= kSubsamples && !is_break; ++q) {
      Eigen::Vector3d next = casts_[j].point;
      if (q < kSubsamples) {
        const Cast& hit = sub[s * (kSubsamples - 1) + (q - 1)];
        if (hit.range_m <= 0) is_break = true;
        next = hit.point;
      }
      largest_jump_m = std::max(largest_jump_m, (next - previous).norm());
      previous = next;
    }
    if (is_break || largest_jump_m > 0.5 * spacing_m) {
      broken_[i * 8 + k] = 1;
      broken_[j * 8 + kOpposite[k]] = 1;
    }
  }
}

// Seeds the image edge and lists the crossings: every lit point's neighbour that is unlit or
// across a break.
void FieldBuilder::FindCrossings() {
  for (size_t i = 0; i < n_; ++i) {
    if (!Lit(i)) continue;
    if (OnImageEdge(i)) Seed(i, 0.0);
    for (int k = 0; k < 8; ++k) {
      size_t j = 0;
      if (!Neighbour(i, k, &j)) continue;
      if (!Lit(j) || broken_[i * 8 + k]) {
        crossings_.push_back(
            {i, j, 0.0, 1.0, !Lit(j) && !broken_[i * 8 + k] && !casts_[j].surface});
      }
    }
  }
}

// Bisection along each crossing's pixel segment (kBisections casts), the crossing being where a
// sample stops being lit and near i (within half the i-j distance: the far side of a
// silhouette is a whole jump away).
void FieldBuilder::LocateCrossings() {
  std::vector<Eigen::Vector2d> probe(crossings_.size());
  for (int step = 0; step < kBisections && !crossings_.empty(); ++step) {
    for (size_t q = 0; q < crossings_.size(); ++q) {
      const Crossing& x = crossings_[q];
      probe[q] = pixels_[x.i] + (pixels_[x.j] - pixels_[x.i]) * (0.5 * (x.lo + x.hi));
    }
    const std::vector<Cast> hits = CastAll(probe);
    for (size_t q = 0; q < crossings_.size(); ++q) {
      Crossing& x = crossings_[q];
      const double mid = 0.5 * (x.lo + x.hi);
      const double jump_limit_m =
          0.5 * (casts_[x.j].range_m > 0 ? (casts_[x.j].point - casts_[x.i].point).norm()
                                         : std::numeric_limits<double>::infinity());
      const bool near_lit =
          hits[q].range_m > 0 && (hits[q].point - casts_[x.i].point).norm() < jump_limit_m;
      (near_lit ? x.lo : x.hi) = mid;
    }
  }
}

// i is seeded with its 3D distance to the crossing, and an unlit j gets minus its distance (in
// metres at i's range), so that the interpolated field passes through 0 at the crossing rather
// than a cell early (a signed distance; lookups clamp at 0).
void FieldBuilder::Spread(const std::function<bool(const Crossing&)>& take) {
  for (const Crossing& x : crossings_) {
    if (!take(x)) continue;
    const double t = 0.5 * (x.lo + x.hi);
    const double pixel_step = (pixels_[x.j] - pixels_[x.i]).norm();
    const double metres_per_px = casts_[x.i].range_m / focal_px_;
    // The 3D distance to the crossing, at least what the pixel distance spans (a chord).
    Seed(x.i, t * pixel_step * metres_per_px);
    if (!Lit(x.j)) outside_[x.j] = std::max(outside_[x.j], -(1.0 - t) * pixel_step * metres_per_px);
  }
  while (!queue_.empty()) {
    const auto [di, i] = queue_.top();
    queue_.pop();
    if (di > d_[i]) continue;
    // Unlit points pass no distance on (their 3D position is not a surface this projector
    // reaches); their lit neighbours were seeded above.
    if (!Lit(i)) continue;
    for (int k = 0; k < 8; ++k) {
      size_t j = 0;
      if (!Neighbour(i, k, &j) || !Lit(j) || broken_[i * 8 + k]) continue;
      const double step_m = (casts_[i].point - casts_[j].point).norm();
      if (di + step_m < d_[j]) {
        d_[j] = di + step_m;
        queue_.emplace(d_[j], j);
      }
    }
  }
}

std::vector<float> FieldBuilder::Distances() const {
  std::vector<float> out(n_, 0.0f);
  const double cell_m = f_.step_px * 1.0 / focal_px_;  // per metre of range
  for (size_t i = 0; i < n_; ++i) {
    if (Lit(i)) {
      out[i] = std::isfinite(d_[i]) ? static_cast<float>(d_[i]) : 0.0f;
    } else if (std::isfinite(outside_[i])) {
      // Unlit: minus the distance to the nearest crossing; deep inside, a cell at 1 m.
      out[i] = static_cast<float>(outside_[i]);
    } else {
      out[i] = static_cast<float>(-cell_m);
      if (casts_[i].surface) continue;
      // Past the rim beside lit points: their mean distance, so that a lookup between the last
      // lit grid points and the rim carries their field on instead of falling to 0.
      double sum = 0.0;
      int count = 0;
      for (int k = 0; k < 8; ++k) {
        size_t j = 0;
        if (Neighbour(i, k, &j) && Lit(j) && std::isfinite(d_[j])) {
          sum += d_[j];
          ++count;
        }
      }
      if (count > 0) out[i] = static_cast<float>(sum / count);
    }
  }
  return out;
}

}  // namespace

DistanceField ComputeDistanceField(NodeId unit, const CameraModel& projector,
                                   const Rigid3d& projector_from_table, const RayCaster& caster,
                                   const BlendOptions& options) {
  DistanceField f;
  f.unit = unit;
  f.projector = projector;
  f.projector_from_table = projector_from_table;
  f.step_px = options.grid_step_px;
  f.cols = DistanceField::PointsAlong(projector.width_px, f.step_px);
  f.rows = DistanceField::PointsAlong(projector.height_px, f.step_px);
  FieldBuilder builder(f, caster, options);
  builder.FindBreaks();
  builder.FindCrossings();
  builder.LocateCrossings();
  // Past the model's rim (no surface at all) no projector lights anything: that is where the
  // surface ends, not this projector's light, and no edge to blend from. (Counted as one, every
  // projector's D fell to 0 at the table's rim and the alphas near it were ratios of small
  // distances: steep, so a pixel's one value over its footprint left steps of several % along
  // the rim.) Only a lit region with no other edge at all (the whole table inside the image)
  // is measured from the rim, as TR09-017 would: it is reached from nothing else.
  builder.Spread([&](const Crossing& x) { return !x.rim || !options.rim_is_no_edge; });
  std::vector<uint8_t> unreached(f.cols * static_cast<size_t>(f.rows), 0);
  for (size_t i = 0; i < unreached.size(); ++i) unreached[i] = builder.Unreached(i);
  builder.Spread([&](const Crossing& x) { return x.rim && unreached[x.i]; });
  f.distance_m = builder.Distances();
  return f;
}

}  // namespace sandtable::node
