// Capture synthesis: the cheap per-frame gather over a TransportMap.
//
//   1. DecodeProjectorFrame: 8-bit frame (CV_8UC1, or CV_8UC3 BGR reduced to Rec. 709 luma) ->
//      emission e = black_level + (1 - black_level) (v / 255)^gamma, a fraction of peak; a 16-bit
//      grey frame (CV_16UC1) the same over v / 65535 (a deeper input than the nodes send).
//   2. GatherLuminance: L = albedo ambient + sum over projectors of the entry's 4 x 4 separable
//      kernel over e (the projector's piecewise-constant pixels integrated over the view
//      pixel's footprint, transport_map.h). L is in nits (cd/m^2) per view pixel.
//   3. SynthesizeCapture: camera response of site.h: s = L exposure_s / saturation_nit_s,
//      photon noise (Poisson in electrons: exact below 32 expected electrons, Gaussian with the
//      Poisson variance above), Gaussian read noise in DN, encoding s^(1/gamma), rounding and
//      clamping to [0, 2^bit_depth - 1]. CV_8UC1 for bit_depth <= 8, else CV_16UC1.
// Deterministic: the noise of row y comes from its own generator seeded with (seed, y).
#pragma once

#include <cstdint>
#include <vector>

#include <opencv2/core.hpp>

#include "common/base/status.h"
#include "sim/site/site.h"
#include "sim/transport/transport_map.h"

namespace sandtable::sim {

struct LinearFrame {
  int width_px = 0, height_px = 0;  // the projector's image
  // Row-major, fraction of peak, with kFramePadding_px of zeros (no light) on every side:
  // pixel (x, y) is at (y + pad) * padded_width() + x + pad.
  std::vector<float> emission;
  int padded_width() const { return width_px + 2 * kFramePadding_px; }
  // One extra zero row at the bottom: a 4 x 4 kernel whose box ends in the last row starts
  // at most at row height - 1 and reads rows up to height + 2 (its unused rows have weight 0,
  // but are still read).
  int padded_height() const { return height_px + 2 * kFramePadding_px + 1; }
  float At(int x, int y) const {
    return emission[static_cast<size_t>(y + kFramePadding_px) * padded_width() + x +
                    kFramePadding_px];
  }
};

// INVALID_ARGUMENT when the frame's size or type does not match the projector.
Expected<LinearFrame> DecodeProjectorFrame(const ProjectorSpec& projector, const cv::Mat& frame);
// A uniform frame of 8-bit value `value`.
LinearFrame UniformFrame(const ProjectorSpec& projector, int value);

// `frames[p]` for site unit p; nullptr = projector switched off (emits nothing).
// INVALID_ARGUMENT when frames.size() differs from the map's projector count.
Status GatherLuminance(const TransportMap& map, const std::vector<const LinearFrame*>& frames,
                       double ambient_luminance_nits, std::vector<float>* luminance_nits);

struct CaptureNoise {
  bool enabled = true;
  uint64_t seed = 0;
};

Expected<cv::Mat> SynthesizeCapture(const CameraSpec& camera, int width_px, int height_px,
                                    const std::vector<float>& luminance_nits,
                                    const CaptureNoise& noise);

}  // namespace sandtable::sim
