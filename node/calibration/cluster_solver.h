// The cluster's solve, on the node elected to run it (the lowest id of the calibrating
// members): initial poses chained from the nodes' local geometry, the joint refinement
// (cluster_bundle.h), the table plane (RANSAC + least squares) and the table frame
// (docs/frames.md), and the model found on the scanned surface (model_registration.h), whose
// metric size also fixes the cluster's scale (the mounts' baselines only know it to ~1 %).
//
// Output: one UnitCalibration per unit reached (source "structured_light", the refined
// camera, projector and projector_from_camera, table_from_projector, table_from_model when a
// model was given and found), the change report per building of the model
// (model_changes.h), and the report of every step.
// Errors: DEGENERATE when the bundle or the table plane cannot be estimated; a model that is
// not found is not an error: the solution carries no table_from_model and the note says why
// (also when the best placement puts fewer than half of the buildings it saw where they stand:
// the table alone matched).
#pragma once

#include <map>
#include <optional>
#include <string>
#include <vector>

#include "common/base/status.h"
#include "common/estimation/plane_fit.h"
#include "common/estimation/table_frame.h"
#include "common/io/unit_calibration_file.h"
#include "common/scene/scene.h"
#include "node/calibration/cluster_bundle.h"
#include "node/calibration/cluster_initializer.h"
#include "node/calibration/model_changes.h"
#include "node/calibration/model_registration.h"

namespace sandtable::node {

struct ClusterSolveOptions {
  BundleOptions bundle;
  // Solves of the bundle at most: after one that left a unit starved (fewer projector
  // observations than bundle_starved_share of the median unit's), again from its poses when they
  // let bundle_pass_gain more tracks triangulate than it used (a long chain of initial poses
  // leaves tracks out).
  int bundle_passes = 3;
  double bundle_pass_gain = 0.05;
  double bundle_starved_share = 0.25;
  PlaneFitOptions plane;  // inlier threshold 3 mm by default here (set in the constructor)
  ModelRegistrationOptions model;
  ModelChangeOptions changes;  // what differs from the model, once it is found
  // Placements of the model judged by the change report (ModelMatcher::RegisterCandidates).
  int model_candidates = 3;
  bool scale_from_model = true;
  // A placement that needs the model scaled further than this from 1 is refused (the model is
  // then not in metres, or not what stands there): noted, the model not placed, the mounts'
  // scale kept. 10 %: straight-down rigs over a mostly
  // flat city leave the scan's scale ~7 % off (grid-4: 0.926), which the model corrects
  // (209 -> 2.9 mm rms); a model that is not the scanned scene is caught by the change report.
  double max_scale_correction = 0.10;
  // A second joint refinement with the points tied to the found model's surface (the model is
  // metric and rigid: it pins what the factory priors alone leave loose).
  // Off by default: measured worse than without on sandtable-3 (docs/calibration.md).
  bool refine_with_model = false;
  double model_surface_sigma_m = 0.0002;
  double model_surface_max_distance_m = 0.003;
  // Planar site: every scanned point within this of the table plane (mm).
  double planar_threshold_mm = 5.0;
  ClusterSolveOptions() { plane.inlier_threshold_m = 0.003; }
  Status Check() const;
};

struct ClusterSolution {
  std::map<NodeId, UnitCalibration> calibrations;
  Rigid3d table_from_world;
  BundleReport bundle;
  std::optional<BundleReport> model_bundle;  // the second refinement, when it ran
  int table_points = 0;
  double table_plane_rms_mm = 0.0;
  double max_height_mm = 0.0;  // highest scanned point above the table (p99.9, robust)
  bool planar = false;
  TableFrameReport frame;
  std::optional<ModelRegistration> model;
  std::optional<ModelChangeReport> changes;  // per building of the model, once it is found
  double scale_correction = 1.0;             // lengths multiplied by this after the model was found
  std::vector<Eigen::Vector3d> points_in_table_m;
  std::vector<std::string> notes;
  double time_s = 0.0;  // thread CPU time of the whole solve
  // Thread CPU time per stage: "bundle", "table", "model", "model_bundle", "changes".
  std::map<std::string, double> stage_time_s;
};

// Adds the thread CPU time since the last stage (or construction) to a solution's
// stage_time_s under a stage's name.
class StageClock {
 public:
  explicit StageClock(ClusterSolution* out);
  void Done(const std::string& stage);

 private:
  ClusterSolution* out_;
  double start_s_;
};

// A unit's calibration from a solve: its (refined) models, its pose on the table, the model's
// placement when the solution found one, its residuals from the solution's bundle report.
UnitCalibration SolvedUnitCalibration(NodeId id, const UnitModel& unit,
                                      const Rigid3d& table_from_projector,
                                      const ClusterSolution& solution);

// Units the bundle left starved (ClusterSolveOptions::bundle_starved_share) get a pose resected
// from the points the other units' cameras triangulate on their light (their factory
// projector intrinsics held; at least 12 points, resection rms under 3 px), written into
// `projector_from_world`. Returns the units moved.
std::vector<NodeId> ResectStarvedUnits(const ClusterObservations& observations,
                                       const BundleResult& bundle,
                                       const ClusterSolveOptions& options,
                                       std::map<NodeId, Rigid3d>* projector_from_world);

Expected<ClusterSolution> SolveCluster(NodeId root, const ClusterObservations& observations,
                                       const std::map<NodeId, LocalGeometry>& local,
                                       const Scene* model, const ClusterSolveOptions& options = {});

}  // namespace sandtable::node
