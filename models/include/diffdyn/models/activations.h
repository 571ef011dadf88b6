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
//     pre-activations in vectorised passes (the batched float and double paths).
//
//   Activation act = Activation::Softplus(2.0);
//   double y = ActivationValue(act, 0.3), dy = ActivationDerivative(act, 0.3);
#pragma once

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <type_traits>
#include <utility>

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

// c[0] + x (c[1] + x (c[2] + ...)), unrolled at compile time (so loops over it vectorise).
template <typename S, std::size_t N, std::size_t... I>
inline S HornerUnrolled(const std::array<S, N>& c, S x, std::index_sequence<I...>) {
  S p = c[N - 1];
  ((p = p * x + c[N - 2 - I]), ...);
  return p;
}
template <typename S, std::size_t N>
inline S Horner(const std::array<S, N>& c, S x) {
  return HornerUnrolled(c, x, std::make_index_sequence<N - 1>());
}

// The constants of ExpOfNonPositive: ln 2 split into a high part with trailing zero
// bits (n ln2_hi is exact) and the rest; the shifter 1.5 2^mantissa (x log2(e) +
// shifter holds the integer nearest to x log2(e) in its low bits); the smallest x
// with a normal exp(x); the degree d of the Taylor polynomial of exp(r), |r| <= ln2/2,
// whose remainder r^(d+1)/(d+1)! is below a tenth of an ulp; and the terms of
// Log1pOfUnit's series (s^(2T-1)/(2T-1) below a tenth of an ulp at |s| <= 0.1716).
template <typename S>
struct ExpConstants;
template <>
struct ExpConstants<double> {
  static constexpr double kLog2e = 1.4426950408889634, kLn2Hi = 6.93147180369123816490e-01,
                          kLn2Lo = 1.90821492927058770002e-10, kShifter = 6755399441055744.0, kMin = -708.0;
  static constexpr int kBias = 1023, kMantissa = 52, kDegree = 12, kAtanhTerms = 11;
};
template <>
struct ExpConstants<float> {
  static constexpr float kLog2e = 1.44269504f, kLn2Hi = 0.693145751953125f, kLn2Lo = 1.428606765330187e-06f,
                         kShifter = 12582912.0f, kMin = -87.0f;
  static constexpr int kBias = 127, kMantissa = 23, kDegree = 7, kAtanhTerms = 6;
};

// 1/k!, k = 0..D, and 2/(2k+1), k = 1..T-1: the series of exp(r) and of (2 atanh(s) / s - 2) / s^2.
template <typename S, int D>
constexpr std::array<S, D + 1> InverseFactorials() {
  std::array<S, D + 1> c{};
  double factorial = 1;
  for (int k = 0; k <= D; ++k) {
    if (k > 0) factorial *= k;
    c[k] = S(1.0 / factorial);
  }
  return c;
}
template <typename S, int T>
constexpr std::array<S, T - 1> TwiceAtanhTail() {
  std::array<S, T - 1> c{};
  for (int k = 1; k < T; ++k) c[k - 1] = S(2.0 / (2 * k + 1));
  return c;
}

// exp(x) for x <= 0 (the activations' exp(-|z|)), branch free with integer masks so
// that loops over it vectorise: x = n ln2 + r, |r| <= ln2/2, exp(r) by its Taylor
// polynomial, times 2^n made in the exponent bits. Within 2 ulp of std::exp for
// x >= kMin (-708 in double, -87 in float); 0 below (where std::exp is subnormal or
// 0); NaN gives NaN. Positive x are outside its contract.
template <typename S>
inline S ExpOfNonPositive(S x) {
  using C = ExpConstants<S>;
  using U = BitsOf<S>;
  using I = std::make_signed_t<U>;  // magnitudes < 2^(bits-1): signed compares (AVX2 has those)
  static constexpr auto kTaylor = InverseFactorials<S, C::kDegree>();
  constexpr U kSign = U(1) << (8 * sizeof(S) - 1);
  constexpr U kMinMagnitude = std::bit_cast<U>(C::kMin) & ~kSign;
  constexpr U kInf = std::bit_cast<U>(std::numeric_limits<S>::infinity());
  const U bits = std::bit_cast<U>(x);
  const U magnitude = bits & ~kSign;
  const U tiny = U(0) - U(I(magnitude) > I(kMinMagnitude));  // x < kMin or NaN: all ones
  const U nan = U(0) - U(I(magnitude) > I(kInf));
  const S clamped = std::bit_cast<S>((bits & ~tiny) | (std::bit_cast<U>(C::kMin) & tiny));
  const S shifted = clamped * C::kLog2e + C::kShifter;
  const S n = shifted - C::kShifter;
  const S r = (clamped - n * C::kLn2Hi) - n * C::kLn2Lo;
  const U biased = std::bit_cast<U>(shifted) - std::bit_cast<U>(C::kShifter) + U(C::kBias);
  const U y = std::bit_cast<U>(Horner(kTaylor, r) * std::bit_cast<S>(biased << C::kMantissa));
  return std::bit_cast<S>((y & ~tiny) | (bits & nan));
}

