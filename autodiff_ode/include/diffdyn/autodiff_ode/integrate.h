// Integrating scalar-generic ODEs with Boost.Odeint on double and Jet states.
//
// A system follows odeint's System concept, sys(x, dxdt, t), for dx/dt = f(x, t):
//
//   struct Pendulum {
//     template <typename T>
//     void operator()(const diffdyn::VectorX<T>& x, diffdyn::VectorX<T>& dxdt, double t) const {
//       dxdt[0] = x[1];
//       dxdt[1] = -9.81 * sin(x[0]);
//     }
//   };
//
// The state is an Eigen column vector of T = double (values) or T = ceres::Jet<double,
// K> (values and K directional derivatives carried through every stage: forward
// sensitivities, see sensitivity.h). Time and step sizes stay double.
//
// Fixed-step methods (euler, midpoint, rk4-classic, rk4 = 3/8 rule) advance N steps
// of h = (t1 - t0) / N at t_k = t0 + k h (an integer count, never t += h); the global
// error is O(h^p) for a method of order p.
//
// Adaptive methods (dopri5, cash-karp) take a trial step h, estimate the local error
// err = x_p - x_hat_{p-1} from the embedded pair, and accept the step when
//
//   max_i |err_i| / (abs_tol + rel_tol |x_i|) <= 1,
//
// shrinking or growing h by (1 / ratio)^(1/p) otherwise. On Jets the ratio is taken
// over the value parts (optionally the derivative parts too): odeint's default
// norm returns the scalar type and does not compile with Jets, so EigenJetAlgebra
// supplies a norm that returns double. A step that shrinks below 1e-14 |t| is a step
// size underflow: diffdyn::NumericalError names the time and the state entry with the
// largest error. A non-finite state entry after a step throws the same, naming the
// entry. Output times are hit exactly (the last step before each is shortened).
//
// Every odeint stepper here is built from the tableaus in butcher.h:
// explicit_generic_rk for the fixed-step ones, explicit_error_generic_rk wrapped in
// controlled_runge_kutta for the embedded pairs (dopri5 this way evaluates all 7
// stages per step; the batched solvers of adjoint.h reuse the FSAL stage).
#pragma once

#include <cmath>
#include <cstddef>
#include <limits>
#include <tuple>
#include <type_traits>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <boost/numeric/odeint/external/eigen/eigen_resize.hpp>
#include <boost/numeric/odeint/stepper/controlled_runge_kutta.hpp>
#include <boost/numeric/odeint/stepper/explicit_error_generic_rk.hpp>
#include <boost/numeric/odeint/stepper/euler.hpp>
#include <boost/numeric/odeint/stepper/explicit_generic_rk.hpp>
#include <ceres/jet.h>

#include "diffdyn/autodiff_ode/butcher.h"
#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/autodiff_ode/jacobian.h"

// odeint's explicit_error_generic_rk forms the error h sum_i (b_i - b_hat_i) k_i with
// generic_rk_scale_sum_err<StageCount>, provided for 1-6 and 13 stages only; dopri5 has 7.
namespace boost::numeric::odeint::detail {
template <class Operations, class Fac, class Time>
struct generic_rk_scale_sum_err<7, Operations, Fac, Time>
    : public Operations::template scale_sum7<Time> {
  generic_rk_scale_sum_err(const boost::array<Fac, 7>& e, Time dt)
      : Operations::template scale_sum7<Time>(e[0] * dt, e[1] * dt, e[2] * dt, e[3] * dt,
                                              e[4] * dt, e[5] * dt, e[6] * dt) {}
  typedef void result_type;
};
}  // namespace boost::numeric::odeint::detail

