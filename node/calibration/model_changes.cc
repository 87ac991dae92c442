#include "node/calibration/model_changes.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <map>
#include <memory>
#include <numeric>

#include <Eigen/Dense>

#include "common/base/thread_cpu_time.h"
#include "node/calibration/model_registration.h"
#include "node/calibration/point_tree.h"

namespace sandtable::node {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kWeld_m = 1e-5;
// Triangles facing up at least this much (normal z) cover a footprint cell: roofs, gables.
constexpr double kUpwardNormalZ = 0.2;
constexpr double kExtraCell_m = 0.01;
constexpr int kIcpIterations = 15;
constexpr double kMinRms_m = 0.0003;
constexpr double kSigmas = 3.0;

struct UnionFind {
  std::vector<int> parent;
  explicit UnionFind(int n) : parent(n) { std::iota(parent.begin(), parent.end(), 0); }
  int Find(int i) {
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return i;
  }
  void Join(int a, int b) { parent[Find(a)] = Find(b); }
};

// Owner of each footprint cell (model frame x, y).
struct Footprints {
  double min_x = 0, min_y = 0, cell = 0;
  int width = 0, height = 0;
  std::vector<int> owner;  // part index or -1
  std::vector<float> top;  // highest model surface in the cell (0: ground)
  int Index(double x, double y) const {
    const int i = static_cast<int>(std::floor((x - min_x) / cell));
    const int j = static_cast<int>(std::floor((y - min_y) / cell));
    if (i < 0 || j < 0 || i >= width || j >= height) return -1;
    return j * width + i;
  }
  int OwnerAt(double x, double y) const {
    const int k = Index(x, y);
    return k < 0 ? -1 : owner[k];
  }
  double TopAt(double x, double y) const {
    const int k = Index(x, y);
    return k < 0 ? 0.0 : top[k];
  }
};

Footprints RasterFootprints(const Scene& model, const std::vector<ModelPart>& parts,
                            const Eigen::AlignedBox2d& region, double cell) {
  Footprints f;
  f.cell = cell;
  f.min_x = region.min().x();
  f.min_y = region.min().y();
  f.width = std::max(1, static_cast<int>(std::ceil(region.sizes().x() / cell)));
  f.height = std::max(1, static_cast<int>(std::ceil(region.sizes().y() / cell)));
  f.owner.assign(static_cast<size_t>(f.width) * f.height, -1);
  f.top.assign(f.owner.size(), 0.0f);
  for (size_t p = 0; p < parts.size(); ++p) {
    for (int t : parts[p].triangles) {
      if (model.FaceNormal(t).z() < kUpwardNormalZ) continue;
      const Eigen::Vector3i& tri = model.triangles[t];
      const Eigen::Vector3d a = model.positions_in_table_m[tri[0]].cast<double>();
      const Eigen::Vector3d b = model.positions_in_table_m[tri[1]].cast<double>();
      const Eigen::Vector3d c = model.positions_in_table_m[tri[2]].cast<double>();
      const double det = (b.x() - a.x()) * (c.y() - a.y()) - (c.x() - a.x()) * (b.y() - a.y());
      if (std::abs(det) < 1e-14) continue;
      const int i0 = std::max(
          0, static_cast<int>(std::floor((std::min({a.x(), b.x(), c.x()}) - f.min_x) / cell)));
      const int i1 = std::min(
          f.width - 1,
          static_cast<int>(std::floor((std::max({a.x(), b.x(), c.x()}) - f.min_x) / cell)));
      const int j0 = std::max(
          0, static_cast<int>(std::floor((std::min({a.y(), b.y(), c.y()}) - f.min_y) / cell)));
      const int j1 = std::min(
          f.height - 1,
          static_cast<int>(std::floor((std::max({a.y(), b.y(), c.y()}) - f.min_y) / cell)));
      for (int j = j0; j <= j1; ++j) {
        for (int i = i0; i <= i1; ++i) {
          const double x = f.min_x + (i + 0.5) * cell, y = f.min_y + (j + 0.5) * cell;
          const double u = ((x - a.x()) * (c.y() - a.y()) - (c.x() - a.x()) * (y - a.y())) / det;
          const double v = ((b.x() - a.x()) * (y - a.y()) - (x - a.x()) * (b.y() - a.y())) / det;
          if (u < 0 || v < 0 || u + v > 1) continue;
          const double z = a.z() + u * (b.z() - a.z()) + v * (c.z() - a.z());
          const size_t k = static_cast<size_t>(j) * f.width + i;
          if (f.owner[k] < 0 || z > f.top[k]) {
            f.owner[k] = static_cast<int>(p);
            f.top[k] = static_cast<float>(z);
          }
        }
      }
    }
  }
  return f;
}

// A part's sampled surface and its k-d tree.
struct PartSurface {
  std::vector<Eigen::Vector3d> points;
  std::vector<Eigen::Vector3d> normals;
  std::unique_ptr<PointTree> tree;
  void Build() { tree = std::make_unique<PointTree>(&points); }
  // Nearest sample; false when there is none within gate.
  bool Nearest(const Eigen::Vector3d& q, double gate, size_t* k) const {
    double d2 = 0;
    *k = tree->Nearest(q, &d2);
    return d2 <= gate * gate;
  }
};

// Where the scan shows a part: x_in_model = R(yaw) (x_part - centre) + centre + t for the part's
// own points x_part.
struct PartPose {
  Eigen::Vector2d t = Eigen::Vector2d::Zero();
  double yaw_rad = 0.0;
  // The scan point brought back to where the part was modelled.
  Eigen::Vector3d ToPart(const Eigen::Vector3d& q, const Eigen::Vector2d& centre) const {
    const double c = std::cos(-yaw_rad), s = std::sin(-yaw_rad);
    const Eigen::Vector2d d = q.head<2>() - centre - t;
    return {c * d.x() - s * d.y() + centre.x(), s * d.x() + c * d.y() + centre.y(), q.z()};
  }
};

struct ScanPoint {
  Eigen::Vector3d q;  // model frame
  bool up = false;
  int owner = -1;
};

// Point-to-plane ICP of the part's surface on the scan points near it, in x, y and yaw.
// `information`: J^T J of the last iteration over rms^2 (t in m, yaw in rad): what the points
// determine; zero rows for what they do not (a roof alone says nothing of x, y).
PartPose FitPart(const PartSurface& surface, const std::vector<const ScanPoint*>& near,
                 const Eigen::Vector2d& centre, PartPose pose, double gate, double* rms_m,
                 int* used, Eigen::Matrix3d* information) {
  *rms_m = 0.0;
  *used = 0;
  information->setZero();
  for (int it = 0; it < kIcpIterations; ++it) {
    const double g = it < 5 ? 2.0 * gate : gate;
    Eigen::Matrix3d a = Eigen::Matrix3d::Zero();
    Eigen::Vector3d b = Eigen::Vector3d::Zero();
    double sum_sq = 0;
    int n = 0;
    for (const ScanPoint* sp : near) {
      const Eigen::Vector3d p = pose.ToPart(sp->q, centre);
      size_t k = 0;
      if (!surface.Nearest(p, g, &k)) continue;
      const Eigen::Vector3d& nq = surface.normals[k];
      const double r = nq.dot(p - surface.points[k]);
      // d(p)/d(t) = -R(-yaw) (x, y), d(p)/d(yaw) = -ez x (p - centre) (the point, in part
      // coordinates, turns the other way); in a linearised step at the current pose.
      const double c = std::cos(-pose.yaw_rad), s = std::sin(-pose.yaw_rad);
      const Eigen::Vector2d nxy = nq.head<2>();
      const Eigen::Vector2d dp_dtx(-c, -s), dp_dty(s, -c);
      const Eigen::Vector2d v = p.head<2>() - centre;
      const Eigen::Vector2d dp_dyaw(v.y(), -v.x());
      const Eigen::Vector3d j(nxy.dot(dp_dtx), nxy.dot(dp_dty), nxy.dot(dp_dyaw));
      a += j * j.transpose();
      b -= j * r;
      sum_sq += r * r;
      ++n;
    }
    *used = n;
    *rms_m = n ? std::sqrt(sum_sq / n) : 0.0;
    if (n < 3) break;
    // The noise floor of a scan point (a few tenths of a mm) bounds the information.
    *information = a / std::max(*rms_m * *rms_m, kMinRms_m * kMinRms_m);
    // Damping: directions the points do not constrain (a roof alone says nothing of x, y)
    // stay where the footprint search put them.
    a += 1e-6 * Eigen::Matrix3d::Identity();
    const Eigen::Vector3d d = a.ldlt().solve(b);
    if (!d.allFinite()) break;
    pose.t += d.head<2>();
    pose.yaw_rad += d.z();
    if (d.head<2>().norm() < 1e-7 && std::abs(d.z()) < 1e-7) break;
  }
  return pose;
}

}  // namespace

