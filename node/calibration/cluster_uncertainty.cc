#include "node/calibration/cluster_uncertainty.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <string>
#include <utility>

#include <ceres/ceres.h>
#include <Eigen/Eigenvalues>

#include "common/estimation/reduced_information.h"

namespace sandtable::node {
namespace {

using RowMajor = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// Words for each parameter of a unit's blocks. The pose's angle-axis components are named as
// one group: away from the identity they are not rotations about fixed axes.
const char* const kPoseNames[] = {"pose rotation",
                                  "pose rotation",
                                  "pose rotation",
                                  "pose shift along the projector's x",
                                  "pose shift along the projector's y",
                                  "distance along the optical axis"};
const char* const kIntrinsicNames[] = {"focal fx", "focal fy", "principal point cx",
                                       "principal point cy"};
const char* const kDistortionNames[] = {"k1", "k2", "p1", "p2", "k3"};
const char* const kMountNames[] = {"mount rotation", "mount rotation", "mount rotation",
                                   "mount x",        "mount y",        "mount z"};

std::string Percent(double share) { return std::to_string(std::lround(share * 100.0)) + " %"; }

Eigen::MatrixXd SqrtPsd(const Eigen::MatrixXd& c) {
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(c);
  const Eigen::VectorXd root = eig.eigenvalues().cwiseMax(0.0).cwiseSqrt();
  return eig.eigenvectors() * root.asDiagonal() * eig.eigenvectors().transpose();
}

// What a displacement field over the samples' pixels looks like in the projector image: a
// shift, a scale or a rotation about the samples' centre, or a warp (what is left). The three
// fitted fields are orthogonal over centred pixels, so their energies add up.
std::string DescribeField(const std::vector<Eigen::Vector2d>& px,
                          const std::vector<Eigen::Vector2d>& d) {
  const size_t n = px.size();
  if (n == 0) return "none";
  Eigen::Vector2d centre = Eigen::Vector2d::Zero(), shift = Eigen::Vector2d::Zero();
  for (size_t i = 0; i < n; ++i) {
    centre += px[i] / static_cast<double>(n);
    shift += d[i] / static_cast<double>(n);
  }
  double spread = 0.0, scale = 0.0, rotation = 0.0, total = 0.0;
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector2d q = px[i] - centre;
    const Eigen::Vector2d perp(-q.y(), q.x());
    spread += q.squaredNorm();
    scale += q.dot(d[i]);
    rotation += perp.dot(d[i]);
    total += d[i].squaredNorm();
  }
  if (!(total > 0)) return "none";
  const double e_shift = static_cast<double>(n) * shift.squaredNorm();
  const double e_scale = spread > 0 ? scale * scale / spread : 0.0;
  const double e_rotation = spread > 0 ? rotation * rotation / spread : 0.0;
  const double e_warp = std::max(0.0, total - e_shift - e_scale - e_rotation);
  const std::pair<double, std::string> kinds[] = {
      {e_shift, std::string("the image shifts (") +
                    (std::abs(shift.x()) >= std::abs(shift.y()) ? "along x" : "along y") + ")"},
      {e_scale, "the image grows or shrinks"},
      {e_rotation, "the image turns"},
      {e_warp, "the image warps (keystone, distortion)"}};
  const auto& top =
      *std::max_element(std::begin(kinds), std::end(kinds),
                        [](const auto& a, const auto& b) { return a.first < b.first; });
  return top.second + ", " + Percent(top.first / total) + " of it";
}

struct UnitColumns {
  std::vector<int> columns;        // into the reduced information
  std::vector<std::string> names;  // one per column
  std::vector<double*> blocks;     // pose, projector k, projector d (those with columns)
  std::vector<int> block_offset;   // first index into `columns` of each block
};

}  // namespace

