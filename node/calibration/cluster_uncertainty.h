// What a cluster self-calibration can say of its own error, before anyone measures it: each
// unit's predicted registration error from the covariance of the joint refinement.
//
// PredictUnitErrors (called by AdjustCluster after its last round):
//  1. The information of every unit parameter (pose, mount, intrinsics, distortion) with the
//     points folded out (common/estimation/reduced_information.h), priors included.
//  2. The noise from the data: sigma^2 = (whitened observation residuals)^2 / (observations -
//     free parameters), so a decoder that does better or worse than observation_sigma_px says
//     so; covariance = sigma^2 S^-1. Directions S does not determine (the gauge: a site held
//     only to a plane can slide on it) are left out and named in BundleReport::undetermined.
//  3. Per unit, for up to uncertainty_samples of its projector observations: the covariance of
//     the pixel where its projector images that point, J C J^T with J = d(px)/d(its pose,
//     projector intrinsics and distortion) and C their marginal covariance. rms -> the unit's
//     predicted_rms_px; the eigen-direction of C weighted by J^T J carrying most of the variance
//     -> weak_direction (its largest parameters, in words) and weak_share.
// The prediction covers what the observation noise does through this geometry; what no model
// here describes (a biased decoder, a wrong distortion model, the model placed wrong) is not
// in it, which is why the lab reports it beside the measured error.
//
// PredictOnTable (called by the solvers once the table frame is known): each sample on the
// table (within max_height_m of z = 0) is carried to the table: the pixel covariance through
// the derivative of the table point a projector pixel lands on (the unit's final model and
// pose, a plane parallel to the table through the point). rms over those samples ->
// PredictedErrorRecord::rms_mm; with fewer than min_table_samples, rms_mm < 0 (not predicted).
//
// Frames: world = the bundle's (root projector, or the model's/table's in a warm start); table
// as docs/frames.md. Units as named.
#pragma once

#include <map>
#include <span>
#include <vector>

#include <ceres/problem.h>

#include "common/base/status.h"
#include "node/calibration/cluster_bundle.h"
#include "node/calibration/unit_calibration.h"

namespace sandtable::node {

// A unit's parameter blocks in the Ceres problem (6, 6, 4, 5, 4, 5 doubles).
struct UnitParameterBlocks {
  double* pose = nullptr;  // projector_from_world: angle-axis, translation (m)
  double* mount = nullptr;
  double* projector_k = nullptr;
  double* projector_d = nullptr;
  double* camera_k = nullptr;
  double* camera_d = nullptr;
};

// One observation's residual block: the projector (camera = false: blocks pose, projector_k,
// projector_d, point) or a camera of `unit` (pose, mount, camera_k, camera_d, point).
struct ObservationBlock {
  ceres::ResidualBlockId id = nullptr;
  NodeId unit = kInvalidNodeId;
  bool camera = false;
  int point = -1;
  Eigen::Vector2d projector_px = Eigen::Vector2d::Zero();  // the track's projector pixel
};

Status PredictUnitErrors(const ceres::Problem& problem,
                         const std::map<NodeId, UnitParameterBlocks>& units,
                         std::span<double* const> points,
                         const std::vector<ObservationBlock>& observations,
                         const BundleOptions& options, BundleReport* report,
                         std::map<NodeId, std::vector<PredictedSample>>* predicted);

struct TablePredictionOptions {
  double max_height_m = 0.01;
  int min_table_samples = 20;
  Status Check() const;
};

// Fills calibrations[id].predicted_error for every unit with a report entry that predicted:
// `points_in_table_m` are the solution's points (indices of the samples), `report` the bundle
// that predicted.
void PredictOnTable(const BundleReport& report,
                    const std::map<NodeId, std::vector<PredictedSample>>& predicted,
                    const std::vector<Eigen::Vector3d>& points_in_table_m,
                    std::map<NodeId, UnitCalibration>* calibrations,
                    const TablePredictionOptions& options = {});

}  // namespace sandtable::node
