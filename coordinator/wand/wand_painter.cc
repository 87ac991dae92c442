#include "coordinator/wand/wand_painter.h"

#include <algorithm>
#include <cmath>
#include <utility>

#include "common/base/check.h"
#include "common/base/units.h"

namespace sandtable::coordinator {
namespace {

void SetVector(const Eigen::Vector3d& v, wire::Vector3* out) {
  out->set_x(v.x());
  out->set_y(v.y());
  out->set_z(v.z());
}

}  // namespace

std::vector<PaletteSwatch> PaletteLayout::DefaultSwatches() {
  return {
      {PaletteTool::kColor, {1.f, 0.f, 0.f}}, {PaletteTool::kColor, {0.f, 1.f, 0.f}},
      {PaletteTool::kColor, {0.f, 0.f, 1.f}}, {PaletteTool::kColor, {1.f, 1.f, 0.f}},
      {PaletteTool::kColor, {1.f, 1.f, 1.f}}, {PaletteTool::kEraser, {0.5f, 0.5f, 0.5f}},
      {PaletteTool::kClear, {0.f, 0.f, 0.f}},
  };
}

Status PaletteLayout::Check() const {
  if (!(inner_radius_m >= 0.0) || !(outer_radius_m > inner_radius_m) ||
      !std::isfinite(outer_radius_m)) {
    return InvalidArgumentError("palette: need 0 <= inner_radius_m < outer_radius_m (finite)");
  }
  if (!(end_angle_deg > start_angle_deg) || end_angle_deg - start_angle_deg > 360.0) {
    return InvalidArgumentError("palette: need start_angle_deg < end_angle_deg <= start + 360");
  }
  for (const PaletteSwatch& s : swatches) {
    if (s.tool == PaletteTool::kColor && !s.color_rgb.allFinite()) {
      return InvalidArgumentError("palette: swatch colours must be finite");
    }
    if ((s.color_rgb.array() < 0.f).any() || (s.color_rgb.array() > 1.f).any()) {
      return InvalidArgumentError("palette: swatch colours must be in [0, 1]");
    }
  }
  return OkStatus();
}

std::optional<size_t> PaletteLayout::SwatchAt(const Eigen::Vector3d& point_in_table_m) const {
  if (swatches.empty()) return std::nullopt;
  const Eigen::Vector2d d = point_in_table_m.head<2>() - center_in_table_m;
  const double r_m = d.norm();
  if (r_m < inner_radius_m || r_m > outer_radius_m) return std::nullopt;
  // Angle brought into [start, start + 360) so segments crossing +-180 deg work.
  double angle_deg = RadToDeg(std::atan2(d.y(), d.x()));
  angle_deg =
      start_angle_deg + std::fmod(std::fmod(angle_deg - start_angle_deg, 360.0) + 360.0, 360.0);
  if (angle_deg > end_angle_deg) return std::nullopt;
  const double fraction = (angle_deg - start_angle_deg) / (end_angle_deg - start_angle_deg);
  return std::min(static_cast<size_t>(fraction * static_cast<double>(swatches.size())),
                  swatches.size() - 1);
}

Eigen::Vector3d PaletteLayout::SwatchCenter(size_t index) const {
  const double span_deg = (end_angle_deg - start_angle_deg) / static_cast<double>(swatches.size());
  const double angle_rad =
      DegToRad(start_angle_deg + (static_cast<double>(index) + 0.5) * span_deg);
  const double r_m = 0.5 * (inner_radius_m + outer_radius_m);
  return Eigen::Vector3d(center_in_table_m.x() + r_m * std::cos(angle_rad),
                         center_in_table_m.y() + r_m * std::sin(angle_rad), 0.0);
}

Status WandPainterOptions::Check() const {
  ST_RETURN_IF_ERROR(palette.Check());
  if (!(width_m > 0.0) || !(min_spacing_m >= 0.0) || !(eraser_radius_m > 0.0) ||
      !std::isfinite(width_m) || !std::isfinite(min_spacing_m) || !std::isfinite(eraser_radius_m)) {
    return InvalidArgumentError(
        "wand painter: width_m and eraser_radius_m must be > 0, min_spacing_m >= 0 (finite)");
  }
  return OkStatus();
}

WandPainter::WandPainter(WandPainterOptions options)
    : options_(std::move(options)), color_rgb_(options_.initial_color_rgb) {
  ST_CHECK(options_.Check().ok()) << options_.Check().ToString();
}

std::vector<wire::AnnotationEvent> WandPainter::OnCursor(const CursorState& cursor,
                                                         uint64_t next_id_floor) {
  std::vector<wire::AnnotationEvent> out;
  const bool down = cursor.button_pressed;
  if (down && !button_was_down_) {
    Press(cursor, next_id_floor, &out);
  } else if (down && active_ && cursor.hit) {
    Hold(cursor.hit->point_in_table_m, /*first=*/false, &out);
  } else if (!down && button_was_down_) {
    Release(&out);
  }
  button_was_down_ = down;
  return out;
}

void WandPainter::Press(const CursorState& cursor, uint64_t next_id_floor,
                        std::vector<wire::AnnotationEvent>* out) {
  active_ = false;
  if (!cursor.hit) return;
  const Eigen::Vector3d& point = cursor.hit->point_in_table_m;
  if (const std::optional<size_t> swatch = options_.palette.SwatchAt(point)) {
    const PaletteSwatch& s = options_.palette.swatches[*swatch];
    switch (s.tool) {
      case PaletteTool::kColor:
        tool_ = PaletteTool::kColor;
        color_rgb_ = s.color_rgb;
        break;
      case PaletteTool::kEraser:
        tool_ = PaletteTool::kEraser;
        break;
      case PaletteTool::kClear:
        out->emplace_back().mutable_clear();
        break;
    }
    return;
  }
  active_ = true;
  if (tool_ == PaletteTool::kColor) {
    last_id_number_ = std::max(last_id_number_ + 1, next_id_floor);
    stroke_id_ = kWandStrokeIdBit | last_id_number_;
    point_count_ = 0;
    wire::StrokeBegin* begin = out->emplace_back().mutable_stroke_begin();
    begin->set_stroke_id(stroke_id_);
    begin->set_color_r(color_rgb_.x());
    begin->set_color_g(color_rgb_.y());
    begin->set_color_b(color_rgb_.z());
    begin->set_width_m(static_cast<float>(options_.width_m));
  }
  Hold(point, /*first=*/true, out);  // the first point (or erase spot) is always taken
}

void WandPainter::Hold(const Eigen::Vector3d& point_in_table_m, bool first,
                       std::vector<wire::AnnotationEvent>* out) {
  if (!first && (point_in_table_m - last_point_in_table_m_).norm() < options_.min_spacing_m) {
    return;
  }
  last_point_in_table_m_ = point_in_table_m;
  if (tool_ == PaletteTool::kColor) {
    wire::StrokePoints* points = out->emplace_back().mutable_stroke_points();
    points->set_stroke_id(stroke_id_);
    points->set_first_point_index(point_count_);
    points->add_points_in_table_m(static_cast<float>(point_in_table_m.x()));
    points->add_points_in_table_m(static_cast<float>(point_in_table_m.y()));
    points->add_points_in_table_m(static_cast<float>(point_in_table_m.z()));
    ++point_count_;
  } else {
    wire::SpotErase* erase = out->emplace_back().mutable_spot_erase();
    SetVector(point_in_table_m, erase->mutable_center_in_table_m());
    erase->set_radius_m(static_cast<float>(options_.eraser_radius_m));
  }
}

void WandPainter::Release(std::vector<wire::AnnotationEvent>* out) {
  if (active_ && stroke_id_ != kInvalidStrokeId) {
    wire::StrokeEnd* end = out->emplace_back().mutable_stroke_end();
    end->set_stroke_id(stroke_id_);
    end->set_point_count(point_count_);
  }
  active_ = false;
  stroke_id_ = kInvalidStrokeId;
  point_count_ = 0;
}

}  // namespace sandtable::coordinator
