// Transition models: x_{t+1} = F(x_t, u_t).
//
// A transition model maps a state x (n) and an action u (m) to the next state;
// a SystemDescription (system_description.h) says what they are (for pushing,
// x = (x, y, theta) is the block's planar pose and u = (push_location, push_angle,
// push_length); for a robot arm, x = (q, qd) and u = tau). The four learned
// models of the NeuralODE-Panda paper (learned_model.h), every continuous-time
// system through one adapter (continuous_model.h: analytic robots, extended
// physics models) and the ODE-engine simulation itself (the "oracle") all
// implement this one interface, so MPPI, evaluation and figures take any of
// them; LoadTransitionModel (solvers/load_model.h) opens each by name.
//
// The interface is the batched `double` path used by training, evaluation and
// MPPI: B samples at once, one sample per column. Derivatives come from the
// concrete model types' templated paths (Jets) and reverse-mode VJPs.
//
// Data sampled irregularly (real logs) gives each transition its own interval dt;
// PredictBatchOver passes it: continuous-time systems integrate over it, models of
// one fixed interval (learned models, the oracle) ignore it.
//
// A model that can be trained (DifferentiableTransitionModel) adds a flat
// parameter vector and batched reverse mode: Forward records a tape in the
// workspace, Backward pulls a cotangent of the next state back to the parameters
// and the state. The trainer (solvers/training.h) needs nothing else.
//
// The model is immutable; scratch space lives in a workspace, one per thread:
//
//   auto ws = model.MakeWorkspace(/*max_batch=*/1000);
//   Eigen::MatrixXd next(n, 1000);
//   model.PredictBatch(states, actions, next, *ws);  // states n x 1000, actions m x 1000
#pragma once

#include <Eigen/Core>
#include <memory>
#include <string>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/autodiff_ode/jacobian.h"
#include "diffdyn/models/precision.h"
#include "diffdyn/models/system_description.h"

namespace diffdyn {

/// Per-thread scratch space of a transition model. Each model derives its own.
class TransitionWorkspace {
 public:
  virtual ~TransitionWorkspace() = default;

  /// ODE-solver steps of the calls made on this workspace, for models that integrate
  /// (accepted steps, and trial steps an adaptive solver's error control rejected);
  /// 0 for the others. Counted since the workspace was made.
  long accepted_steps = 0;
  long rejected_steps = 0;
};

/// x_{t+1} = F(x_t, u_t) over batches: the common interface of every dynamics model.
class TransitionModel {
 public:
  virtual ~TransitionModel() = default;

  /// n, the size of the state x.
  virtual int state_size() const = 0;
  /// m, the size of the action u.
  virtual int action_size() const = 0;
  /// The model-file kind ("abs-nn", "res-node", "oracle", ...).
  virtual std::string kind() const = 0;
  /// The time (s) one transition spans, or 0 where the model does not record it
  /// (a model trained on data without time, e.g. pushes).
  virtual double time_step() const { return 0.0; }
  /// What its states and actions are; the default names them x1..xn and u1..um.
  virtual SystemDescription description() const {
    return SystemDescription::Unnamed(state_size(), action_size());
  }

  /// Scratch space for batches of up to `max_batch` samples (one per thread).
  virtual std::unique_ptr<TransitionWorkspace> MakeWorkspace(int max_batch) const = 0;

  /// next(:, b) = F(states(:, b), actions(:, b)) for b < B. states: n x B,
  /// actions: m x B, next: n x B with B <= the workspace's max_batch.
  /// Throws diffdyn::Error on wrong sizes.
  virtual void PredictBatch(const Eigen::Ref<const Eigen::MatrixXd>& states,
                            const Eigen::Ref<const Eigen::MatrixXd>& actions,
                            Eigen::Ref<Eigen::MatrixXd> next, TransitionWorkspace& ws) const = 0;

  /// next(:, b) = F(states(:, b), actions(:, b)) over the interval dt(b) (seconds, B
  /// entries). The default ignores dt (a model of one fixed interval).
  virtual void PredictBatchOver(const Eigen::Ref<const Eigen::MatrixXd>& states,
                                const Eigen::Ref<const Eigen::MatrixXd>& actions,
                                const Eigen::Ref<const Eigen::RowVectorXd>& dt,
                                Eigen::Ref<Eigen::MatrixXd> next, TransitionWorkspace& ws) const {
    DIFFDYN_CHECK(dt.size() == states.cols(), kind(), ": PredictBatchOver got ", dt.size(),
                  " intervals for ", states.cols(), " samples");
    PredictBatch(states, actions, next, ws);
  }

  /// Whether PredictBatchOver integrates over the given intervals.
  virtual bool uses_intervals() const { return false; }

