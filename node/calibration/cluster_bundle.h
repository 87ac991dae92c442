// The joint refinement of a cluster self-calibration (bundle adjustment, Ceres).
//
// Unknowns, per unit u: projector_from_world (6: angle-axis, translation), the camera mount
// camera_from_projector (6), projector intrinsics fx fy cx cy (4) and Brown k1 k2 p1 p2 k3 (5),
// camera intrinsics (4) and distortion (5); per track, its surface point X in the world frame.
// The world frame is the root unit's projector frame (its pose is held: the gauge).
// Residuals, each divided by observation_sigma_px (whitened), optionally with a Huber loss of
// huber_whitened (off by default):
//   projector u: project(K_pu, D_pu, projector_from_world_u X) - track.projector_px
//   camera j:    project(K_cj, D_cj, camera_from_projector_j projector_from_world_j X) - c_j
// Priors (whitened by their sigmas): every intrinsic, distortion and mount parameter about its
// factory value, with the factory procedure's stated accuracy (BundleOptions); they carry the
// scale (the mounts' baselines) and keep directions the data do not determine where the
// factory put them. A group can be held at its factory value instead (BundleOptions::free_*).
// Two rounds: solve; drop observations whose residual exceeds outlier_px; solve again.
// Points are initialised by triangulating every track from the initial poses (tracks that do
// not triangulate are left out and counted).
// Errors: INVALID_ARGUMENT when a unit has no initial pose or no model; DEGENERATE when fewer
// than min_tracks tracks triangulate; NOT_CONVERGED when Ceres fails.
// Cost: O(iterations x observations) + a dense Schur complement of 30 x units parameters.
#pragma once

#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "common/base/status.h"
#include "node/calibration/cluster_problem.h"

