// First-order equations F(x, V(x), dV/dx(x)) = 0 solved by residual minimisation with a
// deep differential network.
//
// The unknown is a scalar function V on a state domain, represented by an Mlp with n
// inputs and one output; its input Jacobian p = dV/dx comes out of the same forward
// pass in closed form (mlp.h). Over sampled states x_1..x_N the solver minimises
//
//   L(theta) = (1/N) sum_i F(x_i, V(x_i), p(x_i))^2
//
// with Adam on mini-batches (FitMinibatches, training.h). The gradient needs the
// equation's partials F_V and F_p only: the cotangents dL/dV_i = 2 F_i F_V,i / N and
// dL/dp_i = 2 F_i F_p,i / N enter Mlp::Backward, which takes the Jacobian's cotangent
// through the activations' second derivatives to dL/dtheta.
//
// Example with a known solution (examples/residual_lqr.cc, tests): the discounted HJB
// of a linear system dx/dt = A x + B u with cost x^T Q x + u^T R u and discount rho,
//
//   F = rho V - x^T Q x - p^T A x + (1/4) p^T B R^-1 B^T p,
//
// is solved by V = x^T P x with P the Riccati solution for (A - rho/2 I, B, Q, R).
//
//   LinearQuadraticHjb equation(A, B, Q, R, rho);
//   Mlp<double> net = MakeInitializedMlp({{2, 32, 32, 1}, {Activation::Softplus(), Activation::Softplus()}},
//                                        InitOptions::Ddn(), 1);
//   TrainResult r = SolveResidual(equation, states, options, &net);
#pragma once

#include <functional>
#include <vector>

#include <Eigen/Core>

#include "diffdyn/models/mlp.h"
#include "diffdyn/solvers/training.h"

namespace diffdyn {

/// A first-order equation F(x, V, p) = 0 with its partials, batched over B states.
class FirstOrderEquation {
 public:
  virtual ~FirstOrderEquation() = default;
  /// n, the state size.
  virtual int state_size() const = 0;
  /// F (B), dF/dV (B) and dF/dp (n x B) at states x (n x B), values v (B) and
  /// gradients p (n x B).
  virtual void Evaluate(const Eigen::MatrixXd& x, const Eigen::VectorXd& v, const Eigen::MatrixXd& p,
                        Eigen::VectorXd* f, Eigen::VectorXd* f_v, Eigen::MatrixXd* f_p) const = 0;
};

/// F = rho V - x^T Q x - p^T A x + (1/4) p^T B R^-1 B^T p (file comment): A n x n,
/// B n x m, Q n x n, R m x m symmetric positive definite, rho > 0.
class LinearQuadraticHjb final : public FirstOrderEquation {
 public:
  /// Throws diffdyn::Error for bad sizes, R not positive definite or rho <= 0.
  LinearQuadraticHjb(Eigen::MatrixXd a, const Eigen::MatrixXd& b, Eigen::MatrixXd q, const Eigen::MatrixXd& r,
                     double rho);
  int state_size() const override { return static_cast<int>(a_.rows()); }
  void Evaluate(const Eigen::MatrixXd& x, const Eigen::VectorXd& v, const Eigen::MatrixXd& p, Eigen::VectorXd* f,
                Eigen::VectorXd* f_v, Eigen::MatrixXd* f_p) const override;
  /// The known solution's P (n x n): V = x^T P x.
  Eigen::MatrixXd SolutionMatrix() const;

 private:
  Eigen::MatrixXd a_, b_, q_, r_, s_;  // s = B R^-1 B^T
  double rho_;
};

/// The value network's inputs z = phi(x): each state component listed in `periodic`
/// (0-based, increasing) enters as (sin x_i, cos x_i), so that V is periodic in it; the
/// others enter as they are. p = dV/dx = (dz/dx)^T dV/dz.
struct ValueFeatures {
  std::vector<int> periodic;
  /// The number of features for n states.
  int size(int n) const { return n + static_cast<int>(periodic.size()); }
  /// z (size(n) x B) of states x (n x B).
  Eigen::MatrixXd Encode(const Eigen::MatrixXd& x) const;
  /// p (n x B) from dV/dz (size(n) x B) at states x.
  Eigen::MatrixXd PullBack(const Eigen::MatrixXd& x, const Eigen::MatrixXd& dvdz) const;
  /// dL/dz (size(n) x B) from dL/dp (n x B) at states x: the transpose of PullBack.
  Eigen::MatrixXd PushForward(const Eigen::MatrixXd& x, const Eigen::MatrixXd& dldp) const;
};

/// V (B) and p = dV/dx (n x B) of `net` over `features` at states x (n x B).
void ValueAndGradient(const Mlp<double>& net, const Eigen::MatrixXd& x, Eigen::VectorXd* v, Eigen::MatrixXd* p,
                      const ValueFeatures& features = {}, int threads = 1);

/// The mean squared residual L = mean_i F_i^2 of `net` at states x (n x B) and, if
/// grad is not null, dL/dtheta (resized to net's parameter count), on workspace ws.
double ResidualLoss(const FirstOrderEquation& equation, const Mlp<double>& net, const Eigen::MatrixXd& x,
                    Eigen::VectorXd* grad, MlpWorkspace* ws, const ValueFeatures& features = {},
                    int threads = 1);

/// Minimises the mean squared residual over the columns of `states` (n x N; a
/// seeded fraction options.val_fraction held out) by Adam from net's parameters, in
/// place (file comment); the network sees `features` of the states. Losses in the
/// result are mean squared residuals. Throws diffdyn::Error when net does not map
/// features.size(n) inputs to 1 output or the options are bad.
TrainResult SolveResidual(const FirstOrderEquation& equation, const Eigen::MatrixXd& states,
                          const TrainOptions& options, Mlp<double>* net, const ValueFeatures& features = {},
                          const std::function<void(const EpochReport&)>& on_epoch = {});

}  // namespace diffdyn
