// First-order equations F(x, V(x), dV/dx(x)) = 0 solved by residual minimisation with a
// deep differential network.
//
// The unknown is a scalar function V on a state domain, a ValueFunction: an Mlp on
// features of the state and a form (V the network's output, or a quadratic form built
// from it); p = dV/dx comes out of the same forward pass in closed form (mlp.h). Over sampled states x_1..x_N the solver minimises
//
//   L(theta) = (1/N) sum_i F(x_i, V(x_i), p(x_i))^2
//
// with Adam on mini-batches (FitMinibatches, training.h). The gradient needs the
// equation's partials F_V and F_p only: the cotangents dL/dV_i = 2 F_i F_V,i / N and
// dL/dp_i = 2 F_i F_p,i / N enter ValueFunction::Backward, and Mlp::Backward takes the
// Jacobian's cotangent through the activations' second derivatives to dL/dtheta.
//
// Example with a known solution (examples/residual_lqr.cc, tests): the discounted HJB
// of a linear system dx/dt = A x + B u with cost x^T Q x + u^T R u and discount rho,
//
//   F = rho V - x^T Q x - p^T A x + (1/4) p^T B R^-1 B^T p,
//
// is solved by V = x^T P x with P the Riccati solution for (A - rho/2 I, B, Q, R).
//
//   LinearQuadraticHjb equation(A, B, Q, R, rho);
//   ValueFunction value = ValueFunction::Direct(
//       MakeInitializedMlp({{2, 32, 32, 1}, {Activation::Softplus(), Activation::Softplus()}}, InitOptions::Ddn(), 1), 2);
//   TrainResult r = SolveResidual(equation, states, options, &value);
//
// ValueFunction also offers a structured form, V = (z - z0)^T L(z) L(z)^T (z - z0)
// (ValueForm::kQuadratic), whose gradient and reverse mode run through the network's
// Jacobian in the same way.
#pragma once

#include <functional>
#include <vector>

#include <Eigen/Core>

#include "diffdyn/models/input_features.h"
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
  /// gradients p (n x B), resized in place. `threads` (<= 0: all cores) may share
  /// independent per-state work; the results must not depend on it.
  virtual void Evaluate(const Eigen::MatrixXd& x, const Eigen::VectorXd& v, const Eigen::MatrixXd& p,
                        Eigen::VectorXd* f, Eigen::VectorXd* f_v, Eigen::MatrixXd* f_p, int threads) const = 0;
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
                Eigen::VectorXd* f_v, Eigen::MatrixXd* f_p, int threads) const override;
  /// The known solution's P (n x n): V = x^T P x.
  Eigen::MatrixXd SolutionMatrix() const;

 private:
  Eigen::MatrixXd a_, b_, q_, r_, s_;  // s = B R^-1 B^T
  double rho_;
};

/// How V is made of the network's outputs y(z) and their Jacobian dy/dz (mlp.h).
enum class ValueForm {
  /// V = y (one output).
  kDirect,
  /// V = e^T L L^T e with e = z - z0, z0 the goal's features, and L (d x d, d = the
  /// feature count) lower-triangular from the d (d + 1) / 2 outputs, row by row
  /// (L_00, L_10, L_11, L_20, ...), its diagonal softplus(y) + epsilon (the cFVI value
  /// network, lutter_facts.md (d)): V >= 0 everywhere and V = 0, dV/dx = 0 at the goal
  /// by construction.
  kQuadratic,
};

/// Scratch of ValueFunction's batched passes and of the losses built on them: the
/// network's tape, features z, outputs y and stacked Jacobians (mlp.h), then buffers
/// resized in place, so a training loop allocates nothing once its batch size has been
/// seen. One per thread of work.
struct ValueWorkspace {
  MlpWorkspace mlp;
  Eigen::MatrixXd z, y, jac;
  /// dV/dz (d x B); Backward's dL/d(dV/dz) (d x B), dL/dy (m x B) and dL/dJ (m x d B).
  Eigen::MatrixXd dvdz, gdvdz, gy, gjac;
  /// The losses': V, the residuals, F_V and dL/dV (B each); p, F_p and dL/dp (n x B);
  /// an added term's parameter gradient.
  Eigen::VectorXd v, f, f_v, gv, grad;
  Eigen::MatrixXd p, f_p, gp;
};

/// A scalar function V on a state domain of n components, with p = dV/dx in closed
/// form from one forward pass: an Mlp on the features z = phi(x) (InputFeatures) and a
/// ValueForm. Sizes: x n x B, V B, p n x B.
class ValueFunction {
 public:
  ValueFunction() = default;
  /// V = y(phi(x)): `net` maps features.size(n) inputs to 1 output.
  static ValueFunction Direct(Mlp<double> net, int n, InputFeatures features = {});
  /// V = e^T L L^T e (ValueForm::kQuadratic) around `goal` (n): `net` maps
  /// d = features.size(n) inputs to d (d + 1) / 2 outputs; epsilon > 0.
  static ValueFunction Quadratic(Mlp<double> net, const Eigen::VectorXd& goal, InputFeatures features = {},
                                 double epsilon = 1e-3);
  /// The number of network outputs the form needs for d features.
  static int OutputsFor(ValueForm form, int d) { return form == ValueForm::kDirect ? 1 : d * (d + 1) / 2; }