namespace diffdyn {

/// odeint algebra for Eigen vectors of double or Jet: element-wise for_eachN and an
/// infinity norm that returns double, max_i |value(x_i)| (and max |derivative parts|
/// when kDerivativesInNorm).
template <bool kDerivativesInNorm = false>
struct EigenJetAlgebra {
  /// Calls op(s1[i], s2[i], ...) for every entry i; the last argument is op.
  template <typename... Args>
  static void ForEach(Args&&... args) {
    auto refs = std::forward_as_tuple(args...);
    constexpr std::size_t kStates = sizeof...(Args) - 1;
    auto& op = std::get<kStates>(refs);
    const Eigen::Index size = std::get<0>(refs).size();
    [&]<std::size_t... I>(std::index_sequence<I...>) {
      for (Eigen::Index i = 0; i < size; ++i) op(std::get<I>(refs)[i]...);
    }(std::make_index_sequence<kStates>{});
  }
  /// odeint's interface: for_eachN(s1, ..., sN, op) = ForEach(s1, ..., sN, op), N = 1..15.
  template <typename... A> static void for_each1(A&&... a) { ForEach(a...); }
  template <typename... A> static void for_each2(A&&... a) { ForEach(a...); }
  template <typename... A> static void for_each3(A&&... a) { ForEach(a...); }
  template <typename... A> static void for_each4(A&&... a) { ForEach(a...); }
  template <typename... A> static void for_each5(A&&... a) { ForEach(a...); }
  template <typename... A> static void for_each6(A&&... a) { ForEach(a...); }
  template <typename... A> static void for_each7(A&&... a) { ForEach(a...); }
  template <typename... A> static void for_each8(A&&... a) { ForEach(a...); }
  template <typename... A> static void for_each9(A&&... a) { ForEach(a...); }
  template <typename... A> static void for_each10(A&&... a) { ForEach(a...); }
  template <typename... A> static void for_each11(A&&... a) { ForEach(a...); }
  template <typename... A> static void for_each12(A&&... a) { ForEach(a...); }
  template <typename... A> static void for_each13(A&&... a) { ForEach(a...); }
  template <typename... A> static void for_each14(A&&... a) { ForEach(a...); }
  template <typename... A> static void for_each15(A&&... a) { ForEach(a...); }

  /// max_i |x_i| on value parts (plus derivative parts if kDerivativesInNorm), as double.
  template <typename State>
  static double norm_inf(const State& x) {
    double result = 0.0;
    for (Eigen::Index i = 0; i < x.size(); ++i) result = std::max(result, AbsForNorm(x[i]));
    return result;
  }

