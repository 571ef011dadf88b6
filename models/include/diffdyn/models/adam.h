// Adam, with AMSGrad and weight decay as options (PyTorch's semantics).
//
// For parameters theta and gradient g at step t = 1, 2, ...:
//
//   g     <- g + lambda theta                   (L2 weight decay, if not decoupled)
//   theta <- theta (1 - lr lambda)              (AdamW: decoupled weight decay)
//   m     <- beta1 m + (1 - beta1) g
//   v     <- beta2 v + (1 - beta2) g^2
//   vhat  <- max(vhat, v) with AMSGrad, else v
//   theta <- theta - lr / (1 - beta1^t) * m / (sqrt(vhat / (1 - beta2^t)) + eps)
//
// State (m, v, vhat) is sized once; Step does not allocate.
//
//   Adam adam(theta.size(), {.learning_rate = 1e-3, .weight_decay = 1e-6, .amsgrad = true});
//   adam.Step(grad, &theta);
#pragma once

#include <cmath>

#include <Eigen/Core>

#include "diffdyn/autodiff_ode/check.h"

namespace diffdyn {

/// Hyper-parameters of Adam (PyTorch's defaults).
struct AdamOptions {
  /// lr > 0.
  double learning_rate = 1e-3;
  /// beta1 in [0, 1): decay of the first moment m.
  double beta1 = 0.9;
  /// beta2 in [0, 1): decay of the second moment v.
  double beta2 = 0.999;
  /// eps > 0 added to the denominator.
  double epsilon = 1e-8;
  /// lambda >= 0 (L2 penalty, or AdamW decay when decoupled).
  double weight_decay = 0.0;
  /// AMSGrad: use the running maximum of v.
  bool amsgrad = false;
  /// AdamW: decay theta directly instead of adding lambda theta to g.
  bool decoupled_weight_decay = false;
};

/// The Adam optimiser over a flat parameter vector of fixed size.
class Adam {
 public:
  /// Optimiser for `n` parameters; throws diffdyn::Error for invalid options.
  Adam(Eigen::Index n, const AdamOptions& options) : options_(options) {
    DIFFDYN_CHECK(options.learning_rate > 0.0, "Adam: learning rate must be positive, got ",
                  options.learning_rate);
    DIFFDYN_CHECK(options.beta1 >= 0.0 && options.beta1 < 1.0 && options.beta2 >= 0.0 &&
                      options.beta2 < 1.0,
                  "Adam: betas must be in [0, 1), got ", options.beta1, ", ", options.beta2);
    DIFFDYN_CHECK(options.epsilon > 0.0 && options.weight_decay >= 0.0,
                  "Adam: epsilon must be positive and weight decay non-negative");
    m_ = Eigen::VectorXd::Zero(n);
    v_ = Eigen::VectorXd::Zero(n);
    if (options.amsgrad) v_max_ = Eigen::VectorXd::Zero(n);
  }

  /// One update of theta (size n) with gradient g (size n).
  void Step(const Eigen::VectorXd& grad, Eigen::VectorXd* theta) {
    DIFFDYN_CHECK(grad.size() == m_.size() && theta->size() == m_.size(), "Adam: expected ",
                  m_.size(), " parameters and gradients, got ", theta->size(), " and ", grad.size());
    ++step_;
    const AdamOptions& o = options_;
    const double bc1 = 1.0 - std::pow(o.beta1, step_);
    const double bc2 = 1.0 - std::pow(o.beta2, step_);
    const double step_size = o.learning_rate / bc1;
    const double inv_sqrt_bc2 = 1.0 / std::sqrt(bc2);
    const double l2 = o.decoupled_weight_decay ? 0.0 : o.weight_decay;
    if (o.decoupled_weight_decay && o.weight_decay > 0.0) *theta *= 1.0 - o.learning_rate * o.weight_decay;
    auto g = grad.array() + l2 * theta->array();
    m_.array() = o.beta1 * m_.array() + (1.0 - o.beta1) * g;
    v_.array() = o.beta2 * v_.array() + (1.0 - o.beta2) * g * g;
    if (o.amsgrad) {
      v_max_ = v_max_.cwiseMax(v_);
      theta->array() -= step_size * m_.array() / (v_max_.array().sqrt() * inv_sqrt_bc2 + o.epsilon);
    } else {
      theta->array() -= step_size * m_.array() / (v_.array().sqrt() * inv_sqrt_bc2 + o.epsilon);
    }
  }

  /// Number of steps taken.
  long steps() const { return step_; }
  /// The hyper-parameters.
  const AdamOptions& options() const { return options_; }

 private:
  AdamOptions options_;
  Eigen::VectorXd m_, v_, v_max_;
  long step_ = 0;
};

}  // namespace diffdyn
