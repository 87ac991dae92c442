// Does a saved calibration still hold? A check in two frames of the unit's own projector and
// camera, no neighbours needed: a black reference and a grid of small dots. The saved
// calibration predicts where each dot lands on the known surface (the table plane, z = 0 of the
// table frame, and the glTF model at its saved placement) and so where the camera must see it;
// the dots the camera finds are compared with the prediction.
//
// Prediction (PlanCalibrationCheck): dot centres every dot_spacing_px projector px; each
// centre's ray (CameraModel::Unproject, lens included) is cast from the projector's optical
// centre into the surface (Embree); dots at an edge (a ray dot_size_px away meets another face:
// a normal that differs, or a point more than edge_depth_m off the dot's plane, or nothing),
// at grazing incidence (cos under
// min_incidence_cos), hidden from the camera (its ray meets the surface first) or outside its
// image are left out. Evaluation (EvaluateCalibrationCheck): dot image minus black; per dot,
// the brightest pixel within search_radius_px of the prediction, then the centroid of the
// pixels above half that peak in a window of a few px; a peak under min_peak_levels is "not
// found". The offset is |centroid - prediction| in camera px.
// Verdict: holds when at least min_found_fraction of the predicted dots are found, the 90th
// percentile of their offsets is at most threshold_px and, with min_wall_dots or more found on
// walls, their median offset is at most wall_threshold_px. A moved unit (or a moved building
// under its dots) shifts the dots by the parallax of the change: past the threshold, or out of
// the search window (not found).
// Limit: the camera moves with its projector, so over a plane a slide of the unit parallel to
// it or a turn about its normal changes nothing the unit can see (the dots land identically);
// only the walls of buildings show it, weakly (measured: 1 cm and 0.3 degrees move the wall
// dots' median from 0.18 to 0.6 px, the table's dots not at all). A tilt, a change of height or
// of the projector against its camera shows everywhere. Neighbours watching each other's dots
// would see any move; not done (docs/calibration.md).
#pragma once

#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "common/base/status.h"
#include "common/io/unit_calibration_file.h"
#include "common/scene/ray_caster.h"
#include "common/scene/scene.h"

namespace sandtable::node {

struct CalibrationCheckOptions {
  int dot_spacing_px = 40;
  int dot_size_px = 4;
  double edge_depth_m = 0.003;
  double min_incidence_cos = 0.3;
  double search_radius_px = 8.0;
  int min_peak_levels = 12;  // 8-bit levels above the black reference
  double threshold_px = 1.0;
  double min_found_fraction = 0.6;
  int min_dots = 20;
  // Dots on walls (and steep roofs) are what sees a slide of the unit along the table: their
  // median offset, when there are enough of them.
  double wall_threshold_px = 0.45;
  int min_wall_dots = 8;
  Status Check() const;
};

struct PredictedDot {
  Eigen::Vector2d projector_px;
  Eigen::Vector2d camera_px;
  bool on_wall = false;  // the surface there is steeper than kWallNormalZ: sees horizontal moves
};

struct CalibrationCheckPlan {
  cv::Mat dots_frame;  // CV_8UC1 at the projector's resolution: the dots white, the rest black
  std::vector<PredictedDot> dots;
  int dots_left_out = 0;  // at edges, grazing, hidden, outside the camera
};

struct CalibrationCheckReport {
  bool holds = false;
  int dots = 0, found = 0;
  double median_px = 0.0, p90_px = 0.0;
  int wall_dots = 0;  // found on walls
  double wall_median_px = 0.0;
  std::string reason;  // why it does not hold
};

// The surface a calibrated unit knows: the table plane (a 20 m square at z = 0 of the table
// frame) and, when given and placed (calibration.table_from_model), the model; as an Embree
// caster on one thread. Errors: the caster's.
Expected<std::unique_ptr<RayCaster>> KnownSurfaceCaster(const UnitCalibration& calibration,
                                                        const Scene* model);

// INVALID_ARGUMENT when the calibration has no table_from_projector or fails its Check, or the
// options are invalid; DEGENERATE when fewer than min_dots dots can be predicted. `model` (may be
// null) is in its own frame and placed by calibration.table_from_model (ignored without one).
Expected<CalibrationCheckPlan> PlanCalibrationCheck(const UnitCalibration& calibration,
                                                    const Scene* model,
                                                    const CalibrationCheckOptions& options = {});

// `black` and `dots` are 8-bit captures of the unit's camera (To8Bit), same size.
Expected<CalibrationCheckReport> EvaluateCalibrationCheck(
    const CalibrationCheckPlan& plan, const cv::Mat& black, const cv::Mat& dots,
    const CalibrationCheckOptions& options = {});

}  // namespace sandtable::node
