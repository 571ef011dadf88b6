// Mlp<float>: the batched float paths pinned to the double paths on the same
// (float-representable) weights and inputs, for every activation; values,
// stacked input Jacobians (forward chain and reverse sweeps), parameter and
// input gradients; float results identical at any thread count.
//
// Tolerance: both paths see the same rounded inputs, so their difference is the
// float arithmetic's rounding, bounded by a few units of float's epsilon times
// the sizes of the sums (layer widths of 40 and 30 here) and the output scale.
#include <cmath>
#include <limits>
#include <vector>

#include <gtest/gtest.h>

#include "diffdyn/models/mlp.h"
#include "diffdyn/models/random.h"

namespace diffdyn {
namespace {

constexpr double kFloatEps = std::numeric_limits<float>::epsilon();

Eigen::MatrixXf RandomMatrixF(Eigen::Index rows, Eigen::Index cols, double scale, Rng& rng) {
  Eigen::MatrixXf m(rows, cols);
  for (Eigen::Index i = 0; i < m.size(); ++i) {
    m.data()[i] = static_cast<float>(scale * StandardNormal(rng));
  }
  return m;
}

// Largest |a - b| relative to the larger of max |b| and 1.
double RelativeGap(const Eigen::MatrixXf& a, const Eigen::MatrixXd& b) {
  EXPECT_EQ(a.rows(), b.rows());
  EXPECT_EQ(a.cols(), b.cols());
  const double scale = std::max(1.0, b.cwiseAbs().maxCoeff());
  return (a.cast<double>() - b).cwiseAbs().maxCoeff() / scale;
}

struct FloatCase {
  Mlp<float> net_f;
  Mlp<double> net_d;  // the same weights, exactly
  Eigen::MatrixXf x, gy, gj;
};

// A 6-40-30-4 network with hidden activation `act`, a batch of `batch` inputs and
// cotangents of its values and Jacobians.
FloatCase MakeCase(const Activation& act, int batch, std::uint64_t seed) {
  Rng rng(seed);
  MlpArchitecture arch{{6, 40, 30, 4}, {act, act}};
  FloatCase c;
  c.net_f = Mlp<float>(arch, RandomMatrixF(arch.num_parameters(), 1, 0.3, rng));
  c.net_d = c.net_f.cast<double>();
  c.x = RandomMatrixF(6, batch, 1.0, rng);
  c.gy = RandomMatrixF(4, batch, 1.0, rng);
  c.gj = RandomMatrixF(4, 6 * batch, 1.0, rng);
  return c;
}

std::vector<Activation> ActivationsToCheck() {
  return {Activation::Relu(), Activation::Softplus(), Activation::Softplus(2.5),
          Activation::Tanh(), Activation::Sigmoid(),  Activation::Elu(0.8),
          Activation::Cos(),  Activation::Linear()};
}

TEST(MlpFloat, ValuesJacobiansAndGradientsMatchDouble) {
  for (const Activation& act : ActivationsToCheck()) {
    SCOPED_TRACE(ActivationName(act.kind));
    const FloatCase c = MakeCase(act, 300, 5);
    MlpWorkspaceF ws_f(c.net_f.architecture(), 300);
    MlpWorkspace ws_d(c.net_d.architecture(), 300);
    Eigen::MatrixXf y_f, j_f, gx_f;
    Eigen::MatrixXd y_d, j_d, gx_d;
    Eigen::VectorXf grad_f;
    Eigen::VectorXd grad_d;
    c.net_f.Forward(c.x, &y_f, &j_f, &ws_f);
    c.net_f.Backward(c.gy, c.gj, &grad_f, &gx_f, &ws_f);
    c.net_d.Forward(c.x.cast<double>(), &y_d, &j_d, &ws_d);
    c.net_d.Backward(c.gy.cast<double>(), c.gj.cast<double>(), &grad_d, &gx_d, &ws_d);
    EXPECT_LT(RelativeGap(y_f, y_d), 64 * kFloatEps);
    EXPECT_LT(RelativeGap(j_f, j_d), 64 * kFloatEps);
    EXPECT_LT(RelativeGap(gx_f, gx_d), 64 * kFloatEps);
    // Gradients sum 300 samples' terms: the sum's rounding adds to the layers'.
    EXPECT_LT(RelativeGap(grad_f, grad_d), 256 * kFloatEps);
    // The float path really computes in float: it is not the double result rounded.
    EXPECT_GT((y_f.cast<double>() - y_d).cwiseAbs().maxCoeff(), 0.0);
  }
}

TEST(MlpFloat, EvaluateAndReverseJacobiansMatchForward) {
  const FloatCase c = MakeCase(Activation::Softplus(), 200, 13);
  MlpWorkspaceF ws(c.net_f.architecture(), 200);
  Eigen::MatrixXf y, j, y_rev, j_rev;
  c.net_f.Forward(c.x, &y, &j, &ws);
  Eigen::MatrixXf y_eval(4, 200);
  c.net_f.Evaluate(c.x, y_eval, &ws);
  if (kHaveLayerKernel) {
    // The layer kernel sums in another order than the BLAS products: rounding only.
    EXPECT_LT(RelativeGap(y_eval, y.cast<double>()), 64 * kFloatEps);
  } else {
    EXPECT_TRUE(y_eval == y);  // the same products in float without the kernel
  }
  c.net_f.InputJacobianReverse(c.x, &y_rev, &j_rev, &ws);
  EXPECT_LT(RelativeGap(j_rev, j.cast<double>()), 64 * kFloatEps);
}

// Evaluate in float with ReLU (the layer kernel's skip of units dead for a block,
// where built) against the double network of the same weights, at a batch that
// is not a multiple of the kernel's block, and the same at any thread count.
TEST(MlpFloat, ReluEvaluateMatchesDoubleAtAnyThreadCount) {
  const FloatCase c = MakeCase(Activation::Relu(), 203, 19);
  MlpWorkspaceF ws(c.net_f.architecture(), 203, 64, false);
  Eigen::MatrixXf one(4, 203), two(4, 203);
  c.net_f.Evaluate(c.x, one, &ws, 1);
  c.net_f.Evaluate(c.x, two, &ws, 2);
  EXPECT_TRUE(one == two);
  MlpWorkspace wd(c.net_d.architecture(), 203);
  Eigen::MatrixXd yd;
  c.net_d.Forward(c.x.cast<double>(), &yd, nullptr, &wd);
  EXPECT_LT(RelativeGap(one, yd), 64 * kFloatEps);
}

TEST(MlpFloat, ResultsIdenticalAtAnyThreadCount) {
  const FloatCase c = MakeCase(Activation::Tanh(), 700, 17);
  Eigen::VectorXf reference;
  Eigen::MatrixXf reference_y, reference_gx;
  for (int threads : {1, 2, 3}) {
    MlpWorkspaceF ws(c.net_f.architecture(), 700, 128);
    Eigen::MatrixXf y, j, gx;
    Eigen::VectorXf grad;
    c.net_f.Forward(c.x, &y, &j, &ws, threads);
    c.net_f.Backward(c.gy, c.gj, &grad, &gx, &ws, threads);
    if (threads == 1) {
      reference = grad;
      reference_y = y;
      reference_gx = gx;
    } else {
      EXPECT_TRUE(grad == reference) << threads << " threads";
      EXPECT_TRUE(y == reference_y) << threads << " threads";
      EXPECT_TRUE(gx == reference_gx) << threads << " threads";
    }
  }
}

}  // namespace
}  // namespace diffdyn
