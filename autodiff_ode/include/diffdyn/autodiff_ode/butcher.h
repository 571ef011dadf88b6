// Butcher tableaus: the one table of coefficients behind every solver.
//
// An explicit Runge-Kutta method with s stages advances dx/dt = f(x, t) by a
// step h from (x_n, t_n) as
//
//   k_i     = f(Y_i, t_n + c_i h),       Y_i = x_n + h * sum_{j<i} a_ij k_j,
//   x_{n+1} = x_n + h * sum_i b_i k_i.
//
// The coefficients are written as a tableau
//
//     c | A          A strictly lower triangular (explicit method),
//    ---+----        b the weights of the solution of order p,
//       | b^T        b_hat (embedded methods only) the weights of a second
//       | b_hat^T    solution of order p - 1.
//
// An embedded pair estimates the local error of a step as
// err = h * sum_i (b_i - b_hat_i) k_i, which an adaptive controller uses to pick
// the step size. When the last row of A equals b and c_s = 1 (dopri5), the last
// stage is f(x_{n+1}) and is reused as the first stage of the next step ("first
// same as last", FSAL).
//
// The same ButcherTableau value serves (1) the Boost.Odeint steppers built by
// integrate.h (odeint's explicit_generic_rk / explicit_error_generic_rk take A, b,
// c as arrays) and (2) the batched solvers and reverse-mode passes of adjoint.h,
// which need the stages that odeint does not expose. No coefficient is written
// twice.
//
// Methods and their command-line names (ParseMethod):
//
//   "euler"        1 stage,  order 1
//   "midpoint"     2 stages, order 2 (explicit midpoint)
//   "rk4-classic"  4 stages, order 4 (Kutta's classic 1/6, 1/3, 1/3, 1/6)
//   "rk4"          4 stages, order 4 (Kutta's 3/8 rule; torchdiffeq's "rk4")
//   "dopri5"       7 stages, order 5(4), FSAL (Dormand & Prince 1980)
//   "cash-karp"    6 stages, order 5(4) (Cash & Karp 1990)
#pragma once

#include <array>
#include <string>
#include <string_view>

#include "diffdyn/autodiff_ode/check.h"

namespace diffdyn {

/// An explicit Runge-Kutta method (see the table above for names and orders).
enum class Method { kEuler, kMidpoint, kRk4Classic, kRk4, kDopri5, kCashKarp };

/// The largest stage count of any tableau here (dopri5).
inline constexpr int kMaxStages = 7;

/// The coefficients of one explicit Runge-Kutta method with `stages` <= kMaxStages.
/// a is s x s strictly lower triangular (a[i][j] for j < i), b and c have s entries;
/// b_hat (embedded weights, order `order - 1`) is all zero for fixed-step methods.
struct ButcherTableau {
  /// The command-line name ("rk4", "dopri5", ...).
  const char* name;
  /// s, the number of stages.
  int stages;
  /// p, the order of the solution weighted by b.
  int order;
  /// True for embedded pairs (b_hat set, adaptive step size).
  bool adaptive;
  /// A (s x s used of kMaxStages x kMaxStages), strictly lower triangular.
  std::array<std::array<double, kMaxStages>, kMaxStages> a;
  /// b, the solution weights (s used).
  std::array<double, kMaxStages> b;
  /// c, the stage times as fractions of h (s used); c_i = sum_j a_ij.
  std::array<double, kMaxStages> c;
  /// b_hat, the embedded weights of order p - 1 (zero for fixed-step methods).
  std::array<double, kMaxStages> b_hat;

