// The planar path of the cluster self-calibration (docs/calibration.md, "Planar sites"): a
// site whose surface is one plane (nothing rises above PlanarityOptions::threshold_mm) is
// served by plane-to-plane maps, as the iLamps ad-hoc planar cluster does, instead of the
// full path's triangulation, bundle adjustment and 3D model registration.
//
// Data: the projector-cell correspondences of a Gray-code-only sequence (projector_cells.h),
// the prefix of the full path's sequence (so a site that turns out not to be planar loses no
// frame: the full path goes on with the phase frames).
//
// ProbePlanarity, on each projecting node: its own camera's cells of its own projector,
// triangulated with the factory stereo pair (camera + projector + projector_from_camera),
// a plane fitted (RANSAC + least squares), a smooth surface (a bivariate polynomial of
// surface_degree in the plane's coordinates, fitted with the points off it by more than 3
// robust sigmas left out, six passes) fitted to the heights over it, and the height of every
// point over that surface: the factory models bend a triangulated plane smoothly by up to
// ~20 mm (measured on flat-4), relief stands off it in steps. The
// footprint is planar when at most max(outliers_allowed, outlier_fraction x points) points
// stand further than threshold_mm from the plane; max_height_mm is the largest |height| after
// those. Units: mm, camera frame.
//
// SolvePlanarCluster, on the runner:
//  1. Each unit's plane in its camera frame, from its own pair (as the probe), gives the
//     camera's map from pixels to a 2D frame on the plane (origin below the camera, x along
//     the camera's x, metres): a homography once the pixels are undistorted.
//  2. Every camera's cells of every projector go to its plane frame. Cells that two cameras
//     saw tie their frames: one 2D similarity per camera (root camera fixed) by linear least
//     squares over every such pair, twice with pairs past 3x the rms (at least 2 mm) dropped.
//     The site's scale is then the geometric mean of the cameras' (each camera knows it from
//     its own mount's baseline: the errors average instead of the root's being taken).
//  3. The table frame (docs/frames.md) from all cells on the plane z = 0.
//  4. Each projector's pose from its cells' table positions by resection with its factory
//     intrinsics and distortion held (a plane-induced homography with K known).
//  5. (refine) The cluster bundle from there, the cells held to the plane (see below), and
//     the table frame again from the refined cells.
//  6. The model: a flat model is placed by its outline (model_registration.h); a model with
//     buildings on a planar scan is refused, with the reason in the notes.
// Output: a ClusterSolution as SolveCluster's (planar = true; bundle.termination "planar"),
// table_from_world = table_from_site (site: the root camera's plane frame, rescaled).
// Errors: DEGENERATE when the root's own plane cannot be fitted or no projector is posed.
#pragma once

#include <map>
#include <vector>

#include "common/base/status.h"
#include "common/estimation/plane_fit.h"
#include "common/scene/scene.h"
#include "common/structured_light/projector_grid.h"
#include "node/calibration/cluster_problem.h"
#include "node/calibration/cluster_solver.h"

namespace sandtable::node {

struct PlanarityOptions {
  double threshold_mm = 5.0;        // a point higher than this over the plane is relief
  double plane_inlier_mm = 3.0;     // RANSAC inlier threshold of the plane fit
  int outliers_allowed = 2;         // points past the threshold still called noise ...
  double outlier_fraction = 0.001;  // ... or this fraction of the points, whichever is more
  int min_points = 50;
  // Degree of the smooth surface the heights are taken from (0 = the plane itself).
  int surface_degree = 3;
  Status Check() const;
};

struct PlanarityProbe {
  int points = 0;             // own cells triangulated
  Plane plane_in_camera;      // normal towards the camera
  double plane_rms_mm = 0.0;  // of the RANSAC inliers
  double inlier_ratio = 0.0;
  double surface_rms_mm = 0.0;  // the points within the fit's band about the smooth surface
  double max_height_mm = 0.0;   // the largest |height| after the allowed outliers
  int points_over_threshold = 0;
  bool planar = false;
};

Expected<PlanarityProbe> ProbePlanarity(const UnitModel& self,
                                        const std::vector<ProjectorGridPoint>& own_cells,
                                        const PlanarityOptions& options = {});

struct PlanarSolveOptions {
  PlanarityOptions planarity;
  ModelRegistrationOptions model;
  ModelChangeOptions changes;
  int min_shared_cells = 20;  // cells two cameras share to tie their frames
  double resection_loss_scale_px = 1.0;
  // 6. The joint refinement (cluster_bundle.h, its priors and outlier rounds) from steps 1-4,
  // every cell held to the plane z = 0 within surface_sigma_m: the factory intrinsics,
  // distortion and mounts bend each camera's plane frame by millimetres (measured on flat-4:
  // frames tied at ~8 mm rms without it); the refinement removes that.
  bool refine = true;
  BundleOptions bundle;
  double surface_sigma_m = 0.0001;
  Status Check() const;
};

Expected<ClusterSolution> SolvePlanarCluster(NodeId root, const ClusterObservations& observations,
                                             const Scene* model,
                                             const PlanarSolveOptions& options = {});

}  // namespace sandtable::node
