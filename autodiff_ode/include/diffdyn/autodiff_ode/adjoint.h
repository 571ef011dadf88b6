// Reverse mode through ODE solvers for batched vector-Jacobian-product systems.
//
// Gradients with respect to thousands of parameters (a NeuralODE's weights) are
// too many directions for Jets. Reverse mode propagates one adjoint per sample
// instead, a = dL/dz, backward through the solver. It needs only vector-Jacobian
// products (VJPs) of the dynamics, which for a whole batch are matrix products.
//
// The concept, BatchedVjpSystem (kept this small on purpose):
//
//   struct MySystem {
//     using Workspace = ...;           // per-thread scratch, sized once
//     using Scalar = float;            // optional: the matrices' scalar (default double)
//     int state_size() const;          // n
//     int num_params() const;          // p: the flat parameter vector theta
//     // dz/dt = f(z, t; theta) for B states at once: z, dzdt are n x B (column = sample)
//     void Eval(const Eigen::Ref<const Eigen::MatrixXd>& z, double t,
//               Eigen::Ref<Eigen::MatrixXd> dzdt, Workspace& ws) const;
//     // lambda (n x B): vjp_z = (df/dz)^T lambda per column (n x B), overwritten;
//     // grad_theta += sum_b (df/dtheta (z_b))^T lambda_b (p), accumulated
//     void Vjp(const Eigen::Ref<const Eigen::MatrixXd>& z, double t,
//              const Eigen::Ref<const Eigen::MatrixXd>& lambda, Eigen::Ref<Eigen::MatrixXd> vjp_z,
//              Eigen::Ref<Eigen::VectorXd> grad_theta, Workspace& ws) const;
//     Workspace MakeWorkspace(int batch) const;
//   };
//
// A loss L(z(t_1), ..., z(t_T)) on several output times gives dL/dz(t_i) (n x B each).
// BatchedOdeSolver returns dL/dz0 (n x B) and dL/dtheta (p) in one of two ways.
//
// (a) Discrete adjoint: the exact gradient of the discrete solver map. One step of
// an explicit Runge-Kutta method (butcher.h) from (z_n, t_n) with step h is
//
//   Y_i = z_n + h sum_{j<i} a_ij K_j,   K_i = f(Y_i, t_n + c_i h),
//   z_{n+1} = z_n + h sum_i b_i K_i.
//
// Given abar = dL/dz_{n+1}, the chain rule run backward over the stages i = s..1 is
//
//   Kbar_i = h (b_i abar + sum_{j>i} a_ji W_j),   W_i = (df/dz (Y_i))^T Kbar_i,
//   dL/dtheta += (df/dtheta (Y_i))^T Kbar_i,      dL/dz_n = abar + sum_i W_i,
//
// one batched Vjp per stage. The forward pass stores the stage inputs Y_i of every
// step (memory O(steps x stages x n x B)); stages that feed neither b nor a later
// stage (dopri5's seventh, used only for the error estimate) are skipped. For
// adaptive dopri5 / cash-karp the step sizes the forward pass accepted are held
// fixed: the result is the exact gradient of the map through those steps, which is
// what backpropagating through the solver's operations (as torchdiffeq does without
// the adjoint) computes for the state path. One step size is shared by the batch,
// chosen from the RMS of the scaled error over all n x B entries:
//
//   ratio = sqrt(mean_{i,b} (err_ib / (abs_tol + rel_tol max(|z_ib|, |z'_ib|)))^2),
//
// accepted when ratio <= 1, next h = h min(10, max(0.2, 0.9 ratio^(-1/order))).
//
// (b) Continuous adjoint: the augmented adjoint ODE integrated backward in time
//
//   dz/dt = f(z, t),   da/dt = -(df/dz)^T a,   dg/dt = -(df/dtheta)^T a  (summed over b),
//
// from a(t_T) = dL/dz(t_T), g(t_T) = 0 down to t_0, adding dL/dz(t_i) to a at every
// output time. Then a(t_0) = dL/dz0 and g(t_0) = dL/dtheta. The state z is
// re-integrated backward from z(t_T), so memory is independent of the number of
// steps; any odeint stepper from integrate.h does the backward pass (flat state of
// 2 n B + p entries, max-norm error control for the adaptive ones). Its gradient is
// that of the exact flow up to the solver tolerances: it converges to the discrete
// one as both tolerances tighten.
//
// With Scalar = float every matrix (states, adjoints, tape, dL/dtheta) is float and
// the products run in single precision; times, step sizes, the Butcher coefficients
// and the adaptive error norm stay double (the norm is accumulated in double).
//
// Costs per step with s stages: forward s Evals (s - 1 with FSAL), discrete backward
// one Vjp per needed stage, continuous backward one Eval + one Vjp per stage of the
// backward solver. All buffers live in the solver object and are reused across
// calls (they grow only when a longer tape than ever before is needed); one solver per
// thread, the system itself is immutable and shared.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <concepts>
#include <limits>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "diffdyn/autodiff_ode/butcher.h"
#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/autodiff_ode/integrate.h"

