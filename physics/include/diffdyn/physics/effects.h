// Named physical effects that extend any analytic model.
//
// The nominal model says tau = ID(q, qd, qdd). A real joint j "feels" the torque
// the actuator really applies minus the effect torques:
//
//   k tau_meas(t - d) - sum_e tau_e(q, qd, qdd) = ID(q, qd, qdd) + m_p TipLoad(q, qd, qdd),
//
// with the effects of shared/reference/model_conventions.md (parameters, units):
//
//   viscous   tau_e = b qd_j                                    b (N m s/rad | N s/m)
//   coulomb   tau_e = F_c tanh(qd_j / 0.01)                     F_c (N m | N)
//   stribeck  tau_e = (F_c + (F_s - F_c) exp(-(qd_j/v_s)^2)) tanh(qd_j / 0.01)
//   offset    tau_e = -tau_0                                    tau_0 (N m | N)
//   spring    tau_e = k q_j                                     k (N m/rad | N/m)
//   armature  tau_e = I_a qdd_j                                 I_a (kg m^2 | kg)
//   gain      tau_applied = k tau_meas, every joint (joint 0)   k (1 = nominal)
//   delay     tau_applied(t) = tau_meas(t - d) (joint 0)        d (s)
//   payload   point mass m_p at the end of the last link        m_p (kg)
//   residual  a learned network r(q, qd, qdd) (residual_network.h)
//
// ExtendedModel holds a nominal model, its parameters, a list of effects and
// their flat parameter vector theta (the effects' parameters in list order).
// JointTorque<T>(q, qd, qdd, theta) is the right-hand side plus the effect
// torques, i.e. the torque the joints must receive; the torque the sensor reads
// is then tau_meas(t) = JointTorque(x(t + d)) / k. It is templated so Ceres can
// differentiate it with respect to theta (T = DiagJet). ForwardDynamics solves
// JointTorque(q, qd, qdd) = k tau for qdd, for rollouts and simulation.
#pragma once

#include <limits>
#include <memory>
#include <string>
#include <type_traits>
#include <vector>

#include <Eigen/Cholesky>
#include <Eigen/Core>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/autodiff_ode/integrate.h"
#include "diffdyn/physics/analytic_model.h"
#include "diffdyn/physics/residual_network.h"

