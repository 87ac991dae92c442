// The lab's photometric measurements (docs/blend.md, docs/lab.md), on the world's ground truth.
//
// Surfaces: the true scene's triangles grouped into planar faces (triangles sharing an edge in
// one plane), each of a kind: the table (facing up, at z = 0), a roof (facing up at least 0.3,
// above the table) or a wall (|n_z| < 0.3). Faces facing down are not measured.
//
// Step: the largest relative luminance change over `spacing` along a lit surface,
// |L(a) - L(b)| / ((L(a) + L(b)) / 2) in %, over pairs of samples `spacing` apart on one face,
// both lit: above lit_nits (3x the ambient luminance of a white surface by default: the
// projectors' light, not the room's). Pairs that straddle a face edge are not compared (the
// surface turns there: each side is measured on its own face). A fade to dark at the edge of
// the lit area would be a large step between two lit samples and is counted.
//   - Table and roofs: the world's top view (1 px ~ 1 mm), pairs `spacing` apart along rows and
//     columns, on pixels whose surface from above is one face (cast straight down in the truth).
//   - Walls (and roofs, for comparison): a lattice on each face `spacing` apart, the luminance of
//     every sample from the world's truth (all projectors' contributions plus ambient).
// Pixels that straddle: a projector pixel is one value; where its footprint spans two faces (a
// fold, or a silhouette whose far side lies behind it) it cannot be right on both, whatever the
// blend, and its light spills across the edge. That is the projector's resolution at a
// geometric edge, not a blending step: samples lit (or spilt on) through such a pixel of any
// projector are not measured, and the share of lit samples left out is reported.
// Uniformity: min / max luminance over the table pixels the steps are measured on.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "common/base/ids.h"
#include "common/base/status.h"
#include "common/camera/camera_model.h"
#include "common/geometry/rigid3.h"
#include "common/scene/ray_caster.h"
#include "common/scene/scene.h"

namespace sandtable::sim {

enum class SurfaceKind { kNone, kTable, kRoof, kWall };
const char* SurfaceKindName(SurfaceKind kind);

struct FaceGroups {
  std::vector<int> group_of_triangle;   // -1: degenerate
  std::vector<SurfaceKind> kind;        // per group
  std::vector<Eigen::Vector3d> normal;  // per group, unit
  int count() const { return static_cast<int>(kind.size()); }
};
FaceGroups GroupFaces(const Scene& scene);

// The face seen straight down through each pixel of a top view (CV_32SC1, -1: none).
cv::Mat TopViewFaceIds(const RayCaster& truth, const FaceGroups& faces,
                       const Eigen::Vector2d& area_min_m, const Eigen::Vector2d& area_max_m,
                       cv::Size size);

// Per projector, its pixels whose four corner rays (true pose and lens) do not all meet one
// face (or some miss), dilated by one pixel.
class StraddleTest {
 public:
  struct Projector {
    CameraModel model;
    Rigid3d projector_from_table;
  };
  StraddleTest(std::vector<Projector> projectors, const RayCaster& truth, const FaceGroups& faces);
  // Whether a surface point falls in a straddling pixel of any projector.
  bool Straddled(const Eigen::Vector3d& point_in_table_m) const;

