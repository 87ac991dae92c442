#include "sim/transport/world.h"

#include <algorithm>
#include <cmath>

namespace sandtable::sim {

Expected<std::unique_ptr<World>> World::Create(Site site, Scene scene,
                                               const WorldOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  ST_RETURN_IF_ERROR(site.Check());
  std::unique_ptr<World> world(new World());
  world->site_ = std::move(site);
  world->scene_ = std::make_shared<const Scene>(std::move(scene));
  world->options_ = options;
  Expected<std::unique_ptr<RayCaster>> caster =
      RayCaster::Create(world->scene_, options.embree_config);
  if (!caster.ok()) return caster.status();
  world->caster_ = std::move(*caster);
  for (const UnitSpec& unit : world->site_.units) {
    world->frames_.push_back(UniformFrame(unit.projector, 0));
    world->on_.push_back(true);
  }
  return world;
}

Expected<size_t> World::UnitIndex(NodeId unit) const {
  for (size_t i = 0; i < site_.units.size(); ++i) {
    if (site_.units[i].id == unit) return i;
  }
  return NotFoundError("world: no unit " + std::to_string(unit) + " in site '" + site_.name + "'");
}

Status World::SetProjectorFrame(NodeId unit, const cv::Mat& frame) {
  Expected<size_t> index = UnitIndex(unit);
  if (!index.ok()) return index.status();
  const ProjectorSpec& projector = site_.units[*index].projector;
  Expected<LinearFrame> decoded = DecodeProjectorFrame(projector, frame);
  if (!decoded.ok()) return decoded.status().WithContext("unit " + std::to_string(unit));
  frames_[*index] = std::move(*decoded);
  return OkStatus();
}

Status World::SetProjectorUniform(NodeId unit, int value) {
  Expected<size_t> index = UnitIndex(unit);
  if (!index.ok()) return index.status();
  if (value < 0 || value > 255) return InvalidArgumentError("uniform value must be in [0, 255]");
  frames_[*index] = UniformFrame(site_.units[*index].projector, value);
  return OkStatus();
}

Status World::SetProjectorOn(NodeId unit, bool on) {
  Expected<size_t> index = UnitIndex(unit);
  if (!index.ok()) return index.status();
  on_[*index] = on;
  return OkStatus();
}

std::vector<const LinearFrame*> World::CurrentFrames() const {
  std::vector<const LinearFrame*> frames;
  for (size_t i = 0; i < frames_.size(); ++i) frames.push_back(on_[i] ? &frames_[i] : nullptr);
  return frames;
}

Expected<const TransportMap*> World::CameraTransport(NodeId unit) {
  Expected<size_t> index = UnitIndex(unit);
  if (!index.ok()) return index.status();
  const UnitSpec& spec = site_.units[*index];
  if (!spec.camera) return NotFoundError("world: unit " + std::to_string(unit) + " has no camera");
  auto it = camera_maps_.find(unit);
  if (it == camera_maps_.end()) {
    const View view = View::Perspective(spec.camera->model, site_.TableFromCamera(spec));
    Expected<TransportMap> map = BuildTransportMap(site_, *caster_, view, options_.transport);
    if (!map.ok()) return map.status();
    it = camera_maps_.emplace(unit, std::move(*map)).first;
  }
  return &it->second;
}

Expected<cv::Mat> World::Capture(NodeId unit, const CaptureNoise& noise, double exposure_s) {
  if (!std::isfinite(exposure_s) || exposure_s < 0.0) {
    return InvalidArgumentError("capture: exposure_s = " + std::to_string(exposure_s) +
                                " must be finite and >= 0 (0 = the camera's own)");
  }
  Expected<const TransportMap*> map = CameraTransport(unit);
  if (!map.ok()) return map.status();
  ST_RETURN_IF_ERROR(
      GatherLuminance(**map, CurrentFrames(), site_.ambient_luminance_nits, &luminance_scratch_));
  CameraSpec camera = *site_.FindUnit(unit)->camera;
  if (exposure_s > 0.0) camera.exposure_s = exposure_s;
  return SynthesizeCapture(camera, (*map)->width_px, (*map)->height_px, luminance_scratch_, noise);
}

Expected<std::vector<float>> World::RenderLuminance(const View& view) {
  Expected<TransportMap> map = BuildTransportMap(site_, *caster_, view, options_.transport);
  if (!map.ok()) return map.status();
  std::vector<float> luminance;
  ST_RETURN_IF_ERROR(
      GatherLuminance(*map, CurrentFrames(), site_.ambient_luminance_nits, &luminance));
  return luminance;
}

Expected<std::vector<float>> World::RenderLuminanceLit(const View& view,
                                                       const std::vector<NodeId>& lit) {
  std::vector<const LinearFrame*> frames = CurrentFrames();
  if (!lit.empty()) {
    std::vector<bool> keep(frames.size(), false);
    for (NodeId unit : lit) {
      Expected<size_t> index = UnitIndex(unit);
      if (!index.ok()) return index.status();
      keep[*index] = true;
    }
    for (size_t i = 0; i < frames.size(); ++i) {
      if (!keep[i]) frames[i] = nullptr;
    }
  }
  // The view's identity: its size and the rays of its corners (any change of area or pose).
  std::vector<double> key;
  for (int y : {0, view.height_px() - 1}) {
    for (int x : {0, view.width_px() - 1}) {
      Eigen::Vector3d origin, direction;
      if (view.Ray(x, y, &origin, &direction)) {
        key.insert(key.end(), {origin.x(), origin.y(), origin.z(), direction.x(), direction.y(),
                               direction.z()});
      }
    }
  }
  if (!lit_view_map_ || lit_view_width_px_ != view.width_px() ||
      lit_view_height_px_ != view.height_px() || lit_view_key_ != key) {
    Expected<TransportMap> map = BuildTransportMap(site_, *caster_, view, options_.transport);
    if (!map.ok()) return map.status();
    lit_view_map_ = std::move(*map);
    lit_view_width_px_ = view.width_px();
    lit_view_height_px_ = view.height_px();
    lit_view_key_ = key;
  }
  std::vector<float> luminance;
  ST_RETURN_IF_ERROR(
      GatherLuminance(*lit_view_map_, frames, site_.ambient_luminance_nits, &luminance));
  return luminance;
}

Expected<SurfaceTruth> World::TruthAlongRay(const Eigen::Vector3d& origin,
                                            const Eigen::Vector3d& direction) const {
  const std::optional<RayHit> hit = caster_->Intersect(origin, direction);
  if (!hit) return NotFoundError("world: the ray hits no surface");
  SurfaceTruth truth;
  truth.point_in_table_m = hit->point_in_table_m;
  truth.normal_in_table = hit->normal_in_table;  // faces the ray's origin
  truth.triangle = hit->triangle;
  truth.albedo = scene_->AlbedoAt(hit->triangle, hit->u, hit->v);
  truth.luminance_nits = truth.albedo * site_.ambient_luminance_nits;
  for (size_t i = 0; i < site_.units.size(); ++i) {
    const ProjectorSpec& projector = site_.units[i].projector;
    ProjectorTruth p;
    p.unit = site_.units[i].id;
    p.sample = SampleProjector(projector, *caster_, truth.point_in_table_m, truth.normal_in_table);
    if (p.sample.visible && on_[i]) {
      // A point receives the light of the one projector pixel that contains it.
      const int x = std::clamp(static_cast<int>(std::lround(p.sample.pixel_px.x())), 0,
                               projector.model.width_px - 1);
      const int y = std::clamp(static_cast<int>(std::lround(p.sample.pixel_px.y())), 0,
                               projector.model.height_px - 1);
      p.luminance_nits = truth.albedo * projector.peak_luminance_at_1m_nits * p.sample.gain_per_m2 *
                         frames_[i].At(x, y);
    }
    truth.luminance_nits += p.luminance_nits;
    truth.projectors.push_back(p);
  }
  return truth;
}

Expected<ProjectorTruth> World::ProjectorTruthAtPoint(NodeId unit, const Eigen::Vector3d& point,
                                                      double tolerance_m) const {
  Expected<size_t> index = UnitIndex(unit);
  if (!index.ok()) return index.status();
  const ProjectorSpec& projector = site_.units[*index].projector;
  const Eigen::Vector3d centre = projector.table_from_projector.translation;
  // The first surface on the projector's ray towards the point: if it is the point itself,
  // the full truth there (visibility includes facing and the image bounds; the pixel is the
  // projection whether lit or not).
  Expected<SurfaceTruth> truth = TruthAlongRay(centre, point - centre);
  if (truth.ok() && (truth->point_in_table_m - point).norm() <= tolerance_m) {
    return truth->projectors[*index];
  }
  // Shadowed, behind the projector or not on a surface: not lit; the true pixel is the
  // projection where there is one.
  ProjectorTruth out;
  out.unit = unit;
  out.sample = ProjectPoint(projector, point);
  return out;
}

Expected<SurfaceTruth> World::TruthAtTableXY(const Eigen::Vector2d& xy) const {
  return TruthAlongRay(Eigen::Vector3d(xy.x(), xy.y(), 100.0), Eigen::Vector3d(0, 0, -1));
}

cv::Mat LuminanceToImage(const std::vector<float>& luminance, int width, int height,
                         double white_nits) {
  cv::Mat out(height, width, CV_8UC1);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const double l = std::max(0.0, luminance[static_cast<size_t>(y) * width + x] / white_nits);
      out.at<uint8_t>(y, x) =
          static_cast<uint8_t>(std::nearbyint(255.0 * std::min(1.0, std::pow(l, 1.0 / 2.2))));
    }
  }
  return out;
}

}  // namespace sandtable::sim