namespace diffdyn {

/// The scalar of a batched system's matrices: S::Scalar if S declares it, else double.
template <typename S>
struct BatchedScalarOf {
  using type = double;
};
template <typename S>
  requires requires { typename S::Scalar; }
struct BatchedScalarOf<S> {
  using type = typename S::Scalar;
};
template <typename S>
using BatchedScalar = typename BatchedScalarOf<S>::type;

/// A system with batched Eval and Vjp over n x B matrices of BatchedScalar<S> (float or
/// double; see the header comment).
template <typename S>
concept BatchedVjpSystem =
    requires(const S& s, const Eigen::Matrix<BatchedScalar<S>, Eigen::Dynamic, Eigen::Dynamic>& z,
             double t, Eigen::Matrix<BatchedScalar<S>, Eigen::Dynamic, Eigen::Dynamic>& out,
             Eigen::Matrix<BatchedScalar<S>, Eigen::Dynamic, 1>& grad, typename S::Workspace& ws,
             int batch) {
  { s.state_size() } -> std::convertible_to<int>;
  { s.num_params() } -> std::convertible_to<int>;
  { s.MakeWorkspace(batch) } -> std::same_as<typename S::Workspace>;
  s.Eval(z, t, out, ws);
  s.Vjp(z, t, z, out, grad, ws);
};

/// Forward solver over batches of initial states with two reverse modes: the
/// discrete adjoint (BackwardDiscrete) and the continuous adjoint (BackwardContinuous).
/// Holds a reference to the system (which must outlive it) and all scratch memory.
template <BatchedVjpSystem System>
class BatchedOdeSolver {
 public:
  /// float or double: the scalar of states, adjoints and gradients.
  using Scalar = BatchedScalar<System>;
  using Matrix = Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic>;
  using Vector = Eigen::Matrix<Scalar, Eigen::Dynamic, 1>;

  /// Solver of `system` with `options` (method, fixed dt or adaptive tolerances and
  /// first trial step options.dt, max_steps).
  BatchedOdeSolver(const System& system, const OdeOptions& options)
      : system_(system), options_(options), tableau_(TableauOf(options.method)) {
    DIFFDYN_CHECK(options.dt > 0, "BatchedOdeSolver: dt must be positive, got ", options.dt);
    DIFFDYN_CHECK(!tableau_.adaptive || (options.abs_tol > 0 && options.rel_tol >= 0),
                  "BatchedOdeSolver: tolerances must be positive, got abs_tol = ",
                  options.abs_tol, ", rel_tol = ", options.rel_tol);
    // A stage is needed backward if b uses it or a needed later stage reads it.
    for (int i = tableau_.stages - 1; i >= 0; --i) {
      needed_[i] = tableau_.b[i] != 0.0;
      for (int j = i + 1; j < tableau_.stages; ++j) {
        if (needed_[j] && tableau_.a[j][i] != 0.0) needed_[i] = true;
      }
    }
  }

