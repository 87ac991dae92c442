#include "sim/lab/lab_images.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include <opencv2/imgproc.hpp>

#include "common/base/units.h"

namespace sandtable::sim {

namespace {

Expected<View> TopView(const World& world, int width_px) {
  return View::TopOver(world.scene().Bounds(), width_px, /*height_px=*/0);
}

}  // namespace

Expected<cv::Mat> TopViewWhite(World* world, int width_px) {
  if (width_px < 16) return InvalidArgumentError("top view: width_px must be >= 16");
  for (const UnitSpec& unit : world->site().units) {
    ST_RETURN_IF_ERROR(world->SetProjectorUniform(unit.id, 255));
  }
  Expected<View> view = TopView(*world, width_px);
  if (!view.ok()) return view.status();
  Expected<std::vector<float>> luminance = world->RenderLuminance(*view);
  if (!luminance.ok()) return luminance.status();
  return LuminanceToImage(*luminance, view->width_px(), view->height_px(),
                          LitWhiteLevel(*luminance));
}

double LitWhiteLevel(const std::vector<float>& luminance_nits) {
  std::vector<float> positive;
  for (float l : luminance_nits) {
    if (l > 0) positive.push_back(l);
  }
  if (positive.empty()) return 1.0;
  const size_t k = static_cast<size_t>(0.99 * static_cast<double>(positive.size() - 1));
  std::nth_element(positive.begin(), positive.begin() + static_cast<std::ptrdiff_t>(k),
                   positive.end());
  return std::max(1e-6, static_cast<double>(positive[k]));
}

Expected<cv::Mat> RegistrationHeatmap(const World& world,
                                      const std::vector<EstimatedRegistration>& estimates,
                                      const RegistrationMetricOptions& options, int width_px,
                                      double scale_mm) {
  if (width_px < 16) return InvalidArgumentError("heatmap: width_px must be >= 16");
  if (!(scale_mm > 0) || !std::isfinite(scale_mm)) {
    return InvalidArgumentError("heatmap: scale_mm must be > 0");
  }
  Expected<View> view = TopView(world, width_px);
  if (!view.ok()) return view.status();
  const Site& site = world.site();
  std::vector<int> unit_index;  // estimate -> index in site.units
  for (const EstimatedRegistration& e : estimates) {
    int index = -1;
    for (size_t i = 0; i < site.units.size(); ++i) {
      if (site.units[i].id == e.unit_id) index = static_cast<int>(i);
    }
    if (index < 0) return InvalidArgumentError("heatmap: no unit " + std::to_string(e.unit_id));
    unit_index.push_back(index);
  }
  const double min_cos_incidence = std::cos(DegToRad(options.max_incidence_deg));
  constexpr int kBarHeight_px = 28;
  cv::Mat values(view->height_px(), view->width_px(), CV_8UC1, cv::Scalar(0));
  cv::Mat lit(view->height_px(), view->width_px(), CV_8UC1, cv::Scalar(0));
  for (int y = 0; y < view->height_px(); ++y) {
    for (int x = 0; x < view->width_px(); ++x) {
      Eigen::Vector3d origin, direction;
      if (!view->Ray(x, y, &origin, &direction)) continue;
      Expected<SurfaceTruth> truth = world.TruthAlongRay(origin, direction);
      if (!truth.ok()) continue;
      double worst_mm = -1.0;
      for (size_t k = 0; k < estimates.size(); ++k) {
        const ProjectorTruth& light = truth->projectors[unit_index[k]];
        if (!light.sample.visible) continue;
        const ProjectorSpec& projector = site.units[unit_index[k]].projector;
        const Eigen::Vector3d to_projector =
            projector.table_from_projector.translation - truth->point_in_table_m;
        if (std::abs(truth->normal_in_table.dot(to_projector)) / to_projector.norm() <=
            min_cos_incidence) {
          continue;
        }
        std::optional<RegistrationSample> s =
            RegistrationErrorAt(projector, estimates[k], options.true_table_from_model,
                                truth->point_in_table_m, truth->normal_in_table);
        if (s) worst_mm = std::max(worst_mm, s->error_mm);
      }
      if (worst_mm < 0) continue;
      lit.at<uint8_t>(y, x) = 1;
      values.at<uint8_t>(y, x) =
          static_cast<uint8_t>(std::lround(255.0 * std::min(1.0, worst_mm / scale_mm)));
    }
  }
  cv::Mat colour;
  cv::applyColorMap(values, colour, cv::COLORMAP_VIRIDIS);
  colour.setTo(cv::Scalar(64, 64, 64), lit == 0);
  // The colour bar: 0 .. scale_mm left to right, labelled.
  cv::Mat bar(kBarHeight_px, view->width_px(), CV_8UC1);
  for (int x = 0; x < bar.cols; ++x) {
    bar.col(x).setTo(cv::Scalar(255.0 * x / std::max(1, bar.cols - 1)));
  }
  cv::Mat bar_colour;
  cv::applyColorMap(bar, bar_colour, cv::COLORMAP_VIRIDIS);
  char label[64];
  std::snprintf(label, sizeof(label), "0 .. %.2f mm (worst projector per point)", scale_mm);
  cv::putText(bar_colour, label, cv::Point(6, kBarHeight_px - 9), cv::FONT_HERSHEY_SIMPLEX, 0.45,
              cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
  cv::Mat out;
  cv::vconcat(colour, bar_colour, out);
  return out;
}

}  // namespace sandtable::sim
