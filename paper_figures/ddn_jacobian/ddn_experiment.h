// The Jacobian-accuracy experiment of the deep differential network paper
// (Lutter & Peters, Figure 2), as the authors' public code runs it.
//
// Test functions and their symbolic derivatives:
//
//   1-D  f(x) = sin x,            f' = cos x,            f'' = -sin x,     x in [-pi, pi]
//   2-D  f(x, y) = cos x sin y,   J = [-sin x sin y, cos x cos y],
//        H = [[-cos x sin y, -sin x cos y], [-sin x cos y, -cos x sin y]]
//
// Training data: n uniform samples; Gaussian noise (std 1e-3) added to the
// inputs, to f and to the Jacobian labels. Networks: width 128, one hidden
// layer in 1-D, two in 2-D, linear output. Two losses, both a per-sample sum
// averaged over the batch:
//
//   "f+J" (the authors' type 1):  L = mean_b ||f_b - y_b||^2 + ||J_b - dy_b||^2
//   "f"   (type 2):               L = mean_b ||f_b - y_b||^2
//
// Adam with AMSGrad, lr 1e-3, weight decay 1e-6, batch 256 (incomplete batches
// dropped), Xavier-normal init (gain sqrt 2 hidden, 1 output, biases 0.1).
// The test MSE of f, J and H is the mean over all entries on a grid (100
// points in 1-D, 50 x 50 in 2-D); H comes from the network's closed-form
// second-order chain (Mlp::ValueJacobianHessian).
#pragma once

#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <numbers>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/models/adam.h"
#include "diffdyn/models/init.h"
#include "diffdyn/models/losses.h"
#include "diffdyn/models/mlp.h"
#include "diffdyn/models/random.h"

