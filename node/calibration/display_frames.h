// What a calibrated unit shows between calibrations, and what it blanks while a joining
// neighbour captures (docs/calibration.md, "Live join").
//
// TableGridFrame: the operator's registration pattern, lines every spacing_m in the table
// frame's x and y drawn where the unit's calibrated projector puts them on the table plane
// (z = 0; on buildings they appear displaced by the parallax; the renderer's grid pattern
// drapes its lines on the model). Lines line_px wide, level 255 on 0; GRAY8 of the projector's
// size. A calibrated unit without a render loop (a node started with no show) shows this, so a
// live join has a display to keep.
//
// JoinBlankMask: the pixels of this unit's projector that land where a joining projector's
// light was seen by this unit's camera (its pre-pass lit mask of that projector): every
// sample_step_px-th masked camera pixel's ray meets the surface (the table plane and the model
// at its placement, Embree), and that point is projected into this unit's projector; the marks
// are then dilated by margin_px (sampling gaps, calibration error, the edge of the joining
// footprint). CV_8UC1, 255 = blank.
// Errors: INVALID_ARGUMENT for a calibration without table_from_projector or a mask that is
// not CV_8UC1 of the camera's size; the ray caster's.
#pragma once

#include <opencv2/core.hpp>

#include "common/base/status.h"
#include "common/io/unit_calibration_file.h"
#include "common/scene/scene.h"

namespace sandtable::node {

Expected<cv::Mat> TableGridFrame(const UnitCalibration& calibration, double spacing_m = 0.1,
                                 int line_px = 3);

struct JoinBlankOptions {
  int sample_step_px = 2;
  int margin_px = 12;
  Status Check() const;
};

Expected<cv::Mat> JoinBlankMask(const UnitCalibration& calibration, const Scene* model,
                                const cv::Mat& camera_mask, const JoinBlankOptions& options = {});

}  // namespace sandtable::node
