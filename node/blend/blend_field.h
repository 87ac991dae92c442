// Blending in projector space (docs/blend.md): TR09-017 Algorithm 1 on every surface a
// projector lights (table, walls, roofs), with distances measured along the surface.
//
// Each node works in its own projector's image:
//   1. ProjectorSurface: per pixel, the surface point the pixel lights (a ray cast through the
//      calibrated projector into the model as placed, table included), its range and the light a
//      unit emission brings there, cos(incidence) / range^2 (1 / m^2; Shader Lamps' intensity
//      model). A pixel lights nothing when its ray misses, meets a back face, or meets the
//      surface past max_incidence_deg (85: nearly edge-on).
//   2. DistanceField: on a grid every step_px pixels of the image, the distance D along the
//      surface from each grid point to the nearest surface point this projector cannot light
//      (Dijkstra over the grid with 3D edge lengths). What it cannot light is: pixels that light
//      nothing on the model (a back face, past max_incidence_deg; not a ray past the model's
//      rim, where the surface itself ends), the image border, and surface breaks, where
//      neighbouring grid points are far apart in 3D (a building's silhouette: the surface just
//      behind it lies in this projector's shadow, and the building's far side faces away). The
//      field is what a node shares with its overlapping neighbours (with its calibration, so they
//      can look it up).
//   3. D of projector k at a table point x: whether k lights x is decided exactly, as k's own
//      pixels decide it: x in k's image, facing k within max_incidence_deg, and the segment from x
//      to k's centre free of the model (a shadow ray in the same model); then D_k(x) is the
//      grid's bilinear value at x's pixel in k. 0 when k does not light x.
//   4. Weight w_k(x) = (D_k(x) + e) g(theta_k(x)) over the projectors that light x (e the
//      distance floor; g the incidence factor: 1 up to correction_limit_deg, falling smoothly to
//      ~0 at weight_falloff_deg, so a projector meeting a wall edge-on gives way to one that
//      faces it), alpha A_i = w_i / sum_k w_k, and the mask factor A_i T / E'_i(x) (intensity
//      correction) with E' = albedo max(cos theta, cos correction_limit) / range^2 (the albedo
//      of the model's material: every surface then shows white at one luminance): past the limit
//      (60 degrees) the correction stops and a surface that no projector faces better shows
//      dimmer rather than forcing the whole site down. T is the cluster's common level: the
//      largest at which no projector clips, the minimum over all projectors of E'_i / A_i.
// Every node evaluates every D at its own estimate of x with the same lookup, so the alphas of
// the projectors lighting one point sum to 1 up to the registration error times the alpha's
// gradient.
// Frames: the table frame (metres); pixels in the OpenCV convention (pixel centres at integers).
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "common/base/ids.h"
#include "common/base/status.h"
#include "common/camera/camera_model.h"
#include "common/geometry/rigid3.h"
#include "common/scene/ray_caster.h"

