// Mlp: closed-form Jacobians and Hessians against Jets and central differences,
// batched against single-sample paths, reverse mode against Jets and finite
// differences, thread-count determinism.
#include "diffdyn/models/mlp.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include <ceres/jet.h>
#include <gtest/gtest.h>

#include "diffdyn/models/random.h"

namespace diffdyn {
namespace {

constexpr int kJetSize = 8;
using Jet8 = ceres::Jet<double, kJetSize>;

Eigen::VectorXd RandomVector(Eigen::Index n, double scale, Rng& rng) {
  Eigen::VectorXd v(n);
  for (Eigen::Index i = 0; i < n; ++i) v[i] = scale * StandardNormal(rng);
  return v;
}

Eigen::MatrixXd RandomMatrix(Eigen::Index rows, Eigen::Index cols, double scale, Rng& rng) {
  Eigen::MatrixXd m(rows, cols);
  for (Eigen::Index i = 0; i < m.size(); ++i) m.data()[i] = scale * StandardNormal(rng);
  return m;
}

// A 3-6-5-2 network with the given hidden activation and random parameters.
Mlp<double> SmallNet(const Activation& act, std::uint64_t seed) {
  Rng rng(seed);
  MlpArchitecture arch{{3, 6, 5, 2}, {act, act}};
  return Mlp<double>(arch, RandomVector(arch.num_parameters(), 0.6, rng));
}

std::vector<Activation> EveryActivation() {
  return {Activation::Relu(), Activation::Softplus(), Activation::Softplus(2.5),
          Activation::Tanh(), Activation::Sigmoid(),  Activation::Elu(0.8),
          Activation::Cos(),  Activation::Linear()};
}

// Minimum |a| over all hidden pre-activations of x (to keep relu off its kink).
double MinAbsPreactivation(const Mlp<double>& net, const Eigen::VectorXd& x) {
  Eigen::VectorXd h = x;
  double min_abs = 1e300;
  for (int l = 0; l + 1 < net.architecture().num_layers(); ++l) {
    Eigen::VectorXd a = net.W(l) * h + net.b(l);
    min_abs = std::min(min_abs, a.cwiseAbs().minCoeff());
    for (Eigen::Index i = 0; i < a.size(); ++i)
      a[i] = ActivationValue(net.architecture().activations[l], a[i]);
    h = a;
  }
  return min_abs;
}

// Jacobian of net(x) with Jets seeded on the inputs.
Eigen::MatrixXd JetJacobian(const Mlp<double>& net, const Eigen::VectorXd& x) {
  using Jet3 = ceres::Jet<double, 3>;
  Eigen::Matrix<Jet3, Eigen::Dynamic, 1> xj(3);
  for (int i = 0; i < 3; ++i) xj[i] = Jet3(x[i], i);
  const auto y = net(xj);
  Eigen::MatrixXd jac(y.size(), 3);
  for (Eigen::Index k = 0; k < y.size(); ++k) jac.row(k) = y[k].v.transpose();
  return jac;
}

TEST(Mlp, ClosedFormJacobianMatchesJetsAndCentralDifferences) {
  Rng rng(7);
  for (const Activation& act : EveryActivation()) {
    const Mlp<double> net = SmallNet(act, 11);
    int checked = 0;
    for (int trial = 0; checked < 5 && trial < 50; ++trial) {
      const Eigen::VectorXd x = RandomVector(3, 1.0, rng);
      if (MinAbsPreactivation(net, x) < 1e-3) continue;
      ++checked;
      Eigen::VectorXd y;
      Eigen::MatrixXd jac;
      net.ValueAndJacobian(x, &y, &jac);
      EXPECT_LT((y - net(x)).cwiseAbs().maxCoeff(), 1e-14);
      EXPECT_LT((jac - JetJacobian(net, x)).cwiseAbs().maxCoeff(), 1e-12) << ActivationName(act.kind);
      const double h = 1e-6;
      for (int i = 0; i < 3; ++i) {
        Eigen::VectorXd xp = x, xm = x;
        xp[i] += h;
        xm[i] -= h;
        const Eigen::VectorXd fd = (net(xp) - net(xm)) / (2 * h);
        EXPECT_LT((jac.col(i) - fd).cwiseAbs().maxCoeff(), 1e-6) << ActivationName(act.kind);
      }
    }
    EXPECT_EQ(checked, 5) << ActivationName(act.kind);
  }
}

TEST(Mlp, ClosedFormHessianMatchesJetOfJacobianAndCentralDifferences) {
  using Jet3 = ceres::Jet<double, 3>;
  Rng rng(8);
  for (const Activation& act : EveryActivation()) {
    if (act.kind == ActivationKind::kRelu) continue;  // Hessian is 0; checked below
    const Mlp<double> net = SmallNet(act, 12);
    const Eigen::VectorXd x = RandomVector(3, 1.0, rng);
    Eigen::MatrixXd jac;
    std::vector<Eigen::MatrixXd> hess;
    net.ValueJacobianHessian(x, nullptr, &jac, &hess);
    // Second mode: Jets through the closed-form Jacobian.
    Eigen::Matrix<Jet3, Eigen::Dynamic, 1> xj(3), yj;
    for (int i = 0; i < 3; ++i) xj[i] = Jet3(x[i], i);
    Eigen::Matrix<Jet3, Eigen::Dynamic, Eigen::Dynamic> jj;
    net.ValueAndJacobian(xj, &yj, &jj);
    const double h = 1e-5;
    for (int k = 0; k < 2; ++k) {
      for (int i = 0; i < 3; ++i) {
        EXPECT_NEAR(jac(k, i), jj(k, i).a, 1e-14);
        for (int j = 0; j < 3; ++j) {
          EXPECT_NEAR(hess[k](i, j), jj(k, i).v[j], 1e-12) << ActivationName(act.kind);
          Eigen::VectorXd xp = x, xm = x;
          xp[j] += h;
          xm[j] -= h;
          Eigen::MatrixXd jp, jm;
          net.ValueAndJacobian(xp, static_cast<Eigen::VectorXd*>(nullptr), &jp);
          net.ValueAndJacobian(xm, static_cast<Eigen::VectorXd*>(nullptr), &jm);
          EXPECT_NEAR(hess[k](i, j), (jp(k, i) - jm(k, i)) / (2 * h), 1e-6)
              << ActivationName(act.kind);
        }
      }
      EXPECT_LT((hess[k] - hess[k].transpose()).cwiseAbs().maxCoeff(), 1e-12);
    }
  }
  // relu: piecewise linear, Hessian identically zero.
  std::vector<Eigen::MatrixXd> hess;
  SmallNet(Activation::Relu(), 3).ValueJacobianHessian(RandomVector(3, 1.0, rng), nullptr, nullptr, &hess);
  for (const auto& hk : hess) EXPECT_EQ(hk.cwiseAbs().maxCoeff(), 0.0);
}

TEST(Mlp, BatchedForwardMatchesSingleSample) {
  Rng rng(9);
  for (const Activation& act : EveryActivation()) {
    const Mlp<double> net = SmallNet(act, 13);
    const int batch = 37;
    const Eigen::MatrixXd X = RandomMatrix(3, batch, 1.0, rng);
    MlpWorkspace ws(net.architecture(), batch, 16);
    Eigen::MatrixXd Y, J, Y2, Jr;
    net.Forward(X, &Y, &J, &ws, 2);
    net.InputJacobianReverse(X, &Y2, &Jr, &ws, 2);
    ASSERT_EQ(J.rows(), 2);
    ASSERT_EQ(J.cols(), 3 * batch);
    for (int b = 0; b < batch; ++b) {
      Eigen::VectorXd y;
      Eigen::MatrixXd jac;
      net.ValueAndJacobian(Eigen::VectorXd(X.col(b)), &y, &jac);
      EXPECT_LT((Y.col(b) - y).cwiseAbs().maxCoeff(), 1e-12);
      EXPECT_LT((J.middleCols(3 * b, 3) - jac).cwiseAbs().maxCoeff(), 1e-12);
      EXPECT_LT((Jr.middleCols(3 * b, 3) - jac).cwiseAbs().maxCoeff(), 1e-12);
    }
    EXPECT_LT((Y2 - Y).cwiseAbs().maxCoeff(), 1e-15);
  }
}

// Evaluate (values only; the fused layer kernel where built) against Forward's
// BLAS products and the single-sample path: every activation, layer widths
// that leave row tiles of 1-4 units, batches around the 32-sample block.
TEST(Mlp, EvaluateMatchesForwardAndSingleSample) {
  Rng rng(19);
  const std::vector<std::vector<int>> shapes = {
      {6, 100, 100, 6}, {3, 6, 5, 2}, {6, 7, 13, 3}, {1, 9, 1}, {4, 33, 4}};
  for (const Activation& act : EveryActivation()) {
    for (const std::vector<int>& sizes : shapes) {
      MlpArchitecture arch{sizes, std::vector<Activation>(sizes.size() - 2, act)};
      const Mlp<double> net(arch, RandomVector(arch.num_parameters(), 0.4, rng));
      for (int batch : {1, 31, 32, 33, 250}) {
        const Eigen::MatrixXd X = RandomMatrix(sizes.front(), batch, 1.0, rng);
        MlpWorkspace ws(arch, batch, 96, false);
        Eigen::MatrixXd Y;
        net.Forward(X, &Y, nullptr, &ws);
        Eigen::MatrixXd E = Eigen::MatrixXd::Constant(sizes.back(), batch, 7.0);
        net.Evaluate(X, E, &ws, 2);
        const double scale = 1.0 + Y.cwiseAbs().maxCoeff();
        EXPECT_LT((E - Y).cwiseAbs().maxCoeff(), 1e-13 * scale)
            << ActivationName(act.kind) << " " << sizes.size() << " layers, batch " << batch;
        const Eigen::VectorXd y0 = net(Eigen::VectorXd(X.col(batch - 1)));
        EXPECT_LT((E.col(batch - 1) - y0).cwiseAbs().maxCoeff(), 1e-13 * scale);
      }
    }
  }
}

// Evaluate writes into any column block (the MPPI rollouts pass slices) and, with
// the layer kernel, gives each sample the same bits whatever the batch around it,
// the chunk size and the thread count.
TEST(Mlp, EvaluateIsIndependentOfBatchChunksAndThreads) {
  Rng rng(23);
  MlpArchitecture arch{{6, 100, 100, 6}, {Activation::Relu(), Activation::Relu()}};
  const Mlp<double> net(arch, RandomVector(arch.num_parameters(), 0.2, rng));
  const int batch = 333;
  const Eigen::MatrixXd X = RandomMatrix(6, batch, 1.0, rng);
  Eigen::MatrixXd reference(6, batch);
  MlpWorkspace ws(arch, batch, 128, false);
  net.Evaluate(X, reference, &ws, 1);
  for (int threads : {2, 3}) {
    Eigen::MatrixXd Y(6, batch);
    net.Evaluate(X, Y, &ws, threads);
    EXPECT_TRUE(Y == reference) << threads << " threads";
  }
  // Into the middle of a wider matrix, from a column block of another.
  Eigen::MatrixXd wide = Eigen::MatrixXd::Zero(6, batch + 20);
  Eigen::MatrixXd xwide = Eigen::MatrixXd::Zero(6, batch + 20);
  xwide.middleCols(10, batch) = X;
  net.Evaluate(xwide.middleCols(10, batch), wide.middleCols(10, batch), &ws, 2);
  EXPECT_TRUE(wide.middleCols(10, batch) == reference);
  EXPECT_TRUE(wide.leftCols(10).isZero() && wide.rightCols(10).isZero());
  if (kHaveLayerKernel) {
    MlpWorkspace other(arch, batch, 50, false);
    Eigen::MatrixXd Y(6, batch);
    net.Evaluate(X, Y, &other, 2);
    EXPECT_TRUE(Y == reference) << "chunk 50";
    Eigen::MatrixXd tail(6, 7);
    net.Evaluate(X.rightCols(7), tail, &other);
    EXPECT_TRUE(tail == reference.rightCols(7)) << "a batch of the last 7 samples";
  }
}

// With the layer kernel a block of samples skips the ReLU units that are zero for
// all of them, so which samples share a block changes which zero terms are summed:
// each sample's value must not depend on it, to the bit (without the kernel,
// Evaluate runs BLAS products whose blocking may change the rounding: to 1e-13).
// Two interleaved clusters, the same batch shuffled, identical samples and a NaN
// sample, against each sample alone.
TEST(Mlp, EvaluateIsIndependentOfSampleOrder) {
  const auto same = [](const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
    if (kHaveLayerKernel) return a == b;
    return (a - b).cwiseAbs().maxCoeff() <= 1e-13 * (1.0 + b.cwiseAbs().maxCoeff());
  };
  Rng rng(31);
  MlpArchitecture arch{{6, 100, 100, 6}, {Activation::Relu(), Activation::Relu()}};
  const Mlp<double> net(arch, RandomVector(arch.num_parameters(), 0.2, rng));
  const int batch = 250;
  Eigen::MatrixXd X = RandomMatrix(6, batch, 0.05, rng);
  for (int s = 1; s < batch; s += 2) X.col(s).array() += 2.0;  // clusters at 0 and 2
  MlpWorkspace ws(arch, batch, 250, false);
  Eigen::MatrixXd Y(6, batch);
  net.Evaluate(X, Y, &ws, 1);
  std::vector<int> perm(batch);
  for (int s = 0; s < batch; ++s) perm[s] = (s * 97) % batch;  // 97 is prime to 250
  Eigen::MatrixXd Xp(6, batch), Yp(6, batch);
  for (int s = 0; s < batch; ++s) Xp.col(s) = X.col(perm[s]);
  net.Evaluate(Xp, Yp, &ws, 2);
  MlpWorkspace single(arch, 1, 1, false);
  for (int s = 0; s < batch; ++s) {
    Eigen::MatrixXd y(6, 1);
    net.Evaluate(X.col(s), y, &single);
    EXPECT_TRUE(same(Y.col(s), y)) << "sample " << s;
    EXPECT_TRUE(same(Yp.col(s), Y.col(perm[s]))) << "shuffled sample " << s;
  }
  const Eigen::MatrixXd identical = X.col(0).replicate(1, batch);
  net.Evaluate(identical, Y, &ws, 1);
  EXPECT_TRUE(same(Y, Y.col(0).replicate(1, batch)));
  X(3, 17) = std::numeric_limits<double>::quiet_NaN();
  net.Evaluate(X, Y, &ws, 1);
  for (int s : {0, 16, 18, 249}) {
    Eigen::MatrixXd y(6, 1);
    net.Evaluate(X.col(s), y, &single);
    EXPECT_TRUE(same(Y.col(s), y)) << "sample " << s << " beside a NaN";
  }
}

// InputJacobianReverse on a deeper net whose input is its widest layer: the
// Jacobians of the closed form per sample, and the same bytes at any thread count;
// with the layer kernel also at any chunk size (its sums do not depend on it).
TEST(Mlp, InputJacobianReverseIsIndependentOfChunksAndThreads) {
  Rng rng(29);
  MlpArchitecture arch{{12, 9, 11, 7, 3},
                       {Activation::Softplus(), Activation::Tanh(), Activation::Elu(0.8)}};
  const Mlp<double> net(arch, RandomVector(arch.num_parameters(), 0.4, rng));
  const int batch = 101;
  const Eigen::MatrixXd X = RandomMatrix(12, batch, 1.0, rng);
  MlpWorkspace ws(arch, batch, 40, false);
  Eigen::MatrixXd Y, J;
  net.InputJacobianReverse(X, &Y, &J, &ws, 1);
  ASSERT_EQ(J.rows(), 3);
  ASSERT_EQ(J.cols(), 12 * batch);
  for (int b = 0; b < batch; ++b) {
    Eigen::VectorXd y;
    Eigen::MatrixXd jac;
    net.ValueAndJacobian(Eigen::VectorXd(X.col(b)), &y, &jac);
    EXPECT_LT((Y.col(b) - y).cwiseAbs().maxCoeff(), 1e-13);
    EXPECT_LT((J.middleCols(12 * b, 12) - jac).cwiseAbs().maxCoeff(), 1e-13) << "sample " << b;
  }
  for (int threads : {2, 3}) {
    Eigen::MatrixXd Y2, J2;
    net.InputJacobianReverse(X, &Y2, &J2, &ws, threads);
    EXPECT_TRUE(Y2 == Y && J2 == J) << threads << " threads";
  }
  if (kHaveLayerKernel) {
    MlpWorkspace other(arch, batch, 64, false);
    Eigen::MatrixXd Y2, J2;
    net.InputJacobianReverse(X, &Y2, &J2, &other, 2);
    EXPECT_TRUE(Y2 == Y && J2 == J) << "chunk 64";
    // A workspace that evaluated first (Evaluate sizes the same block buffers).
    Eigen::MatrixXd values(3, batch);
    net.Evaluate(X, values, &other, 2);
    net.InputJacobianReverse(X.rightCols(5), &Y2, &J2, &other);
    EXPECT_TRUE(J2 == J.rightCols(12 * 5)) << "a batch of the last 5 samples";
  }
}

// The layer kernel skips hidden units that are zero for a whole block of samples.
// Units dead everywhere, units dead in one block only, and a layer dead in every
// unit (the next layer then sees only its biases) must all give Forward's values.
TEST(Mlp, EvaluateSkipsInactiveUnitsExactly) {
  Rng rng(29);
  MlpArchitecture arch{{6, 100, 100, 3}, {Activation::Relu(), Activation::Relu()}};
  Eigen::VectorXd theta = RandomVector(arch.num_parameters(), 0.3, rng);
  const Eigen::Index w0 = arch.WeightOffset(0), b0 = arch.BiasOffset(0);
  // Units 0-29 never fire; units 40-49 fire only where input 0 is 1.
  for (int i = 0; i < 30; ++i) theta[b0 + i] = -1e3;
  for (int i = 40; i < 50; ++i) {
    for (int j = 0; j < 6; ++j) theta[w0 + i + 100 * j] = j == 0 ? 50.0 : 0.0;
    theta[b0 + i] = -25.0;
  }
  const Mlp<double> net(arch, theta);
  const int batch = 96;  // blocks [0, 32), [32, 64), [64, 96) with the kernel
  Eigen::MatrixXd X = RandomMatrix(6, batch, 1.0, rng);
  X.row(0).setOnes();
  X.row(0).segment(32, 32).setZero();  // the second block: units 40-49 dead too
  MlpWorkspace ws(arch, batch, 64, false);
  Eigen::MatrixXd Y, E(3, batch);
  net.Forward(X, &Y, nullptr, &ws);
  net.Evaluate(X, E, &ws, 2);
  const double scale = 1.0 + Y.cwiseAbs().maxCoeff();
  EXPECT_LT((E - Y).cwiseAbs().maxCoeff(), 1e-13 * scale);
  for (int s : {0, 40, 95}) {
    const Eigen::VectorXd y = net(Eigen::VectorXd(X.col(s)));
    EXPECT_LT((E.col(s) - y).cwiseAbs().maxCoeff(), 1e-13 * scale) << "sample " << s;
  }
  // Every unit of the second hidden layer dead: the output is the last bias.
  const Eigen::Index b1 = arch.BiasOffset(1), b2 = arch.BiasOffset(2);
  for (int i = 0; i < 100; ++i) theta[b1 + i] = -1e4;
  const Mlp<double> dead(arch, theta);
  dead.Evaluate(X, E, &ws, 2);
  for (int s = 0; s < batch; ++s) {
    for (int i = 0; i < 3; ++i) ASSERT_EQ(E(i, s), theta[b2 + i]) << "sample " << s;
  }
}

TEST(Mlp, EvaluateKeepsNoTape) {
  MlpArchitecture arch{{2, 3, 1}, {Activation::Relu()}};
  Rng rng(3);
  const Mlp<double> net(arch, RandomVector(arch.num_parameters(), 1.0, rng));
  MlpWorkspace ws(arch, 4);
  Eigen::MatrixXd Y;
  net.Forward(Eigen::MatrixXd::Ones(2, 4), &Y, nullptr, &ws);
  Eigen::MatrixXd E(1, 4);
  net.Evaluate(Eigen::MatrixXd::Ones(2, 4), E, &ws);
  Eigen::VectorXd grad;
  try {
    net.Backward(Eigen::MatrixXd::Ones(1, 4), Eigen::MatrixXd(), &grad, nullptr, &ws);
    ADD_FAILURE() << "Backward after Evaluate did not throw";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("Evaluate, which keeps no tape"), std::string::npos)
        << e.what();
  }
  Eigen::MatrixXd wrong(2, 4);
  EXPECT_THROW(net.Evaluate(Eigen::MatrixXd::Ones(2, 4), wrong, &ws), Error);
  EXPECT_THROW(net.Evaluate(Eigen::MatrixXd::Ones(3, 4), E, &ws), Error);
}

// L(theta, X) = sum_b gy_b . y_b + <GJ_b, J_b>, evaluated with Jets seeded on
// parameters [start, start + 8).
double JetLossAndGradientBlock(const Mlp<double>& net, const Eigen::MatrixXd& X,
                               const Eigen::MatrixXd& gy, const Eigen::MatrixXd& gj,
                               Eigen::Index start, Eigen::VectorXd* grad) {
  Mlp<Jet8> jnet = net.cast<Jet8>();
  for (int k = 0; k < kJetSize && start + k < net.num_parameters(); ++k) {
    jnet.mutable_parameters()[start + k].v[k] = 1.0;
  }
  Jet8 loss(0.0);
  const int n0 = net.num_inputs();
  for (Eigen::Index b = 0; b < X.cols(); ++b) {
    Eigen::Matrix<Jet8, Eigen::Dynamic, 1> y;
    Eigen::Matrix<Jet8, Eigen::Dynamic, Eigen::Dynamic> jac;
    jnet.ValueAndJacobian(Eigen::VectorXd(X.col(b)), &y, &jac);
    for (Eigen::Index k = 0; k < y.size(); ++k) {
      loss += gy(k, b) * y[k];
      for (int i = 0; i < n0; ++i) loss += gj(k, b * n0 + i) * jac(k, i);
    }
  }
  for (int k = 0; k < kJetSize && start + k < net.num_parameters(); ++k) (*grad)[start + k] = loss.v[k];
  return loss.a;
}

double DoubleLoss(const Mlp<double>& net, const Eigen::MatrixXd& X, const Eigen::MatrixXd& gy,
                  const Eigen::MatrixXd& gj) {
  double loss = 0.0;
  for (Eigen::Index b = 0; b < X.cols(); ++b) {
    Eigen::VectorXd y;
    Eigen::MatrixXd jac;
    net.ValueAndJacobian(Eigen::VectorXd(X.col(b)), &y, &jac);
    loss += gy.col(b).dot(y) + (gj.middleCols(b * net.num_inputs(), net.num_inputs()).cwiseProduct(jac)).sum();
  }
  return loss;
}

// Backward's parameter and input gradients (chunks of 4 samples) of the loss of
// JetLossAndGradientBlock, and the parameter gradient from Jets in blocks of 8.
struct ReverseAndJets {
  Eigen::VectorXd reverse, jets;
  Eigen::MatrixXd input;
};
ReverseAndJets ReverseAndJetGradients(const Mlp<double>& net, const Eigen::MatrixXd& X,
                                      const Eigen::MatrixXd& gy, const Eigen::MatrixXd& gj,
                                      bool jacobian_loss) {
  ReverseAndJets g;
  MlpWorkspace ws(net.architecture(), static_cast<int>(X.cols()), 4);
  Eigen::MatrixXd Y, J;
  net.Forward(X, &Y, jacobian_loss ? &J : nullptr, &ws);
  net.Backward(gy, jacobian_loss ? gj : Eigen::MatrixXd(), &g.reverse, &g.input, &ws);
  g.jets.resize(net.num_parameters());
  for (Eigen::Index s = 0; s < net.num_parameters(); s += kJetSize) {
    JetLossAndGradientBlock(net, X, gy, gj, s, &g.jets);
  }
  return g;
}

void CheckReverseMode(bool jacobian_loss) {
  Rng rng(jacobian_loss ? 21 : 20);
  for (const Activation& act : EveryActivation()) {
    const Mlp<double> net = SmallNet(act, 14);
    const int batch = 9;
    const Eigen::MatrixXd X = RandomMatrix(3, batch, 1.0, rng);
    const Eigen::MatrixXd gy = RandomMatrix(2, batch, 1.0, rng);
    const Eigen::MatrixXd gj =
        jacobian_loss ? RandomMatrix(2, 3 * batch, 1.0, rng) : Eigen::MatrixXd::Zero(2, 3 * batch);
    // Mode 2: Jets on the parameters.
    const ReverseAndJets g = ReverseAndJetGradients(net, X, gy, gj, jacobian_loss);
    const Eigen::VectorXd& grad = g.reverse;
    const Eigen::VectorXd& jet_grad = g.jets;
    const Eigen::MatrixXd& gx = g.input;
    const double scale = jet_grad.cwiseAbs().maxCoeff();
    EXPECT_GT(scale, 1e-3);
    EXPECT_LT((grad - jet_grad).cwiseAbs().maxCoeff(), 1e-8 * scale) << ActivationName(act.kind);

    // Mode 3: central differences on every parameter.
    const double h = 1e-5;
    double fd_err = 0.0;
    for (Eigen::Index p = 0; p < net.num_parameters(); ++p) {
      Mlp<double> plus = net, minus = net;
      plus.mutable_parameters()[p] += h;
      minus.mutable_parameters()[p] -= h;
      const double fd = (DoubleLoss(plus, X, gy, gj) - DoubleLoss(minus, X, gy, gj)) / (2 * h);
      fd_err = std::max(fd_err, std::abs(fd - grad[p]));
    }
    // relu is piecewise linear in theta: exact unless a step crosses a kink.
    EXPECT_LT(fd_err, 1e-8 * scale) << ActivationName(act.kind);

    // Input gradient against central differences in x.
    for (int b = 0; b < batch; b += 4) {
      for (int i = 0; i < 3; ++i) {
        Eigen::MatrixXd xp = X, xm = X;
        xp(i, b) += h;
        xm(i, b) -= h;
        const double fd = (DoubleLoss(net, xp, gy, gj) - DoubleLoss(net, xm, gy, gj)) / (2 * h);
        EXPECT_NEAR(gx(i, b), fd, 1e-7 * (1.0 + std::abs(fd))) << ActivationName(act.kind);
      }
    }
  }
}

TEST(Mlp, ReverseModeValueLossMatchesJetsAndFiniteDifferences) { CheckReverseMode(false); }

TEST(Mlp, ReverseModeJacobianLossMatchesJetsAndFiniteDifferences) { CheckReverseMode(true); }

// Wide hidden layers (both sides above 16) take the plain transposed product in the
// reverse sweep, thin ones a transposed copy of W: both against Jets.
TEST(Mlp, ReverseModeWithWideAndThinLayersMatchesJets) {
  Rng rng(23);
  for (const Activation& act : {Activation::Relu(), Activation::Softplus(), Activation::Tanh()}) {
    MlpArchitecture arch{{3, 20, 18, 2}, {act, act}};
    const Mlp<double> net(arch, RandomVector(arch.num_parameters(), 0.4, rng));
    const int batch = 7;
    const Eigen::MatrixXd X = RandomMatrix(3, batch, 1.0, rng);
    const Eigen::MatrixXd gy = RandomMatrix(2, batch, 1.0, rng);
    for (bool jacobian_loss : {false, true}) {
      const Eigen::MatrixXd gj = jacobian_loss ? RandomMatrix(2, 3 * batch, 1.0, rng)
                                               : Eigen::MatrixXd::Zero(2, 3 * batch);
      const ReverseAndJets g = ReverseAndJetGradients(net, X, gy, gj, jacobian_loss);
      const double scale = g.jets.cwiseAbs().maxCoeff();
      EXPECT_GT(scale, 1e-3);
      EXPECT_LT((g.reverse - g.jets).cwiseAbs().maxCoeff(), 1e-10 * scale)
          << ActivationName(act.kind) << (jacobian_loss ? " with Jacobian loss" : "");
    }
  }
}

TEST(Mlp, InputGradientMatchesJetsWithoutJacobianLoss) {
  using Jet3 = ceres::Jet<double, 3>;
  Rng rng(31);
  const Mlp<double> net = SmallNet(Activation::Tanh(), 15);
  const Eigen::MatrixXd X = RandomMatrix(3, 5, 1.0, rng);
  const Eigen::MatrixXd gy = RandomMatrix(2, 5, 1.0, rng);
  MlpWorkspace ws(net.architecture(), 5);
  Eigen::MatrixXd Y, gx;
  net.Forward(X, &Y, nullptr, &ws);
  net.Backward(gy, Eigen::MatrixXd(), nullptr, &gx, &ws);
  for (int b = 0; b < 5; ++b) {
    Eigen::Matrix<Jet3, Eigen::Dynamic, 1> xj(3);
    for (int i = 0; i < 3; ++i) xj[i] = Jet3(X(i, b), i);
    const auto y = net(xj);
    Jet3 l(0.0);
    for (int k = 0; k < 2; ++k) l += gy(k, b) * y[k];
    for (int i = 0; i < 3; ++i) EXPECT_NEAR(gx(i, b), l.v[i], 1e-13);
  }
}

TEST(Mlp, ResultsIdenticalAtAnyThreadCount) {
  Rng rng(41);
  MlpArchitecture arch{{6, 40, 30, 4}, {Activation::Softplus(), Activation::Tanh()}};
  const Mlp<double> net(arch, RandomVector(arch.num_parameters(), 0.3, rng));
  const int batch = 700;
  const Eigen::MatrixXd X = RandomMatrix(6, batch, 1.0, rng);
  const Eigen::MatrixXd gy = RandomMatrix(4, batch, 1.0, rng);
  const Eigen::MatrixXd gj = RandomMatrix(4, 6 * batch, 1.0, rng);
  Eigen::VectorXd reference;
  Eigen::MatrixXd reference_gx;
  for (int threads : {1, 2, 3, 5}) {
    MlpWorkspace ws(arch, batch, 128);
    Eigen::MatrixXd Y, J, gx;
    Eigen::VectorXd grad;
    net.Forward(X, &Y, &J, &ws, threads);
    net.Backward(gy, gj, &grad, &gx, &ws, threads);
    if (threads == 1) {
      reference = grad;
      reference_gx = gx;
    } else {
      EXPECT_TRUE(grad == reference) << threads << " threads";
      EXPECT_TRUE(gx == reference_gx) << threads << " threads";
    }
  }
  // A different chunking sums in another order: equal to rounding only.
  MlpWorkspace ws(arch, batch, 1000);
  Eigen::MatrixXd Y, J;
  Eigen::VectorXd grad;
  net.Forward(X, &Y, &J, &ws);
  net.Backward(gy, gj, &grad, nullptr, &ws);
  EXPECT_LT((grad - reference).cwiseAbs().maxCoeff(), 1e-10 * reference.cwiseAbs().maxCoeff());
}

TEST(Mlp, AccumulatingBackwardAddsTheSameGradient) {
  Rng rng(47);
  MlpArchitecture arch{{6, 30, 20, 6}, {Activation::Relu(), Activation::Relu()}};
  const Mlp<double> net(arch, RandomVector(arch.num_parameters(), 0.3, rng));
  const int batch = 90;
  const Eigen::MatrixXd X = RandomMatrix(6, batch, 1.0, rng);
  const Eigen::MatrixXd gy = RandomMatrix(6, batch, 1.0, rng);
  const Eigen::VectorXd start = RandomVector(arch.num_parameters(), 1.0, rng);
  // One chunk (written in place) and three chunks (summed slots), at 1 and 2 threads.
  for (int chunk : {batch, 32}) {
    for (int threads : {1, 2}) {
      MlpWorkspace ws(arch, batch, chunk, false);
      Eigen::MatrixXd Y, gx, gx_acc;
      Eigen::VectorXd grad;
      net.Forward(X, &Y, nullptr, &ws, threads);
      net.Backward(gy, Eigen::MatrixXd(), &grad, &gx, &ws, threads);
      Eigen::VectorXd acc = start;
      net.Backward(gy, Eigen::MatrixXd(), &acc, nullptr, &ws, threads, /*accumulate=*/true);
      EXPECT_LT((acc - start - grad).cwiseAbs().maxCoeff(),
                1e-12 * (1.0 + grad.cwiseAbs().maxCoeff()))
          << "chunk " << chunk << ", " << threads << " threads";
      // BackwardAccumulate into a segment of a longer vector, gy through a Ref.
      Eigen::VectorXd longer = Eigen::VectorXd::Zero(arch.num_parameters() + 5);
      longer.head(arch.num_parameters()) = start;
      net.BackwardAccumulate(gy, longer.head(arch.num_parameters()), &gx_acc, &ws, threads);
      EXPECT_LT((longer.head(arch.num_parameters()) - acc).cwiseAbs().maxCoeff(),
                1e-12 * (1.0 + acc.cwiseAbs().maxCoeff()));
      EXPECT_TRUE(longer.tail(5).isZero(0.0));
      EXPECT_TRUE(gx_acc == gx);
      // Cotangent buffers from a wider scratch workspace: the same bits, and the
      // forward workspace's own buffers stay untouched.
      MlpWorkspace scratch(arch, batch, chunk + 7, false);
      Eigen::VectorXd via_scratch = start;
      Eigen::MatrixXd gx_scratch;
      net.BackwardAccumulate(gy, via_scratch, &gx_scratch, &ws, threads, &scratch);
      EXPECT_TRUE(via_scratch == longer.head(arch.num_parameters()));
      EXPECT_TRUE(gx_scratch == gx);
    }
  }
  // ReLU keeps no g' on a plain forward pass (it is read off the layer output);
  // the gradients equal those after a forward pass that stored g' for the Jacobian.
  {
    MlpWorkspace plain(arch, batch, 32, false), with_jacobian(arch, batch, 32, true);
    Eigen::MatrixXd Y1, Y2, J, gx1, gx2;
    Eigen::VectorXd g1, g2;
    net.Forward(X, &Y1, nullptr, &plain, 2);
    net.Forward(X, &Y2, &J, &with_jacobian, 2);
    net.Backward(gy, Eigen::MatrixXd(), &g1, &gx1, &plain, 2);
    net.Backward(gy, Eigen::MatrixXd(), &g2, &gx2, &with_jacobian, 2);
    EXPECT_TRUE(Y1 == Y2);
    EXPECT_TRUE(g1 == g2);
    EXPECT_TRUE(gx1 == gx2);
  }
  // A scratch workspace with narrower chunks than the forward one is refused.
  {
    MlpWorkspace ws(arch, batch, 32, false), narrow(arch, batch, 16, false);
    Eigen::MatrixXd Y;
    net.Forward(X, &Y, nullptr, &ws);
    Eigen::VectorXd acc = start;
    EXPECT_THROW(net.BackwardAccumulate(gy, acc, nullptr, &ws, 1, &narrow), Error);
  }
  // Accumulating into a vector of the wrong size is an error, not a resize.
  MlpWorkspace ws(arch, batch, batch, false);
  Eigen::MatrixXd Y;
  net.Forward(X, &Y, nullptr, &ws);
  Eigen::VectorXd wrong = Eigen::VectorXd::Zero(3);
  EXPECT_THROW(net.Backward(gy, Eigen::MatrixXd(), &wrong, nullptr, &ws, 1, true), Error);
}

TEST(Mlp, WorkspaceReuseAcrossBatchSizes) {
  Rng rng(51);
  const Mlp<double> net = SmallNet(Activation::Softplus(), 16);
  MlpWorkspace ws(net.architecture(), 10, 8);
  for (int batch : {10, 3, 25, 1}) {
    const Eigen::MatrixXd X = RandomMatrix(3, batch, 1.0, rng);
    Eigen::MatrixXd Y;
    net.Forward(X, &Y, nullptr, &ws);
    for (int b = 0; b < batch; ++b) {
      EXPECT_LT((Y.col(b) - net(Eigen::VectorXd(X.col(b)))).cwiseAbs().maxCoeff(), 1e-13);
    }
  }
}

TEST(Mlp, CastKeepsArchitectureAndValues) {
  const Mlp<double> net = SmallNet(Activation::Elu(), 17);
  const Mlp<Jet8> jnet = net.cast<Jet8>();
  EXPECT_EQ(jnet.architecture(), net.architecture());
  const Eigen::Vector3d x(0.1, -0.4, 0.9);
  const auto yj = jnet(x);
  const Eigen::VectorXd y = net(x);
  // The Jet path and the (vectorised) double path round differently on different
  // instruction sets: the values agree to a few ulps, not to the last bit.
  for (int k = 0; k < 2; ++k) {
    EXPECT_NEAR(yj[k].a, y[k], 1e-14 * std::max(1.0, std::abs(y[k])));
    EXPECT_EQ(yj[k].v.norm(), 0.0);
  }
}

TEST(Mlp, RejectsWrongSizes) {
  MlpArchitecture arch{{2, 3, 1}, {Activation::Tanh()}};
  EXPECT_THROW(Mlp<double>(arch, Eigen::VectorXd::Zero(5)), Error);
  EXPECT_THROW(Mlp<double>(MlpArchitecture{{2, 3, 1}, {}}), Error);
  const Mlp<double> net(arch);
  EXPECT_EQ(net.num_parameters(), 3 * 3 + 4);
  EXPECT_THROW(net(Eigen::Vector3d::Zero()), Error);
  MlpWorkspace ws(arch, 4);
  Eigen::MatrixXd Y;
  EXPECT_THROW(net.Forward(Eigen::MatrixXd::Zero(3, 4), &Y, nullptr, &ws), Error);
  net.Forward(Eigen::MatrixXd::Zero(2, 4), &Y, nullptr, &ws);
  Eigen::VectorXd grad;
  EXPECT_THROW(net.Backward(Eigen::MatrixXd::Zero(1, 5), Eigen::MatrixXd(), &grad, nullptr, &ws), Error);
  EXPECT_THROW(net.Backward(Eigen::MatrixXd(), Eigen::MatrixXd::Zero(1, 8), &grad, nullptr, &ws), Error);
}

}  // namespace
}  // namespace diffdyn
