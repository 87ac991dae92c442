// The only conversions between wire messages (proto/*.proto) and domain types of common/.
//
// ToWire never fails. FromWire validates untrusted input and returns a Status naming the
// broken field: non-finite numbers, a missing or non-unit quaternion, a camera model that
// fails CameraModel::Check().
#pragma once

#include <Eigen/Core>

#include "common/base/status.h"
#include "common/camera/camera_model.h"
#include "common/geometry/rigid3.h"
#include "proto/geometry.pb.h"

namespace sandtable::proto {

// A quaternion on the wire must have |q| within this of 1 (it is then renormalised).
constexpr double kQuaternionNormTolerance = 1e-6;

wire::Vector3 ToWire(const Eigen::Vector3d& v);
Expected<Eigen::Vector3d> FromWire(const wire::Vector3& v);

wire::Vector2 ToWire(const Eigen::Vector2d& v);
Expected<Eigen::Vector2d> FromWire(const wire::Vector2& v);

wire::Rigid3 ToWire(const Rigid3d& target_from_source);
Expected<Rigid3d> FromWire(const wire::Rigid3& target_from_source);

wire::CameraModel ToWire(const CameraModel& model);
Expected<CameraModel> FromWire(const wire::CameraModel& model);

}  // namespace sandtable::proto
