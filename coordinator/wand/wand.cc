#include "coordinator/wand/wand.h"

#include <cmath>

#include "proto/convert.h"

namespace sandtable::coordinator {
namespace {

// Hits closer than this to the tip are ignored (a tip resting on a surface still hits it).
constexpr double kMinDistance_m = 1e-9;

}  // namespace

CursorState ComputeCursor(const TrackerSample& sample, const Rigid3d& table_from_tracker,
                          const RayCaster* scene, const WandOptions& options) {
  const Rigid3d table_from_sensor = table_from_tracker * sample.tracker_from_sensor;
  CursorState cursor;
  cursor.tip_in_table_m = table_from_sensor * options.tip_in_sensor_m;
  cursor.direction_in_table = (table_from_sensor.rotation * options.ray_in_sensor).normalized();
  if (scene) {
    cursor.hit = scene->Intersect(cursor.tip_in_table_m, cursor.direction_in_table, kMinDistance_m,
                                  options.max_distance_m);
  }
  cursor.button_pressed = sample.button_pressed;
  cursor.sensor_index = sample.sensor_index;
  return cursor;
}

wire::Cursor ToWire(const CursorState& cursor, int64_t sample_time_ns) {
  wire::Cursor out;
  *out.mutable_tip_in_table_m() = proto::ToWire(cursor.tip_in_table_m);
  *out.mutable_direction_in_table() = proto::ToWire(cursor.direction_in_table);
  out.set_hit(cursor.hit.has_value());
  if (cursor.hit) {
    *out.mutable_hit_in_table_m() = proto::ToWire(cursor.hit->point_in_table_m);
    *out.mutable_normal_in_table() = proto::ToWire(cursor.hit->normal_in_table);
  }
  out.set_sample_time_ns(sample_time_ns);
  out.set_button_pressed(cursor.button_pressed);
  out.set_sensor_index(cursor.sensor_index);
  return out;
}

Status WandOptions::Check() const {
  if (!tip_in_sensor_m.allFinite() || !ray_in_sensor.allFinite() || !(ray_in_sensor.norm() > 0.0)) {
    return InvalidArgumentError("wand: tip and ray finite, the ray non-zero");
  }
  if (!(max_distance_m > 0.0) || !std::isfinite(max_distance_m)) {
    return InvalidArgumentError("wand: max_distance_m must be finite and > 0");
  }
  return OkStatus();
}

}  // namespace sandtable::coordinator