  int state_size() const { return n_; }
  ValueForm form() const { return form_; }
  const InputFeatures& features() const { return features_; }
  /// The goal state (n; quadratic form only, else empty).
  const Eigen::VectorXd& goal() const { return goal_; }
  double epsilon() const { return epsilon_; }
  const Mlp<double>& net() const { return net_; }
  Mlp<double>* mutable_net() { return &net_; }
  /// A workspace for batches of up to max_batch states.
  ValueWorkspace MakeWorkspace(int max_batch, int chunk_size = MlpWorkspace::kDefaultChunkSize) const;

  /// V (B) and p (n x B) at states x (n x B); keeps in ws what Backward needs. The
  /// network's chunks and the quadratic form's per-state heads run on `threads`
  /// (<= 0: all cores), with the same results at any count.
  void Evaluate(const Eigen::MatrixXd& x, Eigen::VectorXd* v, Eigen::MatrixXd* p, ValueWorkspace* ws,
                int threads = 1) const;
  /// The same with a workspace of its own (allocates).
  void Evaluate(const Eigen::MatrixXd& x, Eigen::VectorXd* v, Eigen::MatrixXd* p) const;
  /// Reverse mode after Evaluate(x, ...) on ws: dL/dtheta (net's parameter count) from
  /// the cotangents gv = dL/dV (B) and gp = dL/dp (n x B).
  void Backward(const Eigen::MatrixXd& x, const Eigen::VectorXd& gv, const Eigen::MatrixXd& gp,
                Eigen::VectorXd* grad, ValueWorkspace* ws, int threads = 1) const;

 private:
  ValueFunction(Mlp<double> net, int n, InputFeatures features, ValueForm form, Eigen::VectorXd goal,
                double epsilon);
  // Per sample b: V_b and dV/dz_b from y, jac and z (quadratic form).
  void QuadraticHead(const ValueWorkspace& ws, Eigen::Index b, double* v, Eigen::Ref<Eigen::VectorXd> dvdz) const;
  // Per sample b: dL/dy_b and dL/dJ_b from gv_b and dL/d(dV/dz)_b (quadratic form).
  void QuadraticHeadBackward(const ValueWorkspace& ws, Eigen::Index b, double gv,
                             const Eigen::Ref<const Eigen::VectorXd>& gdvdz, Eigen::Ref<Eigen::VectorXd> gy,
                             Eigen::Ref<Eigen::MatrixXd> gjac) const;

  Mlp<double> net_;
  int n_ = 0;
  InputFeatures features_;
  ValueForm form_ = ValueForm::kDirect;
  Eigen::VectorXd goal_, goal_features_;
  double epsilon_ = 1e-3;
};

/// The mean squared residual L = mean_i F_i^2 of `value` at states x (n x B) and, if
/// grad is not null, dL/dtheta (resized to the network's parameter count), on ws.
double ResidualLoss(const FirstOrderEquation& equation, const ValueFunction& value, const Eigen::MatrixXd& x,
                    Eigen::VectorXd* grad, ValueWorkspace* ws, int threads = 1);

/// Known values of V at a few states (a boundary condition), added to the residual loss
/// as weight * mean_a ((V(x_a) - v_a) / scale_a)^2: states n x A, values and scales A.
struct ValueAnchors {
  Eigen::MatrixXd states;
  Eigen::VectorXd values, scales;
  double weight = 0.0;
  /// Anchors per mini-batch, taken in turn from the columns (0: all of them in every
  /// mini-batch). The term then weighs the mean over the mini-batch's anchors.
  int batch = 0;
};

/// The anchor term weight * mean_a ((V(x_a) - v_a) / scale_a)^2 of `anchors` and, if
/// grad is not null, its gradient added to *grad (the network's parameter count), on ws.
double AnchorLoss(const ValueAnchors& anchors, const ValueFunction& value, Eigen::VectorXd* grad,
                  ValueWorkspace* ws, int threads = 1);

/// Minimises the mean squared residual over the columns of `states` (n x N; a
/// seeded fraction options.val_fraction held out), plus the anchor term of `anchors`
/// if given, by Adam from the value function's parameters, in place (file comment).
/// Losses in the result are mean squared residuals (the anchor term aside). Throws
/// diffdyn::Error when value's state size is not the equation's or the options are bad.
TrainResult SolveResidual(const FirstOrderEquation& equation, const Eigen::MatrixXd& states,
                          const TrainOptions& options, ValueFunction* value,
                          const std::function<void(const EpochReport&)>& on_epoch = {},
                          const ValueAnchors* anchors = nullptr);

}  // namespace diffdyn
