// Your own system, integrated on Jets: a trajectory and its exact sensitivities in one pass.
//
// A mass on a nonlinear spring with drag, pushed by a force u:
//
//   x = [p, v],   dp/dt = v,   dv/dt = (u - k p - k3 p^3 - c v |v|) / mass,   theta = [k, k3, c]
//
// written once as a template on the scalar T. On double it simulates; on
// ceres::Jet<double, 6> seeded on (p0, v0, u, k, k3, c) the same solver also carries
//
//   S = dx(t)/d(x0, u, theta)   (2 x 6),
//
// the solution of the variational equations, exact for the discrete solver map.
// The example checks S against central differences of the double simulation.
//
// Usage: example_own_system_sensitivities [--quick]   (exit 1 if they disagree)
#include <cmath>
#include <cstring>
#include <vector>

#include <fmt/core.h>

#include "diffdyn/autodiff_ode/sensitivity.h"

namespace {

// The system: any scalar T (double or Jet) goes through the same arithmetic.
struct SpringWithDrag {
  double mass = 0.5;
  template <typename T>
  void operator()(const diffdyn::VectorX<T>& x, const diffdyn::VectorX<T>& u, const diffdyn::VectorX<T>& theta,
                  double /*t*/, diffdyn::VectorX<T>& dxdt) const {
    using std::abs;
    const T& p = x[0];
    const T& v = x[1];
    dxdt.resize(2);
    dxdt[0] = v;
    dxdt[1] = (u[0] - theta[0] * p - theta[1] * p * p * p - theta[2] * v * abs(v)) / mass;
  }
};

}  // namespace

int main(int argc, char** argv) {
  using namespace diffdyn;
  const bool quick = argc > 1 && std::strcmp(argv[1], "--quick") == 0;
  const SpringWithDrag system;
  const Eigen::VectorXd x0 = (Eigen::VectorXd(2) << 0.3, -0.1).finished();
  const Eigen::VectorXd u = Eigen::VectorXd::Constant(1, 0.4);
  const Eigen::VectorXd theta = (Eigen::VectorXd(3) << 2.0, 5.0, 0.3).finished();
  OdeOptions options;
  options.method = Method::kRk4Classic;
  options.dt = quick ? 1e-2 : 1e-3;
  const double t1 = 2.0;

  // One Jet integration: x(t1) and all three sensitivity blocks.
  const Sensitivities s = ForwardSensitivities<6>(system, x0, u, theta, 0.0, t1, options);
  Eigen::MatrixXd jets(2, 6);
  jets << s.dx_dx0, s.dx_du, s.dx_dtheta;

  // Central differences of the double simulation, one input at a time.
  auto simulate = [&](const Eigen::VectorXd& z) {
    const Eigen::VectorXd x_start = z.head(2), u_in = z.segment(2, 1), th = z.tail(3);
    return Simulate<double>(system, x_start, u_in, th, {0.0, t1}, options).back();
  };
  Eigen::VectorXd z(6);
  z << x0, u, theta;
  Eigen::MatrixXd central(2, 6);
  const double h = 1e-6;
  for (int j = 0; j < 6; ++j) {
    Eigen::VectorXd plus = z, minus = z;
    plus[j] += h;
    minus[j] -= h;
    central.col(j) = (simulate(plus) - simulate(minus)) / (2 * h);
  }

  const char* names[6] = {"p0", "v0", "u", "k", "k3", "c"};
  fmt::print("x(t1 = {} s) = [{:.6f}, {:.6f}]\n", t1, s.x[0], s.x[1]);
  fmt::print("{:>4} {:>14} {:>14} {:>14} {:>14}\n", "d/d", "dp Jets", "dp central", "dv Jets", "dv central");
  for (int j = 0; j < 6; ++j) {
    fmt::print("{:>4} {:14.8f} {:14.8f} {:14.8f} {:14.8f}\n", names[j], jets(0, j), central(0, j), jets(1, j),
               central(1, j));
  }
  const double error = (jets - central).cwiseAbs().maxCoeff() / std::max(1.0, jets.cwiseAbs().maxCoeff());
  fmt::print("largest difference, relative to the largest entry: {:.2e}\n", error);
  if (!(error < 1e-6)) {
    fmt::print(stderr, "error: Jet sensitivities and central differences differ by {:.2e}\n", error);
    return 1;
  }
  return 0;
}
