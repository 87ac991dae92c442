// Projector-grid correspondences: a dense decoding (camera pixel -> projector px) turned into
// the camera position of regularly spaced projector pixels, the form self-calibration needs:
// a projector pixel is then one 3D point seen by the projector (exactly, at the grid node) and
// by every camera that decoded it, so tracks across cameras are keyed by the grid node alone.
//
// Method (one pass over the camera image, then one small solve per node):
//   Grid nodes sit at (offset + i * step, offset + j * step) projector px, i, j >= 0, inside
//   the projector image. Every decoded camera pixel c with projector position p is assigned to
//   its nearest node n; when |p - n| (max norm) <= support_radius_px it adds to that node's
//   least-squares fit of the local affine inverse map
//       c = c_n + A (p - n)              (c_n: 2, A: 2x2, six unknowns)
//   The node's camera position is c_n, the fit's intercept: the decoded positions around the
//   node are used symmetrically, so the decoder's per-pixel noise averages out (by about the
//   square root of the support) and the affine term absorbs the local slope. A node is kept
//   when it has at least min_support pixels, the 3x3 normal matrix is well conditioned (the
//   support surrounds the node, not a line beside it) and the fit's rms residual in camera px
//   is at most max_fit_rms_px (a support straddling a depth edge does not fit one plane).
//   A camera that sees the projector coarsely (a camera pixel spanning 2.5 projector px or
//   more: a 1920-wide projector seen by a 700 px focal length camera from beside it) puts fewer
//   than min_support pixels inside support_radius_px of any node. Such a node is fitted on its
//   wide support instead, the pixels within wide_support_radius_px (at most half the step, so
//   supports never overlap): the same fit and the same checks on a larger square. A camera is
//   coarse when its median node holds fewer than 2 min_support pixels in the small support; a
//   fine camera's nodes never take the wide support (its nodes short of pixels lie at the rim
//   of what it sees, where a wider support would reach across the edge), nor do nodes with
//   enough pixels in the small one.
// Frames and units: camera px and projector px, pixel (0,0) centred at (0.0, 0.0).
// Errors: INVALID_ARGUMENT for a decoding that is not CV_32FC2 + CV_8UC1 of one size, or bad
// options (Check()). Cost: O(camera pixels + nodes), single-threaded.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "common/base/status.h"
#include "common/structured_light/decoder.h"

namespace sandtable {

struct ProjectorGridOptions {
  int projector_width_px = 1280;
  int projector_height_px = 800;
  double step_px = 16.0;           // grid spacing, projector px (> 0)
  double offset_px = 8.0;          // first node, projector px (>= 0)
  double support_radius_px = 3.0;  // max-norm radius of a node's support, projector px
  // The wide support for nodes with too few pixels in the small one (>= 0; used as clamped to
  // [support_radius_px, step_px / 2]; support_radius_px or less: none).
  double wide_support_radius_px = 7.5;
  int min_support = 6;           // decoded camera pixels per node, at least (>= 3)
  double max_fit_rms_px = 0.75;  // affine fit residual, camera px
  Status Check() const;
};

struct ProjectorGridPoint {
  Eigen::Vector2f projector_px;  // the grid node
  Eigen::Vector2f camera_px;     // where the camera sees it (sub-pixel)
  float fit_rms_px = 0.0f;       // affine fit residual, camera px
  uint16_t support = 0;          // decoded camera pixels used
};

struct ProjectorGridReport {
  int64_t decoded_pixels = 0;     // valid pixels in the decoding
  int64_t supporting_pixels = 0;  // of those, within a node's support radius
  int nodes_with_support = 0;
  int nodes_kept = 0;
  int rejected_support = 0, rejected_conditioning = 0, rejected_fit = 0;
  int nodes_on_wide_support = 0;  // of the kept nodes, fitted on the wide support
};

Expected<std::vector<ProjectorGridPoint>> SampleProjectorGrid(
    const Decoding& decoding, const ProjectorGridOptions& options,
    ProjectorGridReport* report = nullptr);

}  // namespace sandtable
