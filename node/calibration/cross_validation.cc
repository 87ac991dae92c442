#include "node/calibration/cross_validation.h"

#include <algorithm>
#include <chrono>
#include <cmath>

namespace sandtable::node {

Expected<CrossValidationReport> LeaveOnePoseOut(const std::vector<PoseObservation>& poses,
                                                const UnitCalibrationOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  if (poses.size() < 4) {
    return DegenerateError("cross-validation: " + std::to_string(poses.size()) +
                           " poses; leave-one-out needs at least 4 (3 per fold)");
  }
  CrossValidationReport out;
  double projector_sq = 0.0, camera_sq = 0.0;
  int64_t projector_count = 0, camera_count = 0;
  for (size_t held = 0; held < poses.size(); ++held) {
    std::vector<PoseObservation> training;
    for (size_t p = 0; p < poses.size(); ++p) {
      if (p != held) training.push_back(poses[p]);
    }
    Expected<UnitCalibrationResult> fit = CalibrateUnit(training, options);
    if (!fit.ok()) return fit.status().WithContext("fold without " + poses[held].name + ": ");
    Expected<HeldOutPrediction> prediction =
        PredictHeldOutPose(fit->calibration, poses[held], options);
    if (!prediction.ok()) {
      return prediction.status().WithContext("fold without " + poses[held].name + ": ");
    }
    projector_sq += prediction->projector_rms_px * prediction->projector_rms_px *
                    static_cast<double>(prediction->projector_points);
    projector_count += prediction->projector_points;
    const int corners = options.board.corner_count();
    camera_sq += prediction->camera_rms_px * prediction->camera_rms_px * corners;
    camera_count += corners;
    out.worst_projector_rms_px = std::max(out.worst_projector_rms_px, prediction->projector_rms_px);
    out.folds.push_back({*prediction, fit->calibration, fit->report});
  }
  out.heldout_projector_rms_px =
      projector_count > 0 ? std::sqrt(projector_sq / projector_count) : 0.0;
  out.heldout_camera_rms_px = camera_count > 0 ? std::sqrt(camera_sq / camera_count) : 0.0;
  out.compute_time = std::chrono::steady_clock::now() - start;
  return out;
}

}  // namespace sandtable::node
