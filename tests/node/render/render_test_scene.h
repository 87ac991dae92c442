// A small scene and a calibrated projector for the renderer's tests and benchmark: a textured
// table (1.2 x 0.8 m, checker imagery), a red box building and a grey tower, seen by a
// projector 1.4 m above the table looking down at a slant.
#pragma once

#include "common/camera/camera_model.h"
#include "common/geometry/rigid3.h"
#include "common/scene/scene.h"

namespace sandtable::testing {

Scene RenderTestScene();
// The projector at `size` (intrinsics scale with it), with or without Brown distortion.
CameraModel RenderTestProjector(int width_px, int height_px, bool distortion);
Rigid3d RenderTestProjectorFromTable();

}  // namespace sandtable::testing
