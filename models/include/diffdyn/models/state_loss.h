// The state metric of a system: the loss every trainer and evaluation uses.
//
// For predicted and target states of B samples (n x B, one sample per column),
// with differences d_ib = xhat_ib - x_ib,
//
//   L = s sum_b sum_i w_i d_ib^2,          dL/dxhat_ib = 2 s w_i d_ib,
//
// w_i the system's loss weights (SystemDescription::loss_weights, default 1) and
// d_ib wrapped to (-pi, pi] for an angle component when the system wraps angles
// (a wrap has derivative 1 almost everywhere). s is a parameter so that a batch
// split into chunks sums its chunks' losses and gradients with s = 1 / (whole batch).
//
// Two systems show the range. A joint-space robot (x = (q, qd)) has w = 1 and its
// revolute angles wrapped: L is the mean over samples of sum_i d_i^2 in SI units.
// Pushing (x = (x, y, theta)) weighs theta by the block's radius of gyration
// r_g = sqrt((l^2 + w^2) / 12) = 0.040825 m (not squared) and does not wrap it, as in
// the NeuralODE-Panda paper's code: L = MSE(x) + MSE(y) + r_g MSE(theta).
//
//   double loss = StateLoss(system, predicted, target, 1.0 / B, &grad);
#pragma once

#include <cmath>

#include <Eigen/Core>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/models/system_description.h"

namespace diffdyn {

/// L = scale sum_b sum_i w_i d_ib^2 over pred - target (n x B each, see the file
/// comment); if grad is not null, grad = dL/dpred (n x B, resized only if its size
/// differs). Throws diffdyn::Error on a size mismatch.
template <typename Pred, typename Target>
double StateLoss(const SystemDescription& system, const Eigen::MatrixBase<Pred>& pred,
                 const Eigen::MatrixBase<Target>& target, double scale, Eigen::MatrixXd* grad) {
  const int n = system.state_size();
  DIFFDYN_CHECK(pred.rows() == n && target.rows() == n && pred.cols() == target.cols(),
                "StateLoss (", system.name, "): prediction is ", pred.rows(), " x ", pred.cols(),
                ", target is ", target.rows(), " x ", target.cols(), "; expected ", n, " x B each");
  if (grad && (grad->rows() != n || grad->cols() != pred.cols())) grad->resize(n, pred.cols());
  // Per component: its weight and whether it wraps.
  double w[64];
  bool wrap[64];
  DIFFDYN_CHECK(n <= 64, "StateLoss: states of more than 64 components are not supported");
  for (int i = 0; i < n; ++i) {
    w[i] = system.loss_weight(i);
    wrap[i] = system.loss_wraps_angles && system.is_angle(i);
  }
  double sum = 0.0;
  for (Eigen::Index b = 0; b < pred.cols(); ++b) {
    double term = 0.0;
    for (int i = 0; i < n; ++i) {
      double d = pred(i, b) - target(i, b);
      if (wrap[i]) d = WrapAngle(d);
      term += w[i] * d * d;
      if (grad) (*grad)(i, b) = 2.0 * scale * w[i] * d;
    }
    sum += term;
  }
  return scale * sum;
}

}  // namespace diffdyn