Status ModelChangeOptions::Check() const {
  if (!(structure_height_m > 0) || !(cell_m > 0) || !(sample_spacing_m > 0) ||
      !(search_radius_m >= 0) || !(search_step_m > 0) || !(moved_threshold_m > 0) ||
      !(placement_tolerance_m >= 0) || !(icp_gate_m > 0) ||
      !(missing_support >= 0 && missing_support <= 1) || min_points < 1 || min_extra_points < 1) {
    return InvalidArgumentError(
        "model changes: heights, cells, steps, gates > 0; placement tolerance >= 0; "
        "missing_support in [0, 1]; counts >= 1");
  }
  return OkStatus();
}

std::string_view PartStateName(PartState state) {
  switch (state) {
    case PartState::kPresent:
      return "present";
    case PartState::kMoved:
      return "moved";
    case PartState::kMissing:
      return "missing";
    case PartState::kUnobserved:
      return "unobserved";
  }
  return "unknown";
}

std::vector<ModelPart> SegmentModelParts(const Scene& model, double structure_height_m) {
  std::vector<int> raised;
  for (int t = 0; t < model.NumTriangles(); ++t) {
    const Eigen::Vector3i& tri = model.triangles[t];
    double top = -std::numeric_limits<double>::infinity();
    for (int k = 0; k < 3; ++k) top = std::max(top, double{model.positions_in_table_m[tri[k]].z()});
    if (top > structure_height_m) raised.push_back(t);
  }
  UnionFind sets(static_cast<int>(raised.size()));
  std::map<std::array<int64_t, 3>, int> first_with_vertex;
  for (size_t i = 0; i < raised.size(); ++i) {
    const Eigen::Vector3i& tri = model.triangles[raised[i]];
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3f& v = model.positions_in_table_m[tri[k]];
      const std::array<int64_t, 3> key{std::llround(v.x() / kWeld_m), std::llround(v.y() / kWeld_m),
                                       std::llround(v.z() / kWeld_m)};
      const auto [it, inserted] = first_with_vertex.emplace(key, static_cast<int>(i));
      if (!inserted) sets.Join(static_cast<int>(i), it->second);
    }
  }
  std::map<int, ModelPart> by_root;
  for (size_t i = 0; i < raised.size(); ++i) {
    ModelPart& part = by_root[sets.Find(static_cast<int>(i))];
    part.triangles.push_back(raised[i]);
    const Eigen::Vector3i& tri = model.triangles[raised[i]];
    for (int k = 0; k < 3; ++k)
      part.bounds_m.extend(model.positions_in_table_m[tri[k]].cast<double>());
  }
  std::vector<ModelPart> parts;
  for (auto& [root, part] : by_root) parts.push_back(std::move(part));
  // Pieces whose footprints overlap are one building (a roof modelled apart from its walls).
  for (bool merged = true; merged;) {
    merged = false;
    for (size_t i = 0; i < parts.size() && !merged; ++i) {
      for (size_t j = i + 1; j < parts.size() && !merged; ++j) {
        const Eigen::AlignedBox2d a(parts[i].bounds_m.min().head<2>(),
                                    parts[i].bounds_m.max().head<2>());
        const Eigen::AlignedBox2d b(parts[j].bounds_m.min().head<2>(),
                                    parts[j].bounds_m.max().head<2>());
        if (!a.intersection(b).isEmpty() && a.intersection(b).volume() > 0) {
          parts[i].triangles.insert(parts[i].triangles.end(), parts[j].triangles.begin(),
                                    parts[j].triangles.end());
          parts[i].bounds_m.extend(parts[j].bounds_m);
          parts.erase(parts.begin() + static_cast<std::ptrdiff_t>(j));
          merged = true;
        }
      }
    }
  }
  for (ModelPart& p : parts) std::sort(p.triangles.begin(), p.triangles.end());
  std::sort(parts.begin(), parts.end(), [](const ModelPart& a, const ModelPart& b) {
    return a.triangles.front() < b.triangles.front();
  });
  return parts;
}

