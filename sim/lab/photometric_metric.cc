#include "sim/lab/photometric_metric.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <limits>
#include <map>
#include <numbers>
#include <numeric>
#include <tuple>

#include <opencv2/imgproc.hpp>

#include "sim/lab/registration_metric.h"

namespace sandtable::sim {
namespace {

// Quantized position (0.1 um): vertices duplicated per face meet at the same key.
using Key = std::array<int64_t, 3>;
Key KeyOf(const Eigen::Vector3f& p) {
  return {std::llround(p.x() * 1e7), std::llround(p.y() * 1e7), std::llround(p.z() * 1e7)};
}

int Find(std::vector<int>& parent, int i) {
  while (parent[i] != i) {
    parent[i] = parent[parent[i]];
    i = parent[i];
  }
  return i;
}

constexpr double kTableHeight_m = 1e-3;  // a face within this of z = 0 is the table
constexpr double kFaceMargin_m = 3e-3;   // lattice samples keep this far from a face's edges

bool InTriangle2d(const Eigen::Vector2d& p, const Eigen::Vector2d& a, const Eigen::Vector2d& b,
                  const Eigen::Vector2d& c) {
  auto cross = [](const Eigen::Vector2d& u, const Eigen::Vector2d& v) {
    return u.x() * v.y() - u.y() * v.x();
  };
  const double d1 = cross(b - a, p - a), d2 = cross(c - b, p - b), d3 = cross(a - c, p - c);
  const bool neg = d1 < 0 || d2 < 0 || d3<0, pos = d1> 0 || d2 > 0 || d3 > 0;
  return !(neg && pos);
}

double RelativeStepPct(double a, double b) { return 200.0 * std::abs(a - b) / (a + b); }

// Keeps the largest of `over` (all pairs over 1 %) in `stats->worst`, largest first.
void KeepWorst(std::vector<StepStats::Pair>* over, StepStats* stats) {
  const size_t n = std::min<size_t>(over->size(), StepStats::kWorstPairs);
  std::partial_sort(
      over->begin(), over->begin() + static_cast<std::ptrdiff_t>(n), over->end(),
      [](const StepStats::Pair& x, const StepStats::Pair& y) { return x.step_pct > y.step_pct; });
  stats->worst.assign(over->begin(), over->begin() + static_cast<std::ptrdiff_t>(n));
}

StepStats Summarise(std::vector<double>* steps) {
  StepStats s;
  s.pairs = static_cast<int>(steps->size());
  if (steps->empty()) return s;
  s.max_pct = *std::max_element(steps->begin(), steps->end());
  s.p99_pct = Quantile(*steps, 0.99);
  s.pairs_over_1pct = static_cast<int>(
      std::count_if(steps->begin(), steps->end(), [](double v) { return v > 1.0; }));
  return s;
}

// The pixels measured on faces of `kind`: lit, and at least kEdgeMargin_px from another face
// and from an unlit pixel (a view pixel integrates the light over its footprint: one at an
// edge mixes two surfaces, or light and dark).
cv::Mat InnerPixels(const cv::Mat& luminance, const cv::Mat& face_ids, const FaceGroups& faces,
                    SurfaceKind kind, double lit_nits) {
  constexpr int kEdgeMargin_px = 2;
  cv::Mat inner(luminance.size(), CV_8UC1, cv::Scalar(0));
  for (int y = 0; y < luminance.rows; ++y) {
    for (int x = 0; x < luminance.cols; ++x) {
      const int id = face_ids.at<int32_t>(y, x);
      if (id >= 0 && faces.kind[id] == kind && luminance.at<float>(y, x) > lit_nits) {
        inner.at<uint8_t>(y, x) = 255;
      }
    }
  }
  cv::Mat same_face(luminance.size(), CV_8UC1, cv::Scalar(0));
  for (int y = kEdgeMargin_px; y < luminance.rows - kEdgeMargin_px; ++y) {
    for (int x = kEdgeMargin_px; x < luminance.cols - kEdgeMargin_px; ++x) {
      const int id = face_ids.at<int32_t>(y, x);
      bool same = true;
      for (int dy = -kEdgeMargin_px; dy <= kEdgeMargin_px && same; ++dy) {
        for (int dx = -kEdgeMargin_px; dx <= kEdgeMargin_px && same; ++dx) {
          same = face_ids.at<int32_t>(y + dy, x + dx) == id;
        }
      }
      if (same) same_face.at<uint8_t>(y, x) = 255;
    }
  }
  cv::erode(inner, inner,
            cv::getStructuringElement(cv::MORPH_RECT,
                                      cv::Size(2 * kEdgeMargin_px + 1, 2 * kEdgeMargin_px + 1)));
  inner &= same_face;
  return inner;
}

// Casts a top view's pixels straight down, a row at a time (one coherent batch each), and
// hands each row's hits to `row`.
void CastTopViewRows(
    const RayCaster& truth, const Eigen::Vector2d& area_min_m, const Eigen::Vector2d& area_max_m,
    cv::Size size, const std::function<void(int, const std::vector<std::optional<RayHit>>&)>& row) {
  const Eigen::Vector2d span = area_max_m - area_min_m;
  const double top_m = truth.scene().Bounds().max().z() + 1.0;
  std::vector<Ray> rays(static_cast<size_t>(size.width));
  std::vector<std::optional<RayHit>> hits;
  for (int y = 0; y < size.height; ++y) {
    for (int x = 0; x < size.width; ++x) {
      const Eigen::Vector2d xy =
          area_min_m + Eigen::Vector2d((x + 0.5) / size.width * span.x(),
                                       (1.0 - (y + 0.5) / size.height) * span.y());
      rays[x].origin_in_table_m = Eigen::Vector3d(xy.x(), xy.y(), top_m);
      rays[x].direction_in_table = -Eigen::Vector3d::UnitZ();
    }
    truth.IntersectBatch(rays, &hits, /*coherent=*/true);
    row(y, hits);
  }
}

}  // namespace

const char* SurfaceKindName(SurfaceKind kind) {
  switch (kind) {
    case SurfaceKind::kTable:
      return "table";
    case SurfaceKind::kRoof:
      return "roof";
    case SurfaceKind::kWall:
      return "wall";
    case SurfaceKind::kNone:
      break;
  }
  return "none";
}

FaceGroups GroupFaces(const Scene& scene) {
  const int n = scene.NumTriangles();
  std::vector<int> parent(n);
  std::iota(parent.begin(), parent.end(), 0);
  std::vector<Eigen::Vector3d> normal(n);
  std::vector<double> offset(n, 0.0);
  for (int t = 0; t < n; ++t) {
    normal[t] = scene.FaceNormal(t);
    offset[t] = normal[t].dot(scene.positions_in_table_m[scene.triangles[t][0]].cast<double>());
  }
  std::map<std::pair<Key, Key>, int> edge_owner;
  for (int t = 0; t < n; ++t) {
    if (normal[t].squaredNorm() == 0) continue;
    for (int e = 0; e < 3; ++e) {
      Key a = KeyOf(scene.positions_in_table_m[scene.triangles[t][e]]);
      Key b = KeyOf(scene.positions_in_table_m[scene.triangles[t][(e + 1) % 3]]);
      if (b < a) std::swap(a, b);
      auto [it, inserted] = edge_owner.emplace(std::make_pair(a, b), t);
      if (inserted) continue;
      const int u = it->second;
      if (normal[u].dot(normal[t]) > 1.0 - 1e-6 && std::abs(offset[u] - offset[t]) < 1e-6) {
        parent[Find(parent, u)] = Find(parent, t);
      }
    }
  }
  FaceGroups g;
  g.group_of_triangle.assign(n, -1);
  std::map<int, int> id_of_root;
  for (int t = 0; t < n; ++t) {
    if (normal[t].squaredNorm() == 0) continue;
    const int root = Find(parent, t);
    auto [it, inserted] = id_of_root.emplace(root, g.count());
    if (inserted) {
      const double z = scene.positions_in_table_m[scene.triangles[t][0]].z();
      SurfaceKind kind = SurfaceKind::kNone;
      if (std::abs(normal[t].z()) < 0.3) {
        kind = SurfaceKind::kWall;
      } else if (normal[t].z() >= 0.3) {
        kind = normal[t].z() > 0.999 && std::abs(z) < kTableHeight_m ? SurfaceKind::kTable
                                                                     : SurfaceKind::kRoof;
      }
      g.kind.push_back(kind);
      g.normal.push_back(normal[t]);
    }
    g.group_of_triangle[t] = it->second;
  }
  return g;
}

cv::Mat TopViewFaceIds(const RayCaster& truth, const FaceGroups& faces,
                       const Eigen::Vector2d& area_min_m, const Eigen::Vector2d& area_max_m,
                       cv::Size size) {
  cv::Mat ids(size, CV_32SC1, cv::Scalar(-1));
  CastTopViewRows(truth, area_min_m, area_max_m, size,
                  [&](int y, const std::vector<std::optional<RayHit>>& hits) {
                    for (int x = 0; x < size.width; ++x) {
                      if (hits[x] && hits[x]->front_face) {
                        ids.at<int32_t>(y, x) = faces.group_of_triangle[hits[x]->triangle];
                      }
                    }
                  });
  return ids;
}

StraddleTest::StraddleTest(std::vector<Projector> projectors, const RayCaster& truth,
                           const FaceGroups& faces)
    : projectors_(std::move(projectors)) {
  for (const Projector& p : projectors_) {
    const int w = p.model.width_px, h = p.model.height_px;
    const Rigid3d table_from_projector = p.projector_from_table.Inverse();
    const Eigen::Matrix3d rotation = table_from_projector.RotationMatrix();
    // Face hit by each corner ray (-1: none), corners at (c - 0.5, r - 0.5).
    std::vector<int> corner_face(static_cast<size_t>(w + 1) * (h + 1), -1);
    std::vector<Ray> rays(static_cast<size_t>(w + 1));
    std::vector<std::optional<RayHit>> hits;
    for (int r = 0; r <= h; ++r) {
      for (int c = 0; c <= w; ++c) {
        Expected<Eigen::Vector3d> ray = p.model.Unproject(Eigen::Vector2d(c - 0.5, r - 0.5));
        const Eigen::Vector3d dir =
            ray.ok() ? *ray
                     : Eigen::Vector3d(p.model.NormalizedFromPixel({c - 0.5, r - 0.5}).x(),
                                       p.model.NormalizedFromPixel({c - 0.5, r - 0.5}).y(), 1.0);
        rays[c].origin_in_table_m = table_from_projector.translation;
        rays[c].direction_in_table = rotation * dir;
      }
      truth.IntersectBatch(rays, &hits, /*coherent=*/true);
      for (int c = 0; c <= w; ++c) {
        if (hits[c])
          corner_face[static_cast<size_t>(r) * (w + 1) + c] =
              faces.group_of_triangle[hits[c]->triangle];
      }
    }
    cv::Mat mask(h, w, CV_8UC1, cv::Scalar(0));
    for (int r = 0; r < h; ++r) {
      for (int c = 0; c < w; ++c) {
        auto at = [&](int cc, int rr) {
          return corner_face[static_cast<size_t>(rr) * (w + 1) + cc];
        };
        const int a = at(c, r);
        if (a < 0 || at(c + 1, r) != a || at(c, r + 1) != a || at(c + 1, r + 1) != a) {
          mask.at<uint8_t>(r, c) = 255;
        }
      }
    }
    cv::dilate(mask, mask, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(3, 3)));
    masks_.push_back(mask);
  }
}

