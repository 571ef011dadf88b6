// Activation functions with their first and second derivatives.
//
// A layer of a deep differential network (DDN) computes h' = g(a) with
// a = W h + b. Its input Jacobian needs g'(a), and any gradient of a loss on
// that Jacobian (Jacobian losses, DeLaN, Hessians) needs g''(a):
//
//   d h'/d h   = diag(g'(a)) W
//   d g'(a)/da = g''(a)
//
// The activations here, with a parameter p where they have one:
//
//   name      g(a)                          g'(a)                 g''(a)
//   linear    a                             1                     0
//   relu      max(a, 0)                     [a > 0]               0
//   softplus  log(1 + exp(p a)) / p         s = sigmoid(p a)      p s (1 - s)
//   tanh      t = tanh(a)                   1 - t^2               -2 t (1 - t^2)
//   sigmoid   s = 1 / (1 + exp(-a))         s (1 - s)             s (1 - s)(1 - 2 s)
//   elu       a > 0 ? a : p (exp(a) - 1)    a > 0 ? 1 : p exp(a)  a > 0 ? 0 : p exp(a)
//   cos       cos(p a)                      -p sin(p a)           -p^2 cos(p a)
//
// relu's derivative at the kink a = 0 is taken as 0 (as the DDN code does).
// Softplus is evaluated in the overflow-free form max(z, 0) + log1p(exp(-|z|))
// with z = p a, and the sigmoid as 1/(1+e) or e/(1+e) with e = exp(-|z|).
//
// Two evaluation paths share these definitions:
//   * ActivationValue / ActivationDerivative / ActivationSecondDerivative are
//     templated on the scalar (double or ceres::Jet) for single samples;
//   * ApplyActivation evaluates g, g' and optionally g'' over a whole array of
//     pre-activations in one vectorised pass (the batched float and double paths).
//
//   Activation act = Activation::Softplus(2.0);
//   double y = ActivationValue(act, 0.3), dy = ActivationDerivative(act, 0.3);
#pragma once

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <type_traits>

#include <Eigen/Core>

#include "diffdyn/autodiff_ode/check.h"

namespace diffdyn {

/// The activation functions of the table in activations.h.
enum class ActivationKind { kLinear, kRelu, kSoftplus, kTanh, kSigmoid, kElu, kCos };

/// An activation g with its parameter p (softplus beta, elu alpha, cos frequency;
/// ignored by the others). Plain value type.
struct Activation {
  /// Which g.
  ActivationKind kind = ActivationKind::kLinear;
  /// p: softplus beta, elu alpha or cos frequency omega (others ignore it).
  double param = 1.0;

  /// g(a) = a.
  static Activation Linear() { return {ActivationKind::kLinear, 1.0}; }
  /// g(a) = max(a, 0).
  static Activation Relu() { return {ActivationKind::kRelu, 1.0}; }
  /// g(a) = log(1 + exp(beta a)) / beta, beta > 0.
  static Activation Softplus(double beta = 1.0) { return {ActivationKind::kSoftplus, beta}; }
  /// g(a) = tanh(a).
  static Activation Tanh() { return {ActivationKind::kTanh, 1.0}; }
  /// g(a) = 1 / (1 + exp(-a)).
  static Activation Sigmoid() { return {ActivationKind::kSigmoid, 1.0}; }
  /// g(a) = a for a > 0, alpha (exp(a) - 1) otherwise.
  static Activation Elu(double alpha = 1.0) { return {ActivationKind::kElu, alpha}; }
  /// g(a) = cos(omega a).
  static Activation Cos(double omega = 1.0) { return {ActivationKind::kCos, omega}; }

