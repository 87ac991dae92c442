#include "node/calibration/cluster_uncertainty.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <string>
#include <unordered_map>
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

}  // namespace

Expected<BundleUncertainty> EstimateUncertainty(const ceres::Problem& problem,
                                                const std::map<NodeId, UnitParameterBlocks>& units,
                                                std::span<double* const> points,
                                                const std::vector<ObservationBlock>& observations,
                                                const BundleOptions& options,
                                                BundleReport* report) {
  std::vector<double*> kept;
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
  // The noise from the data. The whitened residuals' sum of squares over the redundancy is the
  // variance factor when every observation is as noisy as its weight says; when the projector
  // pixels are exact (grid nodes), their rows carry no noise and the cameras' carry all of it:
  // E[RSS] = sum (1 - h_ii) d_i with d = 0 on projector rows; with the leverage h spread evenly
  // over the rows, d_camera = RSS / redundancy x rows / camera rows.
  double sum_sq = 0.0;
  int rows = 0, camera_rows = 0;
  for (const ObservationBlock& o : observations) {
    double cost = 0.0, v[2];
    problem.EvaluateResidualBlock(o.id, false, &cost, v, nullptr);
    sum_sq += v[0] * v[0] + v[1] * v[1];
    rows += 2;
    if (o.camera) camera_rows += 2;
  }
  int unknowns = 3 * static_cast<int>(points.size());
  for (double* block : kept) {
    if (problem.HasParameterBlock(block) && !problem.IsParameterBlockConstant(block))
      unknowns += problem.ParameterBlockTangentSize(block);
  }
  const int redundancy = rows - unknowns;
  if (redundancy <= 0 || camera_rows == 0) {
    return DegenerateError("uncertainty: " + std::to_string(rows) + " residuals for " +
                           std::to_string(unknowns) + " unknowns");
  }
  const double factor = sum_sq / redundancy;
  const double camera_variance = options.projector_px_exact ? factor * rows / camera_rows : factor;
  const double projector_variance = options.projector_px_exact ? 0.0 : factor;
  std::unordered_map<ceres::ResidualBlockId, double> variance;
  for (const ObservationBlock& o : observations) {
    variance[o.id] = o.camera ? camera_variance : projector_variance;
  }
  report->sigma_px = std::sqrt(camera_variance) * options.observation_sigma_px;
  Expected<ReducedInformation> info =
      ComputeReducedInformation(problem, kept, points, [&](ceres::ResidualBlockId id) {
        const auto it = variance.find(id);
        return it == variance.end() ? 1.0 : it->second;  // priors, surface: as weighted
      });
  if (!info.ok()) return info.status();
  const int parameters = static_cast<int>(info->information.rows());
  MarginalCovariance marginal = SandwichCovariance(*info);

  BundleUncertainty out;
  out.column_names.resize(parameters);
  for (const auto& [block, column] : info->column) {
    const auto& [id, n] = names.at(block);
    const bool camera = block == units.at(id).camera_k || block == units.at(id).camera_d;
    for (int i = 0; i < info->size.at(block); ++i) {
      out.column_names[column + i] =
          "unit " + std::to_string(id) + (camera ? " camera " : " ") + n[i];
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
        text << (k ? ", " : "") << out.column_names[order[k]];
      }
      text << ")";
    }
    report->undetermined = text.str();
  }
  out.covariance = std::move(marginal.covariance);

  for (const auto& [id, u] : units) {
    std::vector<double*> blocks;
    std::vector<int> offsets, columns;
    for (double* block : {u.pose, u.projector_k, u.projector_d}) {
      const auto c = info->column.find(block);
      if (c == info->column.end()) continue;
      blocks.push_back(block);
      offsets.push_back(static_cast<int>(columns.size()));
      for (int i = 0; i < info->size.at(block); ++i) columns.push_back(c->second + i);
    }
    std::vector<const ObservationBlock*> own;
    for (const ObservationBlock& o : observations) {
      if (!o.camera && o.unit == id) own.push_back(&o);
    }
    if (columns.empty() || own.empty()) continue;
    const int k = static_cast<int>(columns.size());
    out.unit_columns[id] = columns;
    const size_t step = std::max<size_t>(1, own.size() / std::max(1, options.uncertainty_samples));
    std::vector<PredictedSample>& samples = out.samples[id];
    for (size_t i = 0; i < own.size(); i += step) {
      const ObservationBlock& o = *own[i];
      std::vector<double*> in_block;
      problem.GetParameterBlocksForResidualBlock(o.id, &in_block);
      std::vector<RowMajor> jac(in_block.size());
      std::vector<double*> pointers(in_block.size(), nullptr);
      std::vector<int> where(in_block.size(), -1);
      for (size_t b = 0; b < in_block.size(); ++b) {
        const auto at = std::find(blocks.begin(), blocks.end(), in_block[b]);
        if (at == blocks.end()) continue;
        where[b] = offsets[static_cast<size_t>(at - blocks.begin())];
        jac[b].resize(2, problem.ParameterBlockTangentSize(in_block[b]));
        pointers[b] = jac[b].data();
      }
      double cost = 0.0, v[2];
      if (!problem.EvaluateResidualBlock(o.id, false, &cost, v, pointers.data())) continue;
      PredictedSample s;
      s.point = o.point;
      s.projector_px = o.projector_px;
      s.jacobian = Eigen::MatrixXd::Zero(2, k);
      for (size_t b = 0; b < in_block.size(); ++b) {
        if (where[b] < 0) continue;
        // Un-whitened: px per unit of the parameter.
        s.jacobian.middleCols(where[b], jac[b].cols()) = jac[b] * options.observation_sigma_px;
      }
      samples.push_back(std::move(s));
    }
  }
  return out;
}

