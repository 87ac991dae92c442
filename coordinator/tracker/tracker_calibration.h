// Tracker calibration (TR09-017 4.1.4): the nodes show a target at known table points, one
// after the other (16 by default, a 4 x 4 grid over the display area); the user touches each
// with the wand tip and clicks; table_from_tracker is fitted to the pairs
// (tip_in_tracker_m, target_in_table_m) by Umeyama (rigid, or similarity when the tracker's
// scale is not trusted), with a residual per point and outliers flagged and left out.
//
// Units: metres in, residuals reported in mm. Frames: tracker (as the device reports, after
// the driver's conversion to metres) and table.
// Failure: fewer than 3 usable pairs, collinear targets or tips, non-finite input: an error
// naming the cause (from Umeyama); never aborts.
#pragma once

#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "common/base/status.h"
#include "common/geometry/rigid3.h"
#include "common/geometry/sim3.h"
#include "coordinator/tracker/tracker_source.h"

namespace sandtable::coordinator {

// n x n grid of targets on the table plane (z = 0), centred on the origin, spanning
// `extent_m` (default: TR09-017's 4 ft display area, inset by 10 %).
std::vector<Eigen::Vector3d> GridCalibrationTargets(int n = 4, double extent_m = 0.9 * 1.2192);

struct TrackerCalibrationOptions {
  bool similarity = false;          // also fit a scale (tracker units not trusted)
  double outlier_threshold_mm = 5;  // residual above this: flagged and left out of the refit
  int min_inliers = 6;              // fewer inliers than this after flagging: error
  Status Check() const;
};

struct TrackerCalibrationReport {
  Rigid3d table_from_tracker;        // the rigid part (the scale of a similarity fit is separate)
  double scale = 1.0;                // table metres per tracker metre (1 for a rigid fit)
  std::vector<double> residuals_mm;  // per target, against the final fit (outliers included)
  std::vector<bool> outlier;         // per target
  double rms_mm = 0.0;               // over inliers
  double max_inlier_mm = 0.0;
  int num_inliers = 0;
  double source_spread_ratio = 0.0;  // from Umeyama: near 0 means tips nearly collinear
  std::string message;               // one line for logs and the status endpoint
};

Expected<TrackerCalibrationReport> FitTableFromTracker(
    const std::vector<Eigen::Vector3d>& tips_in_tracker_m,
    const std::vector<Eigen::Vector3d>& targets_in_table_m,
    const TrackerCalibrationOptions& options = {});

// The table_from_tracker file (docs/file-formats.md), written with the common codec
// (common/io/json_codec.h):
//   {"format": "sandtable.table_from_tracker", "version": 1,
//    "table_from_tracker": {"rotation_xyzw": [x, y, z, w], "translation_m": [x, y, z]}}
// Also read: the older file that is the transform itself,
//   {"rotation_wxyz": [w, x, y, z], "translation_m": [x, y, z]}.
// A quaternion must have norm within io::kQuaternionNormTolerance (1e-3) of 1 (then it is
// normalised). Errors (IO_ERROR, PARSE_ERROR, INVALID_ARGUMENT) name the file and the field.
inline constexpr char kTableFromTrackerFormat[] = "sandtable.table_from_tracker";
inline constexpr int kTableFromTrackerVersion = 1;
nlohmann::json TableFromTrackerToJson(const Rigid3d& table_from_tracker);
Status SaveTableFromTracker(const Rigid3d& table_from_tracker, const std::string& path);
Expected<Rigid3d> TableFromTrackerFromJson(const nlohmann::json& json, std::string_view source);
Expected<Rigid3d> LoadTableFromTracker(const std::string& path);

// The interactive session: shows target i until the wand button is pressed and released; the
// tip positions while pressed are averaged (the press itself jitters the wand less than any
// single sample). Feed it every sample of the calibrating sensor.
class TrackerCalibrationSession {
 public:
  TrackerCalibrationSession(std::vector<Eigen::Vector3d> targets_in_table_m,
                            Eigen::Vector3d tip_in_sensor_m);
  // Returns true when this sample completed a target.
  bool OnSample(const TrackerSample& sample);
  bool done() const { return next_ >= targets_.size(); }
  size_t current_target() const { return next_; }
  const std::vector<Eigen::Vector3d>& targets() const { return targets_; }
  const std::vector<Eigen::Vector3d>& tips_in_tracker_m() const { return tips_; }

 private:
  std::vector<Eigen::Vector3d> targets_;
  Eigen::Vector3d tip_in_sensor_m_;
  std::vector<Eigen::Vector3d> tips_;
  size_t next_ = 0;
  Eigen::Vector3d sum_ = Eigen::Vector3d::Zero();
  int count_ = 0;
};

}  // namespace sandtable::coordinator
