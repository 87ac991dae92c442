// A projector's response measured through a camera: the exponent (gamma) of its input level and
// its black level, from uniform frames captured by a camera that sees it (the unit's own, in the
// self-calibration's pre-pass; docs/calibration.md "Response").
//
// Model (the one the simulated projectors follow, sim/site/site.h): input level v in 0..255 emits
//   e(v) = b + (1 - b) (v / 255)^gamma   (a fraction of peak; b the black level),
// and nothing at all when muted. A linear camera (raw sensor values: the factory camera's
// response is linear, sim/site/site.h camera.gamma 1) sees c = K e + ambient + other light, with K
// the pixel's gain (albedo, fall-off, vignetting). Over the lit pixels P:
//   sum_P (c_v - c_black) / sum_P (c_white - c_black) = (v / 255)^gamma,
//   sum_P (c_black - c_muted) / sum_P (c_white - c_muted) = b,
// which hold whatever K, the ambient and the other projectors' steady light are (they cancel).
// gamma is the least-squares slope of log ratio against log (v / 255) through the origin.
// Pixels that saturate in white or see too little of this projector are left out.
#pragma once

#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "common/base/status.h"

namespace sandtable::node {

// What projectors do: a fitted gamma outside [kMinPlausibleGamma, kMaxPlausibleGamma] or a black
// level over kMaxPlausibleBlackLevel says the camera did not see the projector's own response
// (its auto exposure or its own gamma on, a camera that is not linear), not the projector.
inline constexpr double kMinPlausibleGamma = 1.0;
inline constexpr double kMaxPlausibleGamma = 4.0;
inline constexpr double kMaxPlausibleBlackLevel = 0.25;  // fraction of peak

struct ProjectorResponseOptions {
  int saturation_dn = 250;  // 8-bit captures: a white pixel at or above this is left out
  int min_signal_dn = 16;   // white - black at least this
  int min_pixels = 500;
  Status Check() const;
};

struct ProjectorResponse {
  double gamma = 0.0;
  double black_level = -1.0;  // fraction of peak; < 0: not measured (no muted capture)
  int pixels = 0;             // camera pixels used
  double fit_rms = 0.0;       // rms of the ratio residuals against the fitted power law
};

// `black`, `white`, `muted` (may be empty: no black level) and the greys: 8-bit captures of one
// camera, same size; `lit`: CV_8UC1 mask of the camera pixels this projector lights (empty: all).
// Levels must be in 1..254. INVALID_ARGUMENT for sizes, types or levels that do not fit;
// DEGENERATE when too few pixels are usable or a ratio is not in (0, 1) (a
// projector that does not respond, or a camera that cannot see it); OUT_OF_RANGE naming the value
// when the fitted gamma or black level is not one a projector has (above).
Expected<ProjectorResponse> FitProjectorResponse(const cv::Mat& black, const cv::Mat& white,
                                                 const cv::Mat& muted,
                                                 const std::vector<std::pair<int, cv::Mat>>& greys,
                                                 const cv::Mat& lit,
                                                 const ProjectorResponseOptions& options = {});

}  // namespace sandtable::node