namespace sandtable::node {

// Per planar face of the model, a level below the site's common one (Blender::FaceLevelBounds).
using FaceLevels = std::map<int32_t, double>;

// The lowest level of each face over `maps` and `own`, leaving out `without`'s map.
FaceLevels LowestFaceLevels(const std::map<NodeId, FaceLevels>& maps, const FaceLevels& own,
                            NodeId without = kInvalidNodeId);

// Largest |distance| a field may hold (fields from the wire are checked against it), m.
inline constexpr double kMaxFieldDistance_m = 1000.0;

struct BlendOptions {
  int grid_step_px = 8;                // the distance field's grid spacing in the projector image
  double max_incidence_deg = 85.0;     // a pixel meeting the surface past this lights nothing
  double correction_limit_deg = 60.0;  // the intensity correction stops here
  double weight_falloff_deg = 80.0;    // the incidence factor g is ~0 (1e-3) from here on
  bool incidence_weight = true;        // false: g = 1 (plain Algorithm 1)
  // The weight's pixel-density factor: (pixels per mm^2 of surface)^density_weight (0: none).
  double density_weight = 0.0;
  // Neighbouring grid points farther apart in 3D than this times the spacing the pixel step
  // gives at their range (range x step / f) are checked for a break (two surfaces) by casting
  // the pixels between them.
  double break_ratio = 2.0;
  // A looked-up point is lifted this far off its surface along the normal before the shadow
  // ray to another projector is cast (so it does not shadow itself).
  double shadow_ray_offset_m = 1e-4;
  // Added to every lighting projector's D in the alpha, so that a point all of whose
  // projectors have D = 0 (the field's seeds) is shared among them rather than dark.
  double distance_floor_m = 1e-6;
  // On faces of at least edge_soft_min_face_m2 (the table; not a building's walls and roofs,
  // where seams are a few cm wide and this measured worse), within this distance of its edge a
  // projector's D enters the weight as D^2 / (2 e) (and as D - e / 2 beyond: the same slope, no
  // kink): its alpha leaves 0 with zero slope, so a pixel of another projector straddling its
  // edge (one value across it) is off by far less than half a pixel times the alpha's slope.
  // 0: D as it is (TR09-017). 1.5 mm measured best on sandtable-3 (docs/blend.md).
  double edge_soft_m = 1.5e-3;
  double edge_soft_min_face_m2 = 0.05;
  // Past the model's rim (a ray that meets no surface) the surface ends for every projector:
  // no edge of this one's light, so no seed of its D. false: a seed like any unlit pixel
  // (TR09-017's "cannot light"; every D then falls to 0 at the table's rim).
  bool rim_is_no_edge = true;
  // Where a projector cannot deliver its share (past the correction limit), the others make up
  // the shortfall, each raising its own share at most this many times (Blender::Factor); 1: the
  // projector clips alone.
  double fill_limit = 2.0;
  Status Check() const;
};

// What a projector lights, per pixel (row-major, width x height).
struct ProjectorSurface {
  int width_px = 0, height_px = 0;
  std::vector<Eigen::Vector3f> point_in_table_m;
  std::vector<Eigen::Vector3f> normal_in_table;  // unit, facing the projector
  std::vector<float> range_m;                    // from the projector's centre; 0: lights nothing
  std::vector<float> cos_incidence;              // E = albedo cos / range^2 follows (Blender)
  std::vector<float> albedo;  // the model's material (base colour factor, Rec. 709), [0, 1]
  // The model's planar face each pixel lights (PlanarFaces; -1: unlit, or faces not given), and
  // that face's area (m^2; 0 when faces are not given).
  std::vector<int32_t> face;
  std::vector<float> face_area_m2;
  size_t lit_pixels = 0;
};

// A projector's distance field (what a node shares).
struct DistanceField {
  NodeId unit = kInvalidNodeId;
  CameraModel projector;
  Rigid3d projector_from_table;
  // The grid spans the image from edge to edge: cols x rows points, the first and last on the
  // image's edges (pixel -0.5 and width - 0.5), about step_px apart.
  int step_px = 8, cols = 0, rows = 0;
  // Along the surface, m: >= 0 where the grid point lights the surface; where it does not,
  // minus its distance to the lit surface's edge (a signed field: interpolation passes through
  // 0 at the edge, between grid points); lookups clamp at 0.
  std::vector<float> distance_m;
  static int PointsAlong(int side_px, int step_px) { return (side_px + step_px - 1) / step_px + 1; }
  Eigen::Vector2d Spacing() const {
    return {static_cast<double>(projector.width_px) / (cols - 1),
            static_cast<double>(projector.height_px) / (rows - 1)};
  }
  Eigen::Vector2d GridPixel(int c, int r) const {
    const Eigen::Vector2d s = Spacing();
    return {-0.5 + c * s.x(), -0.5 + r * s.y()};
  }
  // Bilinear D at a pixel of the image (0 outside it).
  float DistanceAtPixel(const Eigen::Vector2d& pixel) const;
  Status Check() const;  // sizes agree, values finite (for fields off the wire)
};

// The same field, value for value (unit, grid, distances, the projector and its pose): a share
// received again (a neighbour asked again, or answered twice) needs no new lookup.
bool SameField(const DistanceField& a, const DistanceField& b);

// Casts every pixel of the projector (distortion included) into `caster`'s scene.
// `face_of_triangle`: the model's planar face of each triangle (PlanarFaces), for the
// surface's `face`; empty: every face -1 (no per-face levels).
ProjectorSurface CastProjectorSurface(const CameraModel& projector,
                                      const Rigid3d& projector_from_table, const RayCaster& caster,
                                      const BlendOptions& options,
                                      const std::vector<int>& face_of_triangle = {});

// The field on the grid (its own casts, grid_step_px apart).
DistanceField ComputeDistanceField(NodeId unit, const CameraModel& projector,
                                   const Rigid3d& projector_from_table, const RayCaster& caster,
                                   const BlendOptions& options);

// The distance term of the weight: D, softened within edge_soft_m of the edge on a face of at
// least edge_soft_min_face_m2.
double EdgeWeight(double distance_m, double face_area_m2, const BlendOptions& options);
// The incidence factor g of a projector meeting a surface at cos(theta).
double IncidenceWeight(double cos_incidence, const BlendOptions& options);
// The pixel-density factor of the weight (1 when options.density_weight is 0).
double DensityWeight(const CameraModel& projector, double cos_incidence, double range_m,
                     const BlendOptions& options);

// The share of the intended light a projector meeting a surface at cos(theta) delivers when
// its correction stops at the limit: min(1, cos theta / cos(correction_limit)).
double Reach(double cos_incidence, const BlendOptions& options);

// D of `field`'s projector at a surface point (normal facing out of the surface); 0 when that
// projector does not light it (`caster`: the same model the fields were cast in).
float LookupDistance(const DistanceField& field, const Eigen::Vector3d& point_in_table_m,
                     const Eigen::Vector3d& normal_in_table, const RayCaster& caster,
                     const BlendOptions& options);

// One node's blend: its own surface and field, and each neighbour's D at its pixels.
class Blender {
 public:
  // `caster` (the model the surface was cast in) must outlive the blender.
  Blender(ProjectorSurface surface, DistanceField own, const RayCaster* caster,
          BlendOptions options);

