// Leave-one-pose-out cross-validation of the unit calibration: for every pose, calibrate on
// the others (CalibrateUnit) and predict the left-out pose (PredictHeldOutPose): its board pose
// comes from its own chessboard corners in the camera only; its dense projector points are then
// predicted through the fold's intrinsics and projector_from_camera. This judges the
// calibration without trusting any projector ground truth.
// Errors: DEGENERATE with fewer than 4 poses (a fold needs 3); errors of the folds, prefixed
// with the held-out pose.
#pragma once

#include <string>
#include <vector>

#include "common/base/status.h"
#include "node/calibration/unit_calibrator.h"

namespace sandtable::node {

struct CrossValidationFold {
  HeldOutPrediction heldout;
  UnitCalibration calibration;  // from the other poses
  UnitCalibrationReport report;
};

struct CrossValidationReport {
  std::vector<CrossValidationFold> folds;
  // RMS over the folds' dense points / corners (each fold's RMS weighted by its count).
  double heldout_projector_rms_px = 0.0;
  double heldout_camera_rms_px = 0.0;
  double worst_projector_rms_px = 0.0;  // max over folds
  Seconds compute_time{0.0};
};

Expected<CrossValidationReport> LeaveOnePoseOut(const std::vector<PoseObservation>& poses,
                                                const UnitCalibrationOptions& options);

}  // namespace sandtable::node