namespace diffdyn {

/// The kinds of named effects (model_conventions.md).
enum class EffectKind {
  kViscous,
  kCoulomb,
  kStribeck,
  kOffset,
  kSpring,
  kArmature,
  kGain,
  kDelay,
  kPayload,
  kResidual
};

/// Velocity scale of the smoothed sign in coulomb and stribeck friction (rad/s or m/s).
inline constexpr double kCoulombVelocityScale = 0.01;

/// Static description of an effect kind: name, parameters and units.
struct EffectKindInfo {
  EffectKind kind;
  const char* name;                  ///< as in named_effects[].kind
  bool per_joint;                    ///< false: acts on the whole system (joint 0)
  std::vector<std::string> params;   ///< parameter names
  std::vector<std::string> units;    ///< units on a revolute joint
  std::vector<std::string> prismatic_units;  ///< units on a prismatic joint
  std::vector<double> neutral;       ///< parameter values that make the effect vanish
  std::vector<double> lower;         ///< admissible range of each parameter: lower bound
  std::vector<double> upper;         ///< admissible range of each parameter: upper bound
};

/// No bound on a parameter.
inline constexpr double kUnbounded = std::numeric_limits<double>::infinity();

/// Every effect kind, in a fixed order.
inline const std::vector<EffectKindInfo>& AllEffectKinds() {
  // Admissible ranges: friction, viscosity, inertia and mass are non-negative;
  // a gain within a factor of 2; a delay of at most 0.1 s.
  constexpr double inf = kUnbounded;
  static const std::vector<EffectKindInfo> kinds = {
      {EffectKind::kViscous, "viscous", true, {"b"}, {"N m s/rad"}, {"N s/m"}, {0.0}, {0.0}, {inf}},
      {EffectKind::kCoulomb, "coulomb", true, {"F_c"}, {"N m"}, {"N"}, {0.0}, {0.0}, {inf}},
      {EffectKind::kStribeck, "stribeck", true, {"F_c", "F_s", "v_s"},
       {"N m", "N m", "rad/s"}, {"N", "N", "m/s"}, {0.0, 0.0, 0.1}, {0.0, 0.0, 1e-3}, {inf, inf, inf}},
      {EffectKind::kOffset, "offset", true, {"tau_0"}, {"N m"}, {"N"}, {0.0}, {-inf}, {inf}},
      {EffectKind::kSpring, "spring", true, {"k"}, {"N m/rad"}, {"N/m"}, {0.0}, {-inf}, {inf}},
      {EffectKind::kArmature, "armature", true, {"I_a"}, {"kg m^2"}, {"kg"}, {0.0}, {0.0}, {inf}},
      {EffectKind::kGain, "gain", false, {"k"}, {"1"}, {"1"}, {1.0}, {0.5}, {2.0}},
      {EffectKind::kDelay, "delay", false, {"d"}, {"s"}, {"s"}, {0.0}, {0.0}, {0.1}},
      {EffectKind::kPayload, "payload", false, {"mass"}, {"kg"}, {"kg"}, {0.0}, {0.0}, {inf}},
      {EffectKind::kResidual, "residual", false, {}, {}, {}, {}, {}, {}},
  };
  return kinds;
}

/// The description of `kind`.
inline const EffectKindInfo& Info(EffectKind kind) {
  for (const auto& info : AllEffectKinds()) {
    if (info.kind == kind) return info;
  }
  throw Error("unknown effect kind");
}

/// The kind named `name` ("viscous", ...); throws diffdyn::Error listing the names.
inline EffectKind ParseEffectKind(const std::string& name) {
  std::string known;
  for (const auto& info : AllEffectKinds()) {
    if (name == info.name) return info.kind;
    if (!known.empty()) known += ", ";
    known += info.name;
  }
  throw Error(StrCat("unknown effect kind '", name, "' (known: ", known, ")"));
}

/// One effect instance: kind, joint (1-based; 0 = the whole system) and parameters.
struct Effect {
  EffectKind kind = EffectKind::kViscous;
  int joint = 0;
  std::vector<double> params;   ///< Info(kind).params.size() values
  std::vector<double> stderrs;  ///< standard errors of params (may be empty)
};

/// Per-joint effect torque tau_e (header table) for kinds viscous..armature;
/// theta points at the effect's parameters.
template <typename T>
T JointEffectTorque(EffectKind kind, const T* theta, const T& q, const T& qd, const T& qdd) {
  using std::exp;
  using std::tanh;
  switch (kind) {
    case EffectKind::kViscous:
      return theta[0] * qd;
    case EffectKind::kCoulomb:
      return theta[0] * tanh(qd / kCoulombVelocityScale);
    case EffectKind::kStribeck: {
      const T ratio = qd / theta[2];
      return (theta[0] + (theta[1] - theta[0]) * exp(-ratio * ratio)) *
             tanh(qd / kCoulombVelocityScale);
    }
    case EffectKind::kOffset:
      return -theta[0];
    case EffectKind::kSpring:
      return theta[0] * q;
    case EffectKind::kArmature:
      return theta[0] * qdd;
    default:
      return T(0.0);
  }
}

/// A nominal model extended by named effects (and optionally a learned residual).
class ExtendedModel {
 public:
  /// `model` with parameters `params` (its param_specs() size) and `effects`
  /// (joints in 1..n for per-joint kinds, 0 for gain/delay/payload/residual).
  /// Throws diffdyn::Error on a bad joint or parameter count.
  ExtendedModel(std::shared_ptr<const AnalyticModel> model, Eigen::VectorXd params,
                std::vector<Effect> effects, std::shared_ptr<const ResidualNetwork> residual = {})
      : model_(std::move(model)),
        params_(std::move(params)),
        effects_(std::move(effects)),
        residual_(std::move(residual)) {
    DIFFDYN_CHECK(model_ != nullptr, "ExtendedModel: no model");
    DIFFDYN_CHECK(params_.size() == static_cast<int>(model_->param_specs().size()),
                  "ExtendedModel: model ", model_->name(), " has ",
                  model_->param_specs().size(), " parameters, got ", params_.size());
    for (const Effect& e : effects_) {
      const EffectKindInfo& info = Info(e.kind);
      DIFFDYN_CHECK(e.params.size() == info.params.size(), "effect ", info.name, " needs ",
                    info.params.size(), " parameters, got ", e.params.size());
      if (info.per_joint) {
        DIFFDYN_CHECK(e.joint >= 1 && e.joint <= model_->dof(), "effect ", info.name,
                      ": joint ", e.joint, " is not in 1..", model_->dof());
      } else {
        DIFFDYN_CHECK(e.joint == 0, "effect ", info.name, " acts on joint 0, got ", e.joint);
      }
    }
    if (residual_) {
      DIFFDYN_CHECK(residual_->dof() == model_->dof(), "ExtendedModel: residual network has ",
                    residual_->dof(), " outputs, model has ", model_->dof(), " joints");
    }
  }

  const AnalyticModel& model() const { return *model_; }
  std::shared_ptr<const AnalyticModel> model_ptr() const { return model_; }
  const Eigen::VectorXd& params() const { return params_; }
  const std::vector<Effect>& effects() const { return effects_; }
  const ResidualNetwork* residual() const { return residual_.get(); }
  int dof() const { return model_->dof(); }

