// Continuous-time systems as transition models: one adapter for every ODE.
//
// A continuous-time system dx/dt = f(x, u, theta, t) (the Dynamics concept of
// sensitivity.h: a functor templated on the scalar) becomes the transition model
//
//   x_{t+1} = F(x_t, u_t) = x(dt),   x(0) = x_t,   u = u_t held over [0, dt],
//
// integrated by one of the project's odeint fixed-step methods (integrate.h) with
// `substeps` equal steps h = dt / substeps. theta (the system's parameters, may be
// empty) is fixed in the model. The same adapter serves an analytic robot with
// effects, a learned continuous model or a user's functor.
//
// Two paths compute F and are pinned to each other by tests:
//
// 1. PredictBatch (TransitionModel): B samples in columns, each integrated by the
//    workspace's odeint stepper on double; nothing is allocated per step (the
//    stepper and the state buffers live in the workspace).
// 2. Predict: one sample on any scalar (Jets: the Jacobian of the discrete map F).
//
//   struct Decay {  // dx/dt = -theta x + u
//     template <typename T>
//     void operator()(const VectorX<T>& x, const VectorX<T>& u, const VectorX<T>& theta,
//                     double, VectorX<T>& dxdt) const { dxdt = -theta[0] * x + u; }
//   };
//   ContinuousTransitionModel<Decay> model(Decay{}, SystemDescription::Unnamed(1, 1),
//                                          Eigen::VectorXd::Constant(1, 2.0),
//                                          {.method = Method::kRk4Classic, .dt = 0.1});
//   auto ws = model.MakeWorkspace(64);
//   model.PredictBatch(states, actions, next, *ws);   // 1 x 64 each
#pragma once

#include <memory>
#include <string>
#include <type_traits>
#include <utility>
#include <variant>

#include <Eigen/Core>

#include "diffdyn/autodiff_ode/butcher.h"
#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/autodiff_ode/integrate.h"
#include "diffdyn/autodiff_ode/sensitivity.h"
#include "diffdyn/models/system_description.h"
#include "diffdyn/models/transition_model.h"

namespace diffdyn {

/// Integration settings of a ContinuousTransitionModel.
struct ContinuousOptions {
  /// A fixed-step method (euler, midpoint, rk4-classic, rk4).
  Method method = Method::kRk4Classic;
  /// The transition's time step (s), > 0.
  double dt = 0.01;
  /// Solver steps per transition, >= 1.
  int substeps = 1;
};

/// Scratch space of a ContinuousTransitionModel: one odeint stepper and the state,
/// action and parameter buffers of one sample.
class ContinuousWorkspace : public TransitionWorkspace {
 public:
  using Stepper = std::variant<FixedStepper<Method::kEuler, Eigen::VectorXd>,
                               FixedStepper<Method::kMidpoint, Eigen::VectorXd>,
                               FixedStepper<Method::kRk4Classic, Eigen::VectorXd>,
                               FixedStepper<Method::kRk4, Eigen::VectorXd>>;

  explicit ContinuousWorkspace(Method method) : stepper(MakeStepper(method)) {}

  Stepper stepper;
  Eigen::VectorXd x, u;

  /// The odeint stepper of a fixed-step `method`; throws diffdyn::Error otherwise.
  static Stepper MakeStepper(Method method) {
    // By index: rk4 and rk4-classic share a stepper type (their tableaus differ).
    switch (method) {
      case Method::kEuler:
        return Stepper(std::in_place_index<0>, MakeFixedStepper<Method::kEuler, Eigen::VectorXd>());
      case Method::kMidpoint:
        return Stepper(std::in_place_index<1>, MakeFixedStepper<Method::kMidpoint, Eigen::VectorXd>());
      case Method::kRk4Classic:
        return Stepper(std::in_place_index<2>,
                       MakeFixedStepper<Method::kRk4Classic, Eigen::VectorXd>());
      case Method::kRk4:
        return Stepper(std::in_place_index<3>, MakeFixedStepper<Method::kRk4, Eigen::VectorXd>());
      default:
        break;
    }
    throw Error(StrCat("continuous model: solver ", MethodName(method),
                       " is adaptive; a transition model integrates with a fixed-step one "
                       "(euler, midpoint, rk4-classic, rk4)"));
  }
};

/// x_{t+1} = x(dt) of dx/dt = f(x, u, theta, t) (see the file comment). `Dynamics` is
/// copied into the model; the model is immutable and serves many threads.
template <typename Dynamics>
class ContinuousTransitionModel final : public TransitionModel {
 public:
  /// f on the system `system` (n states, m actions) with parameters `theta` (p, may be
  /// empty). Throws diffdyn::Error for dt <= 0, substeps < 1, an adaptive method or an
  /// invalid system.
  ContinuousTransitionModel(Dynamics f, SystemDescription system, Eigen::VectorXd theta,
                            ContinuousOptions options, std::string kind = "continuous")
      : f_(std::move(f)),
        system_(std::move(system)),
        theta_(std::move(theta)),
        options_(options),
        kind_(std::move(kind)) {
    system_.Validate();
    DIFFDYN_CHECK(options_.dt > 0 && std::isfinite(options_.dt), kind_,
                  ": dt must be positive, got ", options_.dt);
    DIFFDYN_CHECK(options_.substeps >= 1, kind_, ": substeps must be >= 1, got ", options_.substeps);
    ContinuousWorkspace::MakeStepper(options_.method);  // refuses adaptive methods now
  }

