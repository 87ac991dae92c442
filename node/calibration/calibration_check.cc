#include "node/calibration/calibration_check.h"

#include <algorithm>
#include <cmath>
#include <optional>

#include <opencv2/imgproc.hpp>

#include "common/scene/procedural_scene.h"
#include "common/scene/ray_caster.h"

namespace sandtable::node {
namespace {

// The table plane stands in for everything the model does not cover: a square this wide.
constexpr double kTableSquare_m = 20.0;
// A camera ray that meets the surface this much before the dot's point: the dot is hidden.
constexpr double kOcclusionMargin_m = 0.002;
// Predicted dots this close to the camera image's border are left out (px).
constexpr double kImageMargin_px = 6.0;
constexpr double kWallNormalZ = 0.7;
constexpr double kSameFaceCos = 0.999;

double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  const size_t k = std::min(v.size() - 1, static_cast<size_t>(q * static_cast<double>(v.size())));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

}  // namespace

Status CalibrationCheckOptions::Check() const {
  if (dot_spacing_px < 4 || dot_size_px < 1 || dot_size_px * 2 > dot_spacing_px) {
    return InvalidArgumentError(
        "calibration check: dot_spacing_px >= 4, 1 <= dot_size_px <= half of it");
  }
  if (!(edge_depth_m > 0) || !(search_radius_px > 0) || !(threshold_px > 0) ||
      !(min_incidence_cos >= 0 && min_incidence_cos < 1) ||
      !(min_found_fraction > 0 && min_found_fraction <= 1) || min_peak_levels < 1 || min_dots < 1 ||
      !(wall_threshold_px > 0) || min_wall_dots < 1) {
    return InvalidArgumentError(
        "calibration check: depths, radii, thresholds > 0; fractions in (0, 1]");
  }
  return OkStatus();
}

Expected<std::unique_ptr<RayCaster>> KnownSurfaceCaster(const UnitCalibration& calibration,
                                                        const Scene* model) {
  auto surface = std::make_shared<Scene>(
      MakeRectangleMesh(Eigen::Vector2d(kTableSquare_m, kTableSquare_m), 0));
  if (model && calibration.table_from_model) {
    surface->Append(MovedScene(*model, *calibration.table_from_model));
  }
  return RayCaster::Create(std::shared_ptr<const Scene>(surface), "threads=1");
}

Expected<CalibrationCheckPlan> PlanCalibrationCheck(const UnitCalibration& calibration,
                                                    const Scene* model,
                                                    const CalibrationCheckOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  ST_RETURN_IF_ERROR(calibration.Check());
  if (!calibration.table_from_projector) {
    return InvalidArgumentError("calibration check: the calibration has no table_from_projector");
  }
  Expected<std::unique_ptr<RayCaster>> caster = KnownSurfaceCaster(calibration, model);
  if (!caster.ok()) return caster.status();
  const CameraModel& projector = calibration.projector;
  const CameraModel& camera = calibration.camera;
  const Rigid3d& table_from_projector = *calibration.table_from_projector;
  const Rigid3d table_from_camera = table_from_projector * calibration.projector_from_camera;
  const Rigid3d camera_from_table = table_from_camera.Inverse();
  const Eigen::Matrix3d r = table_from_projector.RotationMatrix();
  const Eigen::Vector3d projector_centre = table_from_projector.translation;
  const Eigen::Vector3d camera_centre = table_from_camera.translation;

  // The surface point of a projector pixel: distance along the ray and the hit.
  auto cast = [&](const Eigen::Vector2d& px) -> std::optional<RayHit> {
    Expected<Eigen::Vector3d> ray = projector.Unproject(px);
    if (!ray.ok()) return std::nullopt;
    return (*caster)->Intersect(projector_centre, r * *ray);
  };

  CalibrationCheckPlan plan;
  plan.dots_frame = cv::Mat::zeros(projector.height_px, projector.width_px, CV_8UC1);
  const int size = options.dot_size_px, spacing = options.dot_spacing_px;
  const double half = 0.5 * (size - 1);
  for (int y = spacing / 2; y + size <= projector.height_px - spacing / 4; y += spacing) {
    for (int x = spacing / 2; x + size <= projector.width_px - spacing / 4; x += spacing) {
      const Eigen::Vector2d centre(x + half, y + half);
      const std::optional<RayHit> hit = cast(centre);
      bool usable = hit.has_value();
      if (usable) {
        const Eigen::Vector3d dir = (hit->point_in_table_m - projector_centre).normalized();
        usable = std::abs(dir.dot(hit->normal_in_table)) >= options.min_incidence_cos;
      }
      for (const Eigen::Vector2d& step : {Eigen::Vector2d(size, 0), Eigen::Vector2d(-size, 0),
                                          Eigen::Vector2d(0, size), Eigen::Vector2d(0, -size)}) {
        if (!usable) break;
        // The neighbourhood on the dot's own face: the same plane within edge_depth_m.
        const std::optional<RayHit> near = cast(centre + step);
        usable =
            near && near->normal_in_table.dot(hit->normal_in_table) > kSameFaceCos &&
            std::abs(hit->normal_in_table.dot(near->point_in_table_m - hit->point_in_table_m)) <=
                options.edge_depth_m;
      }
      std::optional<Eigen::Vector2d> seen;
      if (usable) {
        seen = camera.Project(camera_from_table * hit->point_in_table_m);
        usable = seen && seen->x() >= kImageMargin_px && seen->y() >= kImageMargin_px &&
                 seen->x() <= camera.width_px - 1 - kImageMargin_px &&
                 seen->y() <= camera.height_px - 1 - kImageMargin_px;
      }
      if (usable) {
        const Eigen::Vector3d to_point = hit->point_in_table_m - camera_centre;
        const std::optional<RayHit> first = (*caster)->Intersect(camera_centre, to_point);
        usable = first && first->distance_m >= to_point.norm() - kOcclusionMargin_m;
      }
      if (!usable) {
        ++plan.dots_left_out;
        continue;
      }
      plan.dots_frame(cv::Rect(x, y, size, size)).setTo(255);
      plan.dots.push_back({centre, *seen, std::abs(hit->normal_in_table.z()) < kWallNormalZ});
    }
  }
  if (static_cast<int>(plan.dots.size()) < options.min_dots) {
    return DegenerateError("calibration check: only " + std::to_string(plan.dots.size()) +
                           " dots can be predicted on the known surface (at least " +
                           std::to_string(options.min_dots) + ")");
  }
  return plan;
}

Expected<CalibrationCheckReport> EvaluateCalibrationCheck(const CalibrationCheckPlan& plan,
                                                          const cv::Mat& black, const cv::Mat& dots,
                                                          const CalibrationCheckOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  if (black.type() != CV_8UC1 || dots.type() != CV_8UC1 || black.size() != dots.size() ||
      black.empty()) {
    return InvalidArgumentError("calibration check: captures must be 8-bit, non-empty, one size");
  }
  cv::Mat diff;
  cv::subtract(dots, black, diff, cv::noArray(), CV_32F);  // negative where noise
  const int w = diff.cols, h = diff.rows;
  const int radius = static_cast<int>(std::ceil(options.search_radius_px));
  const int window = std::max(2, static_cast<int>(std::ceil(0.75 * options.dot_size_px)) + 1);
  CalibrationCheckReport report;
  report.dots = static_cast<int>(plan.dots.size());
  std::vector<double> offsets, wall_offsets;
  for (const PredictedDot& dot : plan.dots) {
    const int cx = static_cast<int>(std::lround(dot.camera_px.x()));
    const int cy = static_cast<int>(std::lround(dot.camera_px.y()));
    float peak = -1;
    int px = -1, py = -1;
    for (int y = std::max(0, cy - radius); y <= std::min(h - 1, cy + radius); ++y) {
      const float* row = diff.ptr<float>(y);
      for (int x = std::max(0, cx - radius); x <= std::min(w - 1, cx + radius); ++x) {
        if ((x - dot.camera_px.x()) * (x - dot.camera_px.x()) +
                (y - dot.camera_px.y()) * (y - dot.camera_px.y()) >
            options.search_radius_px * options.search_radius_px) {
          continue;
        }
        if (row[x] > peak) {
          peak = row[x];
          px = x;
          py = y;
        }
      }
    }
    if (peak < options.min_peak_levels) continue;
    double sw = 0, sx = 0, sy = 0;
    for (int y = std::max(0, py - window); y <= std::min(h - 1, py + window); ++y) {
      const float* row = diff.ptr<float>(y);
      for (int x = std::max(0, px - window); x <= std::min(w - 1, px + window); ++x) {
        const double v = row[x] - 0.5 * peak;
        if (v <= 0) continue;
        sw += v;
        sx += v * x;
        sy += v * y;
      }
    }
    if (sw <= 0) continue;
    offsets.push_back((Eigen::Vector2d(sx / sw, sy / sw) - dot.camera_px).norm());
    if (dot.on_wall) wall_offsets.push_back(offsets.back());
  }
  report.found = static_cast<int>(offsets.size());
  report.wall_dots = static_cast<int>(wall_offsets.size());
  report.wall_median_px = Percentile(wall_offsets, 0.5);
  report.median_px = Percentile(offsets, 0.5);
  report.p90_px = Percentile(offsets, 0.9);
  const double found_fraction = report.dots ? report.found / static_cast<double>(report.dots) : 0;
  if (found_fraction < options.min_found_fraction) {
    report.reason = std::to_string(report.found) + " of " + std::to_string(report.dots) +
                    " dots found where predicted (at least " +
                    std::to_string(static_cast<int>(options.min_found_fraction * 100)) + " %)";
  } else if (report.p90_px > options.threshold_px) {
    report.reason = "dots " + std::to_string(report.p90_px) +
                    " px from their prediction (p90; at most " +
                    std::to_string(options.threshold_px) + " px)";
  } else if (report.wall_dots >= options.min_wall_dots &&
             report.wall_median_px > options.wall_threshold_px) {
    report.reason = "dots on walls " + std::to_string(report.wall_median_px) +
                    " px from their prediction (median of " + std::to_string(report.wall_dots) +
                    "; at most " + std::to_string(options.wall_threshold_px) + " px)";
  } else {
    report.holds = true;
  }
  return report;
}

}  // namespace sandtable::node
