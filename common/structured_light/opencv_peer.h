// Adapter to the peer decoder, cv::structured_light::GrayCodePattern (opencv_contrib), used the
// way procam-kamino410's calibrate.py uses it: every camera pixel with
// white - black > black_threshold is passed to getProjPixel, which thresholds each bit pair
// (|I - I_inverse| < white_threshold is an error) and returns integer projector pixels.
// The captures must be in OpenCV order (PatternOptions::OpenCvGrayCode), full resolution.
//
// Output is a Decoding like DecodeStructuredLight's: (u, v) integers as float; flags are
// kDecodeShadow, or kDecodeLowContrast where getProjPixel reported an error (it does not say
// whether contrast or range failed); confidence is 1 where valid.
// Cost: OpenCV decodes pixel by pixel through std::vector pushes (about 2 Mpx/s on one core);
// single-threaded here, as the peer is used.
// Errors: INVALID_ARGUMENT for captures that do not fit the layout; INTERNAL with the OpenCV
// message if OpenCV throws (caught here, never propagated).
#pragma once

#include <vector>

#include <opencv2/core.hpp>

#include "common/base/status.h"
#include "common/structured_light/decoder.h"

namespace sandtable {

struct OpenCvPeerOptions {
  int projector_width_px = 1024;
  int projector_height_px = 768;
  int black_threshold = 40;  // GrayCodePattern's blackThreshold (shadow), gray levels
  int white_threshold = 5;   // GrayCodePattern's whiteThreshold (bit contrast), gray levels
  Status Check() const;
};

// `time_ms` (may be null) receives the wall time of the per-pixel loop.
Expected<Decoding> DecodeWithOpenCvGrayCode(const std::vector<cv::Mat>& captures,
                                            const OpenCvPeerOptions& options,
                                            double* time_ms = nullptr);

// The patterns OpenCV's GrayCodePattern::generate produces for that size, plus its white and
// black frames from getImagesForShadowMasks (42 frames for 1024x768), in OpenCV order.
Expected<std::vector<cv::Mat>> GenerateOpenCvGrayCodePatterns(int width_px, int height_px);

}  // namespace sandtable