Status PredictUnitErrors(const ceres::Problem& problem,
                         const std::map<NodeId, UnitParameterBlocks>& units,
                         std::span<double* const> points,
                         const std::vector<ObservationBlock>& observations,
                         const BundleOptions& options, BundleReport* report,
                         std::map<NodeId, std::vector<PredictedSample>>* predicted) {
  std::vector<double*> kept;
  // Column names for the undetermined directions.
  std::map<const double*, std::pair<NodeId, const char* const*>> names;
  for (const auto& [id, u] : units) {
    const std::pair<double*, const char* const*> blocks[] = {{u.pose, kPoseNames},
                                                             {u.mount, kMountNames},
                                                             {u.projector_k, kIntrinsicNames},
                                                             {u.projector_d, kDistortionNames},
                                                             {u.camera_k, kIntrinsicNames},
                                                             {u.camera_d, kDistortionNames}};
    for (const auto& [block, n] : blocks) {
      kept.push_back(block);
      names[block] = {id, n};
    }
  }
  Expected<ReducedInformation> info = ComputeReducedInformation(problem, kept, points);
  if (!info.ok()) return info.status();
  const int parameters = static_cast<int>(info->information.rows());

  // The noise from the data (whitened residuals, so sigma2 = 1 means observation_sigma_px).
  double sum_sq = 0.0;
  int residuals = 0;
  for (const ObservationBlock& o : observations) {
    double cost = 0.0, v[2];
    problem.EvaluateResidualBlock(o.id, false, &cost, v, nullptr);
    sum_sq += v[0] * v[0] + v[1] * v[1];
    residuals += 2;
  }
  const int redundancy = residuals - 3 * info->eliminated_blocks - parameters;
  if (redundancy <= 0) {
    return DegenerateError("uncertainty: " + std::to_string(residuals) + " residuals for " +
                           std::to_string(3 * info->eliminated_blocks + parameters) + " unknowns");
  }
  const double sigma2 = sum_sq / redundancy;
  report->sigma_px = std::sqrt(sigma2) * options.observation_sigma_px;
  const MarginalCovariance marginal = InvertInformation(info->information, sigma2);

  std::vector<std::string> column_name(parameters);
  for (const auto& [block, column] : info->column) {
    const auto& [id, n] = names.at(block);
    const bool camera = block == units.at(id).camera_k || block == units.at(id).camera_d;
    for (int i = 0; i < info->size.at(block); ++i) {
      column_name[column + i] = "unit " + std::to_string(id) + (camera ? " camera " : " ") + n[i];
    }
  }
  if (!marginal.undetermined.empty()) {
    std::ostringstream text;
    text << marginal.undetermined.size() << " direction(s) the data do not fix:";
    for (const Eigen::VectorXd& v : marginal.undetermined) {
      std::vector<int> order(parameters);
      for (int i = 0; i < parameters; ++i) order[i] = i;
      std::sort(order.begin(), order.end(),
                [&](int a, int b) { return std::abs(v[a]) > std::abs(v[b]); });
      text << " (";
      for (int k = 0; k < std::min(3, parameters); ++k) {
        text << (k ? ", " : "") << column_name[order[k]];
      }
      text << ")";
    }
    report->undetermined = text.str();
  }

  for (const auto& [id, u] : units) {
    UnitColumns cols;
    const std::pair<double*, const char* const*> blocks[] = {
        {u.pose, kPoseNames}, {u.projector_k, kIntrinsicNames}, {u.projector_d, kDistortionNames}};
    for (const auto& [block, n] : blocks) {
      const auto c = info->column.find(block);
      if (c == info->column.end()) continue;
      cols.blocks.push_back(block);
      cols.block_offset.push_back(static_cast<int>(cols.columns.size()));
      for (int i = 0; i < info->size.at(block); ++i) {
        cols.columns.push_back(c->second + i);
        cols.names.push_back(n[i]);
      }
    }
    const int k = static_cast<int>(cols.columns.size());
    std::vector<const ObservationBlock*> own;
    for (const ObservationBlock& o : observations) {
      if (!o.camera && o.unit == id) own.push_back(&o);
    }
    if (k == 0 || own.empty()) continue;
    Eigen::MatrixXd c(k, k);
    for (int a = 0; a < k; ++a)
      for (int b = 0; b < k; ++b) c(a, b) = marginal.covariance(cols.columns[a], cols.columns[b]);
    const size_t step = std::max<size_t>(1, own.size() / std::max(1, options.uncertainty_samples));
    std::vector<PredictedSample>& samples = (*predicted)[id];
    std::vector<Eigen::MatrixXd> jacobians;
    std::vector<Eigen::Vector2d> pixels;
    Eigen::MatrixXd metric = Eigen::MatrixXd::Zero(k, k);
    for (size_t i = 0; i < own.size(); i += step) {
      const ObservationBlock& o = *own[i];
      std::vector<double*> in_block;
      problem.GetParameterBlocksForResidualBlock(o.id, &in_block);
      std::vector<RowMajor> jac(in_block.size());
      std::vector<double*> pointers(in_block.size(), nullptr);
      for (size_t b = 0; b < in_block.size(); ++b) {
        if (std::find(cols.blocks.begin(), cols.blocks.end(), in_block[b]) == cols.blocks.end())
          continue;
        jac[b].resize(2, problem.ParameterBlockTangentSize(in_block[b]));
        pointers[b] = jac[b].data();
      }
      double cost = 0.0, v[2];
      if (!problem.EvaluateResidualBlock(o.id, false, &cost, v, pointers.data())) continue;
      Eigen::MatrixXd j(2, k);
      for (size_t b = 0; b < in_block.size(); ++b) {
        if (!pointers[b]) continue;
        const size_t which = static_cast<size_t>(
            std::find(cols.blocks.begin(), cols.blocks.end(), in_block[b]) - cols.blocks.begin());
        j.middleCols(cols.block_offset[which], jac[b].cols()) =
            jac[b] * options.observation_sigma_px;  // un-whitened: px per unit parameter
      }
      PredictedSample s;
      s.point = o.point;
      s.px_covariance = j * c * j.transpose();
      samples.push_back(s);
      metric += j.transpose() * j;
      jacobians.push_back(j);
      pixels.push_back(o.projector_px);
    }
    if (samples.empty()) continue;
    metric /= static_cast<double>(samples.size());
    // The direction carrying most of the pixel variance: C^1/2 M C^1/2's largest eigenvector.
    const Eigen::MatrixXd root = SqrtPsd(c);
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(root * metric * root);
    const double total = eig.eigenvalues().cwiseMax(0.0).sum();
    UnitBundleReport& unit = report->units[id];
    unit.predicted_rms_px = std::sqrt(total);
    if (!(total > 0)) continue;
    const Eigen::VectorXd direction = root * eig.eigenvectors().col(k - 1);
    unit.weak_share = std::clamp(eig.eigenvalues()[k - 1] / total, 0.0, 1.0);
    std::vector<Eigen::Vector2d> field;
    for (const Eigen::MatrixXd& j : jacobians) field.push_back(j * direction);
    // The parameters moving it most (by their share of the pixel motion), names merged.
    std::map<std::string, double> by_name;
    for (int p = 0; p < k; ++p) {
      by_name[cols.names[p]] += std::abs(direction[p]) * std::sqrt(metric(p, p));
    }
    std::vector<std::pair<double, std::string>> ranked;
    for (const auto& [name, w] : by_name) ranked.push_back({w, name});
    std::sort(ranked.rbegin(), ranked.rend());
    std::string movers = ranked[0].second;
    if (ranked.size() > 1 && ranked[1].first > 0.3 * ranked[0].first)
      movers += " with " + ranked[1].second;
    unit.weak_direction = DescribeField(pixels, field) + ": " + movers;
  }
  return OkStatus();
}

