// The SE(2) pose loss of the block-pushing models.
//
// For predicted and target planar poses p_b = (x, y, theta) of B samples (3 x B,
// one sample per column), with differences d_b = phat_b - p_b,
//
//   L = MSE(x) + MSE(y) + r_g MSE(theta)
//     = s sum_b (d_x^2 + d_y^2 + r_g d_theta^2),          s = 1 / B,
//
//   dL/dphat_b = 2 s (d_x, d_y, r_g d_theta).
//
// r_g = sqrt((l^2 + w^2) / 12) is the radius of gyration of the l x w block
// (0.1 m x 0.1 m: r_g = 0.040825 m); it multiplies the angle MSE directly (not
// squared), as in the paper's code. theta is not wrapped. The scale s is a
// parameter so that a batch split into chunks sums its chunks' losses and
// gradients with s = 1 / (whole batch).
#pragma once

#include <cmath>

#include <Eigen/Core>

#include "diffdyn/autodiff_ode/check.h"

namespace diffdyn {

/// r_g = sqrt((l^2 + w^2) / 12) of a block of length l and width w (metres).
inline double RadiusOfGyration(double length, double width) {
  return std::sqrt((length * length + width * width) / 12.0);
}

/// r_g of the paper's 0.1 m x 0.1 m block.
inline const double kBlockRadiusOfGyration = RadiusOfGyration(0.1, 0.1);

/// L = scale sum_b (d_x^2 + d_y^2 + rg d_theta^2) with d = pred - target (3 x B
/// each); if grad is not null, grad = dL/dpred = 2 scale (d_x, d_y, rg d_theta)
/// (3 x B, resized only if its size differs). Throws diffdyn::Error on size mismatch.
template <typename Pred, typename Target>
double Se2PoseLoss(const Eigen::MatrixBase<Pred>& pred, const Eigen::MatrixBase<Target>& target,
                   double scale, Eigen::MatrixXd* grad, double rg = kBlockRadiusOfGyration) {
  DIFFDYN_CHECK(pred.rows() == 3 && target.rows() == 3 && pred.cols() == target.cols(),
                "Se2PoseLoss: prediction is ", pred.rows(), " x ", pred.cols(), ", target is ",
                target.rows(), " x ", target.cols(), "; expected 3 x B each");
  if (grad && (grad->rows() != 3 || grad->cols() != pred.cols())) grad->resize(3, pred.cols());
  double sum = 0.0;
  for (Eigen::Index b = 0; b < pred.cols(); ++b) {
    const double dx = pred(0, b) - target(0, b);
    const double dy = pred(1, b) - target(1, b);
    const double dt = pred(2, b) - target(2, b);
    sum += dx * dx + dy * dy + rg * dt * dt;
    if (grad) {
      (*grad)(0, b) = 2.0 * scale * dx;
      (*grad)(1, b) = 2.0 * scale * dy;
      (*grad)(2, b) = 2.0 * scale * rg * dt;
    }
  }
  return scale * sum;
}

}  // namespace diffdyn
