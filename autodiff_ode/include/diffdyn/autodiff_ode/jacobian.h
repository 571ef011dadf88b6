// Jacobians of scalar-generic callables with dual numbers (ceres::Jet).
//
// A Jet<double, K> is a number a + sum_k v_k eps_k with eps_j eps_k = 0. Arithmetic
// on Jets applies the chain rule exactly, so evaluating f on
//
//   x_i + eps_i        (seed: value x_i, derivative part e_i, the i-th unit vector)
//
// returns f_j(x) + sum_i (df_j/dx_i) eps_i: the value part is f(x) and the
// derivative parts are row j of the Jacobian J = df/dx (m x n). This is forward
// mode: one evaluation on Jet<double, n> gives all n columns, exact to rounding
// (no step size, unlike finite differences (f(x + h e_i) - f(x - h e_i)) / 2h,
// whose error is O(h^2) truncation plus O(eps/h) rounding).
//
// A callable is scalar-generic when it is a template over the scalar type:
//
//   struct F {
//     template <typename T>
//     Eigen::Matrix<T, 2, 1> operator()(const Eigen::Matrix<T, 3, 1>& x) const;
//   };
//   Eigen::Matrix<double, 2, 3> J = diffdyn::Jacobian<3>(F{}, x);   // sizes checked at compile time
//
// Large or run-time n: JacobianDynamic<K>(f, x) calls f on Eigen::Matrix<Jet<double,
// K>, Dynamic, 1> ceil(n / K) times, seeding columns [cK, cK + K) in chunk c, so a
// Jet never grows beyond K derivatives (K = 8 fits a cache line of derivatives).
//
// Jet of Jet (second derivatives) does not compile with Ceres 2.1 + Eigen 3.4;
// second derivatives come from closed forms elsewhere in the library.
#pragma once

#include <algorithm>
#include <cmath>
#include <type_traits>
#include <utility>

#include <Eigen/Core>
#include <ceres/jet.h>

#include "diffdyn/autodiff_ode/check.h"