bool StraddleTest::Straddled(const Eigen::Vector3d& point_in_table_m) const {
  for (size_t k = 0; k < projectors_.size(); ++k) {
    const std::optional<Eigen::Vector2d> pixel =
        projectors_[k].model.Project(projectors_[k].projector_from_table * point_in_table_m);
    if (!pixel || !projectors_[k].model.InImage(*pixel)) continue;
    const int c = static_cast<int>(std::lround(pixel->x()));
    const int r = static_cast<int>(std::lround(pixel->y()));
    if (c < 0 || r < 0 || c >= masks_[k].cols || r >= masks_[k].rows) continue;
    if (masks_[k].at<uint8_t>(r, c)) return true;
  }
  return false;
}

cv::Mat TopViewStraddled(const RayCaster& truth, const StraddleTest& test,
                         const Eigen::Vector2d& area_min_m, const Eigen::Vector2d& area_max_m,
                         cv::Size size) {
  cv::Mat out(size, CV_8UC1, cv::Scalar(0));
  CastTopViewRows(truth, area_min_m, area_max_m, size,
                  [&](int y, const std::vector<std::optional<RayHit>>& hits) {
                    for (int x = 0; x < size.width; ++x) {
                      if (hits[x] && test.Straddled(hits[x]->point_in_table_m)) {
                        out.at<uint8_t>(y, x) = 255;
                      }
                    }
                  });
  return out;
}

