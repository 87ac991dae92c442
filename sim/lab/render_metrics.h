// The lab's measurements of the nodes' show (docs/render.md, docs/lab.md):
//
// Grid coincidence: every node shows the table grid (10 cm lines in its calibrated table frame,
// draped on the surfaces); the world's viewer renders the table from above with one projector
// lit at a time (TopViewRequest). Where two projectors overlap, their line images must coincide:
// in every 128 x 128 px patch (1 px ~ 1 mm) both projectors fill with lines in both directions,
// the shift between the two images is measured by normalised cross-correlation of the patch's
// centre within +-16 px (sub-pixel: a parabola through the peak), in mm on the table, on patches
// wholly on the table plane. The shift is what a viewer sees as doubled lines:
// the two projectors' registration errors combined. Patches that a projector covers only in part
// (fewer than 60 % of the line pixels a full patch holds) are left out. Periodic lines alias at the
// 10 cm spacing: shifts beyond half a spacing cannot be measured (far beyond any calibration the
// lab accepts).
//
// Timeline skew: every node logs each frame's node steady time, media time and rate (the render
// log); on one machine every node's steady clock is the same clock, so for instants every 20 ms
// across the span all nodes were playing, each node's media time is extrapolated from its last
// frame before the instant; the skew is the spread (max - min) across nodes, in ms.
//
// Tracks: the lab's personnel tracks (CSV of cluster/personnel_tracks.h): `count` people
// walking loops over the table for `duration_s`.
#pragma once

#include <map>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "common/base/ids.h"
#include "common/base/status.h"

namespace sandtable::sim {

struct TopView {
  cv::Mat luminance;  // CV_32FC1, cd/m^2, row 0 at the north (top) edge
  Eigen::Vector2d area_min_m = Eigen::Vector2d::Zero(), area_max_m = Eigen::Vector2d::Zero();
  double mm_per_px() const {
    return 1e3 * (area_max_m.x() - area_min_m.x()) / std::max(1, luminance.cols);
  }
};

struct GridCoincidence {
  int patches = 0;  // patch pairs measured
  double rms_mm = 0.0, p99_mm = 0.0, max_mm = 0.0;
  std::map<std::pair<NodeId, NodeId>, int> patches_per_pair;
  nlohmann::json ToJson() const;
};

// `views`: one top view per projector (only it lit, showing the grid), same area and size.
// `table_mask` (CV_8UC1, same size, optional): the pixels whose surface from above is the table;
// only patches wholly on the table are measured (walls seen edge-on and roofs at another
// height would mix other surfaces into a patch).
Expected<GridCoincidence> MeasureGridCoincidence(const std::map<NodeId, TopView>& views,
                                                 const cv::Mat& table_mask = cv::Mat());

struct TimelineSkew {
  int instants = 0;
  double p50_ms = 0.0, p99_ms = 0.0, max_ms = 0.0;
  int nodes = 0;
  nlohmann::json ToJson() const;
};

// `logs`: node -> path of its render log (node_steady_ns,media_time_s,playing,frame_ms,rate).
// `clock_offsets_ns`: what the lab made a node's clock read off the machine's (its
// --test-clock-offset-s), taken off its times so that instants compare. NOT_FOUND when fewer
// than two nodes logged frames while playing at the same time.
Expected<TimelineSkew> MeasureTimelineSkew(const std::map<NodeId, std::string>& logs,
                                           const std::map<NodeId, int64_t>& clock_offsets_ns = {});

// Writes the tracks CSV; `area_radius_m` bounds where they walk.
Status WriteLabTracks(const std::string& path, int count, double duration_s, double area_radius_m);

// An 8-bit picture of a luminance image (LuminanceToImage, white = LitWhiteLevel), for the
// report.
cv::Mat LuminancePicture(const cv::Mat& luminance);

}  // namespace sandtable::sim
