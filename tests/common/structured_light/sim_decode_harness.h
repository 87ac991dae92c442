// Structured light in the simulated world, for tests and the sweep: project a pattern sequence
// from one unit's projector of a simulated site, capture it with that unit's camera through the
// World, decode it, and compare every decoded camera pixel with the world's ground truth.
//
// Ground truth per camera pixel: the surface point the camera pixel's centre ray hits (the
// camera's transport map), then that projector's TRUE pixel of the point (its Brown model) and
// its visibility (in front, inside the projector image, facing it, shadow ray unobstructed)
// from sim::SampleProjector. "Lit" = visible; these are the pixels the decoder should decode.
// Error of a decoded pixel = |decoded (u, v) - true (u, v)| in projector px (2-D norm).
// Test-only code: links the sim libraries (library code in common/ must not).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "common/base/status.h"
#include "common/structured_light/decoder.h"
#include "common/structured_light/pattern_sequence.h"
#include "sim/transport/world.h"

namespace sandtable::sim_decode {

struct SimDecodeSetup {
  std::string site_preset = "sandtable-3";  // or "flat-4", "grid-N"
  std::string scene_preset = "sandtable";   // sandtable | city | flat
  uint64_t scene_seed = 1;
  int unit_index = 0;  // index into site.units
  // Camera window (crop of the preset camera's sensor around its centre; pixel scale and lens
  // unchanged). 0 = the preset's full sensor.
  int camera_width_px = 0;
  int camera_height_px = 0;
  // Camera noise: multipliers of the preset camera's read noise and of its photon noise
  // variance (full well divided by it); exposure multiplier (less light = more relative noise).
  double read_noise_scale = 1.0;
  double photon_noise_scale = 1.0;
  double exposure_scale = 1.0;
  int transport_threads = 0;  // 0 = hardware concurrency
};

struct SimDecodeWorld {
  std::unique_ptr<sim::World> world;
  NodeId unit = kInvalidNodeId;
  int projector_width_px = 0, projector_height_px = 0;
  cv::Mat truth_px;  // CV_32FC2, camera size: true projector (u, v) px; NaN where not lit
  cv::Mat lit;       // CV_8UC1 255 where the projector lights the camera pixel's surface point
  // 255 where lit and the 3x3 camera neighbourhood is lit with true projector pixels within
  // 4 projector px of this one (no depth or shadow edge inside the camera pixel's footprint).
  cv::Mat lit_interior;
  int64_t lit_pixels = 0;
  double transport_time_s = 0.0;
  double truth_time_s = 0.0;
};

Expected<SimDecodeWorld> MakeSimDecodeWorld(const SimDecodeSetup& setup);

// Shows every frame on the unit's projector (the others black) and captures it. Capture k
// uses noise seed (noise_seed + k) when `noise` is set. `capture_time_s` (optional) gets the
// wall time spent in the world.
Expected<std::vector<cv::Mat>> CaptureSequence(SimDecodeWorld& w,
                                               const std::vector<cv::Mat>& frames, bool noise,
                                               uint64_t noise_seed,
                                               double* capture_time_s = nullptr);

struct DecodeErrorStats {
  int64_t lit_pixels = 0;          // in the mask compared against
  int64_t decoded_lit_pixels = 0;  // decoded among those
  int64_t decoded_unlit_pixels = 0;
  double rms_px = 0.0, p99_px = 0.0, max_px = 0.0;  // over decoded lit pixels (2-D error)
  double rms_u_px = 0.0, rms_v_px = 0.0;
  double DecodedFraction() const {
    return lit_pixels > 0 ? static_cast<double>(decoded_lit_pixels) / lit_pixels : 0.0;
  }
  std::string ToString() const;
};

// Compares `decoding` with the truth over the pixels of `mask` (w.lit or w.lit_interior).
// Only the axes the patterns encode are compared.
DecodeErrorStats CompareWithTruth(const SimDecodeWorld& w, const Decoding& decoding,
                                  const cv::Mat& mask);

// PatternOptions at the unit projector's resolution (other fields from `base`).
PatternOptions PatternsFor(const SimDecodeWorld& w, PatternOptions base);

}  // namespace sandtable::sim_decode