  /// True when the last stage is f(x_{n+1}, t_n + h): last row of A equals b, c_s = 1.
  constexpr bool fsal() const {
    if (stages < 2 || c[stages - 1] != 1.0) return false;
    for (int j = 0; j < stages; ++j) {
      if (a[stages - 1][j] != b[j]) return false;
    }
    return true;
  }
};

namespace tableaus {

/// Forward Euler: x_{n+1} = x_n + h f(x_n, t_n).
inline constexpr ButcherTableau kEuler{"euler", 1, 1, false, {{{0}}}, {1}, {0}, {}};

/// Explicit midpoint: k1 = f(x_n), k2 = f(x_n + h/2 k1, t_n + h/2), x_{n+1} = x_n + h k2.
inline constexpr ButcherTableau kMidpoint{
    "midpoint", 2, 2, false, {{{0}, {0.5}}}, {0.0, 1.0}, {0.0, 0.5}, {}};

/// Classic RK4: c = (0, 1/2, 1/2, 1), b = (1/6, 1/3, 1/3, 1/6).
inline constexpr ButcherTableau kRk4Classic{
    "rk4-classic",
    4,
    4,
    false,
    {{{0}, {0.5}, {0.0, 0.5}, {0.0, 0.0, 1.0}}},
    {1.0 / 6, 1.0 / 3, 1.0 / 3, 1.0 / 6},
    {0.0, 0.5, 0.5, 1.0},
    {}};

/// Kutta's 3/8 rule: c = (0, 1/3, 2/3, 1), b = (1/8, 3/8, 3/8, 1/8).
inline constexpr ButcherTableau kRk4{"rk4",
                                     4,
                                     4,
                                     false,
                                     {{{0}, {1.0 / 3}, {-1.0 / 3, 1.0}, {1.0, -1.0, 1.0}}},
                                     {1.0 / 8, 3.0 / 8, 3.0 / 8, 1.0 / 8},
                                     {0.0, 1.0 / 3, 2.0 / 3, 1.0},
                                     {}};

/// Dormand-Prince 5(4), FSAL: 7 stages, 6 new evaluations per accepted step.
inline constexpr ButcherTableau kDopri5{
    "dopri5",
    7,
    5,
    true,
    {{{0},
      {1.0 / 5},
      {3.0 / 40, 9.0 / 40},
      {44.0 / 45, -56.0 / 15, 32.0 / 9},
      {19372.0 / 6561, -25360.0 / 2187, 64448.0 / 6561, -212.0 / 729},
      {9017.0 / 3168, -355.0 / 33, 46732.0 / 5247, 49.0 / 176, -5103.0 / 18656},
      {35.0 / 384, 0.0, 500.0 / 1113, 125.0 / 192, -2187.0 / 6784, 11.0 / 84}}},
    {35.0 / 384, 0.0, 500.0 / 1113, 125.0 / 192, -2187.0 / 6784, 11.0 / 84, 0.0},
    {0.0, 1.0 / 5, 3.0 / 10, 4.0 / 5, 8.0 / 9, 1.0, 1.0},
    {5179.0 / 57600, 0.0, 7571.0 / 16695, 393.0 / 640, -92097.0 / 339200, 187.0 / 2100,
     1.0 / 40}};

/// Cash-Karp 5(4): 6 stages.
inline constexpr ButcherTableau kCashKarp{
    "cash-karp",
    6,
    5,
    true,
    {{{0},
      {1.0 / 5},
      {3.0 / 40, 9.0 / 40},
      {3.0 / 10, -9.0 / 10, 6.0 / 5},
      {-11.0 / 54, 5.0 / 2, -70.0 / 27, 35.0 / 27},
      {1631.0 / 55296, 175.0 / 512, 575.0 / 13824, 44275.0 / 110592, 253.0 / 4096}}},
    {37.0 / 378, 0.0, 250.0 / 621, 125.0 / 594, 0.0, 512.0 / 1771},
    {0.0, 1.0 / 5, 3.0 / 10, 3.0 / 5, 1.0, 7.0 / 8},
    {2825.0 / 27648, 0.0, 18575.0 / 48384, 13525.0 / 55296, 277.0 / 14336, 1.0 / 4}};

}  // namespace tableaus

/// The tableau of `method`.
constexpr const ButcherTableau& TableauOf(Method method) {
  switch (method) {
    case Method::kEuler:
      return tableaus::kEuler;
    case Method::kMidpoint:
      return tableaus::kMidpoint;
    case Method::kRk4Classic:
      return tableaus::kRk4Classic;
    case Method::kRk4:
      return tableaus::kRk4;
    case Method::kDopri5:
      return tableaus::kDopri5;
    case Method::kCashKarp:
      return tableaus::kCashKarp;
  }
  return tableaus::kRk4;
}

/// All methods, in the order of the enum.
inline constexpr std::array<Method, 6> kAllMethods{Method::kEuler,      Method::kMidpoint,
                                                   Method::kRk4Classic, Method::kRk4,
                                                   Method::kDopri5,     Method::kCashKarp};

/// The command-line name of `method` ("rk4" is the 3/8 rule).
inline std::string MethodName(Method method) { return TableauOf(method).name; }

/// Parses a command-line solver name ("euler", "midpoint", "rk4-classic", "rk4",
/// "dopri5", "cash-karp"); throws diffdyn::Error naming `option` and the value.
inline Method ParseMethod(std::string_view value, std::string_view option = "--solver") {
  for (Method m : kAllMethods) {
    if (value == TableauOf(m).name) return m;
  }
  throw Error(StrCat(option, ": unknown solver '", value,
                     "' (expected one of: euler, midpoint, rk4-classic, rk4, dopri5, cash-karp)"));
}

}  // namespace diffdyn