  /// theta: every effect's parameters concatenated in list order.
  Eigen::VectorXd EffectParams() const {
    std::vector<double> flat;
    for (const Effect& e : effects_) flat.insert(flat.end(), e.params.begin(), e.params.end());
    return Eigen::Map<const Eigen::VectorXd>(flat.data(), static_cast<int>(flat.size()));
  }

  /// Index in theta of the first parameter of effect `index`.
  int ParamOffset(int index) const {
    int offset = 0;
    for (int i = 0; i < index; ++i) offset += static_cast<int>(effects_[i].params.size());
    return offset;
  }

  /// A copy with theta replaced (size EffectParams().size()) and optional stderrs.
  ExtendedModel WithEffectParams(const Eigen::VectorXd& theta,
                                 const Eigen::VectorXd& stderrs = Eigen::VectorXd()) const {
    DIFFDYN_CHECK(theta.size() == EffectParams().size(), "WithEffectParams: expected ",
                  EffectParams().size(), " values, got ", theta.size());
    std::vector<Effect> effects = effects_;
    int k = 0;
    for (Effect& e : effects) {
      e.stderrs.assign(e.params.size(), 0.0);
      for (std::size_t i = 0; i < e.params.size(); ++i, ++k) {
        e.params[i] = theta[k];
        if (stderrs.size() == theta.size()) e.stderrs[i] = stderrs[k];
      }
    }
    return ExtendedModel(model_, params_, std::move(effects), residual_);
  }

  /// A copy with the nominal model's parameters replaced (its param_specs() size).
  ExtendedModel WithNominalParams(Eigen::VectorXd params) const {
    return ExtendedModel(model_, std::move(params), effects_, residual_);
  }

  /// A copy with `more` effects appended.
  ExtendedModel WithMoreEffects(const std::vector<Effect>& more) const {
    std::vector<Effect> effects = effects_;
    effects.insert(effects.end(), more.begin(), more.end());
    return ExtendedModel(model_, params_, std::move(effects), residual_);
  }

  /// A copy with the learned residual replaced (may be null).
  ExtendedModel WithResidual(std::shared_ptr<const ResidualNetwork> residual) const {
    return ExtendedModel(model_, params_, effects_, std::move(residual));
  }

  /// The gain k on the measured torque (product of gain effects; 1 if none).
  template <typename T>
  T Gain(const VectorX<T>& theta) const {
    T k = T(1.0);
    for (int i = 0; i < static_cast<int>(effects_.size()); ++i) {
      if (effects_[i].kind == EffectKind::kGain) k *= theta[ParamOffset(i)];
    }
    return k;
  }

  /// The input delay d (sum of delay effects; 0 if none).
  template <typename T>
  T Delay(const VectorX<T>& theta) const {
    T d = T(0.0);
    for (int i = 0; i < static_cast<int>(effects_.size()); ++i) {
      if (effects_[i].kind == EffectKind::kDelay) d += theta[ParamOffset(i)];
    }
    return d;
  }

  /// The torque the joints must receive (n): ID + m_p TipLoad + sum of per-joint
  /// effects + residual network, at (q, qd, qdd) with effect parameters theta.
  template <typename T>
  VectorX<T> JointTorque(const VectorX<T>& q, const VectorX<T>& qd, const VectorX<T>& qdd,
                         const VectorX<T>& theta) const {
    const VectorX<T> p = params_.template cast<T>();
    VectorX<T> tau = model_->InverseDynamics(q, qd, qdd, p);
    int offset = 0;
    for (const Effect& e : effects_) {
      const T* th = theta.data() + offset;
      if (e.kind == EffectKind::kPayload) {
        tau += th[0] * model_->TipLoad(q, qd, qdd, p);
      } else if (Info(e.kind).per_joint) {
        const int j = e.joint - 1;
        tau[j] += JointEffectTorque<T>(e.kind, th, q[j], qd[j], qdd[j]);
      }
      offset += static_cast<int>(e.params.size());
    }
    if (residual_) tau += (*residual_)(q, qd, qdd);
    return tau;
  }

  /// JointTorque at the stored parameters, double.
  Eigen::VectorXd JointTorque(const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                              const Eigen::VectorXd& qdd) const {
    return JointTorque<double>(q, qd, qdd, EffectParams());
  }