double BundleGaugeRms_px(const BundleUncertainty& uncertainty, NodeId unit) {
  const auto columns = uncertainty.unit_columns.find(unit);
  const auto samples = uncertainty.samples.find(unit);
  if (columns == uncertainty.unit_columns.end() || samples == uncertainty.samples.end() ||
      samples->second.empty()) {
    return -1.0;
  }
  const std::vector<int>& cols = columns->second;
  const int k = static_cast<int>(cols.size());
  Eigen::MatrixXd c(k, k);
  for (int a = 0; a < k; ++a)
    for (int b = 0; b < k; ++b) c(a, b) = uncertainty.covariance(cols[a], cols[b]);
  double sum = 0.0;
  for (const PredictedSample& s : samples->second) {
    sum += (s.jacobian * c * s.jacobian.transpose()).trace();
  }
  return std::sqrt(sum / static_cast<double>(samples->second.size()));
}

Status TablePredictionOptions::Check() const {
  if (!(max_height_m > 0) || min_table_samples < 1) {
    return InvalidArgumentError("table prediction: max_height_m must be > 0, samples >= 1");
  }
  return OkStatus();
}

namespace {

// One sample carried to the table.
struct TableSample {
  NodeId unit = kInvalidNodeId;
  const PredictedSample* sample = nullptr;
  Eigen::Vector3d point = Eigen::Vector3d::Zero();   // table frame, m
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();  // its projector's centre, table frame
  Eigen::Matrix<double, 3, 2> landing;               // m per px
  Eigen::Matrix<double, 2, 3> landing_inverse;       // px per m (pseudo-inverse)
};

std::optional<TableSample> ToTable(NodeId id, const PredictedSample& s,
                                   const UnitCalibration& calibration,
                                   const std::vector<Eigen::Vector3d>& points_in_table_m,
                                   double max_height_m) {
  if (s.point < 0 || s.point >= static_cast<int>(points_in_table_m.size())) return std::nullopt;
  const Eigen::Vector3d& x = points_in_table_m[s.point];
  if (std::abs(x.z()) > max_height_m) return std::nullopt;
  const Rigid3d& table_from_projector = *calibration.table_from_projector;
  const CameraModel& projector = calibration.projector;
  const std::optional<Eigen::Vector2d> u = projector.Project(table_from_projector.Inverse() * x);
  if (!u) return std::nullopt;
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
  if (!p0 || !px || !py) return std::nullopt;
  TableSample t;
  t.unit = id;
  t.sample = &s;
  t.point = x;
  t.centre = table_from_projector.translation;
  t.landing.col(0) = (*px - *p0) / kStep_px;
  t.landing.col(1) = (*py - *p0) / kStep_px;
  const Eigen::Matrix2d ata = t.landing.transpose() * t.landing;
  if (!(std::abs(ata.determinant()) > 0)) return std::nullopt;
  t.landing_inverse = ata.inverse() * t.landing.transpose();
  return t;
}

}  // namespace

