// One chessboard pose of a unit calibration: the chessboard's inner corners in the camera and
// the dense structured-light correspondences (camera pixel -> decoded projector pixel) on the
// board.
//
// Frames and units: the board frame has its origin at inner corner (0, 0), x along the
// fastest-varying corner index (i = 0..cols-1), y along j, z = 0 on the board, metres. Corner
// (i, j) is at (i * square_m, j * square_m, 0) (OpenCV calibrateCamera object points). Pixels
// follow OpenCV (pixel (0, 0) centred at (0.0, 0.0)); camera pixels are distorted (as
// captured), projector pixels are as decoded.
//
// Dense samples are the decoded camera pixels inside the convex hull of the inner corners, on a
// grid of `dense_stride_px`; the hull is the region the board certainly covers (its outer row
// of squares may be cut by the image border).
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "common/base/status.h"
#include "common/structured_light/decoder.h"
#include "common/structured_light/pattern_sequence.h"

namespace sandtable::node {

struct BoardSpec {
  int inner_cols = 9;       // inner corners per row (OpenCV patternSize.width)
  int inner_rows = 7;       // inner corners per column (patternSize.height)
  double square_m = 0.075;  // edge of one square
  Status Check() const;
  int corner_count() const { return inner_cols * inner_rows; }
  // Board-frame position of corner k (k = i + j * inner_cols), metres.
  Eigen::Vector3d CornerInBoard_m(int k) const;
};

struct ObservationOptions {
  PatternOptions patterns = PatternOptions::OpenCvGrayCode(1024, 768);
  DecoderOptions decoder;
  // Grid step of the dense samples in camera px (1 = every decoded pixel on the board).
  int dense_stride_px = 2;
  // Corner refinement window half size (cv::cornerSubPix winSize), camera px.
  int corner_window_px = 11;
  Status Check() const;
};

struct PoseObservation {
  std::string name;  // e.g. "capture_3"
  cv::Size camera_size;
  std::vector<Eigen::Vector2d> corners_in_camera_px;  // BoardSpec corner order
  std::vector<Eigen::Vector2d> dense_in_camera_px;
  std::vector<Eigen::Vector2d> dense_in_projector_px;
  int64_t board_pixels = 0;          // camera pixels inside the corner hull
  int64_t decoded_board_pixels = 0;  // of those, decoded
  double decode_time_ms = 0.0;
};

// Finds the corners on the white frame (cv::findChessboardCorners + cornerSubPix), decodes the
// sequence and collects the dense samples. Errors: INVALID_ARGUMENT (options, captures not
// matching the pattern layout, no white frame in the layout); NOT_FOUND "chessboard 9x7 not
// found in <name> white frame"; decoder errors.
Expected<PoseObservation> ObservePose(const std::string& name, const std::vector<cv::Mat>& captures,
                                      const BoardSpec& board, const ObservationOptions& options);

// The dataset layout: `dir` holds capture_0, capture_1, ... (sorted by their number), each
// with the frames of options.patterns named graycode_NN.png. Reads and observes each pose,
// one at a time (memory: one pose's frames). Errors: IO_ERROR when `dir` has no capture_*
// folder or a frame is missing; errors of ObservePose, prefixed with the folder.
Expected<std::vector<PoseObservation>> ObservePoseFolders(const std::string& dir,
                                                          const BoardSpec& board,
                                                          const ObservationOptions& options);

}  // namespace sandtable::node