  /// Integrates the batch z0 (n x B) through times (strictly increasing, >= 2 points);
  /// outputs (resized to times.size()) receives z(times[i]) (n x B each), outputs[0] =
  /// z0. With record_tape the stage inputs of every step are kept for BackwardDiscrete;
  /// without it memory does not grow with the steps (enough for BackwardContinuous).
  /// Throws diffdyn::Error for wrong sizes or times, diffdyn::NumericalError for
  /// step-size underflow, non-finite states or more than max_steps steps.
  IntegrationStats Forward(const Eigen::Ref<const Matrix>& z0, const std::vector<double>& times,
                           std::vector<Matrix>* outputs, bool record_tape = true) {
    const int n = system_.state_size();
    DIFFDYN_CHECK(z0.rows() == n, "BatchedOdeSolver::Forward: z0 has ", z0.rows(),
                  " rows, the system's state has ", n);
    DIFFDYN_CHECK(z0.cols() >= 1, "BatchedOdeSolver::Forward: empty batch");
    DIFFDYN_CHECK(times.size() >= 2, "BatchedOdeSolver::Forward: need at least 2 times, got ",
                  times.size());
    for (size_t i = 1; i < times.size(); ++i) {
      DIFFDYN_CHECK(times[i] > times[i - 1], "BatchedOdeSolver::Forward: times must increase: "
                    "times[", i - 1, "] = ", times[i - 1], ", times[", i, "] = ", times[i]);
    }
    Resize(static_cast<int>(z0.cols()));
    times_ = times;
    record_ = record_tape;
    num_steps_ = 0;
    output_steps_.assign(1, 0);
    outputs->resize(times.size());
    z_ = z0;
    dt_ = options_.dt;
    have_k0_ = false;
    CheckFinite(z_, times[0]);
    (*outputs)[0] = z_;
    IntegrationStats stats;
    for (size_t i = 1; i < times.size(); ++i) {
      if (tableau_.adaptive) {
        AdvanceAdaptive(times[i - 1], times[i], &stats);
      } else {
        AdvanceFixed(times[i - 1], times[i], &stats);
      }
      output_steps_.push_back(num_steps_);
      (*outputs)[i] = z_;
    }
    final_state_ = z_;
    forward_done_ = true;
    return stats;
  }

  /// Discrete adjoint of the last Forward (recorded with record_tape): from dl_dz
  /// (times.size() entries of n x B, dL/dz(times[i]); an empty matrix means zero) to
  /// dl_dz0 (n x B) and dl_dtheta (p), both overwritten. Exact for the discrete map.
  void BackwardDiscrete(const std::vector<Matrix>& dl_dz, Matrix* dl_dz0, Vector* dl_dtheta) {
    DIFFDYN_CHECK(forward_done_ && record_, "BackwardDiscrete needs a Forward with record_tape");
    CheckLossGradients(dl_dz);
    adjoint_.setZero();
    dl_dtheta->setZero(system_.num_params());
    for (int i = static_cast<int>(times_.size()) - 1; i >= 1; --i) {
      if (dl_dz[i].size() > 0) adjoint_ += dl_dz[i];
      for (int step = output_steps_[i] - 1; step >= output_steps_[i - 1]; --step) {
        StepVjp(step, dl_dtheta);
      }
    }
    if (dl_dz[0].size() > 0) adjoint_ += dl_dz[0];
    *dl_dz0 = adjoint_;
  }