namespace diffdyn::ddn_figure {

/// Settings of one training run (defaults: the authors' full configuration).
struct Config {
  int dim = 1;                  ///< 1: sin x; 2: cos x sin y
  Activation activation = Activation::Softplus();
  bool jacobian_loss = true;    ///< "f+J" loss when true, "f" only otherwise
  int n_train = 25600;
  int batch = 256;
  int epochs = 500;
  int width = 128;
  double noise = 1e-3;
  double learning_rate = 1e-3;
  double weight_decay = 1e-6;
  std::uint64_t seed = 42;
  int grid = 0;                 ///< test points per axis; 0: 100 in 1-D, 50 in 2-D
  int threads = 1;
  /// Called after every epoch with (epochs done, mean training loss), e.g. for a progress bar.
  std::function<void(int, double)> on_epoch;
};

/// Samples in columns: x (dim x n), f (1 x n), J (1 x dim n), H (1 x dim^2 n).
struct Dataset {
  Eigen::MatrixXd x, f, jac, hess;
};

/// f, J and H of the test function at the columns of x.
inline Dataset Evaluate(int dim, const Eigen::MatrixXd& x) {
  const Eigen::Index n = x.cols();
  Dataset d{x, Eigen::MatrixXd(1, n), Eigen::MatrixXd(1, dim * n), Eigen::MatrixXd(1, dim * dim * n)};
  for (Eigen::Index i = 0; i < n; ++i) {
    if (dim == 1) {
      const double s = std::sin(x(0, i)), c = std::cos(x(0, i));
      d.f(0, i) = s;
      d.jac(0, i) = c;
      d.hess(0, i) = -s;
    } else {
      const double sx = std::sin(x(0, i)), cx = std::cos(x(0, i));
      const double sy = std::sin(x(1, i)), cy = std::cos(x(1, i));
      d.f(0, i) = cx * sy;
      d.jac(0, 2 * i) = -sx * sy;
      d.jac(0, 2 * i + 1) = cx * cy;
      d.hess(0, 4 * i + 0) = -cx * sy;
      d.hess(0, 4 * i + 1) = -sx * cy;
      d.hess(0, 4 * i + 2) = -sx * cy;
      d.hess(0, 4 * i + 3) = -cx * sy;
    }
  }
  return d;
}

/// n uniform samples on [-pi, pi]^dim with N(0, noise^2) added to x, f and J.
inline Dataset MakeTrainingData(int dim, int n, double noise, Rng& rng) {
  Eigen::MatrixXd x(dim, n);
  for (Eigen::Index i = 0; i < x.size(); ++i) x.data()[i] = Uniform(rng, -std::numbers::pi, std::numbers::pi);
  Dataset d = Evaluate(dim, x);
  for (Eigen::Index i = 0; i < d.x.size(); ++i) d.x.data()[i] += noise * StandardNormal(rng);
  for (Eigen::Index i = 0; i < d.f.size(); ++i) d.f.data()[i] += noise * StandardNormal(rng);
  for (Eigen::Index i = 0; i < d.jac.size(); ++i) d.jac.data()[i] += noise * StandardNormal(rng);
  return d;
}

/// The test grid: `points` per axis, linspace(-pi, pi), x fastest in 2-D.
inline Dataset MakeTestGrid(int dim, int points) {
  const Eigen::VectorXd axis = Eigen::VectorXd::LinSpaced(points, -std::numbers::pi, std::numbers::pi);
  Eigen::MatrixXd x(dim, dim == 1 ? points : points * points);
  for (int j = 0; j < (dim == 1 ? 1 : points); ++j) {
    for (int i = 0; i < points; ++i) {
      x(0, j * points + i) = axis[i];
      if (dim == 2) x(1, j * points + i) = axis[j];
    }
  }
  return Evaluate(dim, x);
}

/// Network predictions on a dataset's inputs (same layout as Dataset).
inline Dataset Predict(const Mlp<double>& net, const Eigen::MatrixXd& x) {
  const int dim = static_cast<int>(x.rows());
  const Eigen::Index n = x.cols();
  Dataset d{x, Eigen::MatrixXd(1, n), Eigen::MatrixXd(1, dim * n), Eigen::MatrixXd(1, dim * dim * n)};
  Eigen::VectorXd y;
  Eigen::MatrixXd jac;
  std::vector<Eigen::MatrixXd> hess;
  for (Eigen::Index i = 0; i < n; ++i) {
    net.ValueJacobianHessian(x.col(i), &y, &jac, &hess);
    d.f(0, i) = y[0];
    for (int a = 0; a < dim; ++a) {
      d.jac(0, dim * i + a) = jac(0, a);
      for (int b = 0; b < dim; ++b) d.hess(0, dim * dim * i + dim * a + b) = hess[0](a, b);
    }
  }
  return d;
}

/// Test errors and the trained network of one run.
struct Result {
  double mse_f = 0.0, mse_j = 0.0, mse_h = 0.0;
  double final_train_loss = 0.0;
  double seconds = 0.0;
  Mlp<double> net;
};

/// The architecture of the experiment: dim - width (- width) - 1.
inline MlpArchitecture Architecture(const Config& config) {
  if (config.dim == 1) return {{1, config.width, 1}, {config.activation}};
  return {{2, config.width, config.width, 1}, {config.activation, config.activation}};
}

/// Trains one network and measures it on the test grid.
inline Result RunExperiment(const Config& config) {
  DIFFDYN_CHECK(config.dim == 1 || config.dim == 2, "dimension must be 1 or 2, got ", config.dim);
  const auto start = std::chrono::steady_clock::now();
  Rng rng(config.seed);
  const Dataset train = MakeTrainingData(config.dim, config.n_train, config.noise, rng);
  const MlpArchitecture arch = Architecture(config);
  Mlp<double> net(arch, InitializeParameters(arch, InitOptions::Ddn(), rng));
  Adam adam(net.num_parameters(), {.learning_rate = config.learning_rate,
                                   .weight_decay = config.weight_decay,
                                   .amsgrad = true});
  MiniBatcher batches(config.n_train, config.batch, true, rng());
  MlpWorkspace ws(arch, config.batch, MlpWorkspace::kDefaultChunkSize, config.jacobian_loss);
  Eigen::MatrixXd xb, fb, jb, pred, pred_jac, gy, gj;
  Eigen::VectorXd grad;
  const Eigen::MatrixXd no_cotangent;
  double epoch_loss = 0.0;
  for (int epoch = 0; epoch < config.epochs; ++epoch) {
    batches.Shuffle();
    epoch_loss = 0.0;
    for (int b = 0; b < batches.num_batches(); ++b) {
      const auto index = batches.Batch(b);
      const int nb = static_cast<int>(index.size());
      GatherColumnBlocks(train.x, index, 1, &xb);
      GatherColumnBlocks(train.f, index, 1, &fb);
      double loss = 0.0;
      if (config.jacobian_loss) {
        GatherColumnBlocks(train.jac, index, config.dim, &jb);
        net.Forward(xb, &pred, &pred_jac, &ws, config.threads);
        loss = SquaredErrorLoss(pred, fb, nb, &gy) + SquaredErrorLoss(pred_jac, jb, nb, &gj);
        net.Backward(gy, gj, &grad, nullptr, &ws, config.threads);
      } else {
        net.Forward(xb, &pred, nullptr, &ws, config.threads);
        loss = SquaredErrorLoss(pred, fb, nb, &gy);
        net.Backward(gy, no_cotangent, &grad, nullptr, &ws, config.threads);
      }
      if (!std::isfinite(loss)) throw NumericalError(StrCat("training diverged at epoch ", epoch));
      epoch_loss += loss / batches.num_batches();
      adam.Step(grad, &net.mutable_parameters());
    }
    if (config.on_epoch) config.on_epoch(epoch + 1, epoch_loss);
  }
  const int points = config.grid > 0 ? config.grid : (config.dim == 1 ? 100 : 50);
  const Dataset test = MakeTestGrid(config.dim, points);
  const Dataset pred_test = Predict(net, test.x);
  Result result;
  result.mse_f = MeanSquaredError(pred_test.f, test.f);
  result.mse_j = MeanSquaredError(pred_test.jac, test.jac);
  result.mse_h = MeanSquaredError(pred_test.hess, test.hess);
  result.final_train_loss = epoch_loss;
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  result.net = std::move(net);
  return result;
}

/// Where a 1-D network's Jacobian error sits (used for relu, whose Jacobian is
/// piecewise constant with kinks at x_i = -b_i / w_i).
struct JacobianErrorSplit {
  double grid_interior = 0.0;  ///< J MSE on the 100-point test grid without its 2 end points at each side
  double fine = 0.0;           ///< J MSE on a fine midpoint grid of [-pi, pi] (the integral mean)
  double own_kink_floor = 0.0; ///< fine-grid MSE of the best piecewise-constant fit of cos x with the net's own pieces
  int pieces = 0;              ///< pieces of constant slope inside [-pi, pi]
};

/// Splits a 1-D network's Jacobian error. The pieces are maximal runs of the
/// fine grid with equal slope (to 1e-9); on each piece the best constant is
/// the mean of cos x, so own_kink_floor is what a loss on J alone could reach
/// without moving the kinks.
inline JacobianErrorSplit SplitJacobianError1d(const Mlp<double>& net, int fine_points = 40000) {
  DIFFDYN_CHECK(net.architecture().num_inputs() == 1, "SplitJacobianError1d needs a 1-D network");
  JacobianErrorSplit s;
  const Dataset test = MakeTestGrid(1, 100);
  const Dataset pred = Predict(net, test.x);
  for (Eigen::Index i = 2; i < 98; ++i) s.grid_interior += std::pow(pred.jac(0, i) - test.jac(0, i), 2) / 96.0;
  std::vector<double> net_j(fine_points), true_j(fine_points);
  Eigen::VectorXd x(1), y;
  Eigen::MatrixXd jac;
  for (int i = 0; i < fine_points; ++i) {
    x[0] = -std::numbers::pi + 2.0 * std::numbers::pi * (i + 0.5) / fine_points;
    net.ValueAndJacobian(x, &y, &jac);
    net_j[i] = jac(0, 0);
    true_j[i] = std::cos(x[0]);
    s.fine += std::pow(net_j[i] - true_j[i], 2) / fine_points;
  }
  for (int start = 0, i = 1; i <= fine_points; ++i) {
    if (i < fine_points && std::abs(net_j[i] - net_j[i - 1]) <= 1e-9) continue;
    double mean = 0.0;
    for (int k = start; k < i; ++k) mean += true_j[k] / (i - start);
    for (int k = start; k < i; ++k) s.own_kink_floor += std::pow(true_j[k] - mean, 2) / fine_points;
    ++s.pieces;
    start = i;
  }
  return s;
}

}  // namespace diffdyn::ddn_figure