  const SystemDescription& system() const { return system_; }
  const Eigen::VectorXd& theta() const { return theta_; }
  const ContinuousOptions& options() const { return options_; }
  const Dynamics& dynamics() const { return f_; }

  int state_size() const override { return system_.state_size(); }
  int action_size() const override { return system_.action_size(); }
  std::string kind() const override { return kind_; }
  double time_step() const override { return options_.dt; }
  SystemDescription description() const override { return system_; }

  std::unique_ptr<TransitionWorkspace> MakeWorkspace(int /*max_batch*/) const override {
    auto ws = std::make_unique<ContinuousWorkspace>(options_.method);
    ws->x.resize(state_size());
    ws->u.resize(action_size());
    return ws;
  }

  /// next(:, b) = F(states(:, b), actions(:, b)): n x B, m x B, n x B. Throws
  /// diffdyn::NumericalError for a non-finite state.
  void PredictBatch(const Eigen::Ref<const Eigen::MatrixXd>& states,
                    const Eigen::Ref<const Eigen::MatrixXd>& actions, Eigen::Ref<Eigen::MatrixXd> next,
                    TransitionWorkspace& ws) const override {
    CheckBatchSizes(states, actions, next);
    Integrate(states, actions, nullptr, next, ws);
  }

  /// As PredictBatch, sample b integrated over its own dt(b) > 0 (substeps equal steps).
  void PredictBatchOver(const Eigen::Ref<const Eigen::MatrixXd>& states,
                        const Eigen::Ref<const Eigen::MatrixXd>& actions,
                        const Eigen::Ref<const Eigen::RowVectorXd>& dt, Eigen::Ref<Eigen::MatrixXd> next,
                        TransitionWorkspace& ws) const override {
    CheckBatchSizes(states, actions, next);
    DIFFDYN_CHECK(dt.size() == states.cols(), kind_, ": PredictBatchOver got ", dt.size(),
                  " intervals for ", states.cols(), " samples");
    Integrate(states, actions, &dt, next, ws);
  }

  bool uses_intervals() const override { return true; }
  /// Whether f can be evaluated on Jets (a functor templated on the scalar).
  static constexpr bool kJetDynamics =
      std::is_invocable_v<const Dynamics&, const VectorX<JetK<8>>&, const VectorX<JetK<8>>&,
                          const VectorX<JetK<8>>&, double, VectorX<JetK<8>>&>;

  bool differentiable() const override { return kJetDynamics; }

  /// [dF/dx, dF/du] (n x (n + m)) by Jets through the same integration (Predict);
  /// a functor on double only is not differentiable (TransitionModel::Jacobian throws).
  Eigen::VectorXd Jacobian(const Eigen::Ref<const Eigen::VectorXd>& x, const Eigen::Ref<const Eigen::VectorXd>& u,
                           Eigen::MatrixXd* jac) const override {
    if constexpr (kJetDynamics) {
      return JetJacobian([this](const auto& xj, const auto& uj) { return this->Predict(xj, uj); }, x, u, jac);
    } else {
      return TransitionModel::Jacobian(x, u, jac);
    }
  }

  /// F(x, u) for one sample (x: n, u: m entries) on any scalar (Jets for dF/dx, dF/du).
  template <typename DX, typename DU>
  VectorX<typename DX::Scalar> Predict(const Eigen::MatrixBase<DX>& x,
                                       const Eigen::MatrixBase<DU>& u) const {
    using S = typename DX::Scalar;
    DIFFDYN_CHECK(x.size() == state_size() && u.size() == action_size(), kind_, ": Predict got x of ",
                  x.size(), " and u of ", u.size(), " entries, expected ", state_size(), " and ",
                  action_size());
    OdeOptions o;
    o.method = options_.method;
    o.dt = options_.dt / options_.substeps;
    const VectorX<S> x0 = x;
    const VectorX<S> u0 = u.template cast<S>();
    const VectorX<S> theta = theta_.template cast<S>();
    return Simulate<S>(f_, x0, u0, theta, {0.0, options_.dt}, o).back();
  }

 private:
  // Each column over options_.dt, or over (*dt)(b) when dt is given.
  void Integrate(const Eigen::Ref<const Eigen::MatrixXd>& states,
                 const Eigen::Ref<const Eigen::MatrixXd>& actions,
                 const Eigen::Ref<const Eigen::RowVectorXd>* dt, Eigen::Ref<Eigen::MatrixXd> next,
                 TransitionWorkspace& ws_base) const {
    auto* ws = dynamic_cast<ContinuousWorkspace*>(&ws_base);
    DIFFDYN_CHECK(ws != nullptr, kind_, ": the workspace was not made by this model");
    const BoundDynamics<Dynamics, double> system(f_, ws->u, theta_);
    std::visit(
        [&](auto& stepper) {
          for (Eigen::Index b = 0; b < states.cols(); ++b) {
            const double interval = dt ? (*dt)(b) : options_.dt;
            DIFFDYN_CHECK(interval > 0 && std::isfinite(interval), kind_,
                          ": a transition needs a positive interval, got ", interval);
            const double h = interval / options_.substeps;
            ws->x = states.col(b);
            ws->u = actions.col(b);
            for (int k = 0; k < options_.substeps; ++k) stepper.do_step(system, ws->x, k * h, h);
            CheckFiniteState(ws->x, interval);
            next.col(b) = ws->x;
          }
        },
        ws->stepper);
  }

  Dynamics f_;
  SystemDescription system_;
  Eigen::VectorXd theta_;
  ContinuousOptions options_;
  std::string kind_;
};

}  // namespace diffdyn