  /// qdd (n) solving JointTorque(q, qd, qdd) = k tau_measured, where
  /// `tau_measured` is the sensor torque already taken at t - d. JointTorque is
  /// linear in qdd without a residual network, so one Newton step from qdd = 0
  /// with the effective mass matrix (n + 1 JointTorque calls) is exact; with a
  /// network (nonlinear in qdd) a second step is taken. T: double or DiagJet.
  /// Throws diffdyn::NumericalError when the mass matrix is not positive definite
  /// (on Jets the solution is then not finite).
  template <typename T>
  VectorX<T> ForwardDynamics(const VectorX<T>& q, const VectorX<T>& qd, const VectorX<T>& tau_measured) const {
    const int n = dof();
    const VectorX<T> theta = EffectParams().template cast<T>();
    const VectorX<T> target = Gain<T>(theta) * tau_measured;
    VectorX<T> qdd = VectorX<T>::Zero(n);
    const int steps = residual_ ? 2 : 1;
    for (int step = 0; step < steps; ++step) {
      const VectorX<T> bias = JointTorque<T>(q, qd, qdd, theta);
      MatrixX<T> mass(n, n);
      for (int i = 0; i < n; ++i) {
        mass.col(i) = JointTorque<T>(q, qd, qdd + VectorX<T>::Unit(n, i), theta) - bias;
      }
      const MatrixX<T> symmetric = T(0.5) * (mass + mass.transpose());
      if constexpr (std::is_same_v<T, double>) {
        const Eigen::LDLT<Eigen::MatrixXd> ldlt(symmetric);
        if (ldlt.info() != Eigen::Success || !ldlt.isPositive()) {
          throw NumericalError(StrCat(model_->name(), ": extended mass matrix is not positive definite"));
        }
        qdd += ldlt.solve(target - bias);
      } else {
        qdd += SpdSolve(symmetric, VectorX<T>(target - bias));
      }
    }
    return qdd;
  }

  /// ForwardDynamics on double.
  Eigen::VectorXd ForwardDynamics(const Eigen::VectorXd& q, const Eigen::VectorXd& qd,
                                  const Eigen::VectorXd& tau_measured) const {
    return ForwardDynamics<double>(q, qd, tau_measured);
  }

 private:
  std::shared_ptr<const AnalyticModel> model_;
  Eigen::VectorXd params_;
  std::vector<Effect> effects_;
  std::shared_ptr<const ResidualNetwork> residual_;
};

/// Joint motion of `model` driven by a time-varying torque: advances (q, qd) (n each,
/// in place) from t0 to t1 under dx/dt = (qd, ForwardDynamics(q, qd, torque(t))), x =
/// (q, qd), by `steps` steps of the project's rk4-classic (integrate.h). `torque` is a
/// callable t -> the sensor torque (n) at t (interpolated, held or delayed by the
/// caller). Throws diffdyn::NumericalError for a non-finite state or a mass matrix
/// that is not positive definite.
template <typename Torque>
void IntegrateJointMotion(const ExtendedModel& model, const Torque& torque, double t0, double t1,
                          int steps, Eigen::VectorXd& q, Eigen::VectorXd& qd) {
  const int n = model.dof();
  Eigen::VectorXd x(2 * n);
  x.head(n) = q;
  x.tail(n) = qd;
  const auto system = [&](const Eigen::VectorXd& xx, Eigen::VectorXd& dxdt, double t) {
    dxdt.resize(2 * n);
    dxdt.head(n) = xx.tail(n);
    dxdt.tail(n) = model.ForwardDynamics(xx.head(n), xx.tail(n), torque(t));
  };
  IntegrateFixedSteps(Method::kRk4Classic, system, x, t0, t1, steps);
  q = x.head(n);
  qd = x.tail(n);
}

/// An extended model as continuous dynamics for ContinuousTransitionModel
/// (models/continuous_model.h): x = (q, qd) (2n), u = tau_measured (n), no theta,
///
///   dx/dt = (qd, ExtendedModel::ForwardDynamics(q, qd, u)).
///
/// A delay effect needs the past torque, which (q, qd) does not hold: the constructor
/// refuses a model with one.
struct ExtendedDynamics {
  explicit ExtendedDynamics(std::shared_ptr<const ExtendedModel> m) : model(std::move(m)) {
    DIFFDYN_CHECK(model != nullptr, "ExtendedDynamics: no model");
    for (const Effect& e : model->effects()) {
      DIFFDYN_CHECK(e.kind != EffectKind::kDelay, model->model().name(),
                    ": an extended model with a delay effect is not a transition model of (q, qd) "
                    "(the delay needs the past torque)");
    }
  }
  /// T: double, or DiagJet for the Jacobian of the transition.
  template <typename T>
  void operator()(const VectorX<T>& x, const VectorX<T>& u, const VectorX<T>&, double, VectorX<T>& dxdt) const {
    const int n = model->dof();
    dxdt.resize(2 * n);
    dxdt.head(n) = x.tail(n);
    dxdt.tail(n) = model->template ForwardDynamics<T>(x.head(n), x.tail(n), u);
  }
  std::shared_ptr<const ExtendedModel> model;
};

}  // namespace diffdyn
