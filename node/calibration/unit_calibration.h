// A unit's calibration and its file live in common/io/unit_calibration_file.h (one codec for
// every program: the node, the world's factory files, the lab). This header keeps the node's
// names: sandtable::node::UnitCalibration and its functions are those of namespace sandtable.
#pragma once

#include "common/io/unit_calibration_file.h"

namespace sandtable::node {

using ::sandtable::LoadUnitCalibration;
using ::sandtable::ParseUnitCalibration;
using ::sandtable::SaveUnitCalibration;
using ::sandtable::UnitCalibration;
using ::sandtable::UnitCalibrationToJson;

}  // namespace sandtable::node
