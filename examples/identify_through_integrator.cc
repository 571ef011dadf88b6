// Physical parameters fitted through the integrator: a damped pendulum's gravity and damping.
//
// The model, written once as a template on the scalar,
//
//   m l^2 qdd + m g l sin q + b qd = 0,   m = 1 kg, l = 0.5 m,   theta = (g, b),
//
// is "measured": a few free swings simulated with classic RK4 at 0.1 ms (a solver
// independent of the fit's) and sampled at 50 Hz with noise of 0.01 rad and 0.05 rad/s.
// FitTrajectoryParameters then finds theta and each swing's initial state by Ceres'
// Levenberg-Marquardt through dopri5 running on Jets: every prediction's Jacobian
// d q(t_i) / d(theta, x0) is exact, no finite differences. Standard errors come from
// sigma^2 (J^T J)^-1; the example checks that each fitted value lies within 4 of them
// of the truth.
//
// Usage: example_identify_through_integrator [--quick]
#include <cmath>
#include <cstring>
#include <vector>

#include <fmt/core.h>

#include "diffdyn/models/random.h"
#include "diffdyn/solvers/trajectory_fit.h"

namespace {

// dx/dt of x = (q, qd) for theta = (g, b).
struct DampedPendulum {
  static constexpr double kLength = 0.5;
  template <typename T>
  void operator()(const diffdyn::VectorX<T>& x, diffdyn::VectorX<T>& dxdt, double, const T* theta) const {
    using std::sin;
    dxdt[0] = x[1];
    dxdt[1] = -theta[0] / kLength * sin(x[0]) - theta[1] / (kLength * kLength) * x[1];
  }
};

// `count` noisy swings of `seconds` each, sampled at 50 Hz.
std::vector<diffdyn::Trajectory> Measure(const Eigen::Vector2d& truth, int count, double seconds,
                                         diffdyn::Rng& rng) {
  using namespace diffdyn;
  OdeOptions fine;
  fine.method = Method::kRk4Classic;
  fine.dt = 1e-4;
  std::vector<Trajectory> data(count);
  for (Trajectory& swing : data) {
    const int samples = static_cast<int>(seconds * 50) + 1;
    std::vector<double> times;
    for (int i = 0; i < samples; ++i) times.push_back(i / 50.0);
    swing.t = Eigen::Map<const Eigen::VectorXd>(times.data(), samples);
    swing.states.resize(2, samples);
    Eigen::VectorXd x(2);
    x << Uniform(rng, 0.5, 2.5), Uniform(rng, -1.0, 1.0);
    auto system = [&](const VectorX<double>& s, VectorX<double>& dsdt, double t) {
      DampedPendulum{}(s, dsdt, t, truth.data());
    };
    IntegrateTimes(system, x, times, fine, [&](int i, double, const VectorX<double>& s) {
      swing.states(0, i) = s[0] + 0.01 * StandardNormal(rng);
      swing.states(1, i) = s[1] + 0.05 * StandardNormal(rng);
    });
  }
  return data;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace diffdyn;
  const bool quick = argc > 1 && std::strcmp(argv[1], "--quick") == 0;
  const Eigen::Vector2d truth(9.81, 0.02), initial(7.0, 0.0);
  Rng rng(1);
  const std::vector<Trajectory> data = Measure(truth, quick ? 2 : 4, quick ? 3.0 : 6.0, rng);

  TrajectoryFitOptions options;
  options.ode.method = Method::kDopri5;
  options.ode.abs_tol = options.ode.rel_tol = 1e-9;
  const TrajectoryFitResult fit = FitTrajectoryParameters<2>(DampedPendulum{}, data, initial, options);

  fmt::print("{} swings, {} residuals: RMS {:.4g} -> {:.4g} in {} iterations\n", data.size(), fit.num_residuals,
             fit.initial_rms, fit.final_rms, fit.iterations);
  const char* names[2] = {"gravity g (m/s^2)", "damping b (N m s/rad)"};
  bool ok = true;
  for (int i = 0; i < 2; ++i) {
    const double z = std::abs(fit.params[i] - truth[i]) / fit.standard_errors[i];
    fmt::print("{:>22}: truth {:.4g}, initial {:.4g}, fitted {:.5g} +- {:.2g} ({:.2f} standard errors off)\n",
               names[i], truth[i], initial[i], fit.params[i], fit.standard_errors[i], z);
    ok = ok && z < 4.0;
  }
  if (!ok) {
    fmt::print(stderr, "error: a fitted parameter lies more than 4 standard errors from the truth\n");
    return 1;
  }
  return 0;
}