namespace {

// Each part's surface for the fit.
std::vector<PartSurface> PartSurfaces(const Scene& model, const std::vector<ModelPart>& parts,
                                      double sample_spacing_m) {
  std::vector<int> part_of_triangle(model.NumTriangles(), -1);
  for (size_t p = 0; p < parts.size(); ++p) {
    for (int t : parts[p].triangles) part_of_triangle[t] = static_cast<int>(p);
  }
  const ModelSurface samples = SampleModelSurface(model, sample_spacing_m);
  std::vector<PartSurface> surfaces(parts.size());
  for (size_t i = 0; i < samples.points_m.size(); ++i) {
    const int p = part_of_triangle[samples.triangle[i]];
    if (p < 0) continue;
    surfaces[p].points.push_back(samples.points_m[i]);
    surfaces[p].normals.push_back(samples.normals[i]);
  }
  for (PartSurface& s : surfaces) s.Build();
  return surfaces;
}

// The footprint search's answer for one part: the best translation (the centroid of the
// equally good ones), its spread, and how many scan points fell on the footprint there.
struct FootprintFit {
  Eigen::Vector2d mean_t = Eigen::Vector2d::Zero();
  Eigen::Vector2d var_t = Eigen::Vector2d::Zero();  // the plateau's spread and the step's
  int in = 0, up = 0;                               // points on the footprint, of them up
};

// Footprint search: coarse (4 steps) over the whole radius, then every step around the best
// coarse translation; the centroid of the best fine translations.
FootprintFit SearchFootprint(const std::vector<const ScanPoint*>& near,
                             const Footprints& footprints, int part,
                             const ModelChangeOptions& options) {
  auto score_at = [&](const Eigen::Vector2d& t, int* in, int* up) {
    int score = 0;
    *in = 0;
    *up = 0;
    for (const ScanPoint* sp : near) {
      if (footprints.OwnerAt(sp->q.x() - t.x(), sp->q.y() - t.y()) != part) continue;
      ++*in;
      *up += sp->up;
      score += sp->up ? 1 : -1;
    }
    return score;
  };
  const double coarse_step = 4 * options.search_step_m;
  const int coarse_steps = static_cast<int>(std::floor(options.search_radius_m / coarse_step));
  int best_coarse = std::numeric_limits<int>::min();
  Eigen::Vector2d coarse_t = Eigen::Vector2d::Zero();
  for (int jy = -coarse_steps; jy <= coarse_steps; ++jy) {
    for (int jx = -coarse_steps; jx <= coarse_steps; ++jx) {
      const Eigen::Vector2d t(jx * coarse_step, jy * coarse_step);
      if (t.norm() > options.search_radius_m + 1e-12) continue;
      int in = 0, up = 0;
      const int score = score_at(t, &in, &up);
      if (score > best_coarse || (score == best_coarse && t.norm() < coarse_t.norm())) {
        best_coarse = score;
        coarse_t = t;
      }
    }
  }
  FootprintFit fit;
  int best_score = std::numeric_limits<int>::min();
  std::vector<Eigen::Vector2d> tied;
  for (int jy = -4; jy <= 4; ++jy) {
    for (int jx = -4; jx <= 4; ++jx) {
      const Eigen::Vector2d t =
          coarse_t + Eigen::Vector2d(jx * options.search_step_m, jy * options.search_step_m);
      int in = 0, up = 0;
      const int score = score_at(t, &in, &up);
      if (score > best_score) {
        best_score = score;
        fit.in = in;
        fit.up = up;
        tied.clear();
      }
      if (score == best_score) tied.push_back(t);
    }
  }
  for (const Eigen::Vector2d& t : tied) fit.mean_t += t;
  fit.mean_t /= std::max<size_t>(1, tied.size());
  fit.var_t = Eigen::Vector2d::Constant(options.search_step_m * options.search_step_m / 12.0);
  for (const Eigen::Vector2d& t : tied) {
    fit.var_t += (t - fit.mean_t).cwiseAbs2() / static_cast<double>(tied.size());
  }
  return fit;
}

// The fitted pose's uncertainty and whether it moved: a displacement (translation, or the
// footprint's corners turned by the yaw) over the threshold and over 3 sigma of its estimate.
void JudgeMove(const PartPose& pose, const Eigen::Matrix3d& information,
               const Eigen::Vector2d& var_t, const ModelChangeOptions& options,
               PartChange* change) {
  // Uncertainty: the fit's information plus the footprint search's (x, y only).
  Eigen::Matrix3d total = information;
  total(0, 0) += 1.0 / var_t.x();
  total(1, 1) += 1.0 / var_t.y();
  total(2, 2) += 1e-12;  // no yaw from the footprint
  const Eigen::Matrix3d covariance = total.inverse();
  change->moved_sigma_mm = std::sqrt(covariance(0, 0) + covariance(1, 1)) * 1e3;
  change->yaw_sigma_deg = std::sqrt(covariance(2, 2)) * 180.0 / kPi;
  const double corner = 0.5 * change->size_m.head<2>().norm();
  const double shift = pose.t.norm();
  const double turn = std::abs(pose.yaw_rad) * corner;
  const bool shifted =
      shift > options.moved_threshold_m && shift > kSigmas * change->moved_sigma_mm * 1e-3;
  const bool turned = turn > options.moved_threshold_m &&
                      std::abs(change->moved_yaw_deg) > kSigmas * change->yaw_sigma_deg;
  change->state = shifted || turned ? PartState::kMoved : PartState::kPresent;
  change->displacement_m = std::max(shift, turn);
}

// One part against the scan: unobserved, missing, or found (present or moved) at `*pose`.
PartChange AssessPart(const ModelPart& part, int pi, const PartSurface& surface,
                      const std::vector<ScanPoint>& scan, const Footprints& footprints,
                      double margin, const ModelChangeOptions& options, PartPose* pose) {
  PartChange change;
  change.part = pi;
  change.centre_in_model_m = part.bounds_m.center();
  change.size_m = part.bounds_m.sizes();
  const Eigen::Vector2d centre = change.centre_in_model_m.head<2>();
  // Scan points this part could explain: near it, not on another part's footprint.
  Eigen::AlignedBox2d reach(part.bounds_m.min().head<2>(), part.bounds_m.max().head<2>());
  reach.extend(reach.min() - Eigen::Vector2d::Constant(margin));
  reach.extend(reach.max() + Eigen::Vector2d::Constant(margin));
  std::vector<const ScanPoint*> near;
  int up_here = 0;
  for (const ScanPoint& sp : scan) {
    if (!reach.contains(sp.q.head<2>())) continue;
    if (sp.owner >= 0 && sp.owner != pi) continue;
    near.push_back(&sp);
    if (sp.owner == pi) {
      ++change.points_on_footprint;
      up_here += sp.up;
    }
  }
  change.support =
      change.points_on_footprint ? up_here / static_cast<double>(change.points_on_footprint) : 0;
  const FootprintFit fit = SearchFootprint(near, footprints, pi, options);
  const bool observed_here = change.points_on_footprint >= options.min_points;
  const double best_support = fit.in ? fit.up / static_cast<double>(fit.in) : 0.0;
  if (!observed_here && fit.in < options.min_points) {
    change.state = PartState::kUnobserved;
    return change;
  }
  if (fit.in < options.min_points || best_support < options.missing_support) {
    change.state = PartState::kMissing;
    return change;
  }
  PartPose start;
  start.t = fit.mean_t;
  double rms = 0;
  int used = 0;
  Eigen::Matrix3d information;
  *pose = FitPart(surface, near, centre, start, options.icp_gate_m, &rms, &used, &information);
  change.moved_by_m = pose->t;
  change.moved_yaw_deg = pose->yaw_rad * 180.0 / kPi;
  change.fit_rms_mm = rms * 1e3;
  change.fit_points = used;
  JudgeMove(*pose, information, fit.var_t, options, &change);
  return change;
}

// Up points no part explains, above the model where they stand, grouped into connected cells:
// extra structure.
std::vector<ExtraStructure> FindExtras(const std::vector<ScanPoint>& scan,
                                       const std::vector<PartChange>& changes,
                                       const std::vector<PartPose>& found,
                                       const std::vector<PartSurface>& surfaces,
                                       const Footprints& footprints,
                                       const ModelChangeOptions& options) {
  std::map<std::pair<int, int>, std::vector<const ScanPoint*>> cells;
  for (const ScanPoint& sp : scan) {
    if (!sp.up) continue;
    if (sp.q.z() - footprints.TopAt(sp.q.x(), sp.q.y()) <= options.structure_height_m) {
      // At or below the model's surface here: explained unless the part is missing or moved
      // (then the scan should not see it there).
      if (sp.owner >= 0 && (changes[sp.owner].state == PartState::kPresent ||
                            changes[sp.owner].state == PartState::kUnobserved)) {
        continue;
      }
    }
    bool explained = false;
    for (size_t p = 0; p < changes.size() && !explained; ++p) {
      const PartState state = changes[p].state;
      if (state != PartState::kPresent && state != PartState::kMoved) continue;
      const Eigen::Vector3d local = found[p].ToPart(sp.q, changes[p].centre_in_model_m.head<2>());
      size_t k = 0;
      explained = footprints.OwnerAt(local.x(), local.y()) == static_cast<int>(p) ||
                  surfaces[p].Nearest(local, options.icp_gate_m, &k);
    }
    if (explained) continue;
    cells[{static_cast<int>(std::floor(sp.q.x() / kExtraCell_m)),
           static_cast<int>(std::floor(sp.q.y() / kExtraCell_m))}]
        .push_back(&sp);
  }
  std::vector<ExtraStructure> extras;
  std::map<std::pair<int, int>, bool> visited;
  for (const auto& [cell, points] : cells) {
    if (visited[cell]) continue;
    std::vector<std::pair<int, int>> stack{cell}, component;
    visited[cell] = true;
    while (!stack.empty()) {
      const auto c = stack.back();
      stack.pop_back();
      component.push_back(c);
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
          const std::pair<int, int> n{c.first + dx, c.second + dy};
          if (cells.count(n) && !visited[n]) {
            visited[n] = true;
            stack.push_back(n);
          }
        }
      }
    }
    ExtraStructure e;
    Eigen::AlignedBox3d box;
    for (const auto& c : component) {
      for (const ScanPoint* sp : cells.at(c)) {
        box.extend(sp->q);
        e.height_m =
            std::max(e.height_m, sp->q.z() - double{footprints.TopAt(sp->q.x(), sp->q.y())});
        ++e.points;
      }
    }
    if (e.points < options.min_extra_points) continue;
    e.centre_in_model_m = box.center();
    e.size_m = box.sizes().head<2>();
    extras.push_back(e);
  }
  return extras;
}

}  // namespace

