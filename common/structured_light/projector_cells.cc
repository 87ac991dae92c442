#include "common/structured_light/projector_cells.h"

#include <algorithm>
#include <cmath>

namespace sandtable {
namespace {

struct CellSums {
  double x = 0.0, y = 0.0, xx = 0.0, yy = 0.0;
  int count = 0;
};

}  // namespace

Status ProjectorCellOptions::Check() const {
  if (projector_width_px < 1 || projector_height_px < 1) {
    return InvalidArgumentError("projector cells: projector size must be positive");
  }
  if (cell_px < 2) return InvalidArgumentError("projector cells: cell_px must be >= 2");
  if (min_support < 3) return InvalidArgumentError("projector cells: min_support must be >= 3");
  if (!(min_support_ratio >= 0.0 && min_support_ratio <= 1.0)) {
    return InvalidArgumentError("projector cells: min_support_ratio must be in [0, 1]");
  }
  return OkStatus();
}

Expected<std::vector<ProjectorGridPoint>> SampleProjectorCells(const Decoding& decoding,
                                                               const ProjectorCellOptions& options,
                                                               ProjectorCellReport* report) {
  ST_RETURN_IF_ERROR(options.Check());
  if (decoding.projector_px.type() != CV_32FC2 || decoding.valid.type() != CV_8UC1 ||
      decoding.projector_px.size() != decoding.valid.size()) {
    return InvalidArgumentError(
        "projector cells: the decoding must be CV_32FC2 positions and a CV_8UC1 mask of one size");
  }
  const int c = options.cell_px;
  const int nx = (options.projector_width_px + c - 1) / c;
  const int ny = (options.projector_height_px + c - 1) / c;
  const int rows = decoding.valid.rows, cols = decoding.valid.cols;
  ProjectorCellReport local;
  auto cell_of = [&](const cv::Vec2f& p) -> int {
    if (!std::isfinite(p[0]) || !std::isfinite(p[1])) return -1;
    const int i = static_cast<int>(std::floor(p[0] / c));
    const int j = static_cast<int>(std::floor(p[1] / c));
    if (i < 0 || j < 0 || i >= nx || j >= ny) return -1;
    return j * nx + i;
  };
  // visit(x, y, cell) for every decoded camera pixel inside a cell.
  auto for_each_decoded = [&](const auto& visit) {
    for (int y = 0; y < rows; ++y) {
      const uint8_t* valid = decoding.valid.ptr<uint8_t>(y);
      const cv::Vec2f* uv = decoding.projector_px.ptr<cv::Vec2f>(y);
      for (int x = 0; x < cols; ++x) {
        if (!valid[x]) continue;
        const int k = cell_of(uv[x]);
        if (k >= 0) visit(x, y, static_cast<size_t>(k));
      }
    }
  };
  std::vector<CellSums> first(static_cast<size_t>(nx) * ny);
  for_each_decoded([&](int x, int y, size_t k) {
    ++local.decoded_pixels;
    CellSums& s = first[k];
    s.x += x;
    s.y += y;
    ++s.count;
  });
  // Second pass: pixels near their cell's first centroid only.
  std::vector<CellSums> sums(first.size());
  for_each_decoded([&](int x, int y, size_t k) {
    const CellSums& f = first[k];
    const double cx = f.x / f.count, cy = f.y / f.count;
    const double limit = 1.5 * std::sqrt(static_cast<double>(f.count)) + 1.0;
    const double dx = x - cx, dy = y - cy;
    if (dx * dx + dy * dy > limit * limit) {
      ++local.stray_pixels;
      return;
    }
    CellSums& s = sums[k];
    s.x += x;
    s.y += y;
    s.xx += static_cast<double>(x) * x;
    s.yy += static_cast<double>(y) * y;
    ++s.count;
  });
  std::vector<ProjectorGridPoint> out;
  std::vector<int> neighbour_counts;
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      const CellSums& s = sums[static_cast<size_t>(j) * nx + i];
      if (s.count == 0) continue;
      ++local.cells_decoded;
      if (s.count < options.min_support) {
        ++local.rejected_support;
        continue;
      }
      neighbour_counts.clear();
      bool four = true;
      for (int dj = -1; dj <= 1; ++dj) {
        for (int di = -1; di <= 1; ++di) {
          if (di == 0 && dj == 0) continue;
          const int a = i + di, b = j + dj;
          const int n = a < 0 || b < 0 || a >= nx || b >= ny
                            ? 0
                            : sums[static_cast<size_t>(b) * nx + a].count;
          if (n > 0) neighbour_counts.push_back(n);
          if ((di == 0 || dj == 0) && n == 0) four = false;
        }
      }
      if (options.require_neighbours && !four) {
        ++local.rejected_neighbours;
        continue;
      }
      if (!neighbour_counts.empty()) {
        auto mid =
            neighbour_counts.begin() + static_cast<std::ptrdiff_t>(neighbour_counts.size() / 2);
        std::nth_element(neighbour_counts.begin(), mid, neighbour_counts.end());
        if (s.count < options.min_support_ratio * *mid) {
          ++local.rejected_support;
          continue;
        }
      }
      const double n = s.count;
      const double mx = s.x / n, my = s.y / n;
      const double spread = std::sqrt(std::max(0.0, s.xx / n - mx * mx + s.yy / n - my * my));
      ProjectorGridPoint p;
      const int u_end = std::min((i + 1) * c, options.projector_width_px);
      const int v_end = std::min((j + 1) * c, options.projector_height_px);
      p.projector_px = Eigen::Vector2f(0.5f * static_cast<float>(i * c + u_end - 1),
                                       0.5f * static_cast<float>(j * c + v_end - 1));
      p.camera_px = Eigen::Vector2f(static_cast<float>(mx), static_cast<float>(my));
      p.fit_rms_px = static_cast<float>(spread);
      p.support = static_cast<uint16_t>(std::min(s.count, 65535));
      out.push_back(p);
      ++local.cells_kept;
    }
  }
  if (report) *report = local;
  return out;
}

}  // namespace sandtable