namespace diffdyn {

/// Column vector of T of run-time size.
template <typename T>
using VectorX = Eigen::Matrix<T, Eigen::Dynamic, 1>;
/// A dynamic-size matrix of scalar T.
template <typename T>
using MatrixX = Eigen::Matrix<T, Eigen::Dynamic, Eigen::Dynamic>;

/// Jet with K derivative parts.
template <int K>
using JetK = ceres::Jet<double, K>;

/// True for ceres::Jet<double, K>.
template <typename T>
struct IsJet : std::false_type {};
template <typename T, int K>
struct IsJet<ceres::Jet<T, K>> : std::true_type {};

/// Value part of a scalar: x for double, x.a for a Jet.
inline double ValuePart(double x) { return x; }
template <int K>
double ValuePart(const ceres::Jet<double, K>& x) {
  return x.a;
}

/// True when the value (and, for Jets, every derivative part) is finite.
inline bool AllFinite(double x) { return std::isfinite(x); }
template <int K>
bool AllFinite(const ceres::Jet<double, K>& x) {
  return std::isfinite(x.a) && x.v.allFinite();
}

/// Seeds out[i] = x[i] + eps_{i - offset} for offset <= i < offset + K, other entries
/// get zero derivative parts. Sizes: x (n), out resized to n.
template <int K, typename Derived>
void SeedJets(const Eigen::MatrixBase<Derived>& x, int offset, VectorX<JetK<K>>* out) {
  out->resize(x.size());
  for (Eigen::Index i = 0; i < x.size(); ++i) {
    (*out)[i] = JetK<K>(x[i]);
    const Eigen::Index k = i - offset;
    if (k >= 0 && k < K) (*out)[i].v[k] = 1.0;
  }
}

/// Jacobian J = df/dx (M x N) of a scalar-generic f: R^N -> R^M at x, N known at
/// compile time; f is called once with Eigen::Matrix<Jet<double, N>, N, 1>. If `value`
/// is not null it receives f(x) (M). M is taken from f's return type (may be Dynamic).
template <int N, typename F>
auto Jacobian(const F& f, const Eigen::Matrix<double, N, 1>& x,
              Eigen::Matrix<double,
                            std::decay_t<decltype(f(std::declval<Eigen::Matrix<JetK<N>, N, 1>>()))>::
                                RowsAtCompileTime,
                            1>* value = nullptr) {
  static_assert(N != Eigen::Dynamic,
                "diffdyn::Jacobian needs a compile-time input size N; use JacobianDynamic<K> "
                "for run-time sizes");
  static_assert(N > 0, "diffdyn::Jacobian: the input size N must be positive");
  static_assert(N <= 64,
                "diffdyn::Jacobian: N > 64 derivative parts make huge Jets; use "
                "JacobianDynamic<K>, which evaluates in chunks of K");
  using Out = std::decay_t<decltype(f(std::declval<Eigen::Matrix<JetK<N>, N, 1>>()))>;
  static_assert(Out::ColsAtCompileTime == 1,
                "diffdyn::Jacobian: f must return a column vector (Eigen::Matrix<T, M, 1>)");
  static_assert(std::is_same_v<typename Out::Scalar, JetK<N>>,
                "diffdyn::Jacobian: f must return a vector of the scalar type it was called "
                "with (template <typename T> Eigen::Matrix<T, M, 1> operator()(...))");
  constexpr int M = Out::RowsAtCompileTime;
  Eigen::Matrix<JetK<N>, N, 1> xj;
  for (int i = 0; i < N; ++i) xj[i] = JetK<N>(x[i], i);
  const Out y = f(xj);
  Eigen::Matrix<double, M, N> jac(y.size(), N);
  if (value != nullptr) value->resize(y.size());
  for (Eigen::Index j = 0; j < y.size(); ++j) {
    jac.row(j) = y[j].v.transpose();
    if (value != nullptr) (*value)[j] = y[j].a;
  }
  return jac;
}

/// Jacobian J = df/dx (m x n) of a scalar-generic f: R^n -> R^m with n known at run
/// time, evaluated in ceil(n / K) chunks on VectorX<Jet<double, K>>. f must return a
/// VectorX-like vector of the same m for every call (checked). `value` (may be null)
/// receives f(x) (m).
template <int K = 8, typename F>
Eigen::MatrixXd JacobianDynamic(const F& f, const Eigen::VectorXd& x,
                                Eigen::VectorXd* value = nullptr) {
  static_assert(K > 0 && K <= 64, "diffdyn::JacobianDynamic: chunk size K must be in [1, 64]");
  const int n = static_cast<int>(x.size());
  DIFFDYN_CHECK(n > 0, "JacobianDynamic: empty input vector");
  Eigen::MatrixXd jac;
  VectorX<JetK<K>> xj;
  for (int offset = 0; offset < n; offset += K) {
    SeedJets<K>(x, offset, &xj);
    const VectorX<JetK<K>> y = f(xj);
    if (offset == 0) {
      jac.resize(y.size(), n);
      if (value != nullptr) {
        value->resize(y.size());
        for (Eigen::Index j = 0; j < y.size(); ++j) (*value)[j] = y[j].a;
      }
    }
    DIFFDYN_CHECK(y.size() == jac.rows(), "JacobianDynamic: f returned ", y.size(),
                  " outputs for chunk at column ", offset, " but ", jac.rows(), " before");
    const int width = std::min(K, n - offset);
    for (Eigen::Index j = 0; j < y.size(); ++j) {
      jac.row(j).segment(offset, width) = y[j].v.head(width).transpose();
    }
  }
  return jac;
}

/// Central finite-difference Jacobian (m x n) of f: VectorXd -> VectorXd,
/// column i = (f(x + h_i e_i) - f(x - h_i e_i)) / (2 h_i) with h_i = step * max(1, |x_i|).
/// Error O(h^2) + O(eps / h); step ~ 1e-6 balances both for smooth f. A reference
/// for tests and benchmarks, not for production gradients.
template <typename F>
Eigen::MatrixXd JacobianCentralDifference(const F& f, const Eigen::VectorXd& x,
                                          double step = 1e-6) {
  Eigen::VectorXd xp = x;
  Eigen::MatrixXd jac;
  for (Eigen::Index i = 0; i < x.size(); ++i) {
    const double h = step * std::max(1.0, std::abs(x[i]));
    xp[i] = x[i] + h;
    const Eigen::VectorXd fp = f(xp);
    xp[i] = x[i] - h;
    const Eigen::VectorXd fm = f(xp);
    xp[i] = x[i];
    if (i == 0) jac.resize(fp.size(), x.size());
    jac.col(i) = (fp - fm) / (2.0 * h);
  }
  return jac;
}

}  // namespace diffdyn
