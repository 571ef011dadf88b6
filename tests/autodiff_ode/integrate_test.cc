// Odeint glue: tableaus, orders of convergence, adaptive accuracy, Jet states, errors.
#include "diffdyn/autodiff_ode/integrate.h"

#include <cmath>
#include <string>
#include <vector>

#include <gtest/gtest.h>

namespace diffdyn {
namespace {

// x' = x cos(t), y' = -2 t y: x = x0 exp(sin t), y = y0 exp(-t^2). Non-autonomous, so
// the c coefficients matter.
struct KnownSolution {
  template <typename T>
  void operator()(const VectorX<T>& x, VectorX<T>& dxdt, double t) const {
    dxdt[0] = x[0] * std::cos(t);
    dxdt[1] = -2.0 * t * x[1];
  }
  static Eigen::Vector2d Exact(const Eigen::Vector2d& x0, double t) {
    return {x0[0] * std::exp(std::sin(t)), x0[1] * std::exp(-t * t)};
  }
};

// Harmonic oscillator x'' = -x: x(t) = x0 cos t + v0 sin t.
struct Harmonic {
  template <typename T>
  void operator()(const VectorX<T>& x, VectorX<T>& dxdt, double) const {
    dxdt[0] = x[1];
    dxdt[1] = -x[0];
  }
};

// Least-squares slope of log(err) against log(h).
double FittedSlope(const std::vector<double>& h, const std::vector<double>& err) {
  double mx = 0, my = 0;
  for (size_t i = 0; i < h.size(); ++i) mx += std::log(h[i]), my += std::log(err[i]);
  mx /= h.size();
  my /= h.size();
  double sxy = 0, sxx = 0;
  for (size_t i = 0; i < h.size(); ++i) {
    sxy += (std::log(h[i]) - mx) * (std::log(err[i]) - my);
    sxx += (std::log(h[i]) - mx) * (std::log(h[i]) - mx);
  }
  return sxy / sxx;
}

TEST(Butcher, TableausAreConsistent) {
  for (Method m : kAllMethods) {
    const ButcherTableau& tab = TableauOf(m);
    double sum_b = 0, sum_b_hat = 0;
    for (int i = 0; i < tab.stages; ++i) {
      double row = 0;
      for (int j = 0; j < i; ++j) row += tab.a[i][j];
      EXPECT_NEAR(row, tab.c[i], 1e-15) << tab.name << " row " << i;
      sum_b += tab.b[i];
      sum_b_hat += tab.b_hat[i];
    }
    EXPECT_NEAR(sum_b, 1.0, 1e-15) << tab.name;
    if (tab.adaptive) {
      EXPECT_NEAR(sum_b_hat, 1.0, 1e-15) << tab.name;
    }
    EXPECT_EQ(tab.fsal(), m == Method::kDopri5) << tab.name;
    EXPECT_EQ(ParseMethod(tab.name), m);
  }
}

TEST(Butcher, ParseMethodNamesOptionAndValue) {
  try {
    ParseMethod("rk45", "--solver");
    FAIL() << "expected diffdyn::Error";
  } catch (const Error& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("--solver"), std::string::npos) << msg;
    EXPECT_NE(msg.find("'rk45'"), std::string::npos) << msg;
  }
}

// Fixed-step methods through IntegrateFixedSteps: slope of the global error at t = 2.
TEST(Integrate, FixedStepOrderOfConvergence) {
  const Eigen::Vector2d x0(1.0, 0.5);
  const double t1 = 2.0;
  for (Method m : {Method::kEuler, Method::kMidpoint, Method::kRk4Classic, Method::kRk4}) {
    std::vector<double> h, err;
    for (int n : {16, 32, 64, 128}) {
      Eigen::VectorXd x = x0;
      IntegrateFixedSteps(m, KnownSolution{}, x, 0.0, t1, n);
      h.push_back(t1 / n);
      err.push_back((x - KnownSolution::Exact(x0, t1)).norm());
    }
    const double slope = FittedSlope(h, err);
    EXPECT_NEAR(slope, TableauOf(m).order, 0.2) << MethodName(m);
  }
}

// The embedded pairs' high-order solutions, stepped at fixed h, are of order 5.
template <Method M>
double EmbeddedSlope() {
  const Eigen::Vector2d x0(1.0, 0.5);
  std::vector<double> h, err;
  for (int n : {64, 128, 256}) {
    auto stepper = MakeControlledStepper<M, Eigen::VectorXd>(1e-6, 1e-6).stepper();
    Eigen::VectorXd x = x0;
    for (int k = 0; k < n; ++k) stepper.do_step(KnownSolution{}, x, k * 2.0 / n, 2.0 / n);
    h.push_back(2.0 / n);
    err.push_back((x - KnownSolution::Exact(x0, 2.0)).norm());
  }
  return FittedSlope(h, err);
}

TEST(Integrate, EmbeddedPairsAreFifthOrder) {
  EXPECT_NEAR(EmbeddedSlope<Method::kDopri5>(), 5.0, 0.2);
  EXPECT_NEAR(EmbeddedSlope<Method::kCashKarp>(), 5.0, 0.2);
}

TEST(Integrate, AdaptiveErrorFollowsTolerance) {
  const Eigen::Vector2d x0(1.0, 0.5);
  for (Method m : {Method::kDopri5, Method::kCashKarp}) {
    double previous = 1.0;
    for (double tol : {1e-6, 1e-9, 1e-12}) {
      OdeOptions options;
      options.method = m;
      options.abs_tol = options.rel_tol = tol;
      Eigen::VectorXd x = x0;
      const IntegrationStats stats = Integrate(KnownSolution{}, x, 0.0, 2.0, options);
      const double error = (x - KnownSolution::Exact(x0, 2.0)).norm();
      EXPECT_LT(error, 100 * tol) << MethodName(m) << " tol " << tol;
      EXPECT_LT(error, previous) << MethodName(m) << " tol " << tol;
      EXPECT_GT(stats.accepted_steps, 0);
      previous = error;
    }
  }
}

TEST(Integrate, ObserverSeesEveryTimePointExactly) {
  const std::vector<double> times{0.0, 0.1, 0.35, 1.0, 1.7};
  for (Method m : kAllMethods) {
    OdeOptions options;
    options.method = m;
    options.dt = 0.05;
    options.abs_tol = options.rel_tol = 1e-10;
    Eigen::VectorXd x = Eigen::Vector2d(1.0, 0.5);
    std::vector<int> seen;
    IntegrateTimes(KnownSolution{}, x, times, options,
                   [&](int i, double t, const Eigen::VectorXd& xi) {
                     seen.push_back(i);
                     EXPECT_EQ(t, times[i]);
                     const double tol = TableauOf(m).order >= 4 ? 1e-6 : 0.1;
                     EXPECT_LT((xi - KnownSolution::Exact({1.0, 0.5}, t)).norm(), tol);
                   });
    EXPECT_EQ(seen, (std::vector<int>{0, 1, 2, 3, 4})) << MethodName(m);
  }
}

TEST(Integrate, BackwardInTime) {
  OdeOptions options;
  options.abs_tol = options.rel_tol = 1e-11;
  const Eigen::Vector2d at_two = KnownSolution::Exact({1.0, 0.5}, 2.0);
  Eigen::VectorXd x = at_two;
  Integrate(KnownSolution{}, x, 2.0, 0.0, options);
  EXPECT_LT((x - Eigen::Vector2d(1.0, 0.5)).norm(), 1e-8);
}

// Typed over double and Jets: same values; Jets carry dx(t)/dx0 = [[cos, sin], [-sin, cos]].
template <typename T>
class IntegrateScalars : public ::testing::Test {};
using IntegrateScalarTypes = ::testing::Types<double, ceres::Jet<double, 2>, ceres::Jet<double, 5>>;
TYPED_TEST_SUITE(IntegrateScalars, IntegrateScalarTypes);

TYPED_TEST(IntegrateScalars, HarmonicOscillatorValuesAndSensitivities) {
  using T = TypeParam;
  const double t1 = 1.3;
  for (Method m : {Method::kRk4, Method::kDopri5}) {
    OdeOptions options;
    options.method = m;
    options.dt = 1e-3;
    options.abs_tol = options.rel_tol = 1e-12;
    VectorX<T> x(2);
    x[0] = T(0.4);
    x[1] = T(-0.2);
    if constexpr (IsJet<T>::value) {
      x[0].v[0] = 1.0;
      x[1].v[1] = 1.0;
    }
    Eigen::VectorXd xd(2);
    xd << 0.4, -0.2;
    Integrate(Harmonic{}, x, 0.0, t1, options);
    Integrate(Harmonic{}, xd, 0.0, t1, options);
    EXPECT_NEAR(ValuePart(x[0]), xd[0], 1e-14) << MethodName(m);
    EXPECT_NEAR(ValuePart(x[1]), xd[1], 1e-14) << MethodName(m);
    EXPECT_NEAR(xd[0], 0.4 * std::cos(t1) - 0.2 * std::sin(t1), 1e-10);
    if constexpr (IsJet<T>::value) {
      EXPECT_NEAR(x[0].v[0], std::cos(t1), 1e-10);
      EXPECT_NEAR(x[0].v[1], std::sin(t1), 1e-10);
      EXPECT_NEAR(x[1].v[0], -std::sin(t1), 1e-10);
      EXPECT_NEAR(x[1].v[1], std::cos(t1), 1e-10);
    }
  }
}

// Jets with derivative parts in the error norm take at least as many steps.
TEST(Integrate, DerivativesInErrorNormRefineSteps) {
  auto run = [](bool with_derivatives) {
    OdeOptions options;
    options.abs_tol = options.rel_tol = 1e-8;
    options.derivatives_in_error_norm = with_derivatives;
    VectorX<JetK<1>> x(2);
    x[0] = JetK<1>(0.4, 0);
    x[0].v[0] = 1e3;  // large derivative parts dominate the norm
    x[1] = JetK<1>(-0.2);
    return Integrate(Harmonic{}, x, 0.0, 3.0, options).accepted_steps;
  };
  EXPECT_GT(run(true), run(false));
}

// x0' = 0, x1' = x1^2 blows up at t = 1 / x1(0) = 0.5.
struct BlowUp {
  template <typename T>
  void operator()(const VectorX<T>& x, VectorX<T>& dxdt, double) const {
    dxdt[0] = T(0.0);
    dxdt[1] = x[1] * x[1];
  }
};

TEST(Integrate, BlowUpNamesTimeAndEntry) {
  for (Method m : {Method::kRk4, Method::kDopri5, Method::kCashKarp}) {
    OdeOptions options;
    options.method = m;
    options.dt = 0.01;
    Eigen::VectorXd x = Eigen::Vector2d(1.0, 2.0);
    try {
      Integrate(BlowUp{}, x, 0.0, 1.0, options);
      FAIL() << "expected NumericalError for " << MethodName(m);
    } catch (const NumericalError& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find("t = 0."), std::string::npos) << msg;
      EXPECT_NE(msg.find("entry 1"), std::string::npos) << msg;
    }
  }
}

TEST(Integrate, BadTimesAndStepsAreCallerErrors) {
  Eigen::VectorXd x = Eigen::Vector2d(1.0, 0.5);
  OdeOptions options;
  EXPECT_THROW(IntegrateTimes(Harmonic{}, x, {0.0}, options, [](int, double, const auto&) {}),
               Error);
  try {
    IntegrateTimes(Harmonic{}, x, {0.0, 1.0, 0.5}, options, [](int, double, const auto&) {});
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("times[2] = 0.5"), std::string::npos) << e.what();
  }
  EXPECT_THROW(IntegrateFixedSteps(Method::kRk4, Harmonic{}, x, 0.0, 1.0, 0), Error);
  EXPECT_THROW(IntegrateFixedSteps(Method::kDopri5, Harmonic{}, x, 0.0, 1.0, 10), Error);
}

TEST(Integrate, MaxStepsIsANumericalError) {
  OdeOptions options;
  options.max_steps = 5;
  options.abs_tol = options.rel_tol = 1e-12;
  Eigen::VectorXd x = Eigen::Vector2d(1.0, 0.5);
  EXPECT_THROW(Integrate(Harmonic{}, x, 0.0, 10.0, options), NumericalError);
}

}  // namespace
}  // namespace diffdyn