const char* StepPlaceName(StepPlace place) {
  switch (place) {
    case StepPlace::kInterior:
      return "interior";
    case StepPlace::kOneEdge:
      return "one_edge";
    case StepPlace::kTwoEdges:
      return "two_edges";
  }
  return "?";
}

StepPlace PlaceOfStep(const std::vector<ProjectorPairTruth>& projectors, double near_px) {
  int edges = 0;
  for (const ProjectorPairTruth& p : projectors) {
    bool edge = p.a.visible != p.b.visible || p.a.lit_varies_near || p.b.lit_varies_near;
    for (const SampleTruth* t : {&p.a, &p.b}) {
      if (!t->projectable) continue;
      const Eigen::Vector2d& px = t->pixel_px;
      // Distance to the image's border (pixel edges at -0.5 and size - 0.5), either side.
      const double d = std::min({std::abs(px.x() + 0.5), std::abs(p.width_px - 0.5 - px.x()),
                                 std::abs(px.y() + 0.5), std::abs(p.height_px - 0.5 - px.y())});
      if (d < near_px && (t->visible || p.a.visible || p.b.visible)) edge = true;
    }
    edges += edge;
  }
  return edges == 0 ? StepPlace::kInterior
                    : (edges == 1 ? StepPlace::kOneEdge : StepPlace::kTwoEdges);
}