  /// Whether Jacobian is available (the ODE-engine oracle has no derivatives).
  virtual bool differentiable() const { return false; }

  /// The precision of the batched paths (precision.h).
  virtual Precision precision() const { return Precision::kF64; }
  /// Makes the batched paths compute in `p`; false (and no change) if the model has
  /// no path in `p` (the default: float64 only).
  virtual bool SetPrecision(Precision p) { return p == Precision::kF64; }

  /// The Jacobian of one transition, jac = [dF/dx, dF/du] (n x (n + m), resized) at
  /// x (n entries), u (m entries), exact to rounding (forward-mode Jets through the
  /// model's own integration); returns F(x, u) (n). Throws diffdyn::Error for wrong
  /// sizes or a model that is not differentiable(); diffdyn::NumericalError where the
  /// prediction is not finite.
  virtual Eigen::VectorXd Jacobian(const Eigen::Ref<const Eigen::VectorXd>& x,
                                   const Eigen::Ref<const Eigen::VectorXd>& u,
                                   Eigen::MatrixXd* jac) const {
    (void)x;
    (void)u;
    (void)jac;
    throw Error(StrCat(kind(), ": this model has no derivatives (it is not differentiable)"));
  }

 protected:
  /// Checks the sizes of a PredictBatch call, naming them on failure.
  void CheckBatchSizes(const Eigen::Ref<const Eigen::MatrixXd>& states,
                       const Eigen::Ref<const Eigen::MatrixXd>& actions,
                       const Eigen::Ref<Eigen::MatrixXd>& next) const {
    DIFFDYN_CHECK(states.rows() == state_size() && actions.rows() == action_size() &&
                      next.rows() == state_size() && actions.cols() == states.cols() &&
                      next.cols() == states.cols(),
                  kind(), ": PredictBatch got states ", states.rows(), "x", states.cols(),
                  ", actions ", actions.rows(), "x", actions.cols(), ", next ", next.rows(), "x",
                  next.cols(), "; expected ", state_size(), "xB, ", action_size(), "xB, ",
                  state_size(), "xB");
  }

  /// The Jacobian of F by forward-mode Jets, for models with a scalar-generic
  /// `predict(x, u)` (VectorX<Jet> x of n and u of m entries -> VectorX<Jet> of n):
  /// ceil((n + m) / 8) evaluations. Returns F(x, u); checks sizes and finiteness.
  template <typename Predict>
  Eigen::VectorXd JetJacobian(const Predict& predict, const Eigen::Ref<const Eigen::VectorXd>& x,
                              const Eigen::Ref<const Eigen::VectorXd>& u, Eigen::MatrixXd* jac) const {
    const int n = state_size(), m = action_size();
    DIFFDYN_CHECK(x.size() == n && u.size() == m, kind(), ": Jacobian got x of ", x.size(), " and u of ",
                  u.size(), " entries, expected ", n, " and ", m);
    Eigen::VectorXd z(n + m), value;
    z << x, u;
    *jac = JacobianDynamic<8>([&](const auto& zj) { return predict(zj.head(n), zj.tail(m)); }, z, &value);
    if (!value.allFinite() || !jac->allFinite()) {
      throw NumericalError(StrCat(kind(), ": the Jacobian at this state and action is not finite"));
    }
    return value;
  }
};

/// A transition model with parameters theta (one flat vector) and batched reverse mode.
class DifferentiableTransitionModel : public TransitionModel {
 public:
  /// p, the number of parameters.
  virtual Eigen::Index num_parameters() const = 0;
  /// theta (p entries) and writable access for an optimiser.
  virtual const Eigen::VectorXd& parameters() const = 0;
  virtual Eigen::VectorXd& mutable_parameters() = 0;

  /// next = F(states, actions) (n x B, m x B, n x B), recording in `ws` what Backward
  /// needs. Throws diffdyn::NumericalError if the prediction is not finite.
  virtual void Forward(const Eigen::Ref<const Eigen::MatrixXd>& states,
                       const Eigen::Ref<const Eigen::MatrixXd>& actions,
                       Eigen::Ref<Eigen::MatrixXd> next, TransitionWorkspace& ws) const = 0;

  /// Reverse mode of the last Forward on `ws`: given dl_dnext = dL/dnext (n x B), adds
  /// dL/dtheta to *grad_params (p entries; may be null) and writes dL/dstates (n x B;
  /// resized; may be null).
  virtual void Backward(const Eigen::Ref<const Eigen::MatrixXd>& dl_dnext, TransitionWorkspace& ws,
                        Eigen::VectorXd* grad_params, Eigen::MatrixXd* dl_dstates) const = 0;
};

}  // namespace diffdyn
