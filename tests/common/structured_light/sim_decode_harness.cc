#include "tests/common/structured_light/sim_decode_harness.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <sstream>

#include "common/scene/procedural_scene.h"
#include "sim/site/site_presets.h"
#include "sim/transport/transport_map.h"

namespace sandtable::sim_decode {
namespace {

double SecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// A window of the sensor around its centre: same focal length and lens, principal point
// shifted by the cropped margin (pixel (0, 0) of the window is pixel (x0, y0) of the sensor).
Status CropCamera(int width_px, int height_px, sim::CameraSpec* camera) {
  CameraModel& m = camera->model;
  if (width_px <= 0 && height_px <= 0) return OkStatus();
  if (width_px > m.width_px || height_px > m.height_px || width_px <= 0 || height_px <= 0) {
    return InvalidArgumentError("sim decode: camera window " + std::to_string(width_px) + "x" +
                                std::to_string(height_px) + " must fit the " +
                                std::to_string(m.width_px) + "x" + std::to_string(m.height_px) +
                                " sensor");
  }
  const int x0 = (m.width_px - width_px) / 2;
  const int y0 = (m.height_px - height_px) / 2;
  m.cx_px -= x0;
  m.cy_px -= y0;
  m.width_px = width_px;
  m.height_px = height_px;
  return OkStatus();
}

}  // namespace

Expected<SimDecodeWorld> MakeSimDecodeWorld(const SimDecodeSetup& setup) {
  Expected<sim::Site> site = sim::MakeSitePreset(setup.site_preset);
  if (!site.ok()) return site.status();
  if (setup.unit_index < 0 || setup.unit_index >= static_cast<int>(site->units.size())) {
    return InvalidArgumentError("sim decode: unit_index out of range");
  }
  sim::UnitSpec& unit = site->units[setup.unit_index];
  if (!unit.camera) return InvalidArgumentError("sim decode: the unit has no camera");
  ST_RETURN_IF_ERROR(CropCamera(setup.camera_width_px, setup.camera_height_px, &*unit.camera));
  unit.camera->read_noise_dn *= setup.read_noise_scale;
  if (setup.photon_noise_scale > 0)
    unit.camera->full_well_e /= setup.photon_noise_scale;
  else
    unit.camera->full_well_e = 0.0;
  unit.camera->exposure_s *= setup.exposure_scale;

  Expected<ScenePreset> preset = ParseScenePreset(setup.scene_preset);
  if (!preset.ok()) return preset.status();
  ProceduralSceneOptions scene_options;
  scene_options.preset = *preset;
  scene_options.seed = setup.scene_seed;
  Expected<ProceduralScene> scene = MakeProceduralScene(scene_options);
  if (!scene.ok()) return scene.status();

  SimDecodeWorld w;
  w.unit = unit.id;
  w.projector_width_px = unit.projector.model.width_px;
  w.projector_height_px = unit.projector.model.height_px;
  sim::WorldOptions world_options;
  world_options.transport.num_threads = setup.transport_threads;
  Expected<std::unique_ptr<sim::World>> world =
      sim::World::Create(*site, std::move(scene->scene), world_options);
  if (!world.ok()) return world.status();
  w.world = std::move(*world);

  auto start = std::chrono::steady_clock::now();
  Expected<const sim::TransportMap*> map = w.world->CameraTransport(w.unit);
  if (!map.ok()) return map.status();
  w.transport_time_s = SecondsSince(start);

  // Ground truth per camera pixel (the projector spec and caster are the world's own).
  start = std::chrono::steady_clock::now();
  const sim::TransportMap& m = **map;
  const sim::ProjectorSpec& projector = w.world->site().units[setup.unit_index].projector;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  w.truth_px = cv::Mat(m.height_px, m.width_px, CV_32FC2, cv::Scalar(nan, nan));
  w.lit = cv::Mat::zeros(m.height_px, m.width_px, CV_8UC1);
  for (int y = 0; y < m.height_px; ++y) {
    for (int x = 0; x < m.width_px; ++x) {
      const size_t i = static_cast<size_t>(y) * m.width_px + x;
      if (!m.hit[i]) continue;
      const sim::ProjectorSample s =
          sim::SampleProjector(projector, w.world->caster(), m.point_in_table_m[i].cast<double>(),
                               m.normal_in_table[i].cast<double>());
      if (!s.visible) continue;
      w.truth_px.at<cv::Vec2f>(y, x) = cv::Vec2f(s.pixel_px.x(), s.pixel_px.y());
      w.lit.at<uint8_t>(y, x) = 255;
      ++w.lit_pixels;
    }
  }
  // Interior: the whole 3x3 neighbourhood lit and continuous in the projector (an occlusion
  // or shadow edge inside a camera pixel's footprint mixes two surfaces; no decoder can give
  // the centre ray's projector pixel there).
  constexpr float kMaxNeighbourJump_px = 4.0f;
  w.lit_interior = cv::Mat::zeros(m.height_px, m.width_px, CV_8UC1);
  for (int y = 1; y + 1 < m.height_px; ++y) {
    for (int x = 1; x + 1 < m.width_px; ++x) {
      if (!w.lit.at<uint8_t>(y, x)) continue;
      const cv::Vec2f c = w.truth_px.at<cv::Vec2f>(y, x);
      bool ok = true;
      for (int dy = -1; dy <= 1 && ok; ++dy) {
        for (int dx = -1; dx <= 1 && ok; ++dx) {
          if (!w.lit.at<uint8_t>(y + dy, x + dx))
            ok = false;
          else if (cv::norm(w.truth_px.at<cv::Vec2f>(y + dy, x + dx) - c) > kMaxNeighbourJump_px)
            ok = false;
        }
      }
      if (ok) w.lit_interior.at<uint8_t>(y, x) = 255;
    }
  }
  w.truth_time_s = SecondsSince(start);
  return w;
}

Expected<std::vector<cv::Mat>> CaptureSequence(SimDecodeWorld& w,
                                               const std::vector<cv::Mat>& frames, bool noise,
                                               uint64_t noise_seed, double* capture_time_s) {
  const auto start = std::chrono::steady_clock::now();
  for (const sim::UnitSpec& unit : w.world->site().units) {
    if (unit.id != w.unit) ST_RETURN_IF_ERROR(w.world->SetProjectorUniform(unit.id, 0));
  }
  std::vector<cv::Mat> captures;
  captures.reserve(frames.size());
  for (size_t k = 0; k < frames.size(); ++k) {
    ST_RETURN_IF_ERROR(w.world->SetProjectorFrame(w.unit, frames[k]));
    Expected<cv::Mat> image =
        w.world->Capture(w.unit, sim::CaptureNoise{.enabled = noise, .seed = noise_seed + k});
    if (!image.ok()) return image.status();
    if (image->type() != CV_8UC1) {
      return InvalidArgumentError("sim decode: the camera must be 8 bit (the decoder reads 8 bit)");
    }
    captures.push_back(std::move(*image));
  }
  if (capture_time_s != nullptr) *capture_time_s = SecondsSince(start);
  return captures;
}

DecodeErrorStats CompareWithTruth(const SimDecodeWorld& w, const Decoding& decoding,
                                  const cv::Mat& mask) {
  DecodeErrorStats stats;
  std::vector<double> errors;
  double sum_sq = 0, sum_sq_u = 0, sum_sq_v = 0;
  for (int y = 0; y < mask.rows; ++y) {
    for (int x = 0; x < mask.cols; ++x) {
      const bool decoded = decoding.valid.at<uint8_t>(y, x) != 0;
      if (!mask.at<uint8_t>(y, x)) {
        if (decoded && !w.lit.at<uint8_t>(y, x)) ++stats.decoded_unlit_pixels;
        continue;
      }
      ++stats.lit_pixels;
      if (!decoded) continue;
      ++stats.decoded_lit_pixels;
      const cv::Vec2f d = decoding.projector_px.at<cv::Vec2f>(y, x);
      const cv::Vec2f t = w.truth_px.at<cv::Vec2f>(y, x);
      // An axis that was not encoded is NaN in the decoding: it contributes nothing.
      const double du = std::isnan(d[0]) ? 0.0 : d[0] - t[0];
      const double dv = std::isnan(d[1]) ? 0.0 : d[1] - t[1];
      sum_sq_u += du * du;
      sum_sq_v += dv * dv;
      sum_sq += du * du + dv * dv;
      errors.push_back(std::sqrt(du * du + dv * dv));
    }
  }
  const double n = static_cast<double>(errors.size());
  if (n > 0) {
    stats.rms_px = std::sqrt(sum_sq / n);
    stats.rms_u_px = std::sqrt(sum_sq_u / n);
    stats.rms_v_px = std::sqrt(sum_sq_v / n);
    const size_t k99 = std::min(errors.size() - 1, static_cast<size_t>(0.99 * n));
    std::nth_element(errors.begin(), errors.begin() + k99, errors.end());
    stats.p99_px = errors[k99];
    stats.max_px = *std::max_element(errors.begin(), errors.end());
  }
  return stats;
}

std::string DecodeErrorStats::ToString() const {
  std::ostringstream s;
  s << "decoded " << decoded_lit_pixels << " of " << lit_pixels << " lit ("
    << 100.0 * DecodedFraction() << " %), rms " << rms_px << " px (u " << rms_u_px << ", v "
    << rms_v_px << "), p99 " << p99_px << " px, max " << max_px << " px, decoded unlit "
    << decoded_unlit_pixels;
  return s.str();
}

PatternOptions PatternsFor(const SimDecodeWorld& w, PatternOptions base) {
  base.projector_width_px = w.projector_width_px;
  base.projector_height_px = w.projector_height_px;
  return base;
}

}  // namespace sandtable::sim_decode