namespace sandtable::node {

struct BundleOptions {
  bool free_projector_intrinsics = true;
  bool free_projector_distortion = true;
  bool free_camera_intrinsics = true;
  bool free_camera_distortion = true;
  bool free_mounts = true;
  // k3 is held at its factory value: over these footprints (normalized radius <= ~0.45) the
  // r^6 term is not separable from k1 and k2 (measured: docs/calibration.md).
  bool free_k3 = false;
  double observation_sigma_px = 0.1;
  // 0: plain least squares (the default: outliers are dropped between rounds instead). With a
  // Huber loss the solve crept for 50+ iterations along a direction the data hardly see and
  // stopped at an arbitrary point of it (docs/calibration.md); without, it converges in ~13.
  double huber_whitened = 0.0;
  double outlier_px = 1.0;
  // Factory accuracy (one sigma): focal relative, principal point px, k1, k2, p1 p2, k3,
  // mount rotation deg, mount translation m.
  double prior_focal_relative = 0.003;
  double prior_principal_point_px = 2.0;
  double prior_k1 = 0.003, prior_k2 = 0.001, prior_p = 0.0003, prior_k3 = 0.001;
  double prior_mount_rotation_deg = 0.1;
  double prior_mount_translation_m = 0.001;
  int max_iterations = 50;
  // Ceres: relative cost change that ends a round. Measured on sandtable-3: the cost settles
  // within ~12 iterations, then creeps by ~2e-5 per iteration along a direction the data
  // hardly see (docs/calibration.md); 1e-5 stops there.
  double function_tolerance = 1e-5;
  int min_tracks = 50;
  int rounds = 2;
  bool log_progress = false;  // Ceres' per-iteration lines and full report on stderr (sweeps)
  // The covariance of the units' parameters (BundleResult::uncertainty,
  // cluster_uncertainty.h): one Jacobian evaluation of every residual after the last round.
  bool estimate_uncertainty = true;
  int uncertainty_samples = 200;  // per unit: its projector observations, evenly spaced
  // The tracks' projector pixels are exact (grid nodes, projector_grid.h): the noise is all in
  // the camera pixels. The solve weights both alike; the covariance accounts for the difference.
  bool projector_px_exact = true;
  // Units held entirely (pose, mount, intrinsics, distortion: no priors), e.g. the calibrated
  // units a joining unit is fitted against; with any held unit no other pose is held.
  std::set<NodeId> held_units;
  Status Check() const;
};

struct UnitBundleReport {
  int projector_observations = 0;
  int camera_observations = 0;  // by this unit's camera (of any projector)
  double projector_rms_px = 0.0;
  double camera_rms_px = 0.0;
  std::vector<std::string> free_parameters;  // e.g. "projector fx fy cx cy", "mount"
};

struct BundleReport {
  std::string termination;  // Ceres termination of the last round
  int iterations = 0;       // all rounds
  int tracks_used = 0, tracks_untriangulated = 0, observations_dropped = 0;
  double initial_rms_px = 0.0, final_rms_px = 0.0;  // all observations, px
  double solve_time_s = 0.0;                        // thread CPU time
  std::map<NodeId, UnitBundleReport> units;
  // The camera pixels' noise the prediction uses, from the observation residuals corrected for
  // the degrees of freedom (px); 0 when not predicted. `undetermined`: the directions the data do
  // not fix (left to the gauge: the held root pose, the table frame, the model's placement), in
  // words; `uncertainty_note`: why nothing was predicted, when so.
  double sigma_px = 0.0;
  std::string undetermined;
  std::string uncertainty_note;
};

// One sample of a unit's predicted error: a track's point (index into
// BundleResult::points_in_world), the pixel where the unit's projector images it and that
// pixel's derivative by the unit's own parameters (BundleUncertainty::unit_columns).
struct PredictedSample {
  int point = -1;
  Eigen::Vector2d projector_px = Eigen::Vector2d::Zero();
  Eigen::MatrixXd jacobian;  // 2 x unit_columns[unit].size(), px per parameter unit
};

// The bundle's covariance of every free unit parameter (points folded out, scaled by the
// measured noise; cluster_uncertainty.h) and, per unit, the samples it is carried through.
struct BundleUncertainty {
  Eigen::MatrixXd covariance;
  std::vector<std::string> column_names;            // "unit 3 focal fx", ...
  std::map<NodeId, std::vector<int>> unit_columns;  // its pose, projector intrinsics, distortion
  std::map<NodeId, std::vector<PredictedSample>> samples;
};

struct BundleResult {
  std::map<NodeId, UnitModel> units;
  std::map<NodeId, Rigid3d> projector_from_world;
  std::vector<Eigen::Vector3d> points_in_world;  // tracks used
  std::vector<int> point_track;                  // index into the input tracks
  BundleReport report;
  std::optional<BundleUncertainty> uncertainty;  // when estimated
};

// A surface the points must lie on (the registered model): point `point` (index into
// BundleResult::points_in_world) within sigma of the plane through `on_plane_in_world` with
// unit `normal_in_world`.
struct SurfaceConstraint {
  int point = -1;
  Eigen::Vector3d on_plane_in_world = Eigen::Vector3d::Zero();
  Eigen::Vector3d normal_in_world = Eigen::Vector3d::UnitZ();
};

// A second refinement from a previous result (its models, poses and points), with the points
// tied to the registered model's surface (whitened by surface_sigma_m, Huber at 2 sigma). The
// model then fixes the gauge (scale included), so no pose is held. Priors stay about the
// factory values of `observations`.
struct BundleWarmStart {
  const BundleResult* previous = nullptr;
  std::vector<SurfaceConstraint> surface;
  double surface_sigma_m = 0.0002;
};

// How many tracks triangulate (from the units' models in `observations`) at these poses, by the
// same test AdjustCluster applies to its initial poses: a solved set of poses can bring in
// tracks that the initial ones put too far off.
int TracksThatTriangulate(const ClusterObservations& observations,
                          const std::map<NodeId, Rigid3d>& projector_from_world);

Expected<BundleResult> AdjustCluster(const ClusterObservations& observations,
                                     const std::map<NodeId, Rigid3d>& initial_projector_from_world,
                                     NodeId root, const BundleOptions& options = {},
                                     const BundleWarmStart* warm = nullptr);

}  // namespace sandtable::node
