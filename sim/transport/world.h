// World: the simulated site's physics. Owns the TRUE site and scene, the current frame of every
// projector, a transport map per camera (built on first capture, then reused), viewer renders
// and the ground-truth queries the lab's metrics use. Nodes never see any of this: they only
// receive captures.
// Threading: not thread-safe; the server serialises requests.
#pragma once

#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "common/base/ids.h"
#include "common/base/status.h"
#include "common/scene/ray_caster.h"
#include "common/scene/scene.h"
#include "sim/site/site.h"
#include "sim/transport/capture.h"
#include "sim/transport/transport_map.h"
#include "sim/transport/view.h"

namespace sandtable::sim {

struct WorldOptions {
  TransportOptions transport;
  std::string embree_config;  // e.g. "threads=1"
  Status Check() const { return transport.Check(); }
};

struct ProjectorTruth {
  NodeId unit = kInvalidNodeId;
  ProjectorSample sample;       // true pixel, visibility, gain, blur
  double luminance_nits = 0.0;  // this projector's contribution under its current frame
};

struct SurfaceTruth {
  Eigen::Vector3d point_in_table_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d normal_in_table = Eigen::Vector3d::UnitZ();  // facing the query ray's origin
  int triangle = -1;                                           // hit triangle (Scene::triangles)
  double albedo = 0.0;
  std::vector<ProjectorTruth> projectors;  // site.units order
  double luminance_nits = 0.0;             // all projectors + ambient
};

class World {
 public:
  static Expected<std::unique_ptr<World>> Create(Site site, Scene scene,
                                                 const WorldOptions& options = {});

  const Site& site() const { return site_; }
  const Scene& scene() const { return *scene_; }
  const RayCaster& caster() const { return *caster_; }

  // Frames: CV_8UC1, CV_8UC3 or CV_16UC1 at the projector's resolution (capture.h). Every
  // projector starts black.
  Status SetProjectorFrame(NodeId unit, const cv::Mat& frame);
  Status SetProjectorUniform(NodeId unit, int value);
  // A switched-off (or removed) projector emits nothing, not even its black level.
  Status SetProjectorOn(NodeId unit, bool on);

  // The static transport map of a unit's camera (built on first use).
  Expected<const TransportMap*> CameraTransport(NodeId unit);
  // One camera frame under the current projector frames (see capture.h). `exposure_s` > 0
  // replaces the camera's exposure for this capture (0 = the site's); INVALID_ARGUMENT when
  // it is negative or not finite.
  Expected<cv::Mat> Capture(NodeId unit, const CaptureNoise& noise, double exposure_s = 0.0);
  // Surface luminance (nits) a view sees under the current frames; builds a map each call.
  Expected<std::vector<float>> RenderLuminance(const View& view);
  // The same with only the `lit` projectors on (empty: all that are on), reusing the map of the
  // last view asked for here when the view is the same (an orthographic top view of the same
  // area and size: the lab's repeated top views). INVALID_ARGUMENT for an unknown projector.
  Expected<std::vector<float>> RenderLuminanceLit(const View& view, const std::vector<NodeId>& lit);

  // Ground truth at the first surface hit along a ray (e.g. a projector's TRUE ray through an
  // estimated pixel, or a vertical ray above a table point). NOT_FOUND if the ray hits nothing.
  Expected<SurfaceTruth> TruthAlongRay(const Eigen::Vector3d& origin_in_table_m,
                                       const Eigen::Vector3d& direction) const;
  // The surface seen from straight above table point (x, y).
  Expected<SurfaceTruth> TruthAtTableXY(const Eigen::Vector2d& xy_in_table_m) const;
  // What projector `unit` does at a surface point (ProjectorSample): whether the point has a
  // true pixel (`projectable`: in front of the projector and inside its model's domain; the
  // pixel is then the projection of the point, also when it is outside the image, grazing,
  // facing away or shadowed; behind the projector there is none), whether it lights the point
  // (`visible`: the projector's ray towards the point first meets the surface within
  // `tolerance_m` of it, inside the image, at incidence under 90 degrees), gain, and its
  // luminance contribution under the current frame. NOT_FOUND for an unknown unit.
  Expected<ProjectorTruth> ProjectorTruthAtPoint(NodeId unit,
                                                 const Eigen::Vector3d& point_in_table_m,
                                                 double tolerance_m = 1e-4) const;

 private:
  World() = default;
  Expected<size_t> UnitIndex(NodeId unit) const;
  std::vector<const LinearFrame*> CurrentFrames() const;

  Site site_;
  std::shared_ptr<const Scene> scene_;  // shared with the caster
  std::unique_ptr<RayCaster> caster_;
  WorldOptions options_;
  std::vector<LinearFrame> frames_;  // per unit
  std::vector<bool> on_;
  std::map<NodeId, TransportMap> camera_maps_;
  std::vector<float> luminance_scratch_;
  // RenderLuminanceLit's cached map and the view it was built for.
  std::optional<TransportMap> lit_view_map_;
  int lit_view_width_px_ = 0, lit_view_height_px_ = 0;
  std::vector<double> lit_view_key_;  // reused by Capture (no allocation per frame)
};

// Tone-maps luminance for a person: v = 255 (L / white_nits)^(1/2.2), clamped. CV_8UC1.
cv::Mat LuminanceToImage(const std::vector<float>& luminance_nits, int width_px, int height_px,
                         double white_nits);

}  // namespace sandtable::sim