Status TablePredictionOptions::Check() const {
  if (!(max_height_m > 0) || min_table_samples < 1) {
    return InvalidArgumentError("table prediction: max_height_m must be > 0, samples >= 1");
  }
  return OkStatus();
}

void PredictOnTable(const BundleReport& report,
                    const std::map<NodeId, std::vector<PredictedSample>>& predicted,
                    const std::vector<Eigen::Vector3d>& points_in_table_m,
                    std::map<NodeId, UnitCalibration>* calibrations,
                    const TablePredictionOptions& options) {
  for (auto& [id, calibration] : *calibrations) {
    const auto unit = report.units.find(id);
    const auto samples = predicted.find(id);
    if (unit == report.units.end() || unit->second.predicted_rms_px < 0 ||
        samples == predicted.end() || !calibration.table_from_projector) {
      continue;
    }
    PredictedErrorRecord record;
    record.rms_px = unit->second.predicted_rms_px;
    record.sigma_px = report.sigma_px;
    record.weak_direction = unit->second.weak_direction;
    record.weak_share = unit->second.weak_share;
    record.undetermined = report.undetermined;
    const Rigid3d& table_from_projector = *calibration.table_from_projector;
    const Rigid3d projector_from_table = table_from_projector.Inverse();
    const CameraModel& projector = calibration.projector;
    double sum_sq_m2 = 0.0;
    int n = 0;
    for (const PredictedSample& s : samples->second) {
      if (s.point < 0 || s.point >= static_cast<int>(points_in_table_m.size())) continue;
      const Eigen::Vector3d& x = points_in_table_m[s.point];
      if (std::abs(x.z()) > options.max_height_m) continue;
      const std::optional<Eigen::Vector2d> u = projector.Project(projector_from_table * x);
      if (!u) continue;
      // Where pixels about u land on the plane z = x.z (table frame).
      constexpr double kStep_px = 0.5;
      auto land = [&](const Eigen::Vector2d& pixel) -> std::optional<Eigen::Vector3d> {
        Expected<Eigen::Vector3d> ray = projector.Unproject(pixel);
        if (!ray.ok()) return std::nullopt;
        const Eigen::Vector3d d = table_from_projector.rotation * *ray;
        const Eigen::Vector3d& origin = table_from_projector.translation;
        if (std::abs(d.z()) < 1e-9) return std::nullopt;
        const double t = (x.z() - origin.z()) / d.z();
        if (!(t > 0)) return std::nullopt;
        return origin + t * d;
      };
      const auto p0 = land(*u), px = land(*u + Eigen::Vector2d(kStep_px, 0)),
                 py = land(*u + Eigen::Vector2d(0, kStep_px));
      if (!p0 || !px || !py) continue;
      Eigen::Matrix<double, 3, 2> a;
      a.col(0) = (*px - *p0) / kStep_px;
      a.col(1) = (*py - *p0) / kStep_px;
      sum_sq_m2 += (a * s.px_covariance * a.transpose()).trace();
      ++n;
    }
    record.samples = n;
    if (n >= options.min_table_samples) record.rms_mm = std::sqrt(sum_sq_m2 / n) * 1e3;
    calibration.predicted_error = record;
  }
}

}  // namespace sandtable::node
