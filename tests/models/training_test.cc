// Initialisation, Adam, losses and mini-batches.
#include <algorithm>
#include <cmath>
#include <set>
#include <vector>

#include <gtest/gtest.h>

#include "diffdyn/models/adam.h"
#include "diffdyn/models/init.h"
#include "diffdyn/models/losses.h"
#include "diffdyn/models/mlp.h"

namespace diffdyn {
namespace {

MlpArchitecture WideArch() { return {{300, 400, 50}, {Activation::Relu()}}; }

double Variance(const Eigen::VectorXd& v) {
  const double mean = v.mean();
  return (v.array() - mean).square().mean();
}

TEST(Init, TorchDefaultIsUniformWithBoundOneOverSqrtFanIn) {
  const MlpArchitecture arch = WideArch();
  Rng rng(1);
  const Eigen::VectorXd theta = InitializeParameters(arch, InitOptions{}, rng);
  for (int l = 0; l < 2; ++l) {
    const double bound = 1.0 / std::sqrt(arch.sizes[l]);
    const Eigen::VectorXd w =
        theta.segment(arch.WeightOffset(l), arch.BiasOffset(l) - arch.WeightOffset(l));
    const Eigen::VectorXd b = theta.segment(arch.BiasOffset(l), arch.sizes[l + 1]);
    EXPECT_LE(w.cwiseAbs().maxCoeff(), bound);
    EXPECT_GT(w.cwiseAbs().maxCoeff(), 0.99 * bound);
    EXPECT_LE(b.cwiseAbs().maxCoeff(), bound);
    EXPECT_NEAR(Variance(w), bound * bound / 3.0, 0.03 * bound * bound / 3.0);
  }
}

TEST(Init, XavierAndKaimingHaveTheirVariance) {
  const MlpArchitecture arch = WideArch();
  struct Case {
    InitScheme scheme;
    double expected_var;  // for layer 0, gain g = 1.5
  };
  const double g = 1.5, fi = 300, fo = 400;
  for (const Case& c : {Case{InitScheme::kXavierUniform, g * g * 2.0 / (fi + fo)},
                        Case{InitScheme::kXavierNormal, g * g * 2.0 / (fi + fo)},
                        Case{InitScheme::kKaimingUniform, g * g / fi},
                        Case{InitScheme::kKaimingNormal, g * g / fi}}) {
    Rng rng(2);
    const Eigen::VectorXd theta = InitializeParameters(arch, {c.scheme, g, 1.0, 0.1}, rng);
    const Eigen::VectorXd w = theta.segment(0, arch.BiasOffset(0));
    EXPECT_NEAR(Variance(w), c.expected_var, 0.03 * c.expected_var);
    EXPECT_NEAR(w.mean(), 0.0, 0.01 * std::sqrt(c.expected_var));
    EXPECT_TRUE((theta.segment(arch.BiasOffset(0), 400).array() == 0.1).all());
  }
}

TEST(Init, SameSeedSameParameters) {
  const MlpArchitecture arch{{2, 16, 1}, {Activation::Tanh()}};
  const Mlp<double> a = MakeInitializedMlp(arch, InitOptions::Ddn(), 42);
  const Mlp<double> b = MakeInitializedMlp(arch, InitOptions::Ddn(), 42);
  const Mlp<double> c = MakeInitializedMlp(arch, InitOptions::Ddn(), 43);
  EXPECT_TRUE(a.parameters() == b.parameters());
  EXPECT_FALSE(a.parameters() == c.parameters());
  EXPECT_THROW(ParseInitScheme("he"), Error);
  EXPECT_EQ(ParseInitScheme("xavier-normal"), InitScheme::kXavierNormal);
}

// Independent scalar transcription of PyTorch's Adam / AdamW update.
void ScalarAdam(const AdamOptions& o, int t, double g, double* p, double* m, double* v,
                double* vmax) {
  if (o.decoupled_weight_decay) {
    *p *= 1 - o.learning_rate * o.weight_decay;
  } else {
    g += o.weight_decay * *p;
  }
  *m = o.beta1 * *m + (1 - o.beta1) * g;
  *v = o.beta2 * *v + (1 - o.beta2) * g * g;
  *vmax = std::max(*vmax, *v);
  const double vv = o.amsgrad ? *vmax : *v;
  const double denom = std::sqrt(vv) / std::sqrt(1 - std::pow(o.beta2, t)) + o.epsilon;
  *p -= o.learning_rate / (1 - std::pow(o.beta1, t)) * *m / denom;
}

TEST(Adam, MatchesScalarUpdateWithAmsgradAndWeightDecay) {
  for (bool amsgrad : {false, true}) {
    for (bool decoupled : {false, true}) {
      AdamOptions o;
      o.learning_rate = 0.05;
      o.weight_decay = 0.01;
      o.amsgrad = amsgrad;
      o.decoupled_weight_decay = decoupled;
      Rng rng(5);
      Eigen::VectorXd theta(6);
      for (int i = 0; i < 6; ++i) theta[i] = StandardNormal(rng);
      Eigen::VectorXd p = theta, m = Eigen::VectorXd::Zero(6), v = m, vmax = m;
      Adam adam(6, o);
      for (int t = 1; t <= 5; ++t) {
        Eigen::VectorXd grad(6);
        // Shrinking gradients so that AMSGrad's max matters.
        for (int i = 0; i < 6; ++i) grad[i] = StandardNormal(rng) / t;
        adam.Step(grad, &theta);
        for (int i = 0; i < 6; ++i) ScalarAdam(o, t, grad[i], &p[i], &m[i], &v[i], &vmax[i]);
        EXPECT_LT((theta - p).cwiseAbs().maxCoeff(), 1e-14);
      }
      EXPECT_EQ(adam.steps(), 5);
    }
  }
}

TEST(Adam, MinimisesAQuadratic) {
  Eigen::VectorXd theta = Eigen::VectorXd::Constant(3, 2.0);
  const Eigen::Vector3d target(1.0, -1.0, 0.5);
  Adam adam(3, {.learning_rate = 0.05});
  for (int i = 0; i < 2000; ++i) adam.Step(2.0 * (theta - target), &theta);
  EXPECT_LT((theta - target).norm(), 1e-3);
  EXPECT_THROW(Adam(3, {.learning_rate = -1.0}), Error);
}

TEST(Losses, SquaredErrorGradientMatchesCentralDifferences) {
  Rng rng(6);
  Eigen::MatrixXd pred(2, 5), target(2, 5);
  for (int i = 0; i < 10; ++i) {
    pred.data()[i] = StandardNormal(rng);
    target.data()[i] = StandardNormal(rng);
  }
  Eigen::MatrixXd grad;
  const double loss = SquaredErrorLoss(pred, target, 5, &grad);
  EXPECT_NEAR(loss, (pred - target).squaredNorm() / 5, 1e-15);
  const double h = 1e-6;
  for (int i = 0; i < 10; ++i) {
    Eigen::MatrixXd p = pred, m = pred;
    p.data()[i] += h;
    m.data()[i] -= h;
    const double fd = (SquaredErrorLoss(p, target, 5, nullptr) - SquaredErrorLoss(m, target, 5, nullptr)) / (2 * h);
    EXPECT_NEAR(grad.data()[i], fd, 1e-8);
  }
  EXPECT_NEAR(MeanSquaredError(pred, target), (pred - target).squaredNorm() / 10, 1e-15);
  EXPECT_THROW(SquaredErrorLoss(pred, target.leftCols(4), 5, nullptr), Error);
}

TEST(MiniBatcher, EpochsArePermutationsAndSeeded) {
  MiniBatcher a(103, 10, true, 42), b(103, 10, true, 42);
  EXPECT_EQ(a.num_batches(), 10);
  EXPECT_EQ(MiniBatcher(103, 10, false, 1).num_batches(), 11);
  std::vector<int> first;
  for (int epoch = 0; epoch < 3; ++epoch) {
    a.Shuffle();
    b.Shuffle();
    std::vector<int> seen;
    for (int i = 0; i < a.num_batches(); ++i) {
      const auto ia = a.Batch(i);
      const auto ib = b.Batch(i);
      EXPECT_TRUE(std::equal(ia.begin(), ia.end(), ib.begin(), ib.end()));
      seen.insert(seen.end(), ia.begin(), ia.end());
    }
    EXPECT_EQ(seen.size(), 100u);
    EXPECT_EQ(std::set<int>(seen.begin(), seen.end()).size(), 100u);
    if (epoch == 0) first = seen;
    if (epoch == 1) {
      EXPECT_NE(first, seen);
    }
  }
  Eigen::MatrixXd src(2, 12), dst;
  for (int i = 0; i < 24; ++i) src.data()[i] = i;
  const std::vector<int> idx = {5, 0};
  GatherColumnBlocks(src, idx, 2, &dst);
  EXPECT_TRUE(dst.leftCols(2) == src.middleCols(10, 2));
  EXPECT_TRUE(dst.rightCols(2) == src.leftCols(2));
}

// Value + Jacobian training of a small softplus DDN on sin: the losses fall.
TEST(Training, AdamWithJacobianLossFitsSine) {
  const MlpArchitecture arch{{1, 32, 1}, {Activation::Softplus()}};
  Mlp<double> net = MakeInitializedMlp(arch, InitOptions{}, 3);
  const int n = 256;
  Eigen::MatrixXd X(1, n), Y(1, n), DY(1, n);
  for (int i = 0; i < n; ++i) {
    X(0, i) = -M_PI + 2 * M_PI * i / (n - 1);
    Y(0, i) = std::sin(X(0, i));
    DY(0, i) = std::cos(X(0, i));
  }
  Adam adam(net.num_parameters(), {.learning_rate = 1e-2, .weight_decay = 1e-6, .amsgrad = true});
  MlpWorkspace ws(arch, n);
  Eigen::MatrixXd pred, jac, gy, gj;
  Eigen::VectorXd grad;
  double first = 0.0, last = 0.0;
  for (int it = 0; it < 400; ++it) {
    net.Forward(X, &pred, &jac, &ws);
    const double loss = SquaredErrorLoss(pred, Y, n, &gy) + SquaredErrorLoss(jac, DY, n, &gj);
    if (it == 0) first = loss;
    last = loss;
    net.Backward(gy, gj, &grad, nullptr, &ws);
    adam.Step(grad, &net.mutable_parameters());
  }
  EXPECT_LT(last, 0.02 * first);
}

}  // namespace
}  // namespace diffdyn