 private:
  std::vector<Projector> projectors_;
  std::vector<cv::Mat> masks_;  // CV_8UC1 per projector
};

struct StepStats {
  int pairs = 0;
  int pairs_straddled = 0;  // lit pairs left out: a sample in a straddling pixel
  double max_pct = 0.0, p99_pct = 0.0;
  int pairs_over_1pct = 0;
  // Where the largest step is: the pair's first sample (image: pixel x, y; lattice: table frame,
  // m).
  Eigen::Vector3d max_at = Eigen::Vector3d::Zero();
  // The largest steps over 1 %, largest first, at most kWorstPairs: where each pair's samples
  // are (as max_at) and its step.
  struct Pair {
    Eigen::Vector3d a = Eigen::Vector3d::Zero(), b = Eigen::Vector3d::Zero();
    double step_pct = 0.0;
  };
  static constexpr int kWorstPairs = 4096;
  std::vector<Pair> worst;
  nlohmann::json ToJson() const;
};

// Where a large step lies, from each projector's truth at the pair's two samples: near the edge
// of one projector's light (its image border within `near_px` of either sample's pixel, it
// lights one sample and not the other, or what it lights varies around a sample), near the edges of
// two or more (where two projectors' edges cross, every alpha must go from 0 to 1 within a pixel or
// two: a pixel-size limit like a straddling pixel), or away from every edge.
struct SampleTruth {
  bool projectable = false, visible = false;
  Eigen::Vector2d pixel_px = Eigen::Vector2d::Zero();
  // The projector lights some points around the sample (within a few mm, the caller's ring) and
  // not others: a shadow's or a silhouette's edge is near.
  bool lit_varies_near = false;
};
struct ProjectorPairTruth {
  int width_px = 0, height_px = 0;
  SampleTruth a, b;
};
enum class StepPlace { kInterior, kOneEdge, kTwoEdges };
const char* StepPlaceName(StepPlace place);
StepPlace PlaceOfStep(const std::vector<ProjectorPairTruth>& projectors, double near_px = 8.0);

// Where the steps of `steps.worst` over `bound_pct` lie (PlaceOfStep), from each projector's
// truth at each pair's samples and a ring of 8 points 3 pixels around each. `point_of_pixel`
// maps a top-view pixel (x, y) to its table point; `truth` gives one projector's truth at
// points (one sample each, in order). Counts per place, and the largest step away from every
// edge.
struct ProjectorSize {
  NodeId id = kInvalidNodeId;
  int width_px = 0, height_px = 0;
};
struct StepPlaces {
  int pairs = 0;
  bool pairs_capped = false;  // steps.worst held only the largest kWorstPairs
  int count[3] = {0, 0, 0};   // by StepPlace
  double interior_max_pct = 0.0;
  nlohmann::json ToJson(double bound_pct) const;
};
Expected<StepPlaces> PlaceSteps(
    const StepStats& steps, double bound_pct,
    const std::function<Eigen::Vector3d(double x, double y)>& point_of_pixel,
    const std::vector<ProjectorSize>& projectors,
    const std::function<
        Expected<std::vector<SampleTruth>>(NodeId, const std::vector<Eigen::Vector3d>&)>& truth);

// Steps in a top view's luminance (CV_32FC1) on faces of `kind`, pairs `spacing_px` apart.
// `over_1pct` (optional): CV_8UC1 of the view's size, 255 at both pixels of each pair whose
// step exceeds 1 %.
// `straddled` (optional, CV_8UC1 of the view's size): pixels left out (StraddleTest).
StepStats MeasureImageSteps(const cv::Mat& luminance, const cv::Mat& face_ids,
                            const FaceGroups& faces, SurfaceKind kind, int spacing_px,
                            double lit_nits, cv::Mat* over_1pct = nullptr,
                            const cv::Mat& straddled = cv::Mat());
// The straddle mask of a top view: each pixel's surface point (cast straight down) tested.
cv::Mat TopViewStraddled(const RayCaster& truth, const StraddleTest& test,
                         const Eigen::Vector2d& area_min_m, const Eigen::Vector2d& area_max_m,
                         cv::Size size);

// min / max over the table pixels the steps are measured on (0 when none).
double TableUniformity(const cv::Mat& luminance, const cv::Mat& face_ids, const FaceGroups& faces,
                       double lit_nits, const cv::Mat& straddled = cv::Mat());

// Samples on every face of `kind`, `spacing_m` apart (a lattice in the face's plane, points
// on it, 3 mm or more from its edges), and the pairs of lattice neighbours.
struct SurfaceLattice {
  std::vector<Eigen::Vector3d> points_in_table_m;
  std::vector<int> face;
  std::vector<double> edge_distance_m;  // to the face's outline, in its plane
  std::vector<std::pair<int, int>> pairs;
  int faces_sampled = 0;
};
SurfaceLattice SampleFaces(const Scene& scene, const FaceGroups& faces, SurfaceKind kind,
                           double spacing_m);

// `straddle` (optional): samples it flags are not measured.
StepStats MeasureSampleSteps(const std::vector<double>& luminance_nits,
                             const SurfaceLattice& lattice, double lit_nits,
                             const StraddleTest* straddle = nullptr);

}  // namespace sandtable::sim