  /// Continuous adjoint of the last Forward (tape not needed): integrates the augmented
  /// adjoint ODE from times.back() to times[0] with `backward` (any method and
  /// tolerances). dl_dz, dl_dz0 and dl_dtheta as BackwardDiscrete.
  IntegrationStats BackwardContinuous(const std::vector<Matrix>& dl_dz, const OdeOptions& backward,
                                      Matrix* dl_dz0, Vector* dl_dtheta) {
    DIFFDYN_CHECK(forward_done_, "BackwardContinuous needs a Forward first");
    CheckLossGradients(dl_dz);
    const Eigen::Index nb = static_cast<Eigen::Index>(system_.state_size()) * batch_;
    const int p = system_.num_params();
    // Augmented flat state [z, a, g]: 2 n B + p entries.
    augmented_.resize(2 * nb + p);
    Eigen::Map<Matrix>(augmented_.data(), system_.state_size(), batch_) = final_state_;
    augmented_.segment(nb, nb + p).setZero();
    std::vector<double> reversed(times_.rbegin(), times_.rend());
    const int last = static_cast<int>(times_.size()) - 1;
    const AugmentedSystem augmented{this};
    const IntegrationStats stats =
        IntegrateTimes(augmented, augmented_, reversed, backward, [&](int k, double, Vector& x) {
          const Matrix& g = dl_dz[last - k];
          if (g.size() > 0) x.segment(nb, nb) += g.reshaped();
        });
    *dl_dz0 = Eigen::Map<const Matrix>(augmented_.data() + nb, system_.state_size(), batch_);
    *dl_dtheta = augmented_.tail(p);
    return stats;
  }

  /// Start times t_k of the accepted steps of the last Forward (num_steps()).
  const std::vector<double>& step_times() const { return step_t_; }
  /// Sizes h_k of the accepted steps of the last Forward (num_steps()).
  const std::vector<double>& step_sizes() const { return step_h_; }
  /// Number of accepted steps done when times[i] was reached (output_steps()[0] = 0).
  const std::vector<int>& output_steps() const { return output_steps_; }
  /// Accepted steps of the last Forward.
  int num_steps() const { return num_steps_; }

 private:
  // The adjoint ODE as an odeint system on the flat state [z, a, g].
  struct AugmentedSystem {
    BatchedOdeSolver* self;
    void operator()(const Vector& x, Vector& dxdt, double t) const {
      const int n = self->system_.state_size();
      const int b = self->batch_;
      const Eigen::Index nb = static_cast<Eigen::Index>(n) * b;
      const Eigen::Map<const Matrix> z(x.data(), n, b);
      const Eigen::Map<const Matrix> a(x.data() + nb, n, b);
      Eigen::Map<Matrix> dz(dxdt.data(), n, b);
      Eigen::Map<Matrix> da(dxdt.data() + nb, n, b);
      auto dg = dxdt.tail(self->system_.num_params());
      self->system_.Eval(z, t, dz, *self->workspace_);
      dg.setZero();
      self->system_.Vjp(z, t, a, da, dg, *self->workspace_);
      da = -da;
      dg = -dg;
    }
  };

  // Buffers for batch size b (reallocated only when b changes).
  void Resize(int b) {
    if (b == batch_) return;
    batch_ = b;
    const int n = system_.state_size();
    workspace_.emplace(system_.MakeWorkspace(b));
    for (auto* m : {&z_, &z_new_, &err_, &stage_in_, &adjoint_, &kbar_}) m->resize(n, b);
    for (int i = 0; i < kMaxStages; ++i) {
      k_[i].resize(n, b);
      w_[i].resize(n, b);
    }
    tape_.clear();
    tape_capacity_steps_ = 0;
  }

  void CheckFinite(const Matrix& z, double t) const {
    if (z.allFinite()) return;
    for (Eigen::Index b = 0; b < z.cols(); ++b) {
      for (Eigen::Index i = 0; i < z.rows(); ++i) {
        if (!std::isfinite(z(i, b))) {
          throw NumericalError(StrCat("non-finite state at t = ", t, ": entry ", i, " of sample ",
                                      b, " = ", z(i, b)));
        }
      }
    }
  }