Expected<StepPlaces> PlaceSteps(
    const StepStats& steps, double bound_pct,
    const std::function<Eigen::Vector3d(double x, double y)>& point_of_pixel,
    const std::vector<ProjectorSize>& projectors,
    const std::function<
        Expected<std::vector<SampleTruth>>(NodeId, const std::vector<Eigen::Vector3d>&)>& truth) {
  constexpr int kRing = 8;
  constexpr double kRingRadius_px = 3.0;
  std::vector<const StepStats::Pair*> pairs;
  std::vector<Eigen::Vector3d> points;  // per pair: a, a's ring, b, b's ring
  for (const StepStats::Pair& pair : steps.worst) {
    if (pair.step_pct <= bound_pct) break;
    pairs.push_back(&pair);
    for (const Eigen::Vector3d& px : {pair.a, pair.b}) {
      points.push_back(point_of_pixel(px.x(), px.y()));
      for (int k = 0; k < kRing; ++k) {
        const double angle = k * 2.0 * M_PI / kRing;
        points.push_back(point_of_pixel(px.x() + kRingRadius_px * std::cos(angle),
                                        px.y() + kRingRadius_px * std::sin(angle)));
      }
    }
  }
  const size_t per_pair = 2 * (kRing + 1);
  std::vector<std::vector<ProjectorPairTruth>> truths(pairs.size());
  for (const ProjectorSize& projector : projectors) {
    if (points.empty()) break;
    Expected<std::vector<SampleTruth>> t = truth(projector.id, points);
    if (!t.ok()) return t.status();
    if (t->size() != points.size()) return InternalError("truth: one sample per point expected");
    for (size_t i = 0; i < pairs.size(); ++i) {
      ProjectorPairTruth p;
      p.width_px = projector.width_px;
      p.height_px = projector.height_px;
      for (int side = 0; side < 2; ++side) {
        const size_t base = i * per_pair + side * (kRing + 1);
        SampleTruth s = (*t)[base];
        for (int k = 1; k <= kRing; ++k) {
          if ((*t)[base + k].visible != s.visible) s.lit_varies_near = true;
        }
        (side == 0 ? p.a : p.b) = s;
      }
      truths[i].push_back(p);
    }
  }
  StepPlaces places;
  places.pairs = static_cast<int>(pairs.size());
  places.pairs_capped =
      steps.worst.size() == StepStats::kWorstPairs && steps.worst.back().step_pct > bound_pct;
  for (size_t i = 0; i < pairs.size(); ++i) {
    const StepPlace place = PlaceOfStep(truths[i]);
    ++places.count[static_cast<int>(place)];
    if (place == StepPlace::kInterior) {
      places.interior_max_pct = std::max(places.interior_max_pct, pairs[i]->step_pct);
    }
  }
  return places;
}

