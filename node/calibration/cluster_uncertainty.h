// What a cluster self-calibration can say of its own error, before anyone measures it: each
// unit's predicted registration error from the covariance of the joint refinement.
//
// EstimateUncertainty (called by AdjustCluster after its last round):
//  1. The information of every unit parameter (pose, mount, intrinsics, distortion) with the
//     points folded out (common/estimation/reduced_information.h), priors included.
//  2. The noise from the data: sigma^2 = (whitened observation residuals)^2 / (observations -
//     unknowns), so a decoder that does better or worse than observation_sigma_px says so;
//     covariance C = sigma^2 S^-1. Directions S does not determine (a site held only to a plane
//     slides on it) are left out and named in BundleReport::undetermined.
//  3. Per unit, up to uncertainty_samples of its projector observations: the derivative J of
//     the pixel where its projector images that point by its pose, projector intrinsics and
//     distortion.
//
// PredictOnTable (called by the solvers once the table frame and the model are known), for
// the samples on the table (within max_height_m of z = 0):
//  - L_s = A_s J_s: where the pixel lands on the table moves by A_s (the derivative of the
//    landing point by the pixel, the unit's final model and pose, the plane through the point
//    parallel to the table);
//  - what the metric sees is a unit's error relative to where the model is placed, and the
//    model is placed on the scanned points: a motion of the whole solution (poses and points
//    together: a rigid motion, and a scale when the model set the scale) moves the placement
//    with it and costs nothing. So the rigid (and scale) motion that best explains all units'
//    landing displacements is taken out: E = (I - M (M^T M)^-1 M^T) L, M_s the error that
//    motion makes at the sample for this unit: (d n^T / d_n - I) G(x), G the motion's
//    displacement of the point x, d the unit's ray through x, n the table's normal (a motion
//    off the table lands each unit's ray elsewhere along its own direction). The placement's
//    own error is not in the figure.
//  - per unit: rms over its samples of sqrt(trace(E_s C E_s^T)) -> rms_mm, and the same in
//    its projector's pixels (A_s's pseudo-inverse) -> rms_px; the eigen-direction of C weighted
//    by its E_s carrying most of its variance -> weak_direction (what it does to the unit's
//    image, and the parameters moving it most) and weak_share.
// A unit with fewer than min_table_samples table samples gets no prediction.
// The prediction covers what the observation noise does through this geometry; what no model
// here describes (a biased decoder, a wrong distortion model, the model placed wrong) is not
// in it, which is why the lab reports it beside the measured error.
//
// Frames: world = the bundle's; table as docs/frames.md. Units as named.
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

// Fills report->sigma_px and report->undetermined.
Expected<BundleUncertainty> EstimateUncertainty(const ceres::Problem& problem,
                                                const std::map<NodeId, UnitParameterBlocks>& units,
                                                std::span<double* const> points,
                                                const std::vector<ObservationBlock>& observations,
                                                const BundleOptions& options, BundleReport* report);

// rms over a unit's samples of its projector pixel's spread in the bundle's own gauge (the
// held root pose): what a test against the truth in that gauge compares with. < 0: no samples.
double BundleGaugeRms_px(const BundleUncertainty& uncertainty, NodeId unit);

struct TablePredictionOptions {
  double max_height_m = 0.01;
  int min_table_samples = 20;
  bool scale_follows_the_model = false;  // the model set the site's scale (a 7th motion)
  Status Check() const;
};

// Sets calibrations[id].predicted_error for every unit with enough table samples.
// `points_in_table_m`: the solution's points (the samples' indices), `report` the bundle that
// estimated `uncertainty`.
void PredictOnTable(const BundleReport& report, const BundleUncertainty& uncertainty,
                    const std::vector<Eigen::Vector3d>& points_in_table_m,
                    std::map<NodeId, UnitCalibration>* calibrations,
                    const TablePredictionOptions& options = {});

}  // namespace sandtable::node