Expected<ModelChangeReport> DetectModelChanges(const Scene& model,
                                               std::span<const Eigen::Vector3d> scan_in_table_m,
                                               const Rigid3d& table_from_model,
                                               const ModelChangeOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  const double cpu_start = ThreadCpuSeconds();
  ModelChangeReport out;
  const std::vector<ModelPart> parts = SegmentModelParts(model, options.structure_height_m);
  if (parts.empty()) {
    out.time_s = ThreadCpuSeconds() - cpu_start;
    return out;
  }
  Eigen::AlignedBox2d region;
  for (const ModelPart& p : parts) {
    region.extend(p.bounds_m.min().head<2>());
    region.extend(p.bounds_m.max().head<2>());
  }
  const double margin = options.search_radius_m + 2 * options.cell_m;
  region.extend(region.min() - Eigen::Vector2d(margin, margin));
  region.extend(region.max() + Eigen::Vector2d(margin, margin));
  const Footprints footprints = RasterFootprints(model, parts, region, options.cell_m);
  const std::vector<PartSurface> surfaces = PartSurfaces(model, parts, options.sample_spacing_m);

  const Rigid3d model_from_table = table_from_model.Inverse();
  std::vector<ScanPoint> scan;
  for (const Eigen::Vector3d& p : scan_in_table_m) {
    ScanPoint sp;
    sp.q = model_from_table * p;
    if (!sp.q.allFinite() || !region.contains(sp.q.head<2>())) continue;
    sp.up = sp.q.z() > options.structure_height_m;
    sp.owner = footprints.OwnerAt(sp.q.x(), sp.q.y());
    scan.push_back(sp);
  }

  std::vector<PartPose> found(parts.size());
  for (size_t p = 0; p < parts.size(); ++p) {
    const PartChange change = AssessPart(parts[p], static_cast<int>(p), surfaces[p], scan,
                                         footprints, margin, options, &found[p]);
    switch (change.state) {
      case PartState::kPresent:
        ++out.present;
        break;
      case PartState::kMoved:
        ++out.moved;
        break;
      case PartState::kMissing:
        ++out.missing;
        break;
      case PartState::kUnobserved:
        ++out.unobserved;
        break;
    }
    const bool found_here =
        change.state == PartState::kPresent || change.state == PartState::kMoved;
    if (found_here && (change.state == PartState::kPresent ||
                       change.displacement_m <= options.placement_tolerance_m)) {
      ++out.in_place;
    }
    out.parts.push_back(change);
  }
  out.extras = FindExtras(scan, out.parts, found, surfaces, footprints, options);
  out.time_s = ThreadCpuSeconds() - cpu_start;
  return out;
}

}  // namespace sandtable::node
