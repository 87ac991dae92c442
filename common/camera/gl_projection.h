// OpenGL projection and view matrices from the pinhole part of a CameraModel.
//
// The renderer draws what a projector shows with the same intrinsics that calibration
// estimated, so a vertex must land on the pixel CameraModel::Project (zero distortion) gives.
// These matrices are double (Eigen); the renderer converts them to float once, through its
// named conversion functions (node/render), and tests/common/camera/gl_projection_test.cc
// bounds what that costs (kFloatVsDouble_px).
//
// Frames.
//   OpenCV device frame ("camera"): x right, y down, z forward (CameraModel's frame).
//   GL eye frame ("gl_eye"): x right, y up, the camera looks down -z.
//   gl_eye_from_camera is a rotation by 180 degrees about x: (x, y, z) -> (x, -y, -z).
// The full chain for a vertex in the table frame is
//   clip = GlProjectionFromCamera(camera, near_m, far_m) * GlEyeFromTable(camera_from_table)
//          * (x_in_table_m, 1)
// Eye coordinates must be in metres (near_m and far_m are); x and y of the projection do not
// depend on the unit, depth does.
//
// NDC to pixels (viewport glViewport(0, 0, width_px, height_px), glDepthRange(0, 1)).
//   GL window coordinates: x_win = (x_ndc + 1) / 2 * width_px, y_win = (y_ndc + 1) / 2 *
//   height_px, origin at the BOTTOM-LEFT corner of the window, pixel (i, j) covers
//   [i, i + 1] x [j, j + 1] so its centre is (i + 0.5, j + 0.5).
//   OpenCV pixels: origin at the TOP-LEFT, pixel (0, 0) centred at (0.0, 0.0), so the image
//   covers [-0.5, width_px - 0.5] x [-0.5, height_px - 0.5].
//   Hence (the half-pixel offset and the vertical flip):
//     u_px = x_win - 0.5                  = (x_ndc + 1) / 2 * width_px - 0.5
//     v_px = height_px - y_win - 0.5      = (1 - y_ndc) / 2 * height_px - 0.5
//   and conversely x_ndc = 2 (u_px + 0.5) / width_px - 1, y_ndc = 1 - 2 (v_px + 0.5) / height_px.
//   Image row v_px = 0 (the top row for OpenCV) is the LAST row glReadPixels returns (GL row
//   height_px - 1); flip rows when reading back into an OpenCV-ordered image.
//   The GL pixel whose centre is hit by the ray of OpenCV pixel (u, v) is window pixel
//   (u, height_px - 1 - v): rasterisation samples at pixel centres, so a fragment is shaded
//   with exactly the ray CameraModel would use for that pixel.
// Depth: a point at z = near_m in the camera frame gets z_ndc = -1, at z = far_m z_ndc = +1
//   (standard GL, w_clip = z in the camera frame); window depth = (z_ndc + 1) / 2.
//
// Distortion is NOT in this matrix: a projective matrix cannot express Brown distortion. The
// renderer draws with this pinhole matrix and then applies a separate pre-warp pass built from
// CameraModel::Distort / Undistort. Only fx, fy, cx, cy, width_px and height_px are used.
//
// Failure: InvalidArgument when camera.Check() fails, near_m <= 0 or not finite, or
// far_m <= near_m or not finite. The message names the value.
#pragma once

#include <Eigen/Core>

#include "common/base/status.h"
#include "common/camera/camera_model.h"
#include "common/geometry/rigid3.h"

namespace sandtable {

// The fixed change of axes from the OpenCV device frame to the GL eye frame, diag(1, -1, -1, 1).
Eigen::Matrix4d GlEyeFromCamera();

// The GL view matrix: gl_eye_from_table = GlEyeFromCamera() * camera_from_table.
Eigen::Matrix4d GlEyeFromTable(const Rigid3d& camera_from_table);

// The GL projection matrix (clip_from_gl_eye) for `camera`'s pinhole intrinsics and image size,
// with clip planes at near_m and far_m (metres, distances along the optical axis).
//   [ 2 fx / W    0           1 - 2 (cx + 0.5) / W    0                 ]
//   [ 0           2 fy / H    2 (cy + 0.5) / H - 1    0                 ]
//   [ 0           0           -(f + n) / (f - n)      -2 f n / (f - n)  ]
//   [ 0           0           -1                      0                 ]
Expected<Eigen::Matrix4d> GlProjectionFromCamera(const CameraModel& camera, double near_m,
                                                 double far_m);

// The viewport transform above, NDC (x, y) -> OpenCV pixel (u, v), and its inverse.
Eigen::Vector2d PixelFromNdc(const Eigen::Vector2d& ndc, int width_px, int height_px);
Eigen::Vector2d NdcFromPixel(const Eigen::Vector2d& pixel, int width_px, int height_px);

}  // namespace sandtable