  // Looks the neighbour's field up at every lit pixel (the costly part: a projection per lit
  // pixel); replaces an earlier field of the same unit.
  void SetNeighbour(const DistanceField& field);
  // Forgets a neighbour (a node that left): nothing to recompute but the composition.
  bool RemoveNeighbour(NodeId unit);
  std::vector<NodeId> neighbours() const;

  // The largest level T at which this projector does not clip: min over lit pixels of E' / A.
  double LevelBound() const;
  // Alpha (CV_32FC1, 0 where the projector lights nothing) and the mask factor
  // min(A T / (E' R), 1) (CV_32FC1, linear emission; R the share of the intended light the
  // projectors lighting the point deliver, < 1 only past the correction limit).
  cv::Mat Alpha(NodeId without = kInvalidNodeId) const;
  cv::Mat Factor(double level) const;
  // The same with another fill limit than the options' (BlendOptions::fill_limit).
  // `without` (Alpha, Factor, BlackPeak, Lift): as if that neighbour had been removed
  // (RemoveNeighbour), the blender unchanged: a node prepares the mask it would show if a
  // neighbour left, so that a re-blend needs no compose (docs/blend.md, "Prepared masks").
  // `face_levels`: a lower level for some faces (FaceLevelBounds, the lowest over the site):
  // a pixel on such a face uses min(level, its face's).
  cv::Mat Factor(double level, double fill_limit, NodeId without = kInvalidNodeId,
                 const FaceLevels& face_levels = {}) const;

  // Per planar face (ProjectorSurface::face), the highest level the projectors lighting it can
  // deliver at every one of this projector's pixels on it, where that is below `level`: past
  // the correction limit (a wall every projector meets at 60-85 degrees) the site's level is
  // out of reach, and a face showing what is reachable at one point but less at the next has a
  // step wherever the alphas change. At a pixel the reachable level is the largest t with
  // sum_k min(cap_k, fill_limit s_k t / albedo) >= t / albedo (Factor's water filling). The
  // face's level is the lowest of these over the site (the nodes lighting it exchange theirs:
  // blend_service), so the face shows one level everywhere. Faces at `level` are left out.
  FaceLevels FaceLevelBounds(double level, double fill_limit,
                             NodeId without = kInvalidNodeId) const;

  // Black-level matching. A projector showing black still emits its black level b; where
  // footprints overlap those add up. Black light at a lit pixel's point: sum over the
  // projectors lighting it of b_k cos_k / d_k^2 (1 / m^2; the albedo multiplies all alike).
  // `black`: each neighbour's b (one missing counts as `own_black`).
  // BlackPeak: the largest black light over this projector's lit pixels.
  double BlackPeak(double own_black, const std::map<NodeId, double>& black,
                   NodeId without = kInvalidNodeId) const;
  // The lift (CV_32FC1, linear emission as a fraction of the projector's range above black,
  // added to every frame) that raises the black light to `target` everywhere this projector
  // lights, shared with the neighbours by alpha: A_i (target - black light) / (cos_i / d_i^2),
  // at most `max_lift` (a grazing surface is left short rather than washed out).
  cv::Mat Lift(double target, double own_black, const std::map<NodeId, double>& black,
               double max_lift, NodeId without = kInvalidNodeId) const;

  const BlendOptions& options() const { return options_; }
  const ProjectorSurface& surface() const { return surface_; }
  const DistanceField& own_field() const { return own_; }
  const std::vector<float>& own_distance() const { return own_d_; }
  const std::vector<float>& own_weight() const { return own_w_; }
  // Per neighbour, its weight at each of this projector's pixels (0: it does not light it).
  const std::map<NodeId, std::vector<float>>& neighbour_weights() const { return neighbour_w_; }

 private:
  double CorrectedIrradiance(size_t i) const;  // E' of lit pixel i
  // Each neighbour's w r and capacity cos / d^2 per pixel (Factor's and FaceLevelBounds'
  // terms), `without` left out.
  struct Other {
    const float *wr, *cap;
  };
  std::vector<Other> Others(NodeId without) const;

  ProjectorSurface surface_;
  DistanceField own_;
  const RayCaster* caster_;
  BlendOptions options_;
  std::vector<float> own_d_;                              // per pixel (0 unlit)
  std::vector<float> own_w_;                              // per pixel weight (0 unlit)
  std::vector<float> own_reach_;                          // per pixel r (Reach)
  std::vector<float> own_wr_, own_gain_;                  // w r, and w / E' (Factor's terms)
  std::map<NodeId, std::vector<float>> neighbour_w_;      // per pixel weight; 0: it does not light
  std::map<NodeId, std::vector<float>> neighbour_reach_;  // per pixel w r
  std::map<NodeId, std::vector<float>> neighbour_gain_;   // per pixel cos / d^2 (0: not lit)
  // Black light at each lit pixel's point (BlackPeak, Lift).
  std::vector<double> BlackLight(double own_black, const std::map<NodeId, double>& black,
                                 NodeId without) const;
};

}  // namespace sandtable::node
