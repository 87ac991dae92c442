// What a node projects and how a camera node turns what it captured into correspondences, for
// the cluster self-calibration (docs/calibration.md).
//
// Pattern plan: Gray code + phase shift (common/structured_light/pattern_sequence.h). The
// finest Gray stripes the cameras can still resolve set how many least significant Gray bits
// are left out: a Gray cell of 2^skip projector px must cover at least
// min_gray_cell_camera_px camera pixels of the coarsest camera that sees the footprint
// (projector_px_per_camera_px, measured in the overlap pre-pass); the phase shift, of period
// phase_period_cells cells, resolves the rest. Frames per projector:
//   2 (white, black) + 2 (B_u - skip) + 2 (B_v - skip) + 2 N       (B: Gray bits, N: steps)
// Camera side: captures (8 or 16 bit; 16-bit images are scaled to 8 bits by their bit depth)
// -> DecodeStructuredLight -> SampleProjectorGrid.
#pragma once

#include <map>
#include <vector>

#include <opencv2/core.hpp>

#include "common/base/status.h"
#include "common/structured_light/decoder.h"
#include "common/structured_light/pattern_sequence.h"
#include "common/structured_light/projector_cells.h"
#include "common/structured_light/projector_grid.h"
#include "node/calibration/cluster_problem.h"

namespace sandtable::node {

struct PatternPlanOptions {
  double min_gray_cell_camera_px = 4.0;
  int phase_steps = 8;
  int phase_period_cells = 2;  // P = this x the Gray cell
  int max_gray_lsb_skip = 7;
  Status Check() const;
};

PatternOptions PlanPatterns(int projector_width_px, int projector_height_px,
                            double projector_px_per_camera_px, const PatternPlanOptions& options);

// The decoder's options in self-calibration: the defaults (thresholds for 8-bit captures), one
// thread (a node's budget is one core).
DecoderOptions CalibrationDecoderOptions();

// 8-bit view of a capture: CV_8UC1 as is, CV_16UC1 scaled by 255 / (2^bit_depth - 1).
cv::Mat To8Bit(const cv::Mat& capture, int bit_depth);

struct CameraDecodeReport {
  DecodeReport decode;
  ProjectorGridReport grid;
};

// `mask` (optional, CV_8UC1 of the camera size): only camera pixels where it is non-zero are
// used (the pixels this projector lit in the pre-pass, so projectors of one colour that the
// camera sees apart do not mix).
Expected<std::vector<ProjectorGridPoint>> DecodeToProjectorGrid(
    const std::vector<cv::Mat>& captures_8bit, const PatternOptions& patterns,
    const ProjectorGridOptions& grid, CameraDecodeReport* report = nullptr,
    const cv::Mat* mask = nullptr);

// The planar path's decode (docs/calibration.md, "Planar sites"): the Gray frames of
// `patterns` only (its phase_steps must be 0: the prefix of a full plan's sequence), decoded to
// whole cells (no sub-pixel edges), one correspondence per cell centre (projector_cells.h).
// Errors: INVALID_ARGUMENT when patterns has phase steps or no skipped bit (a cell of one
// pixel has no interior to average), and the decoder's.
Expected<std::vector<ProjectorGridPoint>> DecodeToProjectorCells(
    const std::vector<cv::Mat>& captures_8bit, const PatternOptions& patterns,
    ProjectorCellReport* report = nullptr, const cv::Mat* mask = nullptr);

// The plan of the Gray frames alone of a full plan: the same frames, in the same order, up to
// the first phase frame (pattern_sequence.h, kSandtable order).
PatternOptions GrayPrefix(const PatternOptions& full);

// The lit mask of a pre-pass capture: white - black > threshold (8-bit levels).
cv::Mat LitMask(const cv::Mat& white_8bit, const cv::Mat& black_8bit, int threshold);
// True when the two masks come within margin_px of each other on more than min_pixels pixels.
bool MasksOverlap(const cv::Mat& a, const cv::Mat& b, int margin_px, int min_pixels);

// Tracks of one projector from the grid points each camera decoded (keyed by grid node).
std::vector<Track> BuildTracks(NodeId projector_unit,
                               const std::map<NodeId, std::vector<ProjectorGridPoint>>& by_camera);

// Lit pixels of a white-minus-black difference (pre-pass): pixels with white - black above
// threshold (8-bit levels).
int CountLitPixels(const cv::Mat& white_8bit, const cv::Mat& black_8bit, int threshold);

}  // namespace sandtable::node
