// Activations: g' and g'' against Jets and central differences; batched path
// against the scalar path; softplus stability.
#include "diffdyn/models/activations.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include <ceres/jet.h>
#include <gtest/gtest.h>

namespace diffdyn {
namespace {

using Jet1 = ceres::Jet<double, 1>;

std::vector<Activation> AllActivations() {
  return {Activation::Linear(), Activation::Relu(),    Activation::Softplus(),
          Activation::Softplus(3.0), Activation::Tanh(), Activation::Sigmoid(),
          Activation::Elu(0.7),  Activation::Cos(),     Activation::Cos(2.0 * M_PI)};
}

// Points away from relu's and elu's kink at 0.
const std::vector<double> kPoints = {-7.3, -2.1, -0.6, -0.05, 0.03, 0.4, 1.7, 6.2, 25.0, -30.0};

TEST(Activations, FirstDerivativeMatchesJetAndCentralDifference) {
  for (const Activation& act : AllActivations()) {
    for (double a : kPoints) {
      const double dg = ActivationDerivative(act, a);
      const Jet1 jet = ActivationValue(act, Jet1(a, 0));
      EXPECT_NEAR(dg, jet.v[0], 1e-12) << ActivationName(act.kind) << " at " << a;
      const double h = 1e-6;
      const double fd = (ActivationValue(act, a + h) - ActivationValue(act, a - h)) / (2 * h);
      EXPECT_NEAR(dg, fd, 1e-6) << ActivationName(act.kind) << " at " << a;
    }
  }
}

TEST(Activations, SecondDerivativeMatchesJetAndCentralDifference) {
  for (const Activation& act : AllActivations()) {
    for (double a : kPoints) {
      const double ddg = ActivationSecondDerivative(act, a);
      const Jet1 jet = ActivationDerivative(act, Jet1(a, 0));
      EXPECT_NEAR(ddg, jet.v[0], 1e-12) << ActivationName(act.kind) << " at " << a;
      const double h = 1e-6;
      const double fd =
          (ActivationDerivative(act, a + h) - ActivationDerivative(act, a - h)) / (2 * h);
      EXPECT_NEAR(ddg, fd, 1e-6) << ActivationName(act.kind) << " at " << a;
    }
  }
}

TEST(Activations, BatchedMatchesScalar) {
  // 150 points (more than one internal block of 64), including the kink.
  Eigen::ArrayXd a(150);
  for (int i = 0; i < a.size(); ++i) a[i] = -12.0 + 24.0 * i / 149.0 + (i == 75 ? 0.0 : 0.01);
  a[10] = 0.0;
  for (const Activation& act : AllActivations()) {
    Eigen::ArrayXd g(a.size()), dg(a.size()), ddg(a.size());
    ApplyActivation(act, a.data(), a.size(), g.data(), dg.data(), ddg.data());
    for (int i = 0; i < a.size(); ++i) {
      const double scale = 1.0 + std::abs(ActivationValue(act, a[i]));
      EXPECT_NEAR(g[i], ActivationValue(act, a[i]), 1e-14 * scale) << ActivationName(act.kind);
      EXPECT_NEAR(dg[i], ActivationDerivative(act, a[i]), 1e-14 * (1 + act.param))
          << ActivationName(act.kind);
      EXPECT_NEAR(ddg[i], ActivationSecondDerivative(act, a[i]), 1e-13 * (1 + act.param * act.param))
          << ActivationName(act.kind);
    }
    // In place, values only.
    Eigen::ArrayXd inplace = a;
    ApplyActivation(act, inplace.data(), inplace.size(), inplace.data(), nullptr, nullptr);
    EXPECT_TRUE(inplace.isApprox(g, 1e-15) || (inplace - g).abs().maxCoeff() < 1e-15);
  }
}

// The sigmoid's branch (1 / (1 + e) for z >= 0, e / (1 + e) below) is chosen from
// z's sign bit: -0 and +0 give 1/2, a NaN stays NaN, and float agrees with double
// on both sides of 0 (the float path is a separate instantiation).
TEST(Activations, SigmoidBranchFollowsTheSignInBothPrecisions) {
  for (const Activation& act :
       {Activation::Softplus(), Activation::Softplus(3.0), Activation::Sigmoid()}) {
    double a[4] = {-0.0, 0.0, std::nan(""), -3.0}, g[4], dg[4];
    ApplyActivation(act, a, 4, g, dg, nullptr);
    const double at_zero = act.kind == ActivationKind::kSigmoid ? 0.25 : 0.5;
    EXPECT_EQ(dg[0], at_zero) << ActivationName(act.kind);
    EXPECT_EQ(dg[1], at_zero) << ActivationName(act.kind);
    EXPECT_TRUE(std::isnan(dg[2]) && std::isnan(g[2])) << ActivationName(act.kind);
    EXPECT_NEAR(dg[3], ActivationDerivative(act, -3.0), 1e-16) << ActivationName(act.kind);

    Eigen::ArrayXf af(130);
    for (int i = 0; i < af.size(); ++i) af[i] = -9.0f + 18.0f * static_cast<float>(i) / 129.0f;
    Eigen::ArrayXf gf(af.size()), dgf(af.size());
    ApplyActivation(act, af.data(), af.size(), gf.data(), dgf.data(), nullptr);
    for (int i = 0; i < af.size(); ++i) {
      const double x = af[i];
      EXPECT_NEAR(gf[i], ActivationValue(act, x), 2e-6 * (1.0 + std::abs(x)))
          << ActivationName(act.kind) << " at " << x;
      EXPECT_NEAR(dgf[i], ActivationDerivative(act, x), 2e-6 * (1.0 + act.param))
          << ActivationName(act.kind) << " at " << x;
    }
  }
}

// ReLU's indicator and positive part are read off the bits; they must equal the
// comparisons x > 0 ? 1 : 0 and x > 0 ? x : 0 on every class of value.
template <typename S>
void ExpectPositiveBitsMatchComparisons() {
  const S inf = std::numeric_limits<S>::infinity();
  const S tiny = std::numeric_limits<S>::denorm_min();
  for (const S x : {S(0), S(-0.0), tiny, -tiny, S(1e-30), S(2.5), S(-2.5), inf, -inf,
                    std::numeric_limits<S>::max(), std::numeric_limits<S>::lowest(),
                    std::numeric_limits<S>::quiet_NaN(), -std::numeric_limits<S>::quiet_NaN()}) {
    const S indicator = x > S(0) ? S(1) : S(0);
    const S part = x > S(0) ? x : S(0);
    EXPECT_EQ(internal::PositiveIndicator(x), indicator) << x;
    EXPECT_EQ(internal::PositivePart(x), part) << x;
    EXPECT_FALSE(std::signbit(internal::PositivePart(x))) << x;
  }
}

TEST(Activations, ReluPiecesFromBitsMatchComparisons) {
  ExpectPositiveBitsMatchComparisons<double>();
  ExpectPositiveBitsMatchComparisons<float>();
}

TEST(Activations, ReluKinkHasZeroDerivative) {
  EXPECT_EQ(ActivationDerivative(Activation::Relu(), 0.0), 0.0);
  EXPECT_EQ(ActivationValue(Activation::Relu(), -3.0), 0.0);
}

TEST(Activations, SoftplusIsStableForLargeInputs) {
  const Activation sp = Activation::Softplus(2.0);
  for (double a : {-1e3, -400.0, 400.0, 1e3}) {
    const double g = ActivationValue(sp, a);
    EXPECT_TRUE(std::isfinite(g));
    EXPECT_NEAR(g, std::max(a, 0.0), 1e-12);
    EXPECT_NEAR(ActivationDerivative(sp, a), a > 0 ? 1.0 : 0.0, 1e-12);
    EXPECT_TRUE(std::isfinite(ActivationSecondDerivative(sp, a)));
    double batched = 0.0, d = 0.0, dd = 0.0;
    ApplyActivation(sp, &a, 1, &batched, &d, &dd);
    EXPECT_NEAR(batched, std::max(a, 0.0), 1e-12);
  }
  // log(2)/beta at 0.
  EXPECT_NEAR(ActivationValue(sp, 0.0), std::log(2.0) / 2.0, 1e-15);
}

TEST(Activations, MakeActivationParsesAndRejects) {
  EXPECT_EQ(MakeActivation("softplus", 2.0), Activation::Softplus(2.0));
  EXPECT_EQ(MakeActivation("cos"), Activation::Cos());
  EXPECT_THROW(MakeActivation("swish"), Error);
  EXPECT_THROW(MakeActivation("softplus", -1.0), Error);
  EXPECT_THROW(MakeActivation("tanh", NAN), Error);
}

// Distance in units in the last place (of S) between two finite values of the same sign.
template <typename S>
double UlpDistance(S a, S b) {
  if (a == b) return 0.0;
  const S ulp = std::nextafter(std::abs(b), std::numeric_limits<S>::infinity()) - std::abs(b);
  return static_cast<double>(std::abs(a - b)) / static_cast<double>(ulp);
}

// The exponential and log1p behind the batched softplus and sigmoid, against libm
// evaluated in long double and rounded to S: within 2 ulp over their whole domains,
// 0 below exp's normal range, NaN kept, tiny log1p arguments exact.
template <typename S>
void ExpectExpAndLog1pWithinTwoUlp() {
  const S min_x = internal::ExpConstants<S>::kMin;
  double worst_exp = 0.0, worst_log = 0.0;
  for (int i = 0; i <= 200000; ++i) {
    const S x = static_cast<S>(min_x * (static_cast<double>(i) / 200000.0));
    const S ref = static_cast<S>(std::exp(static_cast<long double>(x)));
    const double d = UlpDistance(internal::ExpOfNonPositive(x), ref);
    worst_exp = std::max(worst_exp, d);
    ASSERT_LE(d, 2.0) << "exp(" << x << ")";
  }
  for (int i = 0; i <= 200000; ++i) {
    const S e = static_cast<S>(i / 200000.0);
    const S ref = static_cast<S>(std::log1p(static_cast<long double>(e)));
    const double d = UlpDistance(internal::Log1pOfUnit(e), ref);
    worst_log = std::max(worst_log, d);
    ASSERT_LE(d, 2.0) << "log1p(" << e << ")";
  }
  EXPECT_GT(worst_exp + worst_log, 0.0);  // differs from libm somewhere: the test can see it
  EXPECT_EQ(internal::ExpOfNonPositive(S(0)), S(1));
  EXPECT_EQ(internal::ExpOfNonPositive(S(-0.0)), S(1));
  EXPECT_EQ(internal::ExpOfNonPositive(min_x - S(1)), S(0));
  EXPECT_EQ(internal::ExpOfNonPositive(-std::numeric_limits<S>::infinity()), S(0));
  EXPECT_TRUE(std::isnan(internal::ExpOfNonPositive(std::numeric_limits<S>::quiet_NaN())));
  EXPECT_TRUE(std::isnan(internal::ExpOfNonPositive(-std::numeric_limits<S>::quiet_NaN())));
  EXPECT_EQ(internal::Log1pOfUnit(S(1e-30)), S(1e-30));
  EXPECT_EQ(internal::Log1pOfUnit(S(0)), S(0));
  EXPECT_TRUE(std::isnan(internal::Log1pOfUnit(std::numeric_limits<S>::quiet_NaN())));
}

TEST(Activations, ExpAndLog1pOfTheBatchedPathWithinTwoUlp) {
  ExpectExpAndLog1pWithinTwoUlp<double>();
  ExpectExpAndLog1pWithinTwoUlp<float>();
}

TEST(Activations, VectorizedTanhInFloatWithinFewUlpOfStdTanh) {
  // Log-spaced magnitudes from subnormal to the largest float, both signs, a dense
  // sweep over the bend and around the switch of forms at |x| = 1/2.
  std::vector<float> x;
  for (double m = 1e-44; m < 3e38; m *= 1.37) {
    x.push_back(static_cast<float>(m));
    x.push_back(static_cast<float>(-m));
  }
  for (int i = -40000; i <= 40000; ++i) x.push_back(static_cast<float>(i * 5e-4));
  float below = 0.5f, above = 0.5f;
  for (int i = 0; i < 1000; ++i) {
    below = std::nextafter(below, 0.0f);
    above = std::nextafter(above, 1.0f);
    x.insert(x.end(), {below, above, -below, -above});
  }
  x.insert(x.end(), {0.0f, -0.0f, 0.5f, -0.5f});
  std::vector<float> t(x.size());
  VectorizedTanh(x.data(), static_cast<Eigen::Index>(x.size()), t.data());
  for (size_t i = 0; i < x.size(); ++i) {
    const float ref = std::tanh(x[i]);
    ASSERT_EQ(std::signbit(t[i]), std::signbit(ref)) << "x = " << x[i];
    ASSERT_LE(UlpDistance(t[i], ref), 4.0) << "x = " << x[i] << ": " << t[i] << " vs std::tanh " << ref;
  }
  std::vector<float> s = {INFINITY, -INFINITY, NAN, -NAN};
  VectorizedTanh(s.data(), 4, s.data());
  EXPECT_EQ(s[0], 1.0f);
  EXPECT_EQ(s[1], -1.0f);
  EXPECT_TRUE(std::isnan(s[2]));
  EXPECT_TRUE(std::isnan(s[3]));
}

TEST(Activations, VectorizedTanhWithinFewUlpOfStdTanh) {
  // Log-spaced magnitudes from subnormal to huge, both signs, plus a dense sweep
  // around the branch switch at |x| = 1/2 and over the range where tanh bends.
  std::vector<double> x;
  for (double m = 1e-310; m < 1e300; m *= 1.37) {
    x.push_back(m);
    x.push_back(-m);
  }
  for (int i = -40000; i <= 40000; ++i) x.push_back(i * 5e-4);
  for (int i = -1000; i <= 1000; ++i) x.push_back(0.5 + i * 1e-12);
  x.push_back(0.0);
  x.push_back(-0.0);
  std::vector<double> t(x.size());
  VectorizedTanh(x.data(), static_cast<Eigen::Index>(x.size()), t.data());
  double worst = 0.0;
  for (size_t i = 0; i < x.size(); ++i) {
    const double ref = std::tanh(x[i]);
    ASSERT_EQ(std::signbit(t[i]), std::signbit(ref)) << "x = " << x[i];
    const double d = UlpDistance(t[i], ref);
    worst = std::max(worst, d);
    ASSERT_LE(d, 4.0) << "x = " << x[i] << ": " << t[i] << " vs std::tanh " << ref;
  }
  // Not exact everywhere by accident of the test grid: the forms do differ from libm.
  EXPECT_GT(worst, 0.0);
  // Specials: +-inf give +-1, NaN stays NaN; in place (t aliasing x) gives the same.
  std::vector<double> s = {INFINITY, -INFINITY, NAN, 3.0};
  VectorizedTanh(s.data(), 4, s.data());
  EXPECT_EQ(s[0], 1.0);
  EXPECT_EQ(s[1], -1.0);
  EXPECT_TRUE(std::isnan(s[2]));
  EXPECT_LE(UlpDistance(s[3], std::tanh(3.0)), 4.0);
}

TEST(Activations, BatchedTanhUsesTheVectorizedForm) {
  std::vector<double> a = {-25.0, -1.3, -0.2, 1e-9, 0.49, 0.51, 2.0, 40.0};
  std::vector<double> g(a.size()), dg(a.size()), ddg(a.size());
  ApplyActivation(Activation::Tanh(), a.data(), static_cast<Eigen::Index>(a.size()), g.data(),
                  dg.data(), ddg.data());
  for (size_t i = 0; i < a.size(); ++i) {
    EXPECT_LE(UlpDistance(g[i], std::tanh(a[i])), 4.0) << a[i];
    EXPECT_NEAR(dg[i], 1.0 - std::tanh(a[i]) * std::tanh(a[i]), 1e-15) << a[i];
  }
  // Relative accuracy for tiny inputs (the old (1 - e) / (1 + e) form lost it).
  EXPECT_LE(UlpDistance(g[3], 1e-9), 1.0);
}

}  // namespace
}  // namespace diffdyn
