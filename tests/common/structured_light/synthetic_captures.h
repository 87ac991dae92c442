// Synthetic camera captures of projected patterns for the decoder tests: each projector frame
// goes through projector gamma, a known camera->projector homography (bilinear, so a projector
// pixel edge lies at half-integer u), defocus blur, albedo, ambient light, optional regions
// (shadow: no projector light; saturation: strong gain; heavy blur), Gaussian noise, 8-bit
// rounding and clipping.
#pragma once

#include <cstdint>
#include <vector>

#include <opencv2/core.hpp>

namespace sandtable::testing {

struct SyntheticCamera {
  int width_px = 640;
  int height_px = 480;
  // Maps camera pixel (x, y, 1) to projector (u, v, w); pixel centres at integers.
  cv::Matx33d projector_from_camera = cv::Matx33d::eye();
  double gamma = 2.2;
  double gain = 170.0;    // gray levels of full projector white on the surface
  double ambient = 25.0;  // gray levels added to every frame
  double blur_sigma_px = 0.7;
  double noise_sigma = 2.0;  // gray levels
  cv::Rect shadow;           // no projector light
  cv::Rect saturated;        // gain x 4
  cv::Rect heavy_blur;       // blur sigma 4 px
};

// The default test camera: 640x480 viewing a tilted part of an 800x600 projector image,
// about 0.9..1.2 projector px per camera px.
SyntheticCamera DefaultSyntheticCamera();

// Projector (u, v) of camera pixel (x, y) under cam.projector_from_camera.
cv::Point2d TrueProjectorPixel(const SyntheticCamera& cam, int x, int y);

std::vector<cv::Mat> RenderCaptures(const std::vector<cv::Mat>& patterns,
                                    const SyntheticCamera& cam, uint64_t seed);

}  // namespace sandtable::testing
