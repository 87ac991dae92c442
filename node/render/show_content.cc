#include "node/render/show_content.h"

#include <algorithm>
#include <cmath>

#include "common/scene/ray_caster.h"

namespace sandtable::node {
namespace {

// Distinct colours for traces (display RGB).
const Eigen::Vector3f kPalette[] = {{1.0f, 0.35f, 0.1f}, {0.2f, 0.6f, 1.0f}, {0.3f, 0.9f, 0.3f},
                                    {1.0f, 0.9f, 0.2f},  {0.9f, 0.3f, 0.9f}, {0.2f, 0.9f, 0.9f}};

uint64_t Mix(uint64_t h, uint64_t v) { return (h ^ v) * 0x100000001b3ull; }

}  // namespace

Status SunOptions::Check() const {
  if (!std::isfinite(start_hour) || !std::isfinite(hours_per_media_s) ||
      !(max_elevation_deg > 0.0 && max_elevation_deg <= 90.0)) {
    return InvalidArgumentError(
        "sun: start hour and hours per media second must be finite, the "
        "elevation in (0, 90] deg");
  }
  return OkStatus();
}

std::vector<DrapedTrack> DrapeTracks(const cluster::PersonnelTracks& tracks, const Scene* scene,
                                     double lift_m) {
  std::unique_ptr<RayCaster> caster;
  double top_m = 0.0;
  if (scene && scene->NumTriangles() > 0) {
    Expected<std::unique_ptr<RayCaster>> made =
        RayCaster::Create(std::make_shared<const Scene>(*scene));
    if (made.ok()) caster = std::move(*made);
    top_m = scene->Bounds().max().z();
  }
  std::vector<DrapedTrack> out;
  size_t k = 0;
  for (const auto& [id, samples] : tracks.tracks()) {
    DrapedTrack d;
    d.track_id = id;
    d.colour = kPalette[k++ % std::size(kPalette)];
    for (const cluster::TrackSample& s : samples) {
      Eigen::Vector3d p = s.position_in_table_m;
      if (caster) {
        const Eigen::Vector3d from(p.x(), p.y(), top_m + 1.0);
        if (std::optional<RayHit> hit = caster->Intersect(from, -Eigen::Vector3d::UnitZ())) {
          p = hit->point_in_table_m;
        }
      }
      d.t_s.push_back(s.t_s);
      d.points_in_table_m.push_back(p + Eigen::Vector3d(0, 0, lift_m));
    }
    out.push_back(std::move(d));
  }
  return out;
}

std::vector<Polyline> StrokesFromAnnotations(const cluster::AnnotationState& annotations) {
  std::vector<Polyline> out;
  for (const auto& [id, stroke] : annotations.strokes()) {
    Polyline line;
    line.colour = stroke.color_rgb;
    line.width_m = stroke.width_m > 0.f ? stroke.width_m : 0.005;
    for (const Eigen::Vector3f& p : stroke.points_in_table_m) {
      line.points_in_table_m.push_back(p.cast<double>());
    }
    out.push_back(std::move(line));
  }
  return out;
}

RenderContent BuildContent(const ShowInputs& inputs, double media_time_s) {
  RenderContent c;
  c.pattern = inputs.pattern;
  c.projector_id = inputs.projector_id;
  uint64_t version = Mix(0xcbf29ce484222325ull, inputs.strokes_version);
  if (inputs.sun.enabled) {
    c.sun_direction_in_table =
        SunDirection(inputs.sun.start_hour + inputs.sun.hours_per_media_s * media_time_s,
                     inputs.sun.max_elevation_deg);
  }
  if (inputs.strokes) c.strokes = *inputs.strokes;
  if (inputs.cursor) {
    c.markers.push_back(*inputs.cursor);
    const Eigen::Vector3d& p = inputs.cursor->position_in_table_m;
    version = Mix(version, std::hash<double>()(p.x()) ^ std::hash<double>()(p.y() * 3.0) ^
                               std::hash<double>()(p.z() * 7.0));
  }
  if (inputs.tracks) {
    for (const DrapedTrack& track : *inputs.tracks) {
      if (track.t_s.empty() || media_time_s < track.t_s.front()) continue;
      // Samples up to the media time, then the head interpolated between the two around it.
      const size_t upto = static_cast<size_t>(
          std::upper_bound(track.t_s.begin(), track.t_s.end(), media_time_s) - track.t_s.begin());
      Polyline trace;
      trace.colour = track.colour;
      trace.width_m = 0.006;
      trace.points_in_table_m.assign(track.points_in_table_m.begin(),
                                     track.points_in_table_m.begin() + upto);
      Eigen::Vector3d head = track.points_in_table_m[upto - 1];
      if (upto < track.t_s.size()) {
        const double t0 = track.t_s[upto - 1], t1 = track.t_s[upto];
        const double a = t1 > t0 ? (media_time_s - t0) / (t1 - t0) : 0.0;
        head = (1.0 - a) * track.points_in_table_m[upto - 1] + a * track.points_in_table_m[upto];
        trace.points_in_table_m.push_back(head);
      }
      Marker marker;
      marker.position_in_table_m = head;
      marker.colour = track.colour;
      marker.radius_m = 0.015;
      c.traces.push_back(std::move(trace));
      c.markers.push_back(marker);
      version = Mix(version, upto);
      version = Mix(version, std::hash<double>()(head.x()) ^ std::hash<double>()(head.y()));
    }
  }
  c.overlay_version = version;
  return c;
}

}  // namespace sandtable::node
