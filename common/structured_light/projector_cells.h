// Projector-cell correspondences: a Gray-code-only decoding (no phase shift) turned into the
// camera position of the centre of every projector cell, the correspondences of the planar
// calibration path (docs/calibration.md, "Planar sites").
//
// A Gray code with `skip` least significant bits left out names cells of c = 2^skip projector
// px. Every camera pixel that decodes to cell (i, j) lies in the image of that cell; the
// centroid of those pixels is the image of the cell's centre up to second order in c (an
// affine map keeps centroids; perspective and lens distortion bend a 16 px cell by far less
// than a hundredth of a pixel), and it averages the decoder's per-pixel noise over the whole
// cell: with ~100 camera px per cell, the stripe edges' misclassified pixels move the centroid
// by a few hundredths of a pixel.
//
// Method: one pass accumulates, per cell, the pixel count and the sums of x and y; a second
// pass drops pixels farther than 1.5 sqrt(count) camera px from the first centroid (stray
// decodes) and accumulates again. A cell is kept when its support is at least min_support and
// at least min_support_ratio times the median of its decoded 8-neighbours, and its 4 neighbours
// are decoded (when require_neighbours): cells cut by the footprint's edge, the camera's view,
// a shadow or an occluding edge lose pixels and would bias the centroid.
// Frames and units: camera px and projector px, pixel (0,0) centred at (0.0, 0.0). A cell
// (i, j) covers projector pixels [i c, min((i+1) c, W) - 1] x [j c, ...]; its centre is the
// middle of that range (the last cell of an axis may be narrower).
// Errors: INVALID_ARGUMENT for a decoding that is not CV_32FC2 + CV_8UC1 of one size, or bad
// options (Check()). Cost: two passes over the camera image, single-threaded.
#pragma once

#include <vector>

#include "common/base/status.h"
#include "common/structured_light/decoder.h"
#include "common/structured_light/projector_grid.h"

namespace sandtable {

struct ProjectorCellOptions {
  int projector_width_px = 1280;
  int projector_height_px = 800;
  int cell_px = 16;  // 2^gray_lsb_skip of the pattern (>= 2)
  int min_support = 6;
  double min_support_ratio = 0.75;  // of the median support of the decoded 8-neighbours
  bool require_neighbours = true;   // the 4 neighbours decoded
  Status Check() const;
};

struct ProjectorCellReport {
  int64_t decoded_pixels = 0;
  int64_t stray_pixels = 0;  // dropped in the second pass
  int cells_decoded = 0;
  int cells_kept = 0;
  int rejected_support = 0, rejected_neighbours = 0;
};

// ProjectorGridPoint per kept cell: projector_px = the cell's centre, camera_px = the centroid,
// support = the pixels used (saturated at 65535), fit_rms_px = the rms distance of those pixels
// from the centroid (the cell's size in the camera).
Expected<std::vector<ProjectorGridPoint>> SampleProjectorCells(
    const Decoding& decoding, const ProjectorCellOptions& options,
    ProjectorCellReport* report = nullptr);

}  // namespace sandtable
