// WandPainter: turns the wand's cursor and button into annotation events (TR09-017: painting
// on the model with the wand, a palette on the table's rim).
//
// Per cursor sample (OnCursor), in order:
// - Button goes down with the cursor on a palette swatch: the swatch is applied (colour:
//   selects the colour and the draw tool; eraser: selects the spot eraser; clear: emits one
//   `clear`) and nothing is drawn until the button is released.
// - Button goes down with the cursor on a surface (anywhere else): draw tool: `stroke_begin`
//   with the current colour and width, then `stroke_points` with the hit point; erase tool:
//   `spot_erase` at the hit point (radius eraser_radius_m).
//   Button down while the ray misses: nothing until the button is released and pressed again.
// - Held: each hit point at least min_spacing_m (straight-line, table frame) from the last one
//   used is appended (`stroke_points`, one point per event) or erased (`spot_erase`); closer
//   points and samples whose ray misses are skipped.
// - Released: `stroke_end` with the point count (draw tool).
// The events carry event_sequence 0: the caller submits them to the AnnotationService
// (Submit), which persists before it publishes, like client requests.
//
// Stroke ids: kWandStrokeIdBit | n, where n is larger than every event sequence already in the
// log (next_id_floor, given per begin by the caller) and than the previous wand id, so ids are
// not reused across restarts. Clients are expected to keep their ids below kWandStrokeIdBit.
//
// Palette (PaletteLayout): a ring segment on the table plane around center_in_table_m,
// inner_radius_m <= r <= outer_radius_m, angles (atan2(y, x), degrees, counter-clockwise from
// +x of the table) in [start_angle_deg, end_angle_deg], cut into equal angular swatches in
// order. A hit is on the palette when its xy falls into the segment (z is ignored: the rim is
// the table edge).
#pragma once

#include <optional>
#include <vector>

#include <Eigen/Core>

#include "common/base/ids.h"
#include "common/base/status.h"
#include "coordinator/wand/wand.h"
#include "proto/events.pb.h"

namespace sandtable::coordinator {

constexpr StrokeId kWandStrokeIdBit = StrokeId{1} << 62;

enum class PaletteTool { kColor, kEraser, kClear };

struct PaletteSwatch {
  PaletteTool tool = PaletteTool::kColor;
  // Linear RGB in [0, 1]: the colour selected (kColor) or the swatch's display colour.
  Eigen::Vector3f color_rgb{1.f, 1.f, 1.f};
};

struct PaletteLayout {
  Eigen::Vector2d center_in_table_m = Eigen::Vector2d::Zero();
  double inner_radius_m = 0.90;
  double outer_radius_m = 1.00;
  double start_angle_deg = -120.0;  // front edge (-y) of the table
  double end_angle_deg = -60.0;
  // Default: red, green, blue, yellow, white, eraser, clear-all.
  std::vector<PaletteSwatch> swatches = DefaultSwatches();

  static std::vector<PaletteSwatch> DefaultSwatches();
  Status Check() const;
  // Index of the swatch under `point_in_table_m`, if any.
  std::optional<size_t> SwatchAt(const Eigen::Vector3d& point_in_table_m) const;
  // Centre of swatch `index` (on the mid radius, mid angle), z = 0. For tests and docs.
  Eigen::Vector3d SwatchCenter(size_t index) const;
};

struct WandPainterOptions {
  PaletteLayout palette;
  Eigen::Vector3f initial_color_rgb{1.f, 0.f, 0.f};
  double width_m = 0.005;
  double min_spacing_m = 0.002;
  double eraser_radius_m = 0.02;
  Status Check() const;
};

class WandPainter {
 public:
  explicit WandPainter(WandPainterOptions options = {});

  // Events for one cursor sample (see above). `next_id_floor`: one more than the newest event
  // sequence the log holds (AnnotationStore::last_sequence() + 1).
  std::vector<wire::AnnotationEvent> OnCursor(const CursorState& cursor, uint64_t next_id_floor);

  PaletteTool tool() const { return tool_; }
  const Eigen::Vector3f& color_rgb() const { return color_rgb_; }
  bool drawing() const { return stroke_id_ != kInvalidStrokeId; }

 private:
  void Press(const CursorState& cursor, uint64_t next_id_floor,
             std::vector<wire::AnnotationEvent>* out);
  void Hold(const Eigen::Vector3d& point_in_table_m, bool first,
            std::vector<wire::AnnotationEvent>* out);
  void Release(std::vector<wire::AnnotationEvent>* out);

  WandPainterOptions options_;
  PaletteTool tool_ = PaletteTool::kColor;
  Eigen::Vector3f color_rgb_;
  bool button_was_down_ = false;
  bool active_ = false;  // the current press draws or erases (not a palette press or a miss)
  StrokeId stroke_id_ = kInvalidStrokeId;
  uint64_t last_id_number_ = 0;
  uint32_t point_count_ = 0;
  Eigen::Vector3d last_point_in_table_m_ = Eigen::Vector3d::Zero();
};

}  // namespace sandtable::coordinator
