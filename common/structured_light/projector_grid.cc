#include "common/structured_light/projector_grid.h"

#include <algorithm>
#include <cmath>
#include <string>

#include <Eigen/Dense>

namespace sandtable {
namespace {

// Normal equations of c = c_n + A d over features f = (1, dx, dy): F^T F (symmetric 3x3) and
// F^T c for both camera axes, plus sum |c|^2 for the residual.
struct NodeSums {
  double ff[6] = {0, 0, 0, 0, 0, 0};  // (0,0) (0,1) (0,2) (1,1) (1,2) (2,2)
  double fx[3] = {0, 0, 0};
  double fy[3] = {0, 0, 0};
  double cc = 0.0;
  int count = 0;
  void Add(double dx, double dy, double x, double y) {
    ff[0] += 1.0;
    ff[1] += dx;
    ff[2] += dy;
    ff[3] += dx * dx;
    ff[4] += dx * dy;
    ff[5] += dy * dy;
    fx[0] += x;
    fx[1] += dx * x;
    fx[2] += dy * x;
    fy[0] += y;
    fy[1] += dx * y;
    fy[2] += dy * y;
    cc += x * x + y * y;
    ++count;
  }
};

}  // namespace

Status ProjectorGridOptions::Check() const {
  if (projector_width_px < 1 || projector_height_px < 1) {
    return InvalidArgumentError("projector grid: projector size must be positive");
  }
  if (!(step_px > 0.0) || !std::isfinite(step_px)) {
    return InvalidArgumentError("projector grid: step_px must be > 0");
  }
  if (!(offset_px >= 0.0) || !std::isfinite(offset_px)) {
    return InvalidArgumentError("projector grid: offset_px must be >= 0");
  }
  if (!(support_radius_px > 0.0) || support_radius_px >= step_px) {
    return InvalidArgumentError("projector grid: support_radius_px must be in (0, step_px)");
  }
  if (!(wide_support_radius_px >= 0.0) || !std::isfinite(wide_support_radius_px)) {
    return InvalidArgumentError("projector grid: wide_support_radius_px must be >= 0");
  }
  if (min_support < 3) return InvalidArgumentError("projector grid: min_support must be >= 3");
  if (!(max_fit_rms_px > 0.0)) {
    return InvalidArgumentError("projector grid: max_fit_rms_px must be > 0");
  }
  return OkStatus();
}

Expected<std::vector<ProjectorGridPoint>> SampleProjectorGrid(const Decoding& decoding,
                                                              const ProjectorGridOptions& options,
                                                              ProjectorGridReport* report) {
  ST_RETURN_IF_ERROR(options.Check());
  if (decoding.projector_px.type() != CV_32FC2 || decoding.valid.type() != CV_8UC1 ||
      decoding.projector_px.size() != decoding.valid.size()) {
    return InvalidArgumentError(
        "projector grid: the decoding must be CV_32FC2 positions and a CV_8UC1 mask of one size");
  }
  const int nx = static_cast<int>(std::floor(
                     (options.projector_width_px - 0.5 - options.offset_px) / options.step_px)) +
                 1;
  const int ny = static_cast<int>(std::floor(
                     (options.projector_height_px - 0.5 - options.offset_px) / options.step_px)) +
                 1;
  ProjectorGridReport local;
  std::vector<ProjectorGridPoint> out;
  if (nx <= 0 || ny <= 0) {
    if (report) *report = local;
    return out;
  }
  std::vector<NodeSums> sums(static_cast<size_t>(nx) * ny);
  const double r = options.support_radius_px;
  const double wide_r =
      std::max(r, std::min(options.wide_support_radius_px, 0.5 * options.step_px));
  std::vector<NodeSums> wide_sums(wide_r > r ? sums.size() : 0);
  const double inv_step = 1.0 / options.step_px;
  for (int y = 0; y < decoding.valid.rows; ++y) {
    const uint8_t* valid = decoding.valid.ptr<uint8_t>(y);
    const cv::Vec2f* p = decoding.projector_px.ptr<cv::Vec2f>(y);
    for (int x = 0; x < decoding.valid.cols; ++x) {
      if (!valid[x]) continue;
      ++local.decoded_pixels;
      const double u = p[x][0], v = p[x][1];
      if (!std::isfinite(u) || !std::isfinite(v)) continue;
      const long i = std::lround((u - options.offset_px) * inv_step);
      const long j = std::lround((v - options.offset_px) * inv_step);
      if (i < 0 || j < 0 || i >= nx || j >= ny) continue;
      const double dx = u - (options.offset_px + i * options.step_px);
      const double dy = v - (options.offset_px + j * options.step_px);
      const double distance = std::max(std::abs(dx), std::abs(dy));
      if (distance > wide_r) continue;
      const size_t node = static_cast<size_t>(j) * nx + i;
      if (!wide_sums.empty()) wide_sums[node].Add(dx, dy, x, y);
      if (distance > r) continue;
      ++local.supporting_pixels;
      sums[node].Add(dx, dy, x, y);
    }
  }
  // A coarse camera: the median node holds fewer than twice min_support pixels in its small
  // support. Only then do nodes short of pixels take their wide support; a fine camera's nodes
  // short of pixels lie at the edges of what it sees (a footprint's rim, an occlusion), where
  // a wider support would reach across the edge.
  std::vector<int> inner_counts;
  for (const NodeSums& s : sums) {
    if (s.count > 0) inner_counts.push_back(s.count);
  }
  bool coarse = false;
  if (!wide_sums.empty() && !inner_counts.empty()) {
    std::nth_element(inner_counts.begin(), inner_counts.begin() + inner_counts.size() / 2,
                     inner_counts.end());
    coarse = inner_counts[inner_counts.size() / 2] < 2 * options.min_support;
  }
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      const size_t node = static_cast<size_t>(j) * nx + i;
      const bool wide = coarse && sums[node].count < options.min_support &&
                        wide_sums[node].count >= options.min_support;
      const NodeSums& s = wide ? wide_sums[node] : sums[node];
      if (s.count == 0) continue;
      ++local.nodes_with_support;
      if (s.count < options.min_support) {
        ++local.rejected_support;
        continue;
      }
      // The support is a square of side 2r; a well-surrounded node has second moments of
      // about r^2 / 3 per axis. Less than a tenth of that in some direction: a sliver.
      const double support_r = wide ? wide_r : r;
      const double min_eigen = 0.1 * support_r * support_r / 3.0;
      Eigen::Matrix3d m;
      m << s.ff[0], s.ff[1], s.ff[2], s.ff[1], s.ff[3], s.ff[4], s.ff[2], s.ff[4], s.ff[5];
      // Conditioning of the slope part: covariance of (dx, dy) about their mean.
      const double n = s.ff[0];
      Eigen::Matrix2d cov;
      cov << s.ff[3] / n - (s.ff[1] / n) * (s.ff[1] / n),
          s.ff[4] / n - (s.ff[1] / n) * (s.ff[2] / n), 0.0,
          s.ff[5] / n - (s.ff[2] / n) * (s.ff[2] / n);
      cov(1, 0) = cov(0, 1);
      if (Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d>(cov, Eigen::EigenvaluesOnly)
              .eigenvalues()
              .minCoeff() < min_eigen) {
        ++local.rejected_conditioning;
        continue;
      }
      const Eigen::LDLT<Eigen::Matrix3d> ldlt(m);
      const Eigen::Vector3d bx(s.fx[0], s.fx[1], s.fx[2]);
      const Eigen::Vector3d by(s.fy[0], s.fy[1], s.fy[2]);
      const Eigen::Vector3d ax = ldlt.solve(bx);
      const Eigen::Vector3d ay = ldlt.solve(by);
      // Residual sum of squares of a least-squares fit: sum c^2 - a^T F^T c per axis.
      const double rss = std::max(0.0, s.cc - ax.dot(bx) - ay.dot(by));
      const double dof = std::max(1, 2 * s.count - 6);
      const double rms = std::sqrt(rss / dof);
      if (!(rms <= options.max_fit_rms_px) || !ax.allFinite() || !ay.allFinite()) {
        ++local.rejected_fit;
        continue;
      }
      ProjectorGridPoint point;
      point.projector_px =
          Eigen::Vector2f(static_cast<float>(options.offset_px + i * options.step_px),
                          static_cast<float>(options.offset_px + j * options.step_px));
      point.camera_px = Eigen::Vector2f(static_cast<float>(ax[0]), static_cast<float>(ay[0]));
      point.fit_rms_px = static_cast<float>(rms);
      point.support = static_cast<uint16_t>(std::min(s.count, 65535));
      out.push_back(point);
      local.nodes_on_wide_support += wide;
    }
  }
  local.nodes_kept = static_cast<int>(out.size());
  if (report) *report = local;
  return out;
}

}  // namespace sandtable
