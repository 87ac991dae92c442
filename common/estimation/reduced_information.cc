#include "common/estimation/reduced_information.h"

#include <algorithm>
#include <cmath>
#include <set>
#include <utility>

#include <ceres/ceres.h>
#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

namespace sandtable {
namespace {

using RowMajor = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// One residual block's Jacobian, split by parameter block.
struct BlockJacobian {
  std::vector<double*> blocks;
  std::vector<RowMajor> jacobians;  // empty (0 x 0) for a block without columns
};

Status Evaluate(const ceres::Problem& problem, ceres::ResidualBlockId id,
                const std::map<const double*, int>& tangent, BlockJacobian* out) {
  problem.GetParameterBlocksForResidualBlock(id, &out->blocks);
  const int m = problem.GetCostFunctionForResidualBlock(id)->num_residuals();
  out->jacobians.assign(out->blocks.size(), RowMajor());
  std::vector<double*> pointers(out->blocks.size(), nullptr);
  for (size_t b = 0; b < out->blocks.size(); ++b) {
    const auto t = tangent.find(out->blocks[b]);
    if (t == tangent.end()) continue;  // constant: no Jacobian (Ceres refuses one)
    out->jacobians[b].resize(m, t->second);
    pointers[b] = out->jacobians[b].data();
  }
  std::vector<double> residuals(m);
  double cost = 0.0;
  if (!problem.EvaluateResidualBlock(id, /*apply_loss_function=*/true, &cost, residuals.data(),
                                     pointers.data())) {
    return InvalidArgumentError("reduced information: a residual block could not be evaluated");
  }
  return OkStatus();
}

}  // namespace

Expected<ReducedInformation> ComputeReducedInformation(
    const ceres::Problem& problem, std::span<double* const> kept,
    std::span<double* const> eliminated,
    const std::function<double(ceres::ResidualBlockId)>& true_variance) {
  ReducedInformation out;
  // Tangent sizes of every free block either kept or eliminated.
  std::map<const double*, int> tangent;
  auto free_size = [&](const double* block) {
    if (!problem.HasParameterBlock(block) || problem.IsParameterBlockConstant(block)) return 0;
    return problem.ParameterBlockTangentSize(block);
  };
  int columns = 0;
  for (double* block : kept) {
    const int n = free_size(block);
    if (n == 0 || out.column.count(block)) continue;
    out.column[block] = columns;
    out.size[block] = n;
    tangent[block] = n;
    columns += n;
  }
  std::set<const double*> eliminated_set;
  for (double* block : eliminated) {
    const int n = free_size(block);
    if (n == 0) continue;
    if (out.column.count(block)) {
      return InvalidArgumentError("reduced information: a block is both kept and eliminated");
    }
    tangent[block] = n;
    eliminated_set.insert(block);
  }
  out.information = Eigen::MatrixXd::Zero(columns, columns);
  Eigen::MatrixXd& s = out.information;
  const bool sandwich = static_cast<bool>(true_variance);
  if (sandwich) out.gradient_covariance = Eigen::MatrixXd::Zero(columns, columns);
  Eigen::MatrixXd& n_cov = out.gradient_covariance;

  std::set<ceres::ResidualBlockId> done;
  BlockJacobian j;  // residual blocks on kept blocks only
  // Adds J_a^T J_b of the kept blocks of j to S.
  // Adds J_a^T J_b of the kept blocks of bj to `to`, times `weight`.
  auto add_kept = [&](const BlockJacobian& bj, Eigen::MatrixXd* to, double weight) {
    for (size_t a = 0; a < bj.blocks.size(); ++a) {
      const auto ca = out.column.find(bj.blocks[a]);
      if (ca == out.column.end()) continue;
      for (size_t b = 0; b < bj.blocks.size(); ++b) {
        const auto cb = out.column.find(bj.blocks[b]);
        if (cb == out.column.end()) continue;
        to->block(ca->second, cb->second, bj.jacobians[a].cols(), bj.jacobians[b].cols()) +=
            weight * bj.jacobians[a].transpose() * bj.jacobians[b];
      }
    }
  };
  auto check_blocks = [&](const BlockJacobian& bj, const double* allowed_eliminated) -> Status {
    for (size_t b = 0; b < bj.blocks.size(); ++b) {
      const double* block = bj.blocks[b];
      if (!tangent.count(block)) {
        if (free_size(block) > 0) {
          return InvalidArgumentError(
              "reduced information: a free parameter block is neither kept nor eliminated");
        }
        continue;
      }
      if (eliminated_set.count(block) && block != allowed_eliminated) {
        return InvalidArgumentError(
            "reduced information: a residual block touches two eliminated blocks");
      }
    }
    return OkStatus();
  };

  for (const double* x : eliminated_set) {
    std::vector<ceres::ResidualBlockId> ids;
    problem.GetResidualBlocksForParameterBlock(x, &ids);
    const int n = tangent.at(x);
    Eigen::MatrixXd v = Eigen::MatrixXd::Zero(n, n);
    std::map<const double*, Eigen::MatrixXd> w;  // kept block -> J_x^T J_block
    std::vector<BlockJacobian> rows(ids.size());
    std::vector<size_t> x_index(ids.size());
    for (size_t r = 0; r < ids.size(); ++r) {
      BlockJacobian& row = rows[r];
      ST_RETURN_IF_ERROR(Evaluate(problem, ids[r], tangent, &row));
      ST_RETURN_IF_ERROR(check_blocks(row, x));
      add_kept(row, &s, 1.0);
      x_index[r] = static_cast<size_t>(std::find(row.blocks.begin(), row.blocks.end(), x) -
                                       row.blocks.begin());
      const RowMajor& jx = row.jacobians[x_index[r]];
      v += jx.transpose() * jx;
      for (size_t b = 0; b < row.blocks.size(); ++b) {
        if (!out.column.count(row.blocks[b])) continue;
        Eigen::MatrixXd& wb = w[row.blocks[b]];
        if (wb.size() == 0) wb = Eigen::MatrixXd::Zero(n, row.jacobians[b].cols());
        wb += jx.transpose() * row.jacobians[b];
      }
      done.insert(ids[r]);
      ++out.residual_blocks;
    }
    // V^-1 by an eigen-decomposition: a point seen along one ray only (V of rank 2) has no
    // information along it, and contributes nothing there.
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(v);
    const Eigen::VectorXd& lambda = eig.eigenvalues();
    const double largest = lambda.size() ? lambda.maxCoeff() : 0.0;
    Eigen::VectorXd inverse = Eigen::VectorXd::Zero(n);
    for (int i = 0; i < n; ++i) {
      if (lambda[i] > 1e-12 * largest && lambda[i] > 0) inverse[i] = 1.0 / lambda[i];
    }
    const Eigen::MatrixXd v_inv =
        eig.eigenvectors() * inverse.asDiagonal() * eig.eigenvectors().transpose();
    for (const auto& [a, wa] : w) {
      const Eigen::MatrixXd vw = v_inv * wa;
      for (const auto& [b, wb] : w) {
        s.block(out.column.at(a), out.column.at(b), wa.cols(), wb.cols()) -= vw.transpose() * wb;
      }
    }
    if (sandwich) {
      // K = J_u - J_x V^-1 W per residual block, over the kept blocks this point touches.
      for (size_t r = 0; r < rows.size(); ++r) {
        const double d = true_variance(ids[r]);
        if (d == 0.0) continue;
        const BlockJacobian& row = rows[r];
        const RowMajor& jx = row.jacobians[x_index[r]];
        std::vector<std::pair<int, Eigen::MatrixXd>> k;  // column, K's columns for that block
        for (const auto& [b, wb] : w) {
          Eigen::MatrixXd kb = -jx * (v_inv * wb);
          for (size_t q = 0; q < row.blocks.size(); ++q) {
            if (row.blocks[q] == b) kb += row.jacobians[q];
          }
          k.push_back({out.column.at(b), std::move(kb)});
        }
        for (const auto& [ca, ka] : k) {
          for (const auto& [cb, kb] : k) {
            n_cov.block(ca, cb, ka.cols(), kb.cols()) += d * ka.transpose() * kb;
          }
        }
      }
    }
    ++out.eliminated_blocks;
  }
  // Residual blocks on kept blocks only (priors).
  std::vector<ceres::ResidualBlockId> all;
  problem.GetResidualBlocks(&all);
  for (ceres::ResidualBlockId id : all) {
    if (done.count(id)) continue;
    ST_RETURN_IF_ERROR(Evaluate(problem, id, tangent, &j));
    ST_RETURN_IF_ERROR(check_blocks(j, nullptr));
    add_kept(j, &s, 1.0);
    if (sandwich) add_kept(j, &n_cov, true_variance(id));
    ++out.residual_blocks;
  }
  s = 0.5 * (s + s.transpose()).eval();
  if (sandwich) n_cov = 0.5 * (n_cov + n_cov.transpose()).eval();
  return out;
}

MarginalCovariance SandwichCovariance(const ReducedInformation& reduced, double rank_tolerance) {
  MarginalCovariance out = InvertInformation(reduced.information, 1.0, rank_tolerance);
  if (reduced.gradient_covariance.rows() == out.covariance.rows()) {
    out.covariance = out.covariance * reduced.gradient_covariance * out.covariance;
    out.covariance = 0.5 * (out.covariance + out.covariance.transpose()).eval();
  }
  return out;
}

MarginalCovariance InvertInformation(const Eigen::MatrixXd& information, double sigma2,
                                     double rank_tolerance) {
  MarginalCovariance out;
  const int n = static_cast<int>(information.rows());
  out.covariance = Eigen::MatrixXd::Zero(n, n);
  if (n == 0) return out;
  // Scaled by the diagonal first: parameters in px, radians and metres differ by 1e6 and more,
  // which would bury a weak direction under the column scales.
  Eigen::VectorXd d(n);
  for (int i = 0; i < n; ++i) {
    d[i] = information(i, i) > 0 ? 1.0 / std::sqrt(information(i, i)) : 0.0;
  }
  const Eigen::MatrixXd scaled = d.asDiagonal() * information * d.asDiagonal();
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(scaled);
  const Eigen::VectorXd& lambda = eig.eigenvalues();
  const double largest = lambda.maxCoeff();
  Eigen::VectorXd inverse = Eigen::VectorXd::Zero(n);
  for (int i = 0; i < n; ++i) {
    if (lambda[i] > rank_tolerance * largest && lambda[i] > 0) {
      inverse[i] = 1.0 / lambda[i];
    } else {
      Eigen::VectorXd direction = d.asDiagonal() * eig.eigenvectors().col(i);
      if (direction.norm() > 0) direction.normalize();
      out.undetermined.push_back(direction);
    }
  }
  out.covariance = sigma2 * d.asDiagonal() *
                   (eig.eigenvectors() * inverse.asDiagonal() * eig.eigenvectors().transpose()) *
                   d.asDiagonal();
  return out;
}

}  // namespace sandtable
