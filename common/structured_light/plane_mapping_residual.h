// Decoder accuracy that trusts no projector calibration: on a planar target the map from
// undistorted camera pixels to projector pixels is one homography (plus the projector's lens
// distortion, the same for every decoder). Fitting it to the decoded pixels of a region and
// reporting the residual measures the decoder.
#pragma once

#include <cstdint>

#include <opencv2/core.hpp>

#include "common/base/status.h"
#include "common/structured_light/decoder.h"

namespace sandtable {

struct PlaneMappingOptions {
  double ransac_threshold_px = 3.0;  // projector px
  int ransac_iterations = 2000;
  Status Check() const;
};

struct PlaneMappingReport {
  int64_t region_pixels = 0;     // camera pixels in the region mask
  int64_t decoded_pixels = 0;    // of those, decoded
  double ls_rms_px = 0.0;        // least-squares homography over every decoded pixel (projector px)
  double inlier_fraction = 0.0;  // of decoded pixels, inliers of the RANSAC homography
  double inlier_rms_px = 0.0;    // least-squares refit on the inliers (projector px)
  cv::Matx33d projector_from_undistorted_camera;  // the least-squares fit on the inliers
};

// camera_matrix (3x3) and distortion (OpenCV order k1 k2 p1 p2 [k3]) undistort the camera
// pixels (back to pixels through the same camera matrix) before the fit. region: CV_8UC1 of
// the camera size, non-zero inside the plane.
// Errors: INVALID_ARGUMENT (sizes, types, options); DEGENERATE when fewer than 8 decoded pixels
// lie in the region or OpenCV finds no homography.
Expected<PlaneMappingReport> FitPlaneMapping(const Decoding& decoding, const cv::Mat& region,
                                             const cv::Mat& camera_matrix,
                                             const cv::Mat& distortion,
                                             const PlaneMappingOptions& options = {});

// The chessboard region of a white frame: convex hull of the inner corners found by
// cv::findChessboardCorners + cornerSubPix. NOT_FOUND when the board is not found.
Expected<cv::Mat> ChessboardRegion(const cv::Mat& white, cv::Size inner_corners);

}  // namespace sandtable
