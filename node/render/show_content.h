// ShowContent: what the show puts on the model at a media time, from what the coordinator
// published (node/events) and what the node loaded: the annotation strokes, the wand's cursor,
// the personnel tracks drawn as coloured traces up to the media time with a head marker (TR09-017
// Figure 8), the virtual sun for the time of day the media time stands for, and the operator's
// test pattern. The render loop evaluates it for every frame at the frame's media time, so
// every node draws the same moment.
//
// Traces lie on the surfaces: every track sample is draped at load (DrapeTracks) onto the
// highest surface of the model under it (a ray cast straight down), so a trace runs over the
// table and over the roofs it crosses, as seen from above.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <vector>

#include "cluster/annotation_state.h"
#include "cluster/personnel_tracks.h"
#include "common/scene/scene.h"
#include "node/render/render_content.h"

namespace sandtable::node {

struct SunOptions {
  bool enabled = true;
  double start_hour = 9.0;          // time of day at media time 0
  double hours_per_media_s = 0.05;  // time of day advanced per media second (3 h a minute)
  double max_elevation_deg = 60.0;
  Status Check() const;
  bool operator==(const SunOptions&) const = default;
};

struct DrapedTrack {
  uint32_t track_id = 0;
  std::vector<double> t_s;
  std::vector<Eigen::Vector3d> points_in_table_m;  // draped
  Eigen::Vector3f colour;
};

// The tracks draped onto `scene` (table frame; a point over no surface keeps its z), lifted by
// `lift_m`. Colours from a fixed palette by track order.
std::vector<DrapedTrack> DrapeTracks(const cluster::PersonnelTracks& tracks, const Scene* scene,
                                     double lift_m = 0.002);

// The inputs at one moment; cheap to copy (shared, immutable parts).
struct ShowInputs {
  TestPattern pattern = TestPattern::kNone;
  uint32_t projector_id = 0;
  std::shared_ptr<const std::vector<Polyline>> strokes;
  uint64_t strokes_version = 0;
  std::optional<Marker> cursor;
  std::shared_ptr<const std::vector<DrapedTrack>> tracks;
  SunOptions sun;
  bool timeline_known = false;  // false: no clock yet (media time 0, not playing)
};

// The content at media time `media_time_s`. `overlay_version` changes with every change of what
// the overlay shows (strokes, cursor, the traces' extent).
RenderContent BuildContent(const ShowInputs& inputs, double media_time_s);

// Strokes as the renderer draws them (colour, width, points).
std::vector<Polyline> StrokesFromAnnotations(const cluster::AnnotationState& annotations);

}  // namespace sandtable::node