nlohmann::json StepPlaces::ToJson(double bound_pct) const {
  return {{"bound_pct", bound_pct},
          {"pairs", pairs},
          {"pairs_capped", pairs_capped},
          {StepPlaceName(StepPlace::kInterior), count[0]},
          {StepPlaceName(StepPlace::kOneEdge), count[1]},
          {StepPlaceName(StepPlace::kTwoEdges), count[2]},
          {"interior_max_pct", interior_max_pct}};
}

nlohmann::json StepStats::ToJson() const {
  return {{"pairs", pairs},
          {"pairs_straddled", pairs_straddled},
          {"max_pct", max_pct},
          {"p99_pct", p99_pct},
          {"pairs_over_1pct", pairs_over_1pct}};
}

StepStats MeasureImageSteps(const cv::Mat& luminance, const cv::Mat& face_ids,
                            const FaceGroups& faces, SurfaceKind kind, int spacing_px,
                            double lit_nits, cv::Mat* over_1pct, const cv::Mat& straddled) {
  if (over_1pct) *over_1pct = cv::Mat(luminance.size(), CV_8UC1, cv::Scalar(0));
  std::vector<double> steps;
  const cv::Mat inner = InnerPixels(luminance, face_ids, faces, kind, lit_nits);
  double max_step = -1;
  Eigen::Vector3d max_at = Eigen::Vector3d::Zero();
  int straddled_pairs = 0;
  std::vector<StepStats::Pair> over;
  auto good = [&](int y, int x, int* face) {
    if (!inner.at<uint8_t>(y, x)) return false;
    *face = face_ids.at<int32_t>(y, x);
    return true;
  };
  auto straddles = [&](int y, int x) { return !straddled.empty() && straddled.at<uint8_t>(y, x); };
  for (int y = 0; y < luminance.rows; ++y) {
    for (int x = 0; x < luminance.cols; ++x) {
      int face = -1;
      if (!good(y, x, &face)) continue;
      const int other[2][2] = {{y, x + spacing_px}, {y + spacing_px, x}};
      for (const auto& o : other) {
        if (o[0] >= luminance.rows || o[1] >= luminance.cols) continue;
        int face_b = -1;
        if (!good(o[0], o[1], &face_b) || face_b != face) continue;
        if (straddles(y, x) || straddles(o[0], o[1])) {
          ++straddled_pairs;
          continue;
        }
        const double step =
            RelativeStepPct(luminance.at<float>(y, x), luminance.at<float>(o[0], o[1]));
        steps.push_back(step);
        if (step > max_step) {
          max_step = step;
          max_at = Eigen::Vector3d(x, y, 0);
        }
        if (step > 1.0) {
          over.push_back({Eigen::Vector3d(x, y, 0), Eigen::Vector3d(o[1], o[0], 0), step});
          if (over_1pct) {
            over_1pct->at<uint8_t>(y, x) = 255;
            over_1pct->at<uint8_t>(o[0], o[1]) = 255;
          }
        }
      }
    }
  }
  StepStats stats = Summarise(&steps);
  stats.max_at = max_at;
  stats.pairs_straddled = straddled_pairs;
  KeepWorst(&over, &stats);
  return stats;
}