// All ones where the sign bit of x is set (negatives, -0, negative NaN), else 0.
template <typename S>
inline BitsOf<S> SignMask(S x) {
  return BitsOf<S>(0) - (std::bit_cast<BitsOf<S>>(x) >> (8 * sizeof(S) - 1));
}

// mask ? a : b, on the bits.
template <typename S>
inline S SelectBits(BitsOf<S> mask, S a, S b) {
  using U = BitsOf<S>;
  return std::bit_cast<S>((std::bit_cast<U>(a) & mask) | (std::bit_cast<U>(b) & ~mask));
}

// log(1 + e) for e in [0, 1] (softplus' log1p(exp(-|z|))), branch free, in the form
// of fdlibm's log1p: 1 + e = 2^k (1 + f) with k = 0, f = e, or above sqrt(2) - 1 k = 1,
// f = (e - 1) / 2 (both exact to half an ulp); log(1 + f) = 2 atanh(s), s = f / (2 + f),
// |s| <= 0.1716, written f - s (f - R) with R = 2 s^2/3 + 2 s^4/5 + ... (to s^20 in
// double, s^10 in float: the rest below a tenth of an ulp), so s's rounding only touches
// the small correction; plus k ln 2 in two parts. No 1 + e is rounded: tiny e give e.
template <typename S>
inline S Log1pOfUnit(S e) {
  using U = BitsOf<S>;
  using I = std::make_signed_t<U>;
  static constexpr auto kSeries = TwiceAtanhTail<S, ExpConstants<S>::kAtanhTerms>();
  constexpr U kSplit = std::bit_cast<U>(S(0.41421356237309504880));
  const U upper = U(0) - U(I(std::bit_cast<U>(e)) > I(kSplit));  // all ones above the split
  const S f = SelectBits(upper, (e - S(1)) * S(0.5), e);
  const S s = f / (S(2) + f);
  const S z = s * s;
  const S r = z * Horner(kSeries, z);
  const S k_ln2_hi = std::bit_cast<S>(std::bit_cast<U>(ExpConstants<S>::kLn2Hi) & upper);
  const S k_ln2_lo = std::bit_cast<S>(std::bit_cast<U>(ExpConstants<S>::kLn2Lo) & upper);
  return k_ln2_hi + (f - (s * (f - r) - k_ln2_lo));
}

// exp(-|z|) in [0, 1] (|z| by setting the sign bit).
template <typename S>
inline S ExpOfMinusAbs(S z) {
  constexpr BitsOf<S> kSign = BitsOf<S>(1) << (8 * sizeof(S) - 1);
  return ExpOfNonPositive(std::bit_cast<S>(std::bit_cast<BitsOf<S>>(z) | kSign));
}

// sigmoid(z) from e = exp(-|z|): 1 / (1 + e) for z >= 0, e / (1 + e) below (chosen by
// z's sign bit): no overflow, one division.
template <typename S>
inline S SigmoidFromExp(S z, S e) {
  const S positive = S(1) / (S(1) + e);
  return SelectBits(SignMask(z), e * positive, positive);
}

// For m values z = p a[i]: e[i] = exp(-|z|) in [0, 1] and s[i] = sigmoid(z) =
// 1 / (1 + exp(-z)), as 1 / (1 + e) for z >= 0 and e / (1 + e) otherwise: no
// overflow, one division. e and s must not alias a.
//
// Each element is a long chain of dependent operations (exp's range reduction and
// polynomial, then the division, and for softplus log1p's division and series: some
// 190 cycles of latency in double on AVX2), which one loop body carrying all of it
// leaves the out-of-order window too short to overlap. So the blocks run in two
// vectorised passes over the same m values, exp(-|z|) into e first and the rest from
// it: the same operations per element (the same values, bit for bit), each pass's
// chain half as long. On a 2-core AMD EPYC (AVX2) this took softplus with its
// derivative from 5.0 to 3.5 ns per double and 1.8 to 1.35 ns per float.
template <typename S>
inline void SigmoidBlock(const S* __restrict a, S p, Eigen::Index m, S* __restrict e, S* __restrict s) {
  for (Eigen::Index i = 0; i < m; ++i) e[i] = ExpOfMinusAbs(p * a[i]);
  for (Eigen::Index i = 0; i < m; ++i) s[i] = SigmoidFromExp(p * a[i], e[i]);
}

// For m values z = p a[i]: g[i] = softplus(z) / p = (max(z, 0) + log1p(exp(-|z|))) inv_p
// and s[i] = sigmoid(z) (as SigmoidBlock), in two vectorised passes (e = exp(-|z|) held
// in s between them). g and s must not alias a.
template <typename S>
inline void SoftplusBlock(const S* __restrict a, S p, S inv_p, Eigen::Index m, S* __restrict g,
                          S* __restrict s) {
  for (Eigen::Index i = 0; i < m; ++i) s[i] = ExpOfMinusAbs(p * a[i]);
  for (Eigen::Index i = 0; i < m; ++i) {
    const S z = p * a[i];
    const S e = s[i];
    s[i] = SigmoidFromExp(z, e);
    g[i] = (SelectBits(SignMask(z), S(0), z) + Log1pOfUnit(e)) * inv_p;
  }
}

