// Fitting ODE parameters through the integrator (solvers/trajectory_fit.h).
#include "diffdyn/solvers/trajectory_fit.h"

#include <cmath>

#include <gtest/gtest.h>

#include "diffdyn/models/random.h"

namespace diffdyn {
namespace {

// Van der Pol-like oscillator with two parameters: qdd = -w2 q - mu (q^2 - 1) qd.
struct Oscillator {
  template <typename T>
  void operator()(const VectorX<T>& x, VectorX<T>& dxdt, double, const T* theta) const {
    dxdt[0] = x[1];
    dxdt[1] = -theta[0] * x[0] - theta[1] * (x[0] * x[0] - 1.0) * x[1];
  }
};

std::vector<Trajectory> Simulate(const Eigen::Vector2d& theta, double noise, int count, Rng& rng) {
  std::vector<Trajectory> data;
  for (int k = 0; k < count; ++k) {
    Trajectory d;
    std::vector<double> times;
    for (int i = 0; i <= 100; ++i) times.push_back(0.05 * i);
    d.t = Eigen::Map<const Eigen::VectorXd>(times.data(), 101);
    d.states.resize(2, 101);
    Eigen::VectorXd x(2);
    x << Uniform(rng, -2, 2), Uniform(rng, -1, 1);
    OdeOptions fine;
    fine.method = Method::kRk4Classic;
    fine.dt = 1e-4;
    auto sys = [&](const VectorX<double>& s, VectorX<double>& dsdt, double t) {
      Oscillator{}(s, dsdt, t, theta.data());
    };
    IntegrateTimes(sys, x, times, fine, [&](int i, double, const VectorX<double>& s) {
      d.states(0, i) = s[0] + noise * StandardNormal(rng);
      d.states(1, i) = s[1] + noise * StandardNormal(rng);
    });
    data.push_back(d);
  }
  return data;
}

TEST(TrajectoryFit, RecoversParametersWithinThreeStandardErrors) {
  const Eigen::Vector2d truth(4.0, 0.7);
  int within = 0;
  for (int seed = 0; seed < 6; ++seed) {
    Rng rng(seed);
    const auto data = Simulate(truth, 0.01, 3, rng);
    const auto fit = FitTrajectoryParameters<2>(Oscillator{}, data, Eigen::Vector2d(3.0, 0.3), {});
    ASSERT_TRUE(fit.converged) << fit.summary;
    EXPECT_LT(fit.final_rms, 0.015);   // the noise level, 0.01
    EXPECT_LT(fit.final_rms, fit.initial_rms);
    bool all = true;
    for (int i = 0; i < 2; ++i) {
      EXPECT_LT(std::abs(fit.params[i] - truth[i]), 0.02 * truth[i]) << "seed " << seed;
      all = all && std::abs(fit.params[i] - truth[i]) < 3 * fit.standard_errors[i];
    }
    within += all;
  }
  EXPECT_GE(within, 5);  // ~99 % per parameter if the standard errors are right
}

TEST(TrajectoryFit, NoiseFreeDataGivesExactParameters) {
  Rng rng(3);
  const auto data = Simulate(Eigen::Vector2d(2.5, 0.4), 0.0, 2, rng);
  TrajectoryFitOptions options;
  options.fit_initial_state = false;
  options.ode.abs_tol = options.ode.rel_tol = 1e-11;
  const auto fit = FitTrajectoryParameters<2>(Oscillator{}, data, Eigen::Vector2d(2.0, 0.2), options);
  EXPECT_NEAR(fit.params[0], 2.5, 1e-6);
  EXPECT_NEAR(fit.params[1], 0.4, 1e-6);
  EXPECT_EQ(fit.num_residuals, 2 * 100 * 2);
}

TEST(TrajectoryFit, PartiallyObservedStateStillIdentifies) {
  Rng rng(9);
  const auto data = Simulate(Eigen::Vector2d(4.0, 0.7), 0.005, 3, rng);
  TrajectoryFitOptions options;
  options.observed = {0};  // positions only
  const auto fit = FitTrajectoryParameters<2>(Oscillator{}, data, Eigen::Vector2d(3.0, 0.3), options);
  EXPECT_NEAR(fit.params[0], 4.0, 0.05);
  EXPECT_NEAR(fit.params[1], 0.7, 0.05);
}

TEST(TrajectoryFit, BadInputNamesTheProblem) {
  std::vector<Trajectory> data(1);
  data[0].t = Eigen::VectorXd::LinSpaced(2, 0.0, 0.1);
  data[0].states = Eigen::MatrixXd::Zero(2, 3);
  EXPECT_THROW(FitTrajectoryParameters<2>(Oscillator{}, data, Eigen::Vector2d(1, 1), {}), Error);
  EXPECT_THROW(FitTrajectoryParameters<2>(Oscillator{}, {}, Eigen::Vector2d(1, 1), {}), Error);
  data[0].states = Eigen::MatrixXd::Zero(2, 2);
  TrajectoryFitOptions options;
  options.observed = {5};
  try {
    FitTrajectoryParameters<2>(Oscillator{}, data, Eigen::Vector2d(1, 1), options);
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("observed state index 5"), std::string::npos);
  }
}

TEST(TrajectoryFit, UnidentifiableParameterIsReported) {
  // theta[1] multiplies (q^2 - 1) qd, which is zero on the resting trajectory q = 1, qd = 0.
  std::vector<Trajectory> data(1);
  data[0].t = Eigen::VectorXd::LinSpaced(4, 0.0, 1.5);
  data[0].states = Eigen::MatrixXd::Zero(2, 4);
  TrajectoryFitOptions options;
  options.fit_initial_state = false;
  EXPECT_THROW(FitTrajectoryParameters<2>(Oscillator{}, data, Eigen::Vector2d(1, 1), options),
               NumericalError);
}

}  // namespace
}  // namespace diffdyn