double TableUniformity(const cv::Mat& luminance, const cv::Mat& face_ids, const FaceGroups& faces,
                       double lit_nits, const cv::Mat& straddled) {
  cv::Mat inner = InnerPixels(luminance, face_ids, faces, SurfaceKind::kTable, lit_nits);
  if (!straddled.empty()) inner.setTo(0, straddled);
  if (cv::countNonZero(inner) == 0) return 0.0;
  double lo = 0, hi = 0;
  cv::minMaxLoc(luminance, &lo, &hi, nullptr, nullptr, inner);
  return hi > 0 ? lo / hi : 0.0;
}

SurfaceLattice SampleFaces(const Scene& scene, const FaceGroups& faces, SurfaceKind kind,
                           double spacing_m) {
  SurfaceLattice lattice;
  std::vector<std::vector<int>> triangles_of(faces.count());
  for (int t = 0; t < scene.NumTriangles(); ++t) {
    const int g = faces.group_of_triangle[t];
    if (g >= 0 && faces.kind[g] == kind) triangles_of[g].push_back(t);
  }
  for (int g = 0; g < faces.count(); ++g) {
    if (triangles_of[g].empty()) continue;
    ++lattice.faces_sampled;
    const Eigen::Vector3d n = faces.normal[g];
    // A frame in the face's plane: u horizontal where the face is not (walls: along the wall).
    Eigen::Vector3d u = Eigen::Vector3d::UnitZ().cross(n);
    if (u.norm() < 1e-6) u = Eigen::Vector3d::UnitX();
    u.normalize();
    const Eigen::Vector3d v = n.cross(u);
    const Eigen::Vector3d origin =
        scene.positions_in_table_m[scene.triangles[triangles_of[g][0]][0]].cast<double>();
    std::vector<std::array<Eigen::Vector2d, 3>> flat;
    std::map<std::pair<Key, Key>, std::pair<int, std::array<Eigen::Vector2d, 2>>> edges;
    Eigen::AlignedBox2d box;
    for (int t : triangles_of[g]) {
      std::array<Eigen::Vector2d, 3> tri;
      for (int k = 0; k < 3; ++k) {
        const Eigen::Vector3d p =
            scene.positions_in_table_m[scene.triangles[t][k]].cast<double>() - origin;
        tri[k] = Eigen::Vector2d(p.dot(u), p.dot(v));
        box.extend(tri[k]);
      }
      for (int k = 0; k < 3; ++k) {
        Key a = KeyOf(scene.positions_in_table_m[scene.triangles[t][k]]);
        Key b = KeyOf(scene.positions_in_table_m[scene.triangles[t][(k + 1) % 3]]);
        if (b < a) std::swap(a, b);
        auto& e = edges[{a, b}];
        ++e.first;
        e.second = {tri[k], tri[(k + 1) % 3]};
      }
      flat.push_back(tri);
    }
    // The outline: edges of one triangle only.
    std::vector<std::array<Eigen::Vector2d, 2>> outline;
    for (const auto& [key, e] : edges) {
      if (e.first == 1) outline.push_back(e.second);
    }
    auto edge_distance = [&](const Eigen::Vector2d& q) {
      double best = std::numeric_limits<double>::infinity();
      for (const auto& [a, b] : outline) {
        const Eigen::Vector2d ab = b - a;
        const double t = std::clamp((q - a).dot(ab) / std::max(ab.squaredNorm(), 1e-30), 0.0, 1.0);
        best = std::min(best, (a + t * ab - q).norm());
      }
      return best;
    };
    const int cols = static_cast<int>(std::floor(box.sizes().x() / spacing_m)) + 1;
    const int rows = static_cast<int>(std::floor(box.sizes().y() / spacing_m)) + 1;
    // Centred in the face's box, so a face narrower than the spacing still gets its middle.
    const Eigen::Vector2d start =
        box.min() + 0.5 * (box.sizes() - spacing_m * Eigen::Vector2d(cols - 1, rows - 1));
    std::vector<int> index(static_cast<size_t>(cols) * rows, -1);
    for (int r = 0; r < rows; ++r) {
      for (int c = 0; c < cols; ++c) {
        const Eigen::Vector2d p = start + spacing_m * Eigen::Vector2d(c, r);
        auto inside = [&](const Eigen::Vector2d& q) {
          for (const auto& tri : flat) {
            if (InTriangle2d(q, tri[0], tri[1], tri[2])) return true;
          }
          return false;
        };
        // At least kFaceMargin_m inside the face (probed in 8 directions): a projector pixel
        // straddling the face's edge lights both faces with one value (the top view's edge
        // margin does the same).
        bool keep = inside(p);
        for (int k = 0; k < 8 && keep; ++k) {
          const double angle = k * std::numbers::pi / 4;
          keep = inside(p + kFaceMargin_m * Eigen::Vector2d(std::cos(angle), std::sin(angle)));
        }
        if (!keep) continue;
        index[static_cast<size_t>(r) * cols + c] = static_cast<int>(lattice.face.size());
        lattice.points_in_table_m.push_back(origin + p.x() * u + p.y() * v);
        lattice.face.push_back(g);
        lattice.edge_distance_m.push_back(edge_distance(p));
      }
    }
    for (int r = 0; r < rows; ++r) {
      for (int c = 0; c < cols; ++c) {
        const int a = index[static_cast<size_t>(r) * cols + c];
        if (a < 0) continue;
        if (c + 1 < cols && index[static_cast<size_t>(r) * cols + c + 1] >= 0) {
          lattice.pairs.emplace_back(a, index[static_cast<size_t>(r) * cols + c + 1]);
        }
        if (r + 1 < rows && index[static_cast<size_t>(r + 1) * cols + c] >= 0) {
          lattice.pairs.emplace_back(a, index[static_cast<size_t>(r + 1) * cols + c]);
        }
      }
    }
  }
  return lattice;
}

