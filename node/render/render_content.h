// What one frame shows besides the model: the operator's test pattern, the virtual sun, the
// annotation strokes, the wand cursor and the replayed personnel tracks. Filled by the node's
// render loop from the coordinator's events (node/render/render_loop.h) and by tests directly.
// Frames: every point in the table frame, metres. Colours: display (sRGB-encoded) RGB in [0, 1].
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace sandtable::node {

enum class TestPattern {
  kNone,         // the show: the model, lit, with strokes, cursor and traces
  kProjectorId,  // the unit's id in large digits (raw, no warp or mask)
  kTableGrid,    // lines every grid spacing in table x and y, on every surface, through the
                 // full pipeline (shows the registration across projectors)
  kWhite,        // white on the model through the full pipeline (shows blending)
  kRawWhite,     // every pixel at 255, nothing else
  kColourBars,   // eight vertical bars (raw)
  kBlack,        // black on the model through the full pipeline: each projector's black
                 // level, plus the blend's black-level lift where the site matches black
};

// "none", "id", "grid", "white", "raw-white", "bars", "black" (the names on the command line and
// wire).
const char* TestPatternName(TestPattern pattern);
std::optional<TestPattern> TestPatternFromName(const std::string& name);

struct Polyline {
  std::vector<Eigen::Vector3d> points_in_table_m;
  Eigen::Vector3f colour{1.0f, 1.0f, 1.0f};
  double width_m = 0.01;
};

struct Marker {
  Eigen::Vector3d position_in_table_m = Eigen::Vector3d::Zero();
  Eigen::Vector3f colour{1.0f, 1.0f, 0.0f};
  double radius_m = 0.02;
  bool ring = false;  // a ring (the cursor) rather than a disc (a track's head)
};

struct RenderContent {
  TestPattern pattern = TestPattern::kNone;
  uint32_t projector_id = 0;  // for kProjectorId
  // Towards the sun, table frame, unit length; nullopt: no virtual sun (the model's own
  // colours, unlit). A sun below the horizon (z <= 0) lights nothing: ambient only.
  std::optional<Eigen::Vector3d> sun_direction_in_table;
  std::vector<Polyline> strokes;  // annotations
  std::vector<Polyline> traces;   // personnel tracks up to the current media time
  std::vector<Marker> markers;    // track heads and the wand cursor
  // Changes whenever strokes, traces or markers change: the renderer rebuilds their geometry
  // only then (and when the projector view changes).
  uint64_t overlay_version = 0;
  // Tests and diagnostics: the scene writes each fragment's table position (metres) as its
  // colour, through the pre-warp; needs a float output (OutputFormat::kRgba32f).
  bool debug_positions = false;
  bool has_overlay() const { return !strokes.empty() || !traces.empty() || !markers.empty(); }
};

// The virtual sun at `time_of_day_h` (0..24): rises in the east (+x) at 6 h, culminates in
// the south (-y) at 12 h at `max_elevation_deg`, sets in the west at 18 h; below the horizon
// outside that. Returns the unit vector towards the sun (z <= 0 at night).
Eigen::Vector3d SunDirection(double time_of_day_h, double max_elevation_deg = 60.0);

}  // namespace sandtable::node
