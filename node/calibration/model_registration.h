// Finding the glTF model on the scanned table: table_from_model from the scanned surface points
// alone (no guide lines, no initial placement), then what does not match.
//
// Inputs: the model (common/scene Scene, in its own frame: the loader's z-up table convention,
// the table top at z = 0 of the MODEL, placement on the real table unknown) and the scanned
// surface points in the cluster's table frame (z = 0 the fitted table plane, metres).
// Method:
//   1. Both become height maps on a grid of coarse_cell_m: the model's highest sampled surface
//      per cell, the scan's highest point per cell. A cell is "structure" (+1) above
//      structure_height_m and "table" (-1) below it; model cells outside the model and scan
//      cells with no point are 0 (unknown).
//   2. Coarse search over yaw (coarse_yaw_step_deg, all of 360 degrees) and x, y: for each yaw
//      the scan map is rotated and cross-correlated with the model map by FFT (cv::dft); the
//      score counts agreeing cells minus disagreeing ones. The best few peaks are kept.
//   3. Each candidate is refined by point-to-plane ICP (model surface sampled every
//      sample_spacing_m, a nanoflann k-d tree; pairs farther than icp_max_distance_m are
//      dropped), first with a scale factor free (estimate_scale: the model is metric, the scan's
//      scale is only as good as the units' mount baselines), then rigid. With scale_from_plan
//      (off by default) the scale has two parts, the plan's (x, y) and the relief's (z) over
//      it. The candidate with the lowest trimmed rms wins.
// Output: table_from_model (rigid), scale (the plan's: scan length / model length),
// relief_scale (the scan's heights over its plan, 1 without scale_from_plan), rms, inliers.
// Flat scan and flat model (under 0.5 % of the points above structure_height_m each): placed by
// outlines instead (RegisterByOutline): the scan's points and the model's top become masks
// (4 mm cells, gaps closed), whose area centroids and major axes give x, y and yaw; scale 1.
// Errors: DEGENERATE when the scan has fewer than min_points points, shows no structure and
// the model has some (nothing to register x, y and yaw on), or, flat, covers under 90 % of the
// model's top or has no long axis (a disc: its yaw is open); NOT_FOUND when no candidate
// reaches min_inlier_fraction of the scan within icp_max_distance_m ("the model does not
// match"). The ICP is damped (1e-6 x pairs on its normal equations): directions the points do
// not determine stay put.
// Cost: O(yaw steps x G log G) for G grid cells, plus O(iterations x N log M) for ICP.
#pragma once

#include <memory>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "common/base/status.h"
#include "common/geometry/rigid3.h"
#include "common/scene/scene.h"
#include "node/calibration/point_tree.h"

namespace sandtable::node {

struct ModelRegistrationOptions {
  double structure_height_m = 0.005;
  double coarse_cell_m = 0.02;
  double coarse_yaw_step_deg = 3.0;
  int coarse_candidates = 4;
  double sample_spacing_m = 0.004;
  int icp_iterations = 30;
  double icp_max_distance_m = 0.01;
  double min_inlier_fraction = 0.5;
  bool estimate_scale = true;
  // With estimate_scale: the relief's scale free against the plan's, and the plan's taken as
  // the scan's where the relief differs from it by more than 3 standard errors (a rig looking
  // down from afar trades focal length against distance, which puts the heights off by more
  // than the plan). Off: with exact correspondences it places the projectors better, with
  // decoded ones the free relief takes up other errors of the scan and the plan's scale is
  // worse (docs/results.md, "The model's scale: plan and relief").
  bool scale_from_plan = false;
  int min_points = 100;
  Status Check() const;
};

struct ModelRegistration {
  Rigid3d table_from_model;
  double scale = 1.0;           // scan = scale * (table_from_model * model), before rescaling
  double relief_scale = 1.0;    // the scan's heights over its plan's scale (scale_from_plan)
  double rms_m = 0.0;           // point-to-plane rms of the inliers, final (rigid) fit
  int inliers = 0, points = 0;  // of the scan points fitted (at most 5 000, evenly subsampled)
  double coarse_score = 0.0;    // fraction of the best correlation's possible agreement
  int candidates_tried = 0;
  double structure_fraction = 0.0;  // scan points above structure_height_m
  // Flat scan and flat model: placed by the outline of the scanned top against the model's
  // (area centroid and major axis), scale 1; x, y and yaw then come from the table's edges only.
  bool by_outline = false;
  // A RegisterCandidates() candidate after the first: the coarse rigid ICP on ~2 000 points
  // only; Refine() it (scale free as the options' estimate_scale) before use.
  bool coarse_only = false;
};

// The model's surface sampled for ICP: points and unit normals in the model frame.
struct ModelSurface {
  std::vector<Eigen::Vector3d> points_m;
  std::vector<Eigen::Vector3d> normals;
  std::vector<int> triangle;  // the triangle each sample came from
};
ModelSurface SampleModelSurface(const Scene& model, double spacing_m);

// The model's sampled surface and its k-d tree, built once; Register() runs steps 1-3,
// Refine() step 3 alone from a given placement (rigid when scale_free is false).
class ModelMatcher {
 public:
  ModelMatcher(const Scene& model, const ModelRegistrationOptions& options);
  ~ModelMatcher();
  ModelMatcher(const ModelMatcher&) = delete;
  ModelMatcher& operator=(const ModelMatcher&) = delete;

  Expected<ModelRegistration> Register(std::span<const Eigen::Vector3d> scan_in_table_m) const;
  // Register's best placements, best first: up to max_candidates whose ICP pairs reach 90 % of
  // the best one's; the first refined as Register's, the others coarse_only (the caller judges
  // them otherwise, refining one only when it gets to it: cluster_solver.h takes the one that
  // puts the most buildings where they stand).
  Expected<std::vector<ModelRegistration>> RegisterCandidates(
      std::span<const Eigen::Vector3d> scan_in_table_m, int max_candidates) const;
  // The flat case of Register (see ModelRegistration::by_outline).
  Expected<ModelRegistration> RegisterByOutline(
      std::span<const Eigen::Vector3d> scan_in_table_m) const;
  Expected<ModelRegistration> Refine(std::span<const Eigen::Vector3d> scan_in_table_m,
                                     const Rigid3d& table_from_model, bool scale_free) const;
  // The model's surface plane near a point (model frame): the nearest sample within
  // max_distance_m whose 8 nearest samples share its normal (cos > 0.999: not at an edge).
  // False when there is none.
  bool SurfacePlaneNear(const Eigen::Vector3d& point_in_model_m, double max_distance_m,
                        Eigen::Vector3d* point_on_plane_m, Eigen::Vector3d* normal) const;
  const ModelSurface& surface() const { return surface_; }

 private:
  ModelRegistrationOptions options_;
  ModelSurface surface_;
  std::unique_ptr<PointTree> tree_;
};

Expected<ModelRegistration> RegisterModel(const Scene& model,
                                          std::span<const Eigen::Vector3d> scan_in_table_m,
                                          const ModelRegistrationOptions& options = {});

}  // namespace sandtable::node
