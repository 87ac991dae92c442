// `sandtable-node calibrate-unit`: the factory calibration of one unit from chessboard poses
// with their Gray-code captures (docs/unit-calibration.md).
//
//   sandtable-node calibrate-unit --poses DIR -o unit.json [--report report.json]
//       [--board-cols 9] [--board-rows 7] [--square-mm 75]
//       [--projector-width 1024] [--projector-height 768]
//       [--projector-distortion none|k1|k1k2|radial3|full] [--camera-distortion ...]
//       [--dense-points 500] [--dense-weight 1] [--no-cross-validation]
//
// DIR holds capture_0 .. capture_N, each with graycode_00.png .. in OpenCV GrayCodePattern
// order (the procam-kamino410 layout). Flags are parsed by CLI11 (common/cli/command_line.h):
// --help lists them all (exit 0). Returns the process exit code: 0 on success, 1 when
// calibration fails (message on stderr), 2 for bad usage (an unknown flag, a missing --poses or
// -o, a value of the wrong type or out of range: the message names the flag).
#pragma once

#include <string>
#include <vector>

namespace sandtable::node {

// `args` are the arguments after "calibrate-unit".
int RunCalibrateUnit(const std::vector<std::string>& args);

}  // namespace sandtable::node
