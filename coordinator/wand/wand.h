// Wand: from a tracker sample to the cursor on the scene (TR09-017 4.4): the wand pose is
// taken to the table frame with table_from_tracker, its ray (from the tip along the pointing
// axis) is cast against the scene (common/scene RayCaster), giving the cursor point and the
// surface normal (facing the wand).
//
// Conventions (documented in docs/coordinator.md): tip_in_sensor_m is the tip's offset in the
// sensor frame (0 for a sensor at the tip); the pointing axis is ray_in_sensor (default +x of
// the sensor, the Polhemus stylus axis; configurable). Units: metres.
#pragma once

#include <optional>

#include <Eigen/Core>

#include "common/geometry/rigid3.h"
#include "common/scene/ray_caster.h"
#include "coordinator/tracker/tracker_source.h"
#include "proto/events.pb.h"

namespace sandtable::coordinator {

struct WandOptions {
  Eigen::Vector3d tip_in_sensor_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d ray_in_sensor = Eigen::Vector3d::UnitX();
  double max_distance_m = 10.0;
  Status Check() const;
};

struct CursorState {
  Eigen::Vector3d tip_in_table_m = Eigen::Vector3d::Zero();
  Eigen::Vector3d direction_in_table = Eigen::Vector3d::UnitX();  // unit
  std::optional<RayHit> hit;  // closest hit within (0, max_distance_m]; nullopt: none
  bool button_pressed = false;
  uint32_t sensor_index = 0;
};

// `scene` nullptr: no scene (the cursor never hits).
CursorState ComputeCursor(const TrackerSample& sample, const Rigid3d& table_from_tracker,
                          const RayCaster* scene, const WandOptions& options = {});

// The published event (sample_time_ns: coordinator clock).
wire::Cursor ToWire(const CursorState& cursor, int64_t sample_time_ns);

}  // namespace sandtable::coordinator
