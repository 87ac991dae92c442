// The pictures of the lab's report, rendered from the world's truth (sim/transport/view.h).
//
//   TopViewWhite: the table seen straight from above (orthographic, north up) with every
//     projector showing full white, tone-mapped with LuminanceToImage (white = the 99th
//     percentile of the lit luminance). CV_8UC1.
//   RegistrationHeatmap: the same view; each surface point seen from above and lit by at least
//     one estimated projector is coloured by its registration error (RegistrationErrorAt, the
//     worst projector there), 0 mm (dark blue) to `scale_mm` (yellow, viridis); points nobody
//     lights are grey; a colour bar with its scale in mm is drawn at the bottom. CV_8UC3.
// Both are `width_px` wide over the scene's bounding box. Cost: one ray per pixel plus one
// shadow ray per projector.
// Failure: INVALID_ARGUMENT for width_px < 16 or scale_mm <= 0; errors of the world's render.
#pragma once

#include <vector>

#include <opencv2/core.hpp>

#include "common/base/status.h"
#include "sim/lab/registration_metric.h"
#include "sim/transport/world.h"

namespace sandtable::sim {

// The white level of a luminance picture: the 99th percentile of the lit (> 0) values (1 when
// nothing is lit).
double LitWhiteLevel(const std::vector<float>& luminance_nits);

// Sets every projector of `world` to full white (the world's frames are changed).
Expected<cv::Mat> TopViewWhite(World* world, int width_px);

Expected<cv::Mat> RegistrationHeatmap(const World& world,
                                      const std::vector<EstimatedRegistration>& estimates,
                                      const RegistrationMetricOptions& options, int width_px,
                                      double scale_mm);

}  // namespace sandtable::sim