  void CheckLossGradients(const std::vector<Matrix>& dl_dz) const {
    DIFFDYN_CHECK(dl_dz.size() == times_.size(), "adjoint: ", dl_dz.size(),
                  " loss gradients for ", times_.size(), " output times");
    for (size_t i = 0; i < dl_dz.size(); ++i) {
      DIFFDYN_CHECK(dl_dz[i].size() == 0 ||
                        (dl_dz[i].rows() == system_.state_size() && dl_dz[i].cols() == batch_),
                    "adjoint: dL/dz[", i, "] is ", dl_dz[i].rows(), " x ", dl_dz[i].cols(),
                    ", expected ", system_.state_size(), " x ", batch_, " or empty");
    }
  }

  // Stage inputs of `step` live at tape_[step * stages + i].
  Matrix& TapeSlot(int step, int stage) {
    return tape_[static_cast<size_t>(step) * tableau_.stages + stage];
  }

  // One step from (z_, t) with h: fills k_, z_new_ (and err_ if adaptive). With FSAL and
  // have_k0, k_[0] already holds f(z_, t).
  void TakeStep(double t, double h, bool have_k0) {
    const int s = tableau_.stages;
    for (int i = 0; i < s; ++i) {
      if (i == 0 && have_k0) continue;
      stage_in_ = z_;
      for (int j = 0; j < i; ++j) {
        if (tableau_.a[i][j] != 0.0) stage_in_.noalias() += Scalar(h * tableau_.a[i][j]) * k_[j];
      }
      system_.Eval(stage_in_, t + tableau_.c[i] * h, k_[i], *workspace_);
    }
    z_new_ = z_;
    for (int i = 0; i < s; ++i) {
      if (tableau_.b[i] != 0.0) z_new_.noalias() += Scalar(h * tableau_.b[i]) * k_[i];
    }
    if (tableau_.adaptive) {
      err_.setZero();
      for (int i = 0; i < s; ++i) {
        const double e = tableau_.b[i] - tableau_.b_hat[i];
        if (e != 0.0) err_.noalias() += Scalar(h * e) * k_[i];
      }
    }
  }

  // Stores the stage inputs Y_i of the step just taken from z_ (recomputed from k_).
  void Record(double t, double h) {
    step_t_.resize(num_steps_ + 1);
    step_h_.resize(num_steps_ + 1);
    step_t_[num_steps_] = t;
    step_h_[num_steps_] = h;
    if (!record_) return;
    const int s = tableau_.stages;
    if (num_steps_ >= tape_capacity_steps_) {
      tape_capacity_steps_ = std::max(16, 2 * tape_capacity_steps_);
      tape_.resize(static_cast<size_t>(tape_capacity_steps_) * s);
    }
    for (int i = 0; i < s; ++i) {
      if (!needed_[i]) continue;
      Matrix& y = TapeSlot(num_steps_, i);
      y = z_;
      for (int j = 0; j < i; ++j) {
        if (tableau_.a[i][j] != 0.0) y.noalias() += Scalar(h * tableau_.a[i][j]) * k_[j];
      }
    }
  }

  void AdvanceFixed(double t0, double t1, IntegrationStats* stats) {
    const double span = t1 - t0;
    const long n = std::max(1L, static_cast<long>(std::ceil(span / options_.dt - 1e-9)));
    const double h = span / static_cast<double>(n);
    for (long k = 0; k < n; ++k) {
      const double t = t0 + static_cast<double>(k) * h;
      TakeStep(t, h, false);
      Record(t, h);
      z_.swap(z_new_);
      ++num_steps_;
      CheckFinite(z_, t + h);
    }
    stats->accepted_steps += n;
  }