// a b + c with one rounding (std::fma) where the target has FMA instructions, with two
// (a product, then a sum) elsewhere: the same operations GCC's contraction of Eigen's
// packet products and sums gives on either kind of target, fixed in the source.
template <typename S>
inline S MulAdd(S a, S b, S c) {
#ifdef __FMA__
  return std::fma(a, b, c);
#else
  return a * b + c;
#endif
}

}  // namespace internal

/// t[i] = tanh(x[i]) for n contiguous values of S (double or float), vectorised,
/// within a few ulp of std::tanh everywhere (t may alias x). Two branch-free forms,
/// chosen per element by |x|:
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
/// NaN propagates. Per block of 64 values, e comes from Eigen's vectorised exp; the
/// rest is one loop the compiler vectorises, with each value's recurrences in
/// registers and the choice of form made on the bits of x (integer compares
/// vectorise where a floating-point one does not under GCC's default
/// -ftrapping-math); x^2 D_{k-2} + (2k-1) D_{k-1} and x + x (D / B) are fused
/// multiply-adds where the target has FMA (internal::MulAdd).
template <typename S>
inline void VectorizedTanh(const S* x, Eigen::Index n, S* t) {
  static_assert(std::is_floating_point_v<S>, "VectorizedTanh needs float or double");
  using ArrayS = Eigen::Array<S, Eigen::Dynamic, 1>;
  using U = internal::BitsOf<S>;
  using I = std::make_signed_t<U>;
  constexpr Eigen::Index kBlock = 64;
  constexpr int kLevels = 8;
  constexpr U kSign = U(1) << (8 * sizeof(S) - 1);
  constexpr U kHalf = std::bit_cast<U>(S(0.5));
  S e[kBlock];
  for (Eigen::Index start = 0; start < n; start += kBlock) {
    const Eigen::Index m = std::min(kBlock, n - start);
    Eigen::Map<ArrayS>(e, m) = (S(-2) * Eigen::Map<const ArrayS>(x + start, m).abs()).exp();
    for (Eigen::Index i = 0; i < m; ++i) {
      const S xi = x[start + i];
      const S x2 = xi * xi;
      // D_k and B_k, k = 2..8, from (D_0, D_1) = (-1, 0) and (B_0, B_1) = (1, 1).
      S d_prev = S(-1), d_cur = S(0), b_prev = S(1), b_cur = S(1);
      for (int k = 2; k <= kLevels; ++k) {
        const S odd = S(2 * k - 1);
        const S d_next = internal::MulAdd(x2, d_prev, odd * d_cur);
        const S b_next = internal::MulAdd(x2, b_prev, odd * b_cur);
        d_prev = d_cur;
        d_cur = d_next;
        b_prev = b_cur;
        b_cur = b_next;
      }
      const S small = internal::MulAdd(xi, d_cur / b_cur, xi);
      const S large = (S(1) - e[i]) / (S(1) + e[i]);
      // |x| < 1/2 on the bits of x (NaN's magnitude lies above); sign(x) large by
      // copying x's sign bit onto large (> 0).
      const U bits = std::bit_cast<U>(xi);
      const U use_small = U(0) - U(I(bits & ~kSign) < I(kHalf));
      const U large_bits = std::bit_cast<U>(large) ^ (bits & kSign);
      t[start + i] = internal::SelectBits(use_small, small, std::bit_cast<S>(large_bits));
    }
  }
}

/// Batched evaluation over n contiguous pre-activations a[0..n) of S (double or
/// float): g[i] = g(a[i]), dg[i] = g'(a[i]) and, when ddg is not null,
/// ddg[i] = g''(a[i]). g may alias a (in-place). dg may be null when only values
/// are needed. Softplus and sigmoid take exp(-|z|) and log1p from
/// internal::ExpOfNonPositive and Log1pOfUnit (within 2 ulp, in loops the compiler
/// vectorises); no allocation. In float the parameter p is rounded to float once.
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
      // z = p a; e = exp(-|z|) in [0, 1]: no overflow; s = sigmoid(z);
      // g = (max(z, 0) + log1p(e)) / p, two vectorised passes per block into local
      // buffers (internal::SoftplusBlock; g may alias a).
      constexpr Eigen::Index kBlock = 64;
      S g_buf[kBlock];
      S s_buf[kBlock];
      const S inv_p = one / p;
      for (Eigen::Index start = 0; start < n; start += kBlock) {
        const Eigen::Index m = std::min(kBlock, n - start);
        internal::SoftplusBlock(a + start, p, inv_p, m, g_buf, s_buf);
        const Eigen::Map<const ArrayS> sig(s_buf, m);
        if (dg) Arr(dg + start, m) = sig;
        if (ddg) Arr(ddg + start, m) = p * sig * (one - sig);
        gv.segment(start, m) = Eigen::Map<const ArrayS>(g_buf, m);
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
