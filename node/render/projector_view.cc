#include "node/render/projector_view.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "common/camera/gl_projection.h"

namespace sandtable::node {

Expected<ProjectorView> PrepareProjectorView(const CameraModel& projector,
                                             const Rigid3d& projector_from_table,
                                             const Eigen::AlignedBox3d& scene_bounds) {
  ST_RETURN_IF_ERROR(projector.Check().WithContext("renderer: projector model"));
  ProjectorView view;
  view.projector = projector;
  view.projector_from_table = projector_from_table;
  view.centre_in_table_m = projector_from_table.Inverse().translation;
  // Near and far: the depths of the scene box's corners (in front of the projector).
  double near_m = std::numeric_limits<double>::infinity(), far_m = 0.0;
  if (!scene_bounds.isEmpty()) {
    for (int i = 0; i < 8; ++i) {
      const Eigen::Vector3d corner =
          scene_bounds.corner(static_cast<Eigen::AlignedBox3d::CornerType>(i));
      const double z = (projector_from_table * corner).z();
      near_m = std::min(near_m, z);
      far_m = std::max(far_m, z);
    }
  }
  if (!(far_m > kMinNear_m)) {
    near_m = kMinNear_m;
    far_m = 100.0;
  }
  view.near_m = std::max(kMinNear_m, near_m * (1.0 - kDepthMargin));
  view.far_m = std::max(view.near_m * 2.0, far_m * (1.0 + kDepthMargin));
  Expected<Eigen::Matrix4d> projection = GlProjectionFromCamera(projector, view.near_m, view.far_m);
  if (!projection.ok()) return projection.status().WithContext("renderer");
  view.clip_from_table = *projection * GlEyeFromTable(projector_from_table);

  if (projector.distortion.IsZero()) return view;
  const int w = projector.width_px, h = projector.height_px;
  cv::Mat source(h, w, CV_32FC2);
  double max_displacement = 0.0;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  for (int v = 0; v < h; ++v) {
    auto* row = source.ptr<cv::Vec2f>(v);
    for (int u = 0; u < w; ++u) {
      const Eigen::Vector2d pixel(u, v);
      Expected<Eigen::Vector2d> ideal = projector.Undistort(projector.NormalizedFromPixel(pixel));
      if (!ideal.ok()) {
        row[u] = cv::Vec2f(nan, nan);
        continue;
      }
      const Eigen::Vector2d ideal_px(projector.fx_px * ideal->x() + projector.cx_px,
                                     projector.fy_px * ideal->y() + projector.cy_px);
      max_displacement = std::max(max_displacement, (ideal_px - pixel).norm());
      row[u] = cv::Vec2f(static_cast<float>(ideal_px.x()), static_cast<float>(ideal_px.y()));
    }
  }
  view.max_displacement_px = max_displacement;
  // The lens model's curvature: second differences of Distort over the ideal image, every
  // 16 px, step 8 px.
  const double step_px = 8.0;
  auto distorted_px = [&](const Eigen::Vector2d& ideal_px) {
    return projector.PixelFromNormalized(
        projector.Distort(projector.NormalizedFromPixel(ideal_px)));
  };
  double curvature = 0.0;
  for (int v = 0; v < h; v += 16) {
    for (int u = 0; u < w; u += 16) {
      const Eigen::Vector2d c(u, v);
      const Eigen::Vector2d dc = distorted_px(c);
      for (const Eigen::Vector2d& step :
           {Eigen::Vector2d(step_px, 0), Eigen::Vector2d(0, step_px),
            Eigen::Vector2d(Eigen::Vector2d(step_px, step_px) / std::sqrt(2.0))}) {
        const Eigen::Vector2d second = distorted_px(c + step) - 2.0 * dc + distorted_px(c - step);
        curvature = std::max(curvature, second.norm() / (step_px * step_px));
      }
    }
  }
  view.max_curvature_per_px = curvature;
  // The monotonic domain: bisection on the radius (InDistortionDomain holds on a disc).
  if (!projector.InDistortionDomain(Eigen::Vector2d(10.0, 0.0))) {
    double lo = 0.0, hi = 10.0;
    for (int i = 0; i < 60; ++i) {
      const double mid = 0.5 * (lo + hi);
      (projector.InDistortionDomain(Eigen::Vector2d(mid, 0.0)) ? lo : hi) = mid;
    }
    view.distortion_domain_r2 = lo * lo;
  }
  if (max_displacement >= kSkipDistortion_px) view.source_px = source;
  return view;
}

}  // namespace sandtable::node
