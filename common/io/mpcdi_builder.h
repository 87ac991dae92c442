// The site's MPCDI export from the project's own types: one region per projector unit (profile
// sl, level 1, one buffer), its frustum and coordinate frame from the unit's calibration, its
// warp grid by casting each sample pixel's ray into the scene. The file conventions are
// mpcdi.h's; here is how our frames map onto them.
//
// Frames: the scene and table_from_projector are in the table frame (docs/frames.md: +z up,
// metres); the projector frame is OpenCV's (x right, y down, z forward), which is MPCDI's viewer
// frame. The MPCDI world is the table frame:
//  * coordinateFrame (the same for every region, MpcdiTableCoordinateFrame): pos = the
//    projector's optical centre in the table frame, metres; yaw axis (0, 0, -1), pitch axis
//    (1, 0, 0), roll axis (0, 1, 0): the zero-rotation viewer looks along table +y, right = +x,
//    down = -z (Christie's "surveyor" frame);
//  * frustum yaw/pitch/roll: table_from_projector's rotation in that basis (SetMpcdiOrientation:
//    yaw = heading about the vertical, + turns from +y toward +x; pitch = elevation, a projector
//    looking down at the table has pitch < 0, straight down is -90; roll about the optical axis);
//  * frustum edge angles from the intrinsics alone (ideal pinhole, pixel-centre convention):
//    rightAngle = atan((width_px - 0.5 - cx_px) / fx_px), leftAngle = -atan((cx_px + 0.5) / fx_px),
//    upAngle = atan((cy_px + 0.5) / fy_px), downAngle = -atan((height_px - 0.5 - cy_px) / fy_px);
//    a principal point off centre makes them asymmetric;
//  * warp: samples_x = max(2, ceil(width_px / warp_step_px)) (likewise y); sample (i, j) is
//    projector pixel ((i + 0.5) width_px / samples_x - 0.5, (j + 0.5) height_px / samples_y - 0.5)
//    (MPCDI's fill layout); its ray (CameraModel::Unproject, so the lens distortion is in the
//    warp) is cast from the optical centre; the sample holds the closest hit in the table frame,
//    metres (geometricUnit m, originOf3DData unknown: the table frame's origin is a corner of the
//    table top, none of MPCDI's named origins), NaN when the ray hits nothing or cannot be
//    undistorted (past the lens model's fold).
//  * alpha: the unit's, or 255 everywhere at the projector's resolution until blending fills it.
// Cost: one ray per sample, cast as one coherent Embree batch per projector (80 x 50 rays for a
// 1280x800 projector at the default 16 px).
#pragma once

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "common/base/status.h"
#include "common/camera/camera_model.h"
#include "common/geometry/rigid3.h"
#include "common/io/mpcdi.h"
#include "common/io/unit_calibration_file.h"
#include "common/scene/ray_caster.h"
#include "common/scene/scene.h"

namespace sandtable {

struct MpcdiBuildOptions {
  int warp_step_px = 16;  // warp grid spacing in projector pixels, >= 1
  std::string buffer_id = "sandtable";
  std::string date;  // MpcdiSite::date (empty: the time of writing)
  Status Check() const;
};

struct MpcdiUnit {
  std::string region_id;               // empty: "unit-<unit_id>"
  UnitCalibration calibration;         // projector and table_from_projector are used
  std::optional<MpcdiBlendMap> alpha;  // empty: 255 everywhere at the projector's resolution
};

// The table frame as an MPCDI coordinate frame, with the projector's centre as position.
MpcdiCoordinateFrame MpcdiTableCoordinateFrame(const Eigen::Vector3d& projector_centre_in_table_m);

// Edge angles from the intrinsics and yaw/pitch/roll from the pose (see above).
MpcdiFrustum MpcdiFrustumFromProjector(const CameraModel& projector,
                                       const Rigid3d& table_from_projector);

// The warp grid of one projector (see above). INVALID_ARGUMENT for an invalid model or pose or
// a grid over kMaxMpcdiWarpSamples.
Expected<MpcdiWarp> ComputeMpcdiWarp(const CameraModel& projector,
                                     const Rigid3d& table_from_projector, const RayCaster& caster,
                                     int warp_step_px);

// The site of the given units, ready for WriteMpcdi. INVALID_ARGUMENT naming the unit when a
// calibration fails its Check, has no table_from_projector, or a region id is unusable or
// repeated; the buffer's resolution is the projectors' when they all share one (else omitted).
Expected<MpcdiSite> BuildMpcdiSite(const std::vector<MpcdiUnit>& units, const RayCaster& caster,
                                   const MpcdiBuildOptions& options = {});
// The same over a scene (builds its ray caster; UNAVAILABLE / INVALID_ARGUMENT as
// RayCaster::Create).
Expected<MpcdiSite> BuildMpcdiSite(const std::vector<MpcdiUnit>& units,
                                   std::shared_ptr<const Scene> scene,
                                   const MpcdiBuildOptions& options = {});

}  // namespace sandtable
