#include "node/blend/blend_field.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <queue>
#include <string>
#include <utility>

#include "common/base/units.h"
#include "node/blend/projector_rays.h"

namespace sandtable::node {

using blend_internal::Cast;
using blend_internal::CastPixels;
using blend_internal::RayTable;

Status BlendOptions::Check() const {
  if (grid_step_px < 1 || grid_step_px > 64) {
    return InvalidArgumentError("blend: grid_step_px = " + std::to_string(grid_step_px) +
                                " must be in [1, 64]");
  }
  if (!(correction_limit_deg > 0.0 && correction_limit_deg < weight_falloff_deg &&
        weight_falloff_deg <= max_incidence_deg && max_incidence_deg < 90.0)) {
    return InvalidArgumentError(
        "blend: need 0 < correction_limit_deg < weight_falloff_deg <= max_incidence_deg < 90");
  }
  if (!(break_ratio > 1.0) || !std::isfinite(break_ratio)) {
    return InvalidArgumentError("blend: break_ratio must be > 1");
  }
  if (!(shadow_ray_offset_m > 0.0) || !(shadow_ray_offset_m < 0.01)) {
    return InvalidArgumentError("blend: shadow_ray_offset_m must be in (0, 0.01)");
  }
  if (!(density_weight >= 0.0) || !(density_weight <= 4.0)) {
    return InvalidArgumentError("blend: density_weight must be in [0, 4]");
  }
  if (!(fill_limit >= 1.0) || !(fill_limit <= 100.0)) {
    return InvalidArgumentError("blend: fill_limit must be in [1, 100]");
  }
  if (!(edge_soft_m >= 0.0) || !(edge_soft_m <= 0.1)) {
    return InvalidArgumentError("blend: edge_soft_m must be in [0, 0.1]");
  }
  if (!(edge_soft_min_face_m2 >= 0.0) || !std::isfinite(edge_soft_min_face_m2)) {
    return InvalidArgumentError("blend: edge_soft_min_face_m2 must be finite and >= 0");
  }
  return OkStatus();
}

Status DistanceField::Check() const {
  if (step_px < 1 || step_px > 64 || cols < 1 || rows < 1 ||
      static_cast<int64_t>(cols) * rows > (int64_t{1} << 22)) {
    return InvalidArgumentError("distance field of unit " + std::to_string(unit) + ": grid " +
                                std::to_string(cols) + " x " + std::to_string(rows) + " step " +
                                std::to_string(step_px) + " px is out of range");
  }
  const size_t n = static_cast<size_t>(cols) * rows;
  if (distance_m.size() != n) {
    return InvalidArgumentError("distance field of unit " + std::to_string(unit) + ": " +
                                std::to_string(distance_m.size()) + " distances for a " +
                                std::to_string(cols) + " x " + std::to_string(rows) + " grid");
  }
  for (size_t i = 0; i < n; ++i) {
    if (!std::isfinite(distance_m[i]) || std::abs(distance_m[i]) > kMaxFieldDistance_m) {
      return InvalidArgumentError("distance field of unit " + std::to_string(unit) +
                                  ": a distance is not finite or beyond " +
                                  std::to_string(kMaxFieldDistance_m) + " m");
    }
  }
  ST_RETURN_IF_ERROR(projector.Check());
  if (cols != PointsAlong(projector.width_px, step_px) ||
      rows != PointsAlong(projector.height_px, step_px)) {
    return InvalidArgumentError("distance field of unit " + std::to_string(unit) + ": a " +
                                std::to_string(cols) + " x " + std::to_string(rows) +
                                " grid does not span a " + std::to_string(projector.width_px) +
                                " x " + std::to_string(projector.height_px) + " image at step " +
                                std::to_string(step_px) + " px");
  }
  return OkStatus();
}

ProjectorSurface CastProjectorSurface(const CameraModel& projector,
                                      const Rigid3d& projector_from_table, const RayCaster& caster,
                                      const BlendOptions& options,
                                      const std::vector<int>& face_of_triangle) {
  ProjectorSurface s;
  s.width_px = projector.width_px;
  s.height_px = projector.height_px;
  const size_t n = static_cast<size_t>(s.width_px) * s.height_px;
  s.point_in_table_m.assign(n, Eigen::Vector3f::Zero());
  s.normal_in_table.assign(n, Eigen::Vector3f::UnitZ());
  s.range_m.assign(n, 0.0f);
  s.cos_incidence.assign(n, 0.0f);
  s.albedo.assign(n, 1.0f);
  s.face.assign(n, -1);
  s.face_area_m2.assign(n, 0.0f);
  // Each face's area (faces are indexed by a triangle's index).
  std::vector<double> area(face_of_triangle.size(), 0.0);
  const Scene& scene = caster.scene();
  for (size_t t = 0; t < face_of_triangle.size() && t < scene.triangles.size(); ++t) {
    if (face_of_triangle[t] < 0 || face_of_triangle[t] >= static_cast<int>(area.size())) continue;
    const Eigen::Vector3i& v = scene.triangles[t];
    const Eigen::Vector3d a = scene.positions_in_table_m[v[0]].cast<double>();
    const Eigen::Vector3d b = scene.positions_in_table_m[v[1]].cast<double>();
    const Eigen::Vector3d c = scene.positions_in_table_m[v[2]].cast<double>();
    area[face_of_triangle[t]] += 0.5 * (b - a).cross(c - a).norm();
  }
  const RayTable rays(projector, options.grid_step_px);
  const double min_cos = std::cos(DegToRad(options.max_incidence_deg));
  // Row blocks keep the batches coherent and the memory bounded.
  constexpr int kRowsPerBatch = 32;
  std::vector<Eigen::Vector2d> pixels;
  for (int r0 = 0; r0 < s.height_px; r0 += kRowsPerBatch) {
    const int r1 = std::min(s.height_px, r0 + kRowsPerBatch);
    pixels.clear();
    for (int r = r0; r < r1; ++r) {
      for (int c = 0; c < s.width_px; ++c) pixels.emplace_back(c, r);
    }
    const std::vector<Cast> casts = CastPixels(pixels, rays, projector_from_table, caster, min_cos);
    for (size_t k = 0; k < casts.size(); ++k) {
      const size_t i = static_cast<size_t>(r0) * s.width_px + k;
      if (casts[k].range_m <= 0) continue;
      s.point_in_table_m[i] = casts[k].point.cast<float>();
      s.normal_in_table[i] = casts[k].normal.cast<float>();
      s.range_m[i] = static_cast<float>(casts[k].range_m);
      s.cos_incidence[i] = static_cast<float>(casts[k].cos_incidence);
      s.albedo[i] = static_cast<float>(casts[k].albedo);
      const int t = casts[k].triangle;
      if (t >= 0 && t < static_cast<int>(face_of_triangle.size()) && face_of_triangle[t] >= 0) {
        s.face[i] = face_of_triangle[t];
        s.face_area_m2[i] = static_cast<float>(area[face_of_triangle[t]]);
      }
      ++s.lit_pixels;
    }
  }
  return s;
}

float DistanceField::DistanceAtPixel(const Eigen::Vector2d& pixel) const {
  const Eigen::Vector2d spacing = Spacing();
  const double gx = (pixel.x() + 0.5) / spacing.x(), gy = (pixel.y() + 0.5) / spacing.y();
  if (!(gx >= 0 && gy >= 0 && gx <= cols - 1 && gy <= rows - 1)) return 0.0f;
  const int c = std::min(static_cast<int>(gx), cols - 2);
  const int r = std::min(static_cast<int>(gy), rows - 2);
  const double fx = gx - c, fy = gy - r;
  auto at = [&](int cc, int rr) { return distance_m[static_cast<size_t>(rr) * cols + cc]; };
  const double value = (1 - fy) * ((1 - fx) * at(c, r) + fx * at(c + 1, r)) +
                       fy * ((1 - fx) * at(c, r + 1) + fx * at(c + 1, r + 1));
  return static_cast<float>(std::max(0.0, value));
}

float LookupDistance(const DistanceField& field, const Eigen::Vector3d& point_in_table_m,
                     const Eigen::Vector3d& normal_in_table, const RayCaster& caster,
                     const BlendOptions& options) {
  const Eigen::Vector3d x_in_projector = field.projector_from_table * point_in_table_m;
  const std::optional<Eigen::Vector2d> pixel = field.projector.Project(x_in_projector);
  if (!pixel || !field.projector.InImage(*pixel)) return 0.0f;
  const Eigen::Vector3d centre = field.projector_from_table.Inverse().translation;
  const Eigen::Vector3d to_centre = centre - point_in_table_m;
  const double range_m = to_centre.norm();
  if (normal_in_table.dot(to_centre) < std::cos(DegToRad(options.max_incidence_deg)) * range_m) {
    return 0.0f;
  }
  const float d = field.DistanceAtPixel(*pixel);
  if (d <= 0) return 0.0f;
  if (caster.Occluded(point_in_table_m + options.shadow_ray_offset_m * normal_in_table, centre)) {
    return 0.0f;
  }
  return d;
}

bool SameField(const DistanceField& a, const DistanceField& b) {
  const CameraModel &p = a.projector, &q = b.projector;
  return a.unit == b.unit && a.step_px == b.step_px && a.cols == b.cols && a.rows == b.rows &&
         a.distance_m == b.distance_m && p.width_px == q.width_px && p.height_px == q.height_px &&
         p.fx_px == q.fx_px && p.fy_px == q.fy_px && p.cx_px == q.cx_px && p.cy_px == q.cy_px &&
         p.distortion.ToArray() == q.distortion.ToArray() &&
         a.projector_from_table.rotation.coeffs() == b.projector_from_table.rotation.coeffs() &&
         a.projector_from_table.translation == b.projector_from_table.translation;
}

Blender::Blender(ProjectorSurface surface, DistanceField own, const RayCaster* caster,
                 BlendOptions options)
    : surface_(std::move(surface)), own_(std::move(own)), caster_(caster), options_(options) {
  // A lit pixel of this projector lights its point: D at the pixel itself.
  const size_t n = surface_.range_m.size();
  own_d_.assign(n, 0.0f);
  for (int y = 0; y < surface_.height_px; ++y) {
    for (int x = 0; x < surface_.width_px; ++x) {
      const size_t i = static_cast<size_t>(y) * surface_.width_px + x;
      if (surface_.range_m[i] <= 0) continue;
      own_d_[i] = own_.DistanceAtPixel(Eigen::Vector2d(x, y));
    }
  }
  own_w_.assign(n, 0.0f);
  own_reach_.assign(n, 0.0f);
  for (size_t i = 0; i < n; ++i) {
    if (surface_.range_m[i] <= 0) continue;
    own_w_[i] = static_cast<float>(
        EdgeWeight(own_d_[i] + options_.distance_floor_m, surface_.face_area_m2[i], options_) *
        IncidenceWeight(surface_.cos_incidence[i], options_) *
        DensityWeight(own_.projector, surface_.cos_incidence[i], surface_.range_m[i], options_));
    own_reach_[i] = static_cast<float>(Reach(surface_.cos_incidence[i], options_));
  }
  own_wr_.assign(n, 0.0f);
  own_gain_.assign(n, 0.0f);
  for (size_t i = 0; i < n; ++i) {
    if (surface_.range_m[i] <= 0 || own_w_[i] <= 0) continue;
    own_wr_[i] = own_w_[i] * own_reach_[i];
    own_gain_[i] = static_cast<float>(own_w_[i] / CorrectedIrradiance(i));
  }
}

double EdgeWeight(double distance_m, double face_area_m2, const BlendOptions& options) {
  const double e = options.edge_soft_m;
  if (e <= 0 || face_area_m2 < options.edge_soft_min_face_m2) return distance_m;
  return distance_m < e ? distance_m * distance_m / (2 * e) : distance_m - e / 2;
}

double Reach(double cos_incidence, const BlendOptions& options) {
  return std::min(1.0, cos_incidence / std::cos(DegToRad(options.correction_limit_deg)));
}

double DensityWeight(const CameraModel& projector, double cos_incidence, double range_m,
                     const BlendOptions& options) {
  if (options.density_weight == 0.0) return 1.0;
  // Pixels per mm^2 of the surface: f^2 cos(theta) / d^2.
  const double density =
      projector.fx_px * projector.fy_px * cos_incidence / (range_m * range_m) * 1e-6;
  return std::pow(std::max(density, 1e-12), options.density_weight);
}

double IncidenceWeight(double cos_incidence, const BlendOptions& options) {
  if (!options.incidence_weight) return 1.0;
  constexpr double kFloor = 1e-3;
  const double c0 = std::cos(DegToRad(options.weight_falloff_deg));
  const double c1 = std::cos(DegToRad(options.correction_limit_deg));
  const double t = std::clamp((cos_incidence - c0) / (c1 - c0), 0.0, 1.0);
  return kFloor + (1.0 - kFloor) * t * t * (3.0 - 2.0 * t);  // smoothstep
}

void Blender::SetNeighbour(const DistanceField& field) {
  const size_t n = surface_.range_m.size();
  std::vector<float> w(n, 0.0f), reach(n, 0.0f), gain(n, 0.0f);
  // Which lit pixels fall in the neighbour's image facing it: those then cast shadow rays to
  // its centre, in one coherent batch.
  const Eigen::Vector3d centre = field.projector_from_table.Inverse().translation;
  const double min_cos = std::cos(DegToRad(options_.max_incidence_deg));
  std::vector<size_t> candidates;
  std::vector<Eigen::Vector3d> from;
  for (size_t i = 0; i < n; ++i) {
    if (surface_.range_m[i] <= 0) continue;
    const Eigen::Vector3d x = surface_.point_in_table_m[i].cast<double>();
    const Eigen::Vector3d normal = surface_.normal_in_table[i].cast<double>();
    const Eigen::Vector3d to_centre = centre - x;
    const double cos_incidence = normal.dot(to_centre) / to_centre.norm();
    if (cos_incidence < min_cos) continue;
    const std::optional<Eigen::Vector2d> pixel =
        field.projector.Project(field.projector_from_table * x);
    if (!pixel || !field.projector.InImage(*pixel)) continue;
    w[i] = static_cast<float>(
        EdgeWeight(field.DistanceAtPixel(*pixel) + options_.distance_floor_m,
                   surface_.face_area_m2[i], options_) *
        IncidenceWeight(cos_incidence, options_) *
        DensityWeight(field.projector, cos_incidence, to_centre.norm(), options_));
    reach[i] = w[i] * static_cast<float>(Reach(cos_incidence, options_));  // w r
    gain[i] = static_cast<float>(cos_incidence / to_centre.squaredNorm());
    candidates.push_back(i);
    from.push_back(x + options_.shadow_ray_offset_m * normal);
  }
  std::vector<uint8_t> occluded;
  caster_->OccludedToPoint(from, centre, 1e-5, &occluded);
  for (size_t k = 0; k < candidates.size(); ++k) {
    if (occluded[k]) w[candidates[k]] = reach[candidates[k]] = gain[candidates[k]] = 0.0f;
  }
  neighbour_w_[field.unit] = std::move(w);
  neighbour_reach_[field.unit] = std::move(reach);
  neighbour_gain_[field.unit] = std::move(gain);
}

bool Blender::RemoveNeighbour(NodeId unit) {
  neighbour_reach_.erase(unit);
  neighbour_gain_.erase(unit);
  return neighbour_w_.erase(unit) > 0;
}

std::vector<NodeId> Blender::neighbours() const {
  std::vector<NodeId> out;
  for (const auto& [unit, w] : neighbour_w_) out.push_back(unit);
  return out;
}

cv::Mat Blender::Alpha(NodeId without) const {
  cv::Mat alpha(surface_.height_px, surface_.width_px, CV_32FC1, cv::Scalar(0));
  float* a = alpha.ptr<float>();
  const size_t n = own_d_.size();
  for (size_t i = 0; i < n; ++i) {
    if (surface_.range_m[i] <= 0) continue;
    float sum = own_w_[i];
    for (const auto& [unit, w] : neighbour_w_) {
      if (unit != without) sum += w[i];
    }
    a[i] = own_w_[i] / sum;
  }
  return alpha;
}

double Blender::CorrectedIrradiance(size_t i) const {
  const double r = surface_.range_m[i];
  const double limit = std::cos(DegToRad(options_.correction_limit_deg));
  // A dark surface needs more light for the same luminance; a black one cannot be corrected
  // (its albedo is floored at 1 %, so it does not set the site's level to 0).
  return std::max(static_cast<double>(surface_.cos_incidence[i]), limit) *
         std::max(static_cast<double>(surface_.albedo[i]), 0.01) / (r * r);
}

double Blender::LevelBound() const {
  const cv::Mat alpha = Alpha();
  const float* a = alpha.ptr<float>();
  double bound = std::numeric_limits<double>::infinity();
  for (size_t i = 0; i < own_d_.size(); ++i) {
    if (a[i] <= 0) continue;
    bound = std::min(bound, CorrectedIrradiance(i) / static_cast<double>(a[i]));
  }
  return bound;
}

cv::Mat Blender::Factor(double level) const { return Factor(level, options_.fill_limit); }

cv::Mat Blender::Factor(double level, double fill_limit, NodeId without,
                        const FaceLevels& face_levels) const {
  // A_i T / (E'_i R), R = sum_j A_j r_j: the share of the intended light the projectors lighting
  // the point deliver together (a projector past the correction limit delivers r < 1 of it);
  // dividing by R restores the level where one that faces the surface better can make it up.
  // A_i / R = w_i / sum_j w_j r_j. One pass over the pixels with the neighbours' w r gathered
  // (a re-blend after a neighbour left is this alone).
  //
  // Past the correction limit that can ask a projector for more than it has (A T / (E' R) > 1).
  // Clipped alone, the others' shares stay as they were and the total follows the clipped
  // projector's alpha: a step wherever the alphas change (walls met at 60-85 degrees). With
  // fill_limit > 1 the others make up the shortfall (water filling): every projector lighting
  // the point delivers min(its capacity cos / d^2, c x its share of the intended light), one c
  // for all, the smallest that reaches the intended light, at most fill_limit: a projector's
  // light must still end continuously where its share does (its edges, D -> 0; an unbounded c
  // lit grazing projectors fully up to their image edge: steps of 35 %). Every node computes the
  // same c from the same terms (its own and its neighbours' w r and capacity), so the
  // projectors still add up to one level, lower only where together they cannot reach it.
  cv::Mat factor(surface_.height_px, surface_.width_px, CV_32FC1, cv::Scalar(0));
  float* f = factor.ptr<float>();
  const std::vector<Other> others = Others(without);
  // The faces' levels by face id, for a lookup per pixel. Ids are triangle indices: one past
  // the model's triangles (a share off the wire) is no face of this model and is left out.
  std::vector<double> level_of_face;
  const int32_t triangles = caster_ ? caster_->scene().NumTriangles() : 0;
  for (const auto& [face, l] : face_levels) {
    if (face < 0 || face >= triangles) continue;
    if (level_of_face.size() <= static_cast<size_t>(face)) level_of_face.resize(face + 1, level);
    level_of_face[face] = std::min(level, l);
  }
  struct Term {
    double room, share;  // what it may deliver (irradiance); its share of the intended light
  };
  std::vector<Term> terms;
  const size_t n = own_d_.size();
  for (size_t i = 0; i < n; ++i) {
    if (own_gain_[i] <= 0) continue;
    float delivered = own_wr_[i];
    bool shared = false;
    for (const Other& o : others) {
      delivered += o.wr[i];
      shared = shared || o.wr[i] > 0;
    }
    const int32_t face = surface_.face.empty() ? -1 : surface_.face[i];
    const double level_here = face >= 0 && face < static_cast<int32_t>(level_of_face.size())
                                  ? level_of_face[face]
                                  : level;
    const float unclipped =
        static_cast<float>(level_here) * own_gain_[i] / std::max(delivered, 1e-30f);
    // Lit by this projector alone and within its reach: nothing to fill (most pixels; the
    // terms below are what a re-blend's compose spent its time on).
    if (!shared && unclipped <= 1.0f) {
      f[i] = unclipped;
      continue;
    }
    if (fill_limit <= 1.0) {
      f[i] = std::min(1.0f, unclipped);
      continue;
    }
    // The intended irradiance at the point (the surface shows T whatever its albedo).
    const double range = surface_.range_m[i];
    const double own_cap = surface_.cos_incidence[i] / (range * range);
    const double target = level_here / std::max(static_cast<double>(surface_.albedo[i]), 0.01);
    const double own_share = own_wr_[i] / delivered;
    bool any_clips = unclipped > 1.0f;
    for (const Other& o : others) {
      any_clips = any_clips || (o.wr[i] > 0 && o.wr[i] / delivered * target > o.cap[i]);
    }
    if (!any_clips) {
      f[i] = unclipped;
      continue;
    }
    terms.clear();
    const double own_room = std::min(own_cap, fill_limit * own_share * target);
    terms.push_back({own_room, own_share});
    for (const Other& o : others) {
      if (o.wr[i] <= 0) continue;
      const double share = o.wr[i] / delivered;
      terms.push_back(
          {std::min(static_cast<double>(o.cap[i]), fill_limit * share * target), share});
    }
    // Raise every share by one factor c until the intended light is reached; the terms run
    // out of room in the order of room / share.
    std::sort(terms.begin(), terms.end(),
              [](const Term& x, const Term& y) { return x.room * y.share < y.room * x.share; });
    double fixed = 0.0, free_share = 1.0, c = std::numeric_limits<double>::infinity();
    for (const Term& t : terms) {
      if (free_share <= 1e-12) break;
      const double full_at = t.room / (t.share * target);  // c at which t has no room left
      if (fixed + full_at * free_share * target >= target) {
        c = (target - fixed) / (free_share * target);
        break;
      }
      fixed += t.room;
      free_share -= t.share;
    }
    f[i] = static_cast<float>(std::min(1.0, std::min(own_room, c * own_share * target) / own_cap));
  }
  return factor;
}

namespace {

// The largest target irradiance u that projectors with (capacity, share) terms reach together
// when each delivers min(capacity, fill_limit share u) (Blender::Factor's water filling); the
// shares sum to 1. h(u) = sum_k min(cap_k, f s_k u) - u is concave and 0 at u = 0, rising or
// flat there (f >= 1); the reachable target is where it falls below 0. Term k saturates at
// u_k = cap_k / (f s_k).
double ReachableTarget(std::vector<std::pair<double, double>>* terms, double fill_limit) {
  std::sort(terms->begin(), terms->end(),
            [](const auto& x, const auto& y) { return x.first * y.second < y.first * x.second; });
  double fixed = 0.0, free_share = 1.0;
  for (const auto& [cap, share] : *terms) {
    if (share <= 0) continue;  // never given any light
    const double u_k = cap / (fill_limit * share);
    const double slope = fill_limit * free_share - 1.0;  // h(u) = fixed + slope u up to u_k
    if (fixed + slope * u_k < 0.0) return fixed / -slope;
    fixed += cap;
    free_share -= share;
  }
  return fixed;  // every term saturated: all the light there is
}

}  // namespace

FaceLevels LowestFaceLevels(const std::map<NodeId, FaceLevels>& maps, const FaceLevels& own,
                            NodeId without) {
  FaceLevels out = own;
  for (const auto& [unit, levels] : maps) {
    if (unit == without) continue;
    for (const auto& [face, level] : levels) {
      auto [it, inserted] = out.emplace(face, level);
      if (!inserted) it->second = std::min(it->second, level);
    }
  }
  return out;
}

std::vector<Blender::Other> Blender::Others(NodeId without) const {
  std::vector<Other> others;
  for (const auto& [unit, wr] : neighbour_reach_) {
    if (unit == without) continue;
    others.push_back({wr.data(), neighbour_gain_.at(unit).data()});
  }
  return others;
}

FaceLevels Blender::FaceLevelBounds(double level, double fill_limit, NodeId without) const {
  FaceLevels out;
  if (surface_.face.empty()) return out;
  const std::vector<Other> others = Others(without);
  std::vector<std::pair<double, double>> terms;
  const double f = std::max(fill_limit, 1.0);
  for (size_t i = 0; i < own_d_.size(); ++i) {
    if (own_gain_[i] <= 0 || surface_.face[i] < 0) continue;
    double delivered = own_wr_[i];
    for (const Other& o : others) delivered += o.wr[i];
    if (delivered <= 0) continue;
    const double range = surface_.range_m[i];
    const double own_cap = surface_.cos_incidence[i] / (range * range);
    const double albedo = std::max(static_cast<double>(surface_.albedo[i]), 0.01);
    // Where no projector clips at the level, the level is reached (each delivers at least its
    // share of it): most pixels, skipped.
    const double target = level / albedo;
    bool any_clips = own_wr_[i] / delivered * target > own_cap;
    for (const Other& o : others) {
      any_clips = any_clips || (o.wr[i] > 0 && o.wr[i] / delivered * target > o.cap[i]);
    }
    if (!any_clips) continue;
    terms.clear();
    terms.emplace_back(own_cap, own_wr_[i] / delivered);
    for (const Other& o : others) {
      if (o.wr[i] > 0) terms.emplace_back(o.cap[i], o.wr[i] / delivered);
    }
    const double reachable = ReachableTarget(&terms, f) * albedo;
    if (reachable >= level) continue;
    auto [it, inserted] = out.emplace(surface_.face[i], reachable);
    if (!inserted) it->second = std::min(it->second, reachable);
  }
  return out;
}

std::vector<double> Blender::BlackLight(double own_black, const std::map<NodeId, double>& black,
                                        NodeId without) const {
  const size_t n = own_d_.size();
  std::vector<double> light(n, 0.0);
  for (size_t i = 0; i < n; ++i) {
    const double r = surface_.range_m[i];
    if (r > 0) light[i] = own_black * surface_.cos_incidence[i] / (r * r);
  }
  for (const auto& [unit, gain] : neighbour_gain_) {
    if (unit == without) continue;
    auto it = black.find(unit);
    const double b = it == black.end() ? own_black : it->second;
    for (size_t i = 0; i < n; ++i) light[i] += b * gain[i];
  }
  return light;
}

double Blender::BlackPeak(double own_black, const std::map<NodeId, double>& black,
                          NodeId without) const {
  const std::vector<double> light = BlackLight(own_black, black, without);
  double peak = 0.0;
  for (size_t i = 0; i < light.size(); ++i) {
    if (own_w_[i] > 0) peak = std::max(peak, light[i]);
  }
  return peak;
}

cv::Mat Blender::Lift(double target, double own_black, const std::map<NodeId, double>& black,
                      double max_lift, NodeId without) const {
  cv::Mat lift(surface_.height_px, surface_.width_px, CV_32FC1, cv::Scalar(0));
  float* out = lift.ptr<float>();
  const std::vector<double> light = BlackLight(own_black, black, without);
  const cv::Mat alpha = Alpha(without);
  const float* a = alpha.ptr<float>();
  const double range = 1.0 - own_black;  // emission per unit of frame value above black
  for (size_t i = 0; i < light.size(); ++i) {
    const double r = surface_.range_m[i];
    if (own_w_[i] <= 0 || r <= 0 || light[i] >= target) continue;
    const double gain = surface_.cos_incidence[i] / (r * r);
    const double emission = a[i] * (target - light[i]) / gain;
    out[i] = static_cast<float>(std::min(max_lift, emission / range));
  }
  return lift;
}

}  // namespace sandtable::node
