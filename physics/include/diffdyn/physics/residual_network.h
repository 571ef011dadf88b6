// A learned residual torque: a one-hidden-layer tanh network for what no named
// effect explains.
//
// Inputs x = (q, qd, qdd) (3n) are standardised, s = (x - mean) / scale, and
//
//   r(x) = W2 tanh(W1 s + b1) + b2          (W1: H x 3n, W2: n x H),
//
// gives n joint torques. An input that is constant in the training data (the
// diagnosis passes qdd = 0, so the residual depends on (q, qd) only and cannot
// make the extended mass matrix indefinite) gets zero weights. The hidden layer is drawn once from a seed (random
// features, W1 ~ N(0, 1/3n)) and only the output layer is learned, by ridge
// regression on the residual torques:
//
//   [W2 b2] = argmin sum_k |y_k - W2 h_k - b2|^2 + lambda |W2|^2,
//
// a linear least-squares problem with a closed-form solution, so fitting is
// deterministic and takes milliseconds. The network is the project's Mlp
// (models/mlp.h), evaluated on double or Jets, so it can sit inside an extended
// model's torque.
#pragma once

#include <cmath>

#include <Eigen/Cholesky>
#include <Eigen/Core>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/models/mlp.h"
#include "diffdyn/models/random.h"
#include "diffdyn/physics/analytic_model.h"

namespace diffdyn {

/// r(q, qd, qdd) = W2 tanh(W1 s + b1) + b2; see the header comment for sizes.
struct ResidualNetwork {
  Eigen::VectorXd in_mean;   ///< 3n
  Eigen::VectorXd in_scale;  ///< 3n, positive
  /// The network [3n, H (tanh), n]: W1 = net.W(0), b1 = net.b(0), W2 = net.W(1),
  /// b2 = net.b(1); its flat parameters are [vec(W1), b1, vec(W2), b2].
  Mlp<double> net;

  /// The architecture of a residual over n joints with `hidden` features.
  static MlpArchitecture Architecture(int n, int hidden) { return {{3 * n, hidden, n}, {Activation::Tanh()}}; }

  /// Number of joints n (0 for an empty network).
  int dof() const { return net.architecture().sizes.empty() ? 0 : net.num_outputs(); }
  /// Number of hidden features H.
  int hidden() const { return net.architecture().sizes[1]; }

  /// r(x) (n) for x = (q, qd, qdd), each of size n.
  template <typename T>
  VectorX<T> operator()(const VectorX<T>& q, const VectorX<T>& qd, const VectorX<T>& qdd) const {
    const int n = dof();
    VectorX<T> s(3 * n);
    for (int j = 0; j < n; ++j) {
      s[j] = (q[j] - in_mean[j]) / in_scale[j];
      s[n + j] = (qd[j] - in_mean[n + j]) / in_scale[n + j];
      s[2 * n + j] = (qdd[j] - in_mean[2 * n + j]) / in_scale[2 * n + j];
    }
    return net(s);
  }

  /// Fits the output layer. inputs: 3n x N (q; qd; qdd per column), targets:
  /// n x N residual torques, `hidden` random features, ridge weight `lambda`
  /// (relative to the mean feature energy). Throws diffdyn::Error on bad sizes.
  static ResidualNetwork Fit(const Eigen::MatrixXd& inputs, const Eigen::MatrixXd& targets,
                             int hidden, double lambda, Rng& rng) {
    const int d = static_cast<int>(inputs.rows());
    const int n = static_cast<int>(targets.rows());
    const int count = static_cast<int>(inputs.cols());
    DIFFDYN_CHECK(d == 3 * n && targets.cols() == count && count > 0 && hidden > 0,
                  "ResidualNetwork::Fit: inputs ", d, "x", count, ", targets ", n, "x",
                  targets.cols(), ", hidden ", hidden);
    ResidualNetwork result;
    result.in_mean = inputs.rowwise().mean();
    result.in_scale = ((inputs.colwise() - result.in_mean).array().square().rowwise().mean().sqrt() + 1e-9).matrix();
    Eigen::MatrixXd w1(hidden, d);
    Eigen::VectorXd b1(hidden);
    const double w_scale = 1.0 / std::sqrt(static_cast<double>(d));
    for (int k = 0; k < hidden; ++k) {
      for (int i = 0; i < d; ++i) w1(k, i) = w_scale * StandardNormal(rng);
      b1[k] = StandardNormal(rng);
    }
    // A constant input (e.g. qdd given as zeros) is left out: its weights are
    // zeroed, so the network does not depend on it at all.
    for (int i = 0; i < d; ++i) {
      if (result.in_scale[i] <= 2e-9) w1.col(i).setZero();
    }
    // Hidden features of every sample, with a constant row for b2.
    const Eigen::MatrixXd s = (inputs.colwise() - result.in_mean).array().colwise() / result.in_scale.array();
    Eigen::MatrixXd h(hidden + 1, count);
    h.topRows(hidden) = ((w1 * s).colwise() + b1).array().tanh().matrix();
    h.row(hidden).setOnes();
    Eigen::MatrixXd gram = h * h.transpose();
    const double energy = gram.diagonal().head(hidden).mean();
    gram.diagonal().head(hidden).array() += lambda * energy;
    const Eigen::MatrixXd solution = gram.ldlt().solve(h * targets.transpose());  // (H+1) x n
    // The network's flat parameters [vec(W1), b1, vec(W2), b2].
    const MlpArchitecture arch = Architecture(n, hidden);
    Eigen::VectorXd theta(arch.num_parameters());
    theta << w1.reshaped(), b1, solution.topRows(hidden).transpose().reshaped(), solution.row(hidden).transpose();
    result.net = Mlp<double>(arch, std::move(theta));
    return result;
  }
};

}  // namespace diffdyn