StepStats MeasureSampleSteps(const std::vector<double>& luminance_nits,
                             const SurfaceLattice& lattice, double lit_nits,
                             const StraddleTest* straddle) {
  std::vector<double> steps;
  std::vector<int8_t> straddled(lattice.points_in_table_m.size(), -1);
  auto clear = [&](int i) {
    if (!straddle) return true;
    if (straddled[i] < 0) straddled[i] = straddle->Straddled(lattice.points_in_table_m[i]) ? 1 : 0;
    return straddled[i] == 0;
  };
  int straddled_pairs = 0;
  double max_step = -1;
  Eigen::Vector3d max_at = Eigen::Vector3d::Zero();
  std::vector<StepStats::Pair> over;
  for (const auto& [a, b] : lattice.pairs) {
    const double la = luminance_nits[a], lb = luminance_nits[b];
    if (!(la > lit_nits) || !(lb > lit_nits)) continue;
    if (!clear(a) || !clear(b)) {
      ++straddled_pairs;
      continue;
    }
    steps.push_back(RelativeStepPct(la, lb));
    if (steps.back() > 1.0) {
      over.push_back({lattice.points_in_table_m[a], lattice.points_in_table_m[b], steps.back()});
    }
    if (steps.back() > max_step) {
      max_step = steps.back();
      max_at = lattice.points_in_table_m[a];
    }
  }
  StepStats stats = Summarise(&steps);
  stats.max_at = max_at;
  stats.pairs_straddled = straddled_pairs;
  KeepWorst(&over, &stats);
  return stats;
}

}  // namespace sandtable::sim
