#include "common/estimation/reduced_information.h"

#include <map>
#include <memory>
#include <random>
#include <vector>

#include <ceres/ceres.h>
#include <gtest/gtest.h>
#include <Eigen/Dense>

namespace sandtable {
namespace {

constexpr double kExactTolerance = 1e-9;  // relative to the largest covariance entry

using RowMajor = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// r = sum_k M_k x_k - y: a linear residual, so the Jacobian is exact and known.
class LinearCost : public ceres::CostFunction {
 public:
  LinearCost(std::vector<Eigen::MatrixXd> m, Eigen::VectorXd y) : m_(std::move(m)), y_(y) {
    set_num_residuals(static_cast<int>(y_.size()));
    for (const Eigen::MatrixXd& mk : m_) mutable_parameter_block_sizes()->push_back(mk.cols());
  }
  bool Evaluate(double const* const* x, double* r, double** jacobians) const override {
    Eigen::VectorXd out = -y_;
    for (size_t k = 0; k < m_.size(); ++k) {
      out += m_[k] * Eigen::Map<const Eigen::VectorXd>(x[k], m_[k].cols());
      if (jacobians && jacobians[k]) {
        Eigen::Map<RowMajor>(jacobians[k], m_[k].rows(), m_[k].cols()) = m_[k];
      }
    }
    Eigen::Map<Eigen::VectorXd>(r, out.size()) = out;
    return true;
  }

 private:
  std::vector<Eigen::MatrixXd> m_;
  Eigen::VectorXd y_;
};

// Kept blocks a (2) and b (3), points p_i (3) seen by both through random 2x. maps, a prior on
// a, and the full Jacobian written out densely alongside.
struct ToyProblem {
  static constexpr int kPoints = 6;
  std::vector<double> a = std::vector<double>(2, 0.1), b = std::vector<double>(3, -0.2);
  std::vector<std::vector<double>> p = std::vector<std::vector<double>>(kPoints, {0, 0, 0});
  ceres::Problem problem;
  Eigen::MatrixXd jacobian;                 // rows: residuals; columns: a, b, p_0 ... p_5
  std::vector<ceres::ResidualBlockId> ids;  // in the order of the rows, 2 rows each