void PredictOnTable(const BundleReport& report, const BundleUncertainty& uncertainty,
                    const std::vector<Eigen::Vector3d>& points_in_table_m,
                    std::map<NodeId, UnitCalibration>* calibrations,
                    const TablePredictionOptions& options) {
  std::vector<TableSample> table;
  for (const auto& [id, samples] : uncertainty.samples) {
    const auto c = calibrations->find(id);
    if (c == calibrations->end() || !c->second.table_from_projector) continue;
    for (const PredictedSample& s : samples) {
      std::optional<TableSample> t =
          ToTable(id, s, c->second, points_in_table_m, options.max_height_m);
      if (t) table.push_back(*t);
    }
  }
  const int n = static_cast<int>(table.size());
  const int p = static_cast<int>(uncertainty.covariance.rows());
  if (n == 0 || p == 0) return;
  // L: landing displacement per parameter; M: the site's motion (translation, rotation about
  // the samples' centre, and scale about it when the model set the scale).
  const int motions = options.scale_follows_the_model ? 7 : 6;
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  for (const TableSample& t : table) centre += t.point / n;
  Eigen::MatrixXd l = Eigen::MatrixXd::Zero(3 * n, p), m = Eigen::MatrixXd::Zero(3 * n, motions);
  for (int i = 0; i < n; ++i) {
    const TableSample& t = table[i];
    const std::vector<int>& cols = uncertainty.unit_columns.at(t.unit);
    const Eigen::MatrixXd lj = t.landing * t.sample->jacobian;
    for (size_t k = 0; k < cols.size(); ++k) l.block(3 * i, cols[k], 3, 1) = lj.col(k);
    // The motion moves the surface point by D = G g; the unit's ray through it then lands
    // D_n d / d_n away (d: the ray's direction, n = z) while the point itself moved by D: the
    // error it makes is (d n^T / d_n - I) D, in the plane. (A motion off the plane becomes an
    // in-plane error along each unit's own ray.)
    const Eigen::Vector3d r = t.point - centre;
    Eigen::Matrix<double, 3, 7> g = Eigen::Matrix<double, 3, 7>::Zero();
    g.block<3, 3>(0, 0).setIdentity();
    g.block<3, 3>(0, 3) << 0, r.z(), -r.y(), -r.z(), 0, r.x(), r.y(), -r.x(), 0;  // w x r
    g.block<3, 1>(0, 6) = r;
    const Eigen::Vector3d d = (t.point - t.centre).normalized();
    Eigen::Matrix3d along_ray = Eigen::Matrix3d::Zero();
    if (std::abs(d.z()) > 1e-9) along_ray.col(2) = d / d.z();
    m.middleRows(3 * i, 3) = ((along_ray - Eigen::Matrix3d::Identity()) * g).leftCols(motions);
  }
  const Eigen::MatrixXd e = l - m * (m.transpose() * m).ldlt().solve(m.transpose() * l);
  const Eigen::MatrixXd& c = uncertainty.covariance;
  const Eigen::MatrixXd root = SqrtPsd(c);

  std::map<NodeId, std::vector<int>> by_unit;
  for (int i = 0; i < n; ++i) by_unit[table[i].unit].push_back(i);
  for (const auto& [id, rows] : by_unit) {
    const int count = static_cast<int>(rows.size());
    if (count < options.min_table_samples) continue;
    double sum_m2 = 0.0, sum_px2 = 0.0;
    Eigen::MatrixXd metric = Eigen::MatrixXd::Zero(p, p);
    for (int i : rows) {
      const Eigen::MatrixXd ei = e.middleRows(3 * i, 3);
      const Eigen::Matrix3d spread = ei * c * ei.transpose();
      sum_m2 += spread.trace();
      sum_px2 += (table[i].landing_inverse * spread * table[i].landing_inverse.transpose()).trace();
      const Eigen::MatrixXd epx = table[i].landing_inverse * ei;
      metric += epx.transpose() * epx;
    }
    metric /= count;
    PredictedErrorRecord record;
    record.rms_mm = std::sqrt(sum_m2 / count) * 1e3;
    record.rms_px = std::sqrt(sum_px2 / count);
    record.samples = count;
    record.sigma_px = report.sigma_px;
    record.undetermined = report.undetermined;
    // The direction carrying most of the pixel variance: C^1/2 N C^1/2's largest eigenvector.
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(root * metric * root);
    const double total = eig.eigenvalues().cwiseMax(0.0).sum();
    if (total > 0) {
      const Eigen::VectorXd direction = root * eig.eigenvectors().col(p - 1);
      record.weak_share = std::clamp(eig.eigenvalues()[p - 1] / total, 0.0, 1.0);
      std::vector<Eigen::Vector2d> pixels, field;
      for (int i : rows) {
        pixels.push_back(table[i].sample->projector_px);
        field.push_back(table[i].landing_inverse * e.middleRows(3 * i, 3) * direction);
      }
      std::map<std::string, double> by_name;
      for (int q = 0; q < p; ++q) {
        by_name[uncertainty.column_names[q]] += std::abs(direction[q]) * std::sqrt(metric(q, q));
      }
      std::vector<std::pair<double, std::string>> ranked;
      for (const auto& [name, w] : by_name) ranked.push_back({w, name});
      std::sort(ranked.rbegin(), ranked.rend());
      std::string movers = ranked[0].second;
      if (ranked.size() > 1 && ranked[1].first > 0.3 * ranked[0].first)
        movers += " with " + ranked[1].second;
      record.weak_direction = DescribeField(pixels, field) + ": " + movers;
    }
    (*calibrations)[id].predicted_error = record;
  }
}

}  // namespace sandtable::node