  // Adaptive steps from t0 to t1 with one step size for the batch (RMS error norm).
  void AdvanceAdaptive(double t0, double t1, IntegrationStats* stats) {
    const bool fsal = tableau_.fsal();
    const double exponent = -1.0 / tableau_.order;
    double t = t0;
    while (t < t1) {
      if (stats->accepted_steps + stats->rejected_steps >= options_.max_steps) {
        throw NumericalError(StrCat("integration exceeded max_steps = ", options_.max_steps,
                                    " at t = ", t));
      }
      const bool clipped = dt_ >= t1 - t;
      const double h = clipped ? t1 - t : dt_;
      TakeStep(t, h, fsal && have_k0_);
      if (fsal) have_k0_ = true;
      const double ratio = ErrorRatio();
      const double factor =
          ratio == 0.0 ? 10.0 : std::clamp(0.9 * std::pow(ratio, exponent), 0.2, 10.0);
      if (ratio <= 1.0) {
        Record(t, h);
        z_.swap(z_new_);
        if (fsal) k_[0].swap(k_[tableau_.stages - 1]);
        ++num_steps_;
        ++stats->accepted_steps;
        t = clipped ? t1 : t + h;
        CheckFinite(z_, t);
        dt_ = clipped ? std::max(dt_, h * factor) : h * factor;
      } else {
        ++stats->rejected_steps;
        dt_ = h * std::min(1.0, factor);
        if (!std::isfinite(ratio)) CheckFinite(z_new_, t + h);
        if (dt_ < 1e-14 * std::max(1.0, std::abs(t))) ThrowUnderflow(t, h);
      }
    }
  }

  // |err| / (abs_tol + rel_tol max(|z|, |z'|)) entry by entry, in double.
  auto ScaledError() const {
    const auto z = z_.array().template cast<double>().abs();
    const auto z_new = z_new_.array().template cast<double>().abs();
    return err_.array().template cast<double>().abs() /
           (options_.abs_tol + options_.rel_tol * z.max(z_new));
  }

  // The RMS of the scaled error over all n x B entries (accepted when <= 1).
  double ErrorRatio() const { return std::sqrt(ScaledError().square().mean()); }

  [[noreturn]] void ThrowUnderflow(double t, double h) const {
    const Eigen::ArrayXXd scaled = ScaledError();
    Eigen::Index row = 0, col = 0;
    scaled.maxCoeff(&row, &col);
    throw NumericalError(StrCat("step size underflow at t = ", t, " (dt = ", h,
                                "): largest error in state entry ", row, " of sample ", col, " = ",
                                static_cast<double>(z_(row, col))));
  }

  // adjoint_ <- dL/dz_step from dL/dz_{step+1}; accumulates dL/dtheta.
  void StepVjp(int step, Vector* dl_dtheta) {
    const int s = tableau_.stages;
    const double t = step_t_[step];
    const double h = step_h_[step];
    for (int i = s - 1; i >= 0; --i) {
      if (!needed_[i]) continue;
      kbar_ = Scalar(h * tableau_.b[i]) * adjoint_;
      for (int j = i + 1; j < s; ++j) {
        if (needed_[j] && tableau_.a[j][i] != 0.0)
          kbar_.noalias() += Scalar(h * tableau_.a[j][i]) * w_[j];
      }
      system_.Vjp(TapeSlot(step, i), t + tableau_.c[i] * h, kbar_, w_[i], *dl_dtheta,
                  *workspace_);
    }
    for (int i = 0; i < s; ++i) {
      if (needed_[i]) adjoint_ += w_[i];
    }
  }

  const System& system_;
  OdeOptions options_;
  const ButcherTableau& tableau_;
  std::array<bool, kMaxStages> needed_{};
  int batch_ = -1;
  std::optional<typename System::Workspace> workspace_;
  // Forward state, stage derivatives, stage input, error estimate.
  Matrix z_, z_new_, err_, stage_in_, final_state_;
  std::array<Matrix, kMaxStages> k_;
  double dt_ = 0.0;
  bool have_k0_ = false;
  // Tape: steps, output boundaries, stage inputs.
  std::vector<double> times_, step_t_, step_h_;
  std::vector<int> output_steps_;
  std::vector<Matrix> tape_;
  int tape_capacity_steps_ = 0;
  int num_steps_ = 0;
  bool record_ = false;
  bool forward_done_ = false;
  // Backward buffers.
  Matrix adjoint_, kbar_;
  std::array<Matrix, kMaxStages> w_;
  Vector augmented_;
};

}  // namespace diffdyn
