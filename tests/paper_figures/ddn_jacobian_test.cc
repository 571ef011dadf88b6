// DDN Figure 2 on a reduced, fixed-seed configuration (4,096 samples, width
// 128 in 1-D and 64 in 2-D, batch 64, 120 epochs, lr 2e-3, seed 42; seeds 1
// and 2 too for the seed-sensitive 1-D relu gain): the qualitative findings
// of the authors' experiment must hold.
#include <algorithm>
#include <cstdint>
#include <map>
#include <string>
#include <tuple>
#include <vector>

#include <ceres/jet.h>
#include <gtest/gtest.h>

#include "ddn_experiment.h"

namespace diffdyn::ddn_figure {
namespace {

using Key = std::tuple<int, std::string, bool>;  // dim, activation, Jacobian loss

Config Reduced(int dim, const Activation& act, bool jacobian_loss) {
  Config c;
  c.dim = dim;
  c.activation = act;
  c.jacobian_loss = jacobian_loss;
  c.n_train = 4096;
  c.batch = 64;
  c.epochs = 120;
  c.width = dim == 1 ? 128 : 64;  // the authors' width in 1-D; halved in 2-D for time
  c.learning_rate = 2e-3;
  c.seed = 42;
  return c;
}

// One test (one process under gtest_discover_tests): the eight trainings run once.
TEST(DdnJacobianFigure, ReducedRunShowsTheAuthorsFindings) {
  std::map<Key, Result> results;
  for (int dim : {1, 2}) {
    for (const auto& [name, act] : {std::pair{std::string("relu"), Activation::Relu()},
                                    std::pair{std::string("softplus"), Activation::Softplus()}}) {
      for (bool jac : {true, false}) results[{dim, name, jac}] = RunExperiment(Reduced(dim, act, jac));
    }
  }
  auto get = [&](int dim, const std::string& act, bool jac) -> const Result& {
    return results.at({dim, act, jac});
  };

  // relu: Hessian identically zero, so its MSE is the mean of H^2 (about 0.5
  // in 1-D, 0.25 in 2-D); softplus's is far lower.
  for (int dim : {1, 2}) {
    const Dataset test = MakeTestGrid(dim, dim == 1 ? 100 : 50);
    for (bool jac : {true, false}) {
      SCOPED_TRACE(::testing::Message() << dim << "-D relu, Jacobian loss " << jac);
      const Result& r = get(dim, "relu", jac);
      EXPECT_EQ(Predict(r.net, test.x).hess.cwiseAbs().maxCoeff(), 0.0);
      EXPECT_NEAR(r.mse_h, test.hess.squaredNorm() / test.hess.size(), 1e-15);
      EXPECT_LT(get(dim, "softplus", true).mse_h, 0.2 * r.mse_h);
    }
  }

  // Softplus's Jacobian error at least 5x below relu's in 2-D (both f+J).
  const double relu2 = get(2, "relu", true).mse_j;
  const double softplus2 = get(2, "softplus", true).mse_j;
  EXPECT_LT(5.0 * softplus2, relu2) << "relu " << relu2 << " softplus " << softplus2;

  // The Jacobian loss lowers the Jacobian error: relu 2-D and softplus 2-D at
  // seed 42 (2.0-3.6x and 40-105x over seeds 1-5 and 42 in this configuration).
  for (const auto& [dim, act] : {std::pair{2, std::string("relu")}, std::pair{2, std::string("softplus")}}) {
    EXPECT_LT(get(dim, act, true).mse_j, get(dim, act, false).mse_j) << dim << "-D " << act;
  }
  // relu 1-D: the gain varies with the seed (1.2x to 4.2x over seeds 1-5 and
  // 42), because the Jacobian loss cannot move relu's kinks and most of the
  // gain comes from the slopes of the two end pieces (README), so assert on the
  // median gain of three seeds.
  std::vector<double> gains;
  for (std::uint64_t seed : {42, 1, 2}) {
    double mse_j[2];
    for (bool jac : {true, false}) {
      if (seed == 42) {
        mse_j[jac] = get(1, "relu", jac).mse_j;
      } else {
        Config c = Reduced(1, Activation::Relu(), jac);
        c.seed = seed;
        mse_j[jac] = RunExperiment(c).mse_j;
      }
    }
    gains.push_back(mse_j[false] / mse_j[true]);
  }
  std::sort(gains.begin(), gains.end());
  EXPECT_GT(gains[1], 1.0) << "1-D relu gains " << gains[0] << ' ' << gains[1] << ' ' << gains[2];

  // A relu network's slope is constant between kinks, so its Jacobian error is
  // at least the best staircase on its own pieces (at most width + 1 of them).
  for (bool jac : {true, false}) {
    const JacobianErrorSplit split = SplitJacobianError1d(get(1, "relu", jac).net);
    EXPECT_LE(split.own_kink_floor, split.fine);
    EXPECT_GT(split.own_kink_floor, 0.0);
    EXPECT_GE(split.pieces, 2);
    EXPECT_LE(split.pieces, 129);
  }

  // Every network fits f.
  for (const auto& [key, r] : results) {
    EXPECT_LT(r.mse_f, 0.05) << std::get<0>(key) << "-D " << std::get<1>(key);
    EXPECT_GT(r.mse_f, 0.0);
  }

  // The closed-form Jacobian of a trained network equals Jets.
  using Jet2 = ceres::Jet<double, 2>;
  const Mlp<double>& net = get(2, "softplus", true).net;
  const Dataset grid = MakeTestGrid(2, 7);
  for (Eigen::Index i = 0; i < grid.x.cols(); ++i) {
    Eigen::VectorXd y;
    Eigen::MatrixXd jac;
    net.ValueAndJacobian(grid.x.col(i), &y, &jac);
    const Eigen::Matrix<Jet2, 2, 1> xj(Jet2(grid.x(0, i), 0), Jet2(grid.x(1, i), 1));
    const auto yj = net(xj);
    EXPECT_NEAR(jac(0, 0), yj[0].v[0], 1e-12);
    EXPECT_NEAR(jac(0, 1), yj[0].v[1], 1e-12);
  }
}

TEST(DdnJacobianFigureData, SameSeedSameNetwork) {
  Config c = Reduced(2, Activation::Tanh(), true);
  c.epochs = 2;
  c.n_train = 512;
  const Result a = RunExperiment(c);
  const Result b = RunExperiment(c);
  EXPECT_TRUE(a.net.parameters() == b.net.parameters());
  EXPECT_EQ(a.mse_j, b.mse_j);
  c.seed = 43;
  EXPECT_FALSE(RunExperiment(c).net.parameters() == a.net.parameters());
}

TEST(DdnJacobianFigureData, ConstantSlopeNetworkHasOnePieceAndCosVarianceFloor) {
  // All-zero parameters: J = 0 on one piece, so fine = floor = mean cos^2 = 1/2.
  const Mlp<double> net(MlpArchitecture{{1, 8, 1}, {Activation::Relu()}});
  const JacobianErrorSplit split = SplitJacobianError1d(net, 4000);
  EXPECT_EQ(split.pieces, 1);
  EXPECT_NEAR(split.fine, 0.5, 1e-9);
  EXPECT_NEAR(split.own_kink_floor, 0.5, 1e-9);
  const Dataset test = MakeTestGrid(1, 100);
  double interior = 0.0;
  for (Eigen::Index i = 2; i < 98; ++i) interior += test.jac(0, i) * test.jac(0, i) / 96.0;
  EXPECT_NEAR(split.grid_interior, interior, 1e-15);
}

TEST(DdnJacobianFigureData, TestFunctionDerivativesMatchCentralDifferences) {
  for (int dim : {1, 2}) {
    const Dataset grid = MakeTestGrid(dim, 9);
    const double h = 1e-6;
    for (Eigen::Index i = 0; i < grid.x.cols(); ++i) {
      for (int a = 0; a < dim; ++a) {
        Eigen::MatrixXd xp = grid.x.col(i), xm = grid.x.col(i);
        xp(a, 0) += h;
        xm(a, 0) -= h;
        const Dataset p = Evaluate(dim, xp), m = Evaluate(dim, xm);
        EXPECT_NEAR(grid.jac(0, dim * i + a), (p.f(0, 0) - m.f(0, 0)) / (2 * h), 1e-8);
        for (int b = 0; b < dim; ++b) {
          EXPECT_NEAR(grid.hess(0, dim * dim * i + dim * b + a), (p.jac(0, b) - m.jac(0, b)) / (2 * h), 1e-8);
        }
      }
    }
  }
}

}  // namespace
}  // namespace diffdyn::ddn_figure