  explicit ToyProblem(uint64_t seed) {
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> g(0.0, 1.0);
    auto random = [&](int rows, int cols) {
      Eigen::MatrixXd m(rows, cols);
      for (int i = 0; i < rows; ++i)
        for (int j = 0; j < cols; ++j) m(i, j) = g(rng);
      return m;
    };
    const int columns = 5 + 3 * kPoints;
    std::vector<Eigen::RowVectorXd> rows;
    auto add_rows = [&](const std::vector<std::pair<int, Eigen::MatrixXd>>& parts) {
      for (int r = 0; r < parts.front().second.rows(); ++r) {
        Eigen::RowVectorXd row = Eigen::RowVectorXd::Zero(columns);
        for (const auto& [col, m] : parts) row.segment(col, m.cols()) = m.row(r);
        rows.push_back(row);
      }
    };
    for (int i = 0; i < kPoints; ++i) {
      const Eigen::MatrixXd ma = random(2, 2), pa = random(2, 3), mb = random(2, 3),
                            pb = random(2, 3);
      ids.push_back(problem.AddResidualBlock(new LinearCost({ma, pa}, random(2, 1)), nullptr,
                                             a.data(), p[i].data()));
      ids.push_back(problem.AddResidualBlock(new LinearCost({mb, pb}, random(2, 1)), nullptr,
                                             b.data(), p[i].data()));
      add_rows({{0, ma}, {5 + 3 * i, pa}});
      add_rows({{2, mb}, {5 + 3 * i, pb}});
    }
    const Eigen::MatrixXd prior = Eigen::MatrixXd::Identity(2, 2);
    ids.push_back(problem.AddResidualBlock(new LinearCost({prior}, Eigen::VectorXd::Zero(2)),
                                           nullptr, a.data()));
    add_rows({{0, prior}});
    jacobian.resize(static_cast<int>(rows.size()), columns);
    for (size_t r = 0; r < rows.size(); ++r) jacobian.row(static_cast<int>(r)) = rows[r];
  }
  std::vector<double*> points() {
    std::vector<double*> out;
    for (auto& q : p) out.push_back(q.data());
    return out;
  }
};

TEST(ReducedInformation, MatchesTheFullInverseOfTheNormalEquations) {
  ToyProblem toy(7);
  const std::vector<double*> kept = {toy.a.data(), toy.b.data()};
  Expected<ReducedInformation> reduced = ComputeReducedInformation(toy.problem, kept, toy.points());
  ASSERT_TRUE(reduced.ok()) << reduced.status().message();
  EXPECT_EQ(reduced->column.at(toy.a.data()), 0);
  EXPECT_EQ(reduced->column.at(toy.b.data()), 2);
  EXPECT_EQ(reduced->eliminated_blocks, ToyProblem::kPoints);
  const Eigen::MatrixXd full = (toy.jacobian.transpose() * toy.jacobian).inverse();
  const Eigen::MatrixXd expected = full.topLeftCorner(5, 5);
  const double sigma2 = 2.5;
  const MarginalCovariance marginal = InvertInformation(reduced->information, sigma2);
  EXPECT_TRUE(marginal.undetermined.empty());
  const double scale = expected.cwiseAbs().maxCoeff();
  EXPECT_LT((marginal.covariance - sigma2 * expected).cwiseAbs().maxCoeff(),
            kExactTolerance * scale * sigma2);
}

// Weighted otherwise than their noise: the residuals on a exact (variance 0), those on b twice
// as noisy as weighted, the prior as weighted. The estimate's covariance is the sandwich
// H^-1 J^T D J H^-1 of the full problem.
TEST(ReducedInformation, TheSandwichMatchesTheFullProblemsOne) {
  ToyProblem toy(13);
  std::map<ceres::ResidualBlockId, double> variance;
  Eigen::VectorXd d(toy.jacobian.rows());
  for (size_t i = 0; i < toy.ids.size(); ++i) {
    const bool prior = i + 1 == toy.ids.size();
    const double v = prior ? 1.0 : (i % 2 == 0 ? 0.0 : 2.0);
    variance[toy.ids[i]] = v;
    d.segment(2 * static_cast<int>(i), 2).setConstant(v);
  }
  const std::vector<double*> kept = {toy.a.data(), toy.b.data()};
  Expected<ReducedInformation> reduced = ComputeReducedInformation(
      toy.problem, kept, toy.points(), [&](ceres::ResidualBlockId id) { return variance.at(id); });
  ASSERT_TRUE(reduced.ok()) << reduced.status().message();
  const Eigen::MatrixXd h_inv = (toy.jacobian.transpose() * toy.jacobian).inverse();
  const Eigen::MatrixXd full =
      h_inv * toy.jacobian.transpose() * d.asDiagonal() * toy.jacobian * h_inv;
  const Eigen::MatrixXd expected = full.topLeftCorner(5, 5);
  const MarginalCovariance sandwich = SandwichCovariance(*reduced);
  EXPECT_LT((sandwich.covariance - expected).cwiseAbs().maxCoeff(),
            kExactTolerance * expected.cwiseAbs().maxCoeff());
  // Not the plain inverse: the weights are wrong here.
  const MarginalCovariance plain = InvertInformation(reduced->information, 1.0);
  EXPECT_GT((plain.covariance - expected).cwiseAbs().maxCoeff(),
            0.01 * expected.cwiseAbs().maxCoeff());
}

TEST(ReducedInformation, AHeldBlockHasNoColumnsAndConditionsTheRest) {
  ToyProblem toy(11);
  toy.problem.SetParameterBlockConstant(toy.a.data());
  const std::vector<double*> kept = {toy.a.data(), toy.b.data()};
  Expected<ReducedInformation> reduced = ComputeReducedInformation(toy.problem, kept, toy.points());
  ASSERT_TRUE(reduced.ok()) << reduced.status().message();
  EXPECT_FALSE(reduced->column.count(toy.a.data()));
  ASSERT_EQ(reduced->information.rows(), 3);
  // The full problem without a's columns.
  Eigen::MatrixXd j(toy.jacobian.rows(), toy.jacobian.cols() - 2);
  j << toy.jacobian.rightCols(toy.jacobian.cols() - 2);
  const Eigen::MatrixXd expected = (j.transpose() * j).inverse().topLeftCorner(3, 3);
  const MarginalCovariance marginal = InvertInformation(reduced->information, 1.0);
  EXPECT_LT((marginal.covariance - expected).cwiseAbs().maxCoeff(),
            kExactTolerance * expected.cwiseAbs().maxCoeff());
}

TEST(ReducedInformation, RefusesAFreeBlockItWasNotToldAbout) {
  ToyProblem toy(3);
  const std::vector<double*> kept = {toy.a.data()};  // b forgotten
  Expected<ReducedInformation> reduced = ComputeReducedInformation(toy.problem, kept, toy.points());
  ASSERT_FALSE(reduced.ok());
  EXPECT_NE(reduced.status().message().find("neither kept nor eliminated"), std::string::npos);
}

TEST(ReducedInformation, RefusesAResidualOnTwoEliminatedBlocks) {
  ToyProblem toy(5);
  Eigen::MatrixXd m = Eigen::MatrixXd::Identity(3, 3);
  toy.problem.AddResidualBlock(new LinearCost({m, m}, Eigen::VectorXd::Zero(3)), nullptr,
                               toy.p[0].data(), toy.p[1].data());
  const std::vector<double*> kept = {toy.a.data(), toy.b.data()};
  Expected<ReducedInformation> reduced = ComputeReducedInformation(toy.problem, kept, toy.points());
  ASSERT_FALSE(reduced.ok());
  EXPECT_NE(reduced.status().message().find("two eliminated blocks"), std::string::npos);
}

TEST(ReducedInformation, NamesTheDirectionTheDataDoNotDetermine) {
  // x and y enter only as x + y (in metres) while z (in px, 1e4 times larger) is determined.
  Eigen::MatrixXd information(3, 3);
  information << 1, 1, 0, 1, 1, 0, 0, 0, 1e8;
  const MarginalCovariance marginal = InvertInformation(information, 1.0);
  ASSERT_EQ(marginal.undetermined.size(), 1u);
  const Eigen::VectorXd& v = marginal.undetermined.front();
  EXPECT_NEAR(std::abs(v[0]), std::sqrt(0.5), 1e-9);
  EXPECT_NEAR(v[0], -v[1], 1e-9);
  EXPECT_NEAR(v[2], 0.0, 1e-9);
  // The determined direction keeps its variance; the undetermined one contributes none.
  EXPECT_NEAR(marginal.covariance(2, 2), 1e-8, 1e-17);
  EXPECT_NEAR((marginal.covariance * v).norm(), 0.0, 1e-9);
}

}  // namespace
}  // namespace sandtable
