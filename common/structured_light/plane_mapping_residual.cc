#include "common/structured_light/plane_mapping_residual.h"

#include <cmath>
#include <string>
#include <vector>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

namespace sandtable {

namespace {

constexpr size_t kMinPairs = 8;

double ResidualRms(const cv::Mat& h, const std::vector<cv::Point2f>& from,
                   const std::vector<cv::Point2f>& to) {
  std::vector<cv::Point2f> mapped;
  cv::perspectiveTransform(from, mapped, h);
  double sum = 0.0;
  for (size_t i = 0; i < from.size(); ++i) {
    const cv::Point2f d = mapped[i] - to[i];
    sum += static_cast<double>(d.x) * d.x + static_cast<double>(d.y) * d.y;
  }
  return std::sqrt(sum / static_cast<double>(from.size()));
}

}  // namespace

Status PlaneMappingOptions::Check() const {
  if (!(ransac_threshold_px > 0.0) || ransac_iterations < 1) {
    return InvalidArgumentError(
        "plane mapping: ransac_threshold_px > 0 and ransac_iterations >= 1");
  }
  return OkStatus();
}

Expected<PlaneMappingReport> FitPlaneMapping(const Decoding& decoding, const cv::Mat& region,
                                             const cv::Mat& camera_matrix,
                                             const cv::Mat& distortion,
                                             const PlaneMappingOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  if (region.type() != CV_8UC1 || region.size() != decoding.valid.size() ||
      decoding.projector_px.type() != CV_32FC2 || camera_matrix.total() != 9) {
    return InvalidArgumentError(
        "plane mapping: region must be CV_8UC1 of the camera size, the decoding CV_32FC2 and the "
        "camera matrix 3x3");
  }
  PlaneMappingReport report;
  std::vector<cv::Point2f> camera, projector;
  for (int y = 0; y < region.rows; ++y) {
    for (int x = 0; x < region.cols; ++x) {
      if (region.at<uint8_t>(y, x) == 0) continue;
      ++report.region_pixels;
      if (decoding.valid.at<uint8_t>(y, x) == 0) continue;
      const cv::Vec2f uv = decoding.projector_px.at<cv::Vec2f>(y, x);
      camera.emplace_back(static_cast<float>(x), static_cast<float>(y));
      projector.emplace_back(uv[0], uv[1]);
    }
  }
  report.decoded_pixels = static_cast<int64_t>(camera.size());
  if (camera.size() < kMinPairs) {
    return DegenerateError("plane mapping: " + std::to_string(camera.size()) +
                           " decoded pixels in the region, at least 8 needed");
  }
  try {
    std::vector<cv::Point2f> undistorted;
    cv::undistortPoints(camera, undistorted, camera_matrix, distortion, cv::noArray(),
                        camera_matrix);
    const cv::Mat h_ls = cv::findHomography(undistorted, projector, 0);
    std::vector<uint8_t> inliers;
    const cv::Mat h_ransac =
        cv::findHomography(undistorted, projector, cv::RANSAC, options.ransac_threshold_px, inliers,
                           options.ransac_iterations);
    if (h_ls.empty() || h_ransac.empty()) {
      return DegenerateError("plane mapping: OpenCV found no homography");
    }
    report.ls_rms_px = ResidualRms(h_ls, undistorted, projector);
    std::vector<cv::Point2f> in_from, in_to;
    for (size_t i = 0; i < inliers.size(); ++i) {
      if (inliers[i] == 0) continue;
      in_from.push_back(undistorted[i]);
      in_to.push_back(projector[i]);
    }
    report.inlier_fraction = static_cast<double>(in_from.size()) / camera.size();
    if (in_from.size() < kMinPairs) {
      return DegenerateError("plane mapping: fewer than 8 RANSAC inliers");
    }
    const cv::Mat h_in = cv::findHomography(in_from, in_to, 0);
    if (h_in.empty()) return DegenerateError("plane mapping: OpenCV found no inlier homography");
    report.inlier_rms_px = ResidualRms(h_in, in_from, in_to);
    report.projector_from_undistorted_camera = cv::Matx33d(h_in);
  } catch (const cv::Exception& e) {
    return InvalidArgumentError(std::string("plane mapping: OpenCV threw: ") + e.what());
  }
  return report;
}

Expected<cv::Mat> ChessboardRegion(const cv::Mat& white, cv::Size inner_corners) {
  if (white.empty() || white.type() != CV_8UC1) {
    return InvalidArgumentError("chessboard region: need a non-empty CV_8UC1 white frame");
  }
  try {
    std::vector<cv::Point2f> corners;
    if (!cv::findChessboardCorners(white, inner_corners, corners,
                                   cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE)) {
      return NotFoundError("chessboard region: " + std::to_string(inner_corners.width) + "x" +
                           std::to_string(inner_corners.height) +
                           " inner corners not found in the white frame");
    }
    cv::cornerSubPix(white, corners, cv::Size(11, 11), cv::Size(-1, -1),
                     cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 50, 1e-3));
    std::vector<cv::Point> points, hull;
    for (const cv::Point2f& c : corners) points.emplace_back(cvRound(c.x), cvRound(c.y));
    cv::convexHull(points, hull);
    cv::Mat region = cv::Mat::zeros(white.size(), CV_8UC1);
    cv::fillConvexPoly(region, hull, cv::Scalar(255));
    return region;
  } catch (const cv::Exception& e) {
    return InvalidArgumentError(std::string("chessboard region: OpenCV threw: ") + e.what());
  }
}

}  // namespace sandtable