 private:
  static double AbsForNorm(double v) { return std::abs(v); }
  template <int K>
  static double AbsForNorm(const ceres::Jet<double, K>& v) {
    double r = std::abs(v.a);
    if constexpr (kDerivativesInNorm) r = std::max(r, v.v.cwiseAbs().maxCoeff());
    return r;
  }
};

namespace internal {

namespace odeint = boost::numeric::odeint;

// Row i (1-based stage index) of A as the boost::array odeint expects.
template <std::size_t kRow>
boost::array<double, kRow> TableauRow(const ButcherTableau& tab) {
  boost::array<double, kRow> row{};
  for (std::size_t j = 0; j < kRow; ++j) row[j] = tab.a[kRow][j];
  return row;
}

template <std::size_t kStages>
boost::array<double, kStages> TableauVector(const std::array<double, kMaxStages>& v) {
  boost::array<double, kStages> out{};
  for (std::size_t j = 0; j < kStages; ++j) out[j] = v[j];
  return out;
}

template <typename CoefA, std::size_t... I>
CoefA TableauA(const ButcherTableau& tab, std::index_sequence<I...>) {
  return CoefA(TableauRow<I + 1>(tab)...);
}

}  // namespace internal

/// odeint fixed-step stepper of `M` (a fixed-step method) on states of type State:
/// odeint's `euler` for the one-stage method (explicit_generic_rk<1> declares a
/// zero-length array, which only g++ accepts), explicit_generic_rk otherwise.
template <Method M, typename State, typename Algebra = EigenJetAlgebra<>>
using FixedStepper = std::conditional_t<
    TableauOf(M).stages == 1,
    boost::numeric::odeint::euler<State, double, State, double, Algebra,
                                  boost::numeric::odeint::default_operations,
                                  boost::numeric::odeint::initially_resizer>,
    boost::numeric::odeint::explicit_generic_rk<
        TableauOf(M).stages, TableauOf(M).order, State, double, State, double, Algebra,
        boost::numeric::odeint::default_operations, boost::numeric::odeint::initially_resizer>>;

/// odeint error stepper (embedded pair) of `M` (dopri5 or cash-karp).
template <Method M, typename State, typename Algebra = EigenJetAlgebra<>>
using ErrorStepper = boost::numeric::odeint::explicit_error_generic_rk<
    TableauOf(M).stages, TableauOf(M).order, TableauOf(M).order, TableauOf(M).order - 1, State,
    double, State, double, Algebra, boost::numeric::odeint::default_operations,
    boost::numeric::odeint::initially_resizer>;

/// odeint controlled stepper (error stepper + step-size controller) of `M`.
template <Method M, typename State, typename Algebra = EigenJetAlgebra<>>
using ControlledStepper =
    boost::numeric::odeint::controlled_runge_kutta<ErrorStepper<M, State, Algebra>>;

/// Builds the odeint stepper of fixed-step method M from its tableau.
template <Method M, typename State, typename Algebra = EigenJetAlgebra<>>
FixedStepper<M, State, Algebra> MakeFixedStepper() {
  using Stepper = FixedStepper<M, State, Algebra>;
  constexpr int kS = TableauOf(M).stages;
  if constexpr (kS == 1) {
    static_assert(TableauOf(M).b[0] == 1.0 && TableauOf(M).c[0] == 0.0, "one stage is Euler");
    return Stepper();
  } else {
    const ButcherTableau& tab = TableauOf(M);
    return Stepper(internal::TableauA<typename Stepper::coef_a_type>(
                     tab, std::make_index_sequence<kS - 1>{}),
                   internal::TableauVector<kS>(tab.b), internal::TableauVector<kS>(tab.c));
  }
}

/// Builds the odeint controlled stepper of embedded method M: error = h sum (b - b_hat) k,
/// accepted when max |err_i| / (abs_tol + rel_tol |x_i|) <= 1.
template <Method M, typename State, typename Algebra = EigenJetAlgebra<>>
ControlledStepper<M, State, Algebra> MakeControlledStepper(double abs_tol, double rel_tol) {
  static_assert(TableauOf(M).adaptive, "MakeControlledStepper needs an embedded pair");
  using Error = ErrorStepper<M, State, Algebra>;
  using Controlled = ControlledStepper<M, State, Algebra>;
  constexpr int kS = TableauOf(M).stages;
  const ButcherTableau& tab = TableauOf(M);
  std::array<double, kMaxStages> b_diff{};
  for (int j = 0; j < kS; ++j) b_diff[j] = tab.b[j] - tab.b_hat[j];
  Error error_stepper(
      internal::TableauA<typename Error::coef_a_type>(tab, std::make_index_sequence<kS - 1>{}),
      internal::TableauVector<kS>(tab.b), internal::TableauVector<kS>(b_diff),
      internal::TableauVector<kS>(tab.c));
  typename Controlled::error_checker_type checker(abs_tol, rel_tol, 1.0, 0.0);
  return Controlled(checker, typename Controlled::step_adjuster_type(), error_stepper);
}

/// Options of IntegrateTimes / Integrate.
struct OdeOptions {
  /// The Runge-Kutta method.
  Method method = Method::kDopri5;
  /// Fixed-step methods: the largest step (each output interval is split into
  /// ceil(|interval| / dt) equal steps). Adaptive methods: the first trial step.
  double dt = 1e-2;
  /// Adaptive methods: absolute tolerance of the local error.
  double abs_tol = 1e-8;
  /// Adaptive methods: relative tolerance of the local error.
  double rel_tol = 1e-8;
  /// Accepted plus rejected steps before diffdyn::NumericalError.
  long max_steps = 1'000'000;
  /// Jet states: include the derivative parts in the error norm.
  bool derivatives_in_error_norm = false;
};

/// Counts of one integration.
struct IntegrationStats {
  /// Steps taken (fixed-step methods: all steps).
  long accepted_steps = 0;
  /// Trial steps rejected by the error control (adaptive methods only).
  long rejected_steps = 0;
};

/// Throws diffdyn::NumericalError naming `t` and the first non-finite entry of x.
template <typename State>
void CheckFiniteState(const State& x, double t) {
  for (Eigen::Index i = 0; i < x.size(); ++i) {
    if (!AllFinite(x[i])) {
      throw NumericalError(StrCat("non-finite state at t = ", t, ": entry ", i, " = ",
                                  ValuePart(x[i])));
    }
  }
}

namespace internal {

inline void CheckTimes(const std::vector<double>& times) {
  DIFFDYN_CHECK(times.size() >= 2, "integration needs at least 2 time points, got ",
                times.size());
  const double sign = times.back() > times.front() ? 1.0 : -1.0;
  for (std::size_t i = 1; i < times.size(); ++i) {
    DIFFDYN_CHECK(std::isfinite(times[i]) && sign * (times[i] - times[i - 1]) > 0,
                  "time points must be finite and strictly monotone: times[", i - 1,
                  "] = ", times[i - 1], ", times[", i, "] = ", times[i]);
  }
}

// Fixed-step loop over every output interval.
template <Method M, typename State, typename System, typename Observer>
IntegrationStats IntegrateTimesFixed(const System& sys, State& x, const std::vector<double>& times,
                                     const OdeOptions& options, Observer& observer) {
  DIFFDYN_CHECK(options.dt > 0, "fixed-step dt must be positive, got ", options.dt);
  auto stepper = MakeFixedStepper<M, State>();
  IntegrationStats stats;
  observer(0, times[0], x);
  for (std::size_t i = 1; i < times.size(); ++i) {
    const double span = times[i] - times[i - 1];
    const long n = std::max(1L, static_cast<long>(std::ceil(std::abs(span) / options.dt - 1e-9)));
    const double h = span / static_cast<double>(n);
    for (long k = 0; k < n; ++k) {
      stepper.do_step(sys, x, times[i - 1] + static_cast<double>(k) * h, h);
      CheckFiniteState(x, times[i - 1] + static_cast<double>(k + 1) * h);
    }
    stats.accepted_steps += n;
    observer(static_cast<int>(i), times[i], x);
  }
  return stats;
}

// Names the time and the state entry with the largest scaled error when the step underflows.
template <typename Controlled, typename State, typename System>
[[noreturn]] void ThrowUnderflow(Controlled& stepper, const System& sys, const State& x, double t,
                                 double dt, const OdeOptions& options) {
  State out = x;
  State err = x;
  stepper.stepper().do_step(sys, x, t, out, dt, err);
  Eigen::Index worst = 0;
  double worst_ratio = -1.0;
  for (Eigen::Index i = 0; i < x.size(); ++i) {
    const double ratio = std::abs(ValuePart(err[i])) /
                         (options.abs_tol + options.rel_tol * std::abs(ValuePart(x[i])));
    if (!(ratio <= worst_ratio)) {
      worst_ratio = ratio;
      worst = i;
      if (!std::isfinite(ratio)) break;
    }
  }
  throw NumericalError(StrCat("step size underflow at t = ", t, " (dt = ", dt,
                              "): largest error in state entry ", worst, " = ",
                              ValuePart(x[worst])));
}

// Adaptive loop: steps clipped to hit every output time exactly.
template <Method M, typename Algebra, typename State, typename System, typename Observer>
IntegrationStats IntegrateTimesAdaptive(const System& sys, State& x,
                                        const std::vector<double>& times,
                                        const OdeOptions& options, Observer& observer) {
  namespace odeint = boost::numeric::odeint;
  DIFFDYN_CHECK(options.abs_tol > 0 && options.rel_tol >= 0, "tolerances must be positive, got ",
                "abs_tol = ", options.abs_tol, ", rel_tol = ", options.rel_tol);
  DIFFDYN_CHECK(options.dt > 0, "initial dt must be positive, got ", options.dt);
  auto stepper = MakeControlledStepper<M, State, Algebra>(options.abs_tol, options.rel_tol);
  const double sign = times.back() > times.front() ? 1.0 : -1.0;
  IntegrationStats stats;
  observer(0, times[0], x);
  double t = times[0];
  double dt = sign * options.dt;
  for (std::size_t i = 1; i < times.size(); ++i) {
    while (sign * (times[i] - t) > 0) {
      if (stats.accepted_steps + stats.rejected_steps >= options.max_steps) {
        throw NumericalError(StrCat("integration exceeded max_steps = ", options.max_steps,
                                    " at t = ", t));
      }
      const double remaining = times[i] - t;
      const bool clipped = std::abs(dt) >= std::abs(remaining);
      double h = clipped ? remaining : dt;
      const double t_before = t;
      if (stepper.try_step(sys, x, t, h) == odeint::success) {
        ++stats.accepted_steps;
        CheckFiniteState(x, t);
        if (clipped) t = times[i];
        dt = clipped ? sign * std::max(std::abs(dt), std::abs(h)) : h;
      } else {
        ++stats.rejected_steps;
        dt = h;
        if (std::abs(h) < 1e-14 * std::max(1.0, std::abs(t_before))) {
          ThrowUnderflow(stepper, sys, x, t_before, h, options);
        }
      }
    }
    observer(static_cast<int>(i), times[i], x);
  }
  return stats;
}

template <Method M, typename State, typename System, typename Observer>
IntegrationStats IntegrateTimesWith(const System& sys, State& x, const std::vector<double>& times,
                                    const OdeOptions& options, Observer& observer) {
  if constexpr (TableauOf(M).adaptive) {
    if constexpr (IsJet<typename State::Scalar>::value) {
      if (options.derivatives_in_error_norm) {
        return IntegrateTimesAdaptive<M, EigenJetAlgebra<true>>(sys, x, times, options, observer);
      }
    }
    return IntegrateTimesAdaptive<M, EigenJetAlgebra<false>>(sys, x, times, options, observer);
  } else {
    return IntegrateTimesFixed<M>(sys, x, times, options, observer);
  }
}

}  // namespace internal

/// Integrates sys from times[0] through times[1], ... (strictly monotone, increasing
/// or decreasing), updating x (n, double or Jet entries) in place and calling
/// observer(i, times[i], x) at every time point including times[0]. The observer may
/// take x by non-const reference and change it (a jump at times[i], as an adjoint
/// does when it adds dL/dx(t_i)): every stepper here re-evaluates f after it. Throws
/// diffdyn::Error for bad times or options, diffdyn::NumericalError for step-size
/// underflow, a non-finite state, or more than options.max_steps steps.
template <typename State, typename System, typename Observer>
IntegrationStats IntegrateTimes(const System& sys, State& x, const std::vector<double>& times,
                                const OdeOptions& options, Observer&& observer) {
  internal::CheckTimes(times);
  CheckFiniteState(x, times[0]);
  switch (options.method) {
    case Method::kEuler:
      return internal::IntegrateTimesWith<Method::kEuler>(sys, x, times, options, observer);
    case Method::kMidpoint:
      return internal::IntegrateTimesWith<Method::kMidpoint>(sys, x, times, options, observer);
    case Method::kRk4Classic:
      return internal::IntegrateTimesWith<Method::kRk4Classic>(sys, x, times, options, observer);
    case Method::kRk4:
      return internal::IntegrateTimesWith<Method::kRk4>(sys, x, times, options, observer);
    case Method::kDopri5:
      return internal::IntegrateTimesWith<Method::kDopri5>(sys, x, times, options, observer);
    case Method::kCashKarp:
      return internal::IntegrateTimesWith<Method::kCashKarp>(sys, x, times, options, observer);
  }
  throw Error("IntegrateTimes: unknown method");
}

/// Integrates x (in place) from t0 to t1 != t0; see IntegrateTimes.
template <typename State, typename System>
IntegrationStats Integrate(const System& sys, State& x, double t0, double t1,
                           const OdeOptions& options) {
  return IntegrateTimes(sys, x, {t0, t1}, options, [](int, double, const State&) {});
}

/// Advances x (in place) by `num_steps` fixed steps h = (t1 - t0) / num_steps of the
/// fixed-step `method` at t_k = t0 + k h. Throws diffdyn::Error for num_steps < 1 or an
/// adaptive method, diffdyn::NumericalError for a non-finite state.
template <typename State, typename System>
void IntegrateFixedSteps(Method method, const System& sys, State& x, double t0, double t1,
                         int num_steps) {
  DIFFDYN_CHECK(num_steps >= 1, "IntegrateFixedSteps: num_steps must be >= 1, got ", num_steps);
  DIFFDYN_CHECK(!TableauOf(method).adaptive, "IntegrateFixedSteps: ", MethodName(method),
                " is adaptive; use Integrate");
  OdeOptions options;
  options.method = method;
  options.dt = std::abs(t1 - t0) / num_steps;
  IntegrateTimes(sys, x, {t0, t1}, options, [](int, double, const State&) {});
}

}  // namespace diffdyn