  /// Same kind and parameter.
  bool operator==(const Activation&) const = default;
};

/// The lower-case name of an activation kind ("relu", "softplus", ...).
inline std::string ActivationName(ActivationKind kind) {
  switch (kind) {
    case ActivationKind::kLinear: return "linear";
    case ActivationKind::kRelu: return "relu";
    case ActivationKind::kSoftplus: return "softplus";
    case ActivationKind::kTanh: return "tanh";
    case ActivationKind::kSigmoid: return "sigmoid";
    case ActivationKind::kElu: return "elu";
    case ActivationKind::kCos: return "cos";
  }
  return "unknown";
}

/// Parses a name of ActivationName() with parameter `param`; throws diffdyn::Error
/// for an unknown name or a non-positive softplus beta.
inline Activation MakeActivation(const std::string& name, double param = 1.0) {
  DIFFDYN_CHECK(std::isfinite(param), "activation '", name, "': parameter is not finite");
  for (ActivationKind kind :
       {ActivationKind::kLinear, ActivationKind::kRelu, ActivationKind::kSoftplus,
        ActivationKind::kTanh, ActivationKind::kSigmoid, ActivationKind::kElu,
        ActivationKind::kCos}) {
    if (ActivationName(kind) == name) {
      DIFFDYN_CHECK(kind != ActivationKind::kSoftplus || param > 0.0,
                    "activation 'softplus' needs beta > 0, got ", param);
      return {kind, param};
    }
  }
  throw Error(StrCat("unknown activation '", name,
                     "' (expected linear, relu, softplus, tanh, sigmoid, elu or cos)"));
}

namespace internal {

// Logistic sigmoid without overflow: 1/(1+e) for z >= 0, e/(1+e) otherwise.
template <typename S>
S StableSigmoid(const S& z) {
  using std::abs;
  using std::exp;
  const S e = exp(-abs(z));
  return z >= S(0.0) ? S(1.0) / (S(1.0) + e) : e / (S(1.0) + e);
}

}  // namespace internal

/// g(a) for a scalar a (double or ceres::Jet).
template <typename S>
S ActivationValue(const Activation& act, const S& a) {
  using std::abs;
  using std::cos;
  using std::exp;
  using std::expm1;
  using std::log1p;
  using std::tanh;
  const double p = act.param;
  switch (act.kind) {
    case ActivationKind::kLinear: return a;
    case ActivationKind::kRelu: return a > S(0.0) ? a : S(0.0);
    case ActivationKind::kSoftplus: {
      const S z = p * a;
      const S pos = z > S(0.0) ? z : S(0.0);
      return (pos + log1p(exp(-abs(z)))) / p;
    }
    case ActivationKind::kTanh: return tanh(a);
    case ActivationKind::kSigmoid: return internal::StableSigmoid(a);
    case ActivationKind::kElu: return a > S(0.0) ? a : p * expm1(a);
    case ActivationKind::kCos: return cos(p * a);
  }
  return a;
}

/// g'(a) for a scalar a (double or ceres::Jet); relu's g'(0) = 0.
template <typename S>
S ActivationDerivative(const Activation& act, const S& a) {
  using std::cos;
  using std::exp;
  using std::sin;
  using std::tanh;
  const double p = act.param;
  switch (act.kind) {
    case ActivationKind::kLinear: return S(1.0);
    case ActivationKind::kRelu: return a > S(0.0) ? S(1.0) : S(0.0);
    case ActivationKind::kSoftplus: return internal::StableSigmoid(S(p * a));
    case ActivationKind::kTanh: {
      const S t = tanh(a);
      return S(1.0) - t * t;
    }
    case ActivationKind::kSigmoid: {
      const S s = internal::StableSigmoid(a);
      return s * (S(1.0) - s);
    }
    case ActivationKind::kElu: return a > S(0.0) ? S(1.0) : p * exp(a);
    case ActivationKind::kCos: return -p * sin(p * a);
  }
  return S(1.0);
}

/// g''(a) for a scalar a (double or ceres::Jet); relu's g'' = 0 everywhere.
template <typename S>
S ActivationSecondDerivative(const Activation& act, const S& a) {
  using std::cos;
  using std::exp;
  using std::tanh;
  const double p = act.param;
  switch (act.kind) {
    case ActivationKind::kLinear:
    case ActivationKind::kRelu: return S(0.0);
    case ActivationKind::kSoftplus: {
      const S s = internal::StableSigmoid(S(p * a));
      return p * s * (S(1.0) - s);
    }
    case ActivationKind::kTanh: {
      const S t = tanh(a);
      return S(-2.0) * t * (S(1.0) - t * t);
    }
    case ActivationKind::kSigmoid: {
      const S s = internal::StableSigmoid(a);
      return s * (S(1.0) - s) * (S(1.0) - S(2.0) * s);
    }
    case ActivationKind::kElu: return a > S(0.0) ? S(0.0) : p * exp(a);
    case ActivationKind::kCos: return -p * p * cos(p * a);
  }
  return S(0.0);
}

/// t[i] = tanh(x[i]) for n contiguous values of S (double or float), vectorised
/// (Eigen packets), within a few ulp of std::tanh everywhere (t may alias x). Two
/// branch-free forms, chosen per element by |x|:
///
///   |x| <  1/2:  the 8th convergent of Lambert's continued fraction
///                tanh x = x / (1 + x^2 / (3 + x^2 / (5 + ...))) = x A_8 / B_8, from
///                the recurrences A_k = (2k-1) A_{k-1} + x^2 A_{k-2} (same for B;
///                A_0 = 0, A_1 = 1, B_0 = B_1 = 1). It is evaluated as
///                t = x + x D_8 / B_8 with D_k = A_k - B_k obeying the same recurrence
///                (D_0 = -1, D_1 = 0): every D_k is <= 0 and every B_k > 0, so there is
///                no cancellation, and the rounding of the small correction
///                x D / B (|D / B| < 1/12) barely reaches t. Truncation error < 1e-18
///                relative; tiny and subnormal x give x, -0 gives -0;
///   |x| >= 1/2:  sign(x) (1 - e) / (1 + e), e = exp(-2|x|) in (0, 0.37]: no
///                cancellation, no overflow (large |x| gives e = 0, t = +-1).
///
/// NaN propagates.
template <typename S>
inline void VectorizedTanh(const S* x, Eigen::Index n, S* t) {
  static_assert(std::is_floating_point_v<S>, "VectorizedTanh needs float or double");
  using ArrayS = Eigen::Array<S, Eigen::Dynamic, 1>;
  constexpr Eigen::Index kBlock = 64;
  constexpr int kLevels = 8;
  using Block = Eigen::Array<S, kBlock, 1>;
  Block e, x2, d_prev, d_cur, b_prev, b_cur, next;
  for (Eigen::Index start = 0; start < n; start += kBlock) {
    const Eigen::Index m = std::min(kBlock, n - start);
    const Eigen::Map<const ArrayS> xv(x + start, m);
    e.head(m) = (S(-2) * xv.abs()).exp();
    x2.head(m) = xv * xv;
    d_prev.head(m).setConstant(S(-1));
    d_cur.head(m).setZero();
    b_prev.head(m).setOnes();
    b_cur.head(m).setOnes();
    for (int k = 2; k <= kLevels; ++k) {
      const S odd = S(2 * k - 1);
      next.head(m) = odd * d_cur.head(m) + x2.head(m) * d_prev.head(m);
      d_prev.head(m) = d_cur.head(m);
      d_cur.head(m) = next.head(m);
      next.head(m) = odd * b_cur.head(m) + x2.head(m) * b_prev.head(m);
      b_prev.head(m) = b_cur.head(m);
      b_cur.head(m) = next.head(m);
    }
    const auto small = xv + xv * (d_cur.head(m) / b_cur.head(m));
    const auto large = (S(1) - e.head(m)) / (S(1) + e.head(m));
    Eigen::Map<ArrayS> tv(t + start, m);
    tv = (xv.abs() < S(0.5)).select(small, (xv < S(0)).select(-large, large));
  }
}

namespace internal {

// The unsigned integer of S's size, for choices made on a value's bits: GCC does not
// vectorise a floating-point comparison under -ftrapping-math (its default), nor does
// Eigen 3.4 vectorise select, while integer comparisons and masks vectorise.
template <typename S>
using BitsOf = std::conditional_t<sizeof(S) == 4, std::uint32_t, std::uint64_t>;

// All ones where x > 0 (up to +inf), else 0 (for +-0, negatives and NaN): x > 0 exactly
// when its bits, read as an unsigned integer, lie in [1, bits(+inf)].
template <typename S>
inline BitsOf<S> PositiveMask(S x) {
  using U = BitsOf<S>;
  constexpr U kInf = std::bit_cast<U>(std::numeric_limits<S>::infinity());
  return U(0) - U(std::bit_cast<U>(x) - U(1) < kInf);
}

// [x > 0] (1 or 0) and x [x > 0] (x or +0) from PositiveMask, the same values as the
// comparisons give, NaN included (0 and +0).
template <typename S>
inline S PositiveIndicator(S x) {
  return std::bit_cast<S>(PositiveMask(x) & std::bit_cast<BitsOf<S>>(S(1)));
}
template <typename S>
inline S PositivePart(S x) {
  return std::bit_cast<S>(PositiveMask(x) & std::bit_cast<BitsOf<S>>(x));
}

// v[i] = sign bit of z[i] clear ? v[i] : e[i] v[i], in bit operations (see BitsOf).
// z = -0 takes e v, which is v there (e = 1).
template <typename S>
inline void MultiplyWhereNegative(const S* __restrict z, const S* __restrict e,
                                  S* __restrict v, Eigen::Index m) {
  using U = BitsOf<S>;
  constexpr int kSignShift = 8 * sizeof(S) - 1;
  for (Eigen::Index i = 0; i < m; ++i) {
    const U negative = U(0) - (std::bit_cast<U>(z[i]) >> kSignShift);  // all ones or 0
    const U keep = std::bit_cast<U>(v[i]);
    const U scaled = std::bit_cast<U>(e[i] * v[i]);
    v[i] = std::bit_cast<S>((keep & ~negative) | (scaled & negative));
  }
}

// For m values z = p a[i] (m <= 64): e[i] = exp(-|z|) in (0, 1] and
// s[i] = sigmoid(z) = 1 / (1 + exp(-z)), as 1 / (1 + e) for z >= 0 and
// e / (1 + e) otherwise: no overflow, one division. e and s must not alias a.
template <typename S>
inline void SigmoidBlock(const S* a, S p, Eigen::Index m, S* e, S* s) {
  using ArrayS = Eigen::Array<S, Eigen::Dynamic, 1>;
  const Eigen::Map<const ArrayS> av(a, m);
  Eigen::Map<ArrayS> ev(e, m), sv(s, m);
  S z[64];
  Eigen::Map<ArrayS>(z, m) = p * av;
  ev = (-Eigen::Map<ArrayS>(z, m).abs()).exp();
  sv = S(1) / (S(1) + ev);
  MultiplyWhereNegative(z, e, s, m);
}

}  // namespace internal

/// Batched evaluation over n contiguous pre-activations a[0..n) of S (double or
/// float): g[i] = g(a[i]), dg[i] = g'(a[i]) and, when ddg is not null,
/// ddg[i] = g''(a[i]). g may alias a (in-place). dg may be null when only values
/// are needed. Uses Eigen's vectorised exp; no allocation. In float the
/// parameter p is rounded to float once.
template <typename S>
inline void ApplyActivation(const Activation& act, const S* a, Eigen::Index n,
                            std::type_identity_t<S>* g, std::type_identity_t<S>* dg,
                            std::type_identity_t<S>* ddg) {
  static_assert(std::is_floating_point_v<S>, "ApplyActivation needs float or double");
  using ArrayS = Eigen::Array<S, Eigen::Dynamic, 1>;
  using Arr = Eigen::Map<ArrayS>;
  const Eigen::Map<const ArrayS> av(a, n);
  Arr gv(g, n);
  const S p = static_cast<S>(act.param);
  const S one(1), zero(0);
  switch (act.kind) {
    case ActivationKind::kLinear:
      if (g != a) gv = av;
      if (dg) Arr(dg, n).setOnes();
      if (ddg) Arr(ddg, n).setZero();
      return;
    case ActivationKind::kRelu:
      // One pass: g' = [a > 0] first (g may alias a), then g = max(a, 0).
      if (dg) {
        for (Eigen::Index i = 0; i < n; ++i) {
          const S v = a[i];
          dg[i] = internal::PositiveIndicator(v);
          g[i] = internal::PositivePart(v);
        }
      } else {
        gv = av.max(zero);
      }
      if (ddg) Arr(ddg, n).setZero();
      return;
    case ActivationKind::kSoftplus: {
      // z = p a; e = exp(-|z|) in (0, 1]: no overflow; s = sigmoid(z);
      // g = (max(z, 0) + log(1 + e)) / p.
      constexpr Eigen::Index kBlock = 64;
      S e_buf[kBlock];
      S s_buf[kBlock];
      for (Eigen::Index start = 0; start < n; start += kBlock) {
        const Eigen::Index m = std::min(kBlock, n - start);
        internal::SigmoidBlock(a + start, p, m, e_buf, s_buf);
        const Eigen::Map<const ArrayS> e(e_buf, m);
        const Eigen::Map<const ArrayS> sig(s_buf, m);
        if (dg) Arr(dg + start, m) = sig;
        if (ddg) Arr(ddg + start, m) = p * sig * (one - sig);
        gv.segment(start, m) = ((p * av.segment(start, m)).max(zero) + (one + e).log()) / p;
      }
      return;
    }
    case ActivationKind::kTanh: {
      VectorizedTanh(a, n, g);
      if (dg) Arr(dg, n) = one - gv * gv;
      if (ddg) Arr(ddg, n) = S(-2) * gv * (one - gv * gv);
      return;
    }
    case ActivationKind::kSigmoid: {
      constexpr Eigen::Index kBlock = 64;
      S e_buf[kBlock];
      S s_buf[kBlock];
      for (Eigen::Index start = 0; start < n; start += kBlock) {
        const Eigen::Index m = std::min(kBlock, n - start);
        internal::SigmoidBlock(a + start, one, m, e_buf, s_buf);
        const Eigen::Map<const ArrayS> sig(s_buf, m);
        gv.segment(start, m) = sig;
        if (dg) Arr(dg + start, m) = sig * (one - sig);
        if (ddg) Arr(ddg + start, m) = sig * (one - sig) * (one - S(2) * sig);
      }
      return;
    }
    case ActivationKind::kElu: {
      constexpr Eigen::Index kBlock = 64;
      S e_buf[kBlock];
      for (Eigen::Index start = 0; start < n; start += kBlock) {
        const Eigen::Index m = std::min(kBlock, n - start);
        Eigen::Map<ArrayS> e(e_buf, m);
        const auto x = av.segment(start, m);
        e = x.min(zero).exp();
        const auto pos = (x > zero);
        if (dg) Arr(dg + start, m) = pos.select(one, p * e);
        if (ddg) Arr(ddg + start, m) = pos.select(zero, p * e);
        gv.segment(start, m) = pos.select(x, p * (e - one));
      }
      return;
    }
    case ActivationKind::kCos: {
      for (Eigen::Index i = 0; i < n; ++i) {
        const S c = std::cos(p * a[i]);
        if (dg) dg[i] = -p * std::sin(p * a[i]);
        if (ddg) ddg[i] = -p * p * c;
        g[i] = c;
      }
      return;
    }
  }
}

}  // namespace diffdyn
