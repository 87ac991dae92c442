#include "node/calibration/display_frames.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "node/calibration/calibration_check.h"

namespace sandtable::node {
namespace {

// The grid covers this square about the table frame's origin quadrant (metres).
constexpr double kGridFrom_m = -1.0, kGridTo_m = 4.0;
constexpr double kGridSample_m = 0.005;

}  // namespace

Expected<cv::Mat> TableGridFrame(const UnitCalibration& calibration, double spacing_m,
                                 int line_px) {
  if (!calibration.table_from_projector) {
    return InvalidArgumentError("table grid: the calibration has no table_from_projector");
  }
  if (!(spacing_m > 0.0) || line_px < 1) {
    return InvalidArgumentError("table grid: spacing_m > 0 and line_px >= 1");
  }
  const CameraModel& projector = calibration.projector;
  const Rigid3d projector_from_table = calibration.table_from_projector->Inverse();
  cv::Mat frame = cv::Mat::zeros(projector.height_px, projector.width_px, CV_8UC1);
  const int lines = static_cast<int>(std::floor((kGridTo_m - kGridFrom_m) / spacing_m)) + 1;
  const int samples = static_cast<int>((kGridTo_m - kGridFrom_m) / kGridSample_m) + 1;
  for (int axis = 0; axis < 2; ++axis) {
    for (int k = 0; k < lines; ++k) {
      const double fixed = std::ceil(kGridFrom_m / spacing_m) * spacing_m + k * spacing_m;
      std::optional<cv::Point> previous;
      for (int i = 0; i < samples; ++i) {
        const double along = kGridFrom_m + i * kGridSample_m;
        const Eigen::Vector3d in_table =
            axis == 0 ? Eigen::Vector3d(fixed, along, 0.0) : Eigen::Vector3d(along, fixed, 0.0);
        const std::optional<Eigen::Vector2d> px =
            projector.Project(projector_from_table * in_table);
        if (!px || !(std::abs(px->x()) < 1e5 && std::abs(px->y()) < 1e5)) {
          previous.reset();
          continue;
        }
        const cv::Point p(static_cast<int>(std::lround(px->x())),
                          static_cast<int>(std::lround(px->y())));
        if (previous) cv::line(frame, *previous, p, cv::Scalar(255), line_px, cv::LINE_8);
        previous = p;
      }
    }
  }
  return frame;
}

Expected<cv::Mat> JoinBlankMask(const UnitCalibration& calibration, const Scene* model,
                                const cv::Mat& camera_mask, const JoinBlankOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  if (!calibration.table_from_projector) {
    return InvalidArgumentError("blank mask: the calibration has no table_from_projector");
  }
  const CameraModel& camera = calibration.camera;
  if (camera_mask.type() != CV_8UC1 || camera_mask.cols != camera.width_px ||
      camera_mask.rows != camera.height_px) {
    return InvalidArgumentError("blank mask: the camera mask must be CV_8UC1 of the camera's size");
  }
  Expected<std::unique_ptr<RayCaster>> caster = KnownSurfaceCaster(calibration, model);
  if (!caster.ok()) return caster.status();
  const Rigid3d table_from_camera =
      *calibration.table_from_projector * calibration.projector_from_camera;
  const Rigid3d projector_from_table = calibration.table_from_projector->Inverse();
  const Eigen::Matrix3d r = table_from_camera.RotationMatrix();
  const CameraModel& projector = calibration.projector;
  cv::Mat mask = cv::Mat::zeros(projector.height_px, projector.width_px, CV_8UC1);
  const int step = std::max(1, options.sample_step_px);
  for (int y = 0; y < camera_mask.rows; y += step) {
    const uint8_t* row = camera_mask.ptr<uint8_t>(y);
    for (int x = 0; x < camera_mask.cols; x += step) {
      if (!row[x]) continue;
      Expected<Eigen::Vector3d> ray = camera.Unproject(Eigen::Vector2d(x, y));
      if (!ray.ok()) continue;
      const std::optional<RayHit> hit =
          (*caster)->Intersect(table_from_camera.translation, r * *ray);
      if (!hit) continue;
      const std::optional<Eigen::Vector2d> px =
          projector.Project(projector_from_table * hit->point_in_table_m);
      if (!px || !projector.InImage(*px)) continue;
      const int u = std::clamp(static_cast<int>(std::lround(px->x())), 0, projector.width_px - 1);
      const int v = std::clamp(static_cast<int>(std::lround(px->y())), 0, projector.height_px - 1);
      mask.at<uint8_t>(v, u) = 255;
    }
  }
  const int radius = std::max(1, options.margin_px);
  cv::dilate(
      mask, mask,
      cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * radius + 1, 2 * radius + 1)));
  return mask;
}

Status JoinBlankOptions::Check() const {
  if (sample_step_px < 1 || margin_px < 0) {
    return InvalidArgumentError("join blank: sample_step_px >= 1, margin_px >= 0");
  }
  return OkStatus();
}

}  // namespace sandtable::node
