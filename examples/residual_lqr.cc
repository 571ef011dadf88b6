// Solving a first-order PDE by residual minimisation, checked against its known solution.
//
// The discounted Hamilton-Jacobi-Bellman equation of a linear system dx/dt = A x + B u with
// running cost x^T Q x + u^T R u and discount rho is
//
//   F(x, V, p) = rho V - x^T Q x - p^T A x + (1/4) p^T B R^-1 B^T p = 0,   p = dV/dx,
//
// and V = x^T P x solves it, P the Riccati solution for (A - rho/2 I, B, Q, R). A deep
// differential network V(x) (2-64-64-1, softplus) gives V and p in one pass; SolveResidual
// minimises mean F^2 over states sampled in [-1, 1]^2 with Adam, in two stages (the second
// at a tenth of the step). The system is the damped oscillator x1' = x2,
// x2' = -x1 - 0.2 x2 + u with Q = I, R = 1, rho = 1.
//
// Usage: example_residual_lqr [--quick]   (exit 1 if V misses x^T P x by more than the
// tolerance: 1 % root-mean-square relative, 3 % in the quick mode)
#include <cmath>
#include <cstring>

#include <fmt/core.h>

#include "diffdyn/models/init.h"
#include "diffdyn/models/random.h"
#include "diffdyn/solvers/residual_solver.h"

namespace {

Eigen::MatrixXd UniformStates(int count, std::uint64_t seed) {
  diffdyn::Rng rng(seed);
  Eigen::MatrixXd x(2, count);
  for (Eigen::Index i = 0; i < x.size(); ++i) x.data()[i] = 2.0 * diffdyn::UniformUnit(rng) - 1.0;
  return x;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace diffdyn;
  const bool quick = argc > 1 && std::strcmp(argv[1], "--quick") == 0;
  Eigen::MatrixXd a(2, 2), b(2, 1);
  a << 0, 1, -1, -0.2;
  b << 0, 1;
  const LinearQuadraticHjb equation(a, b, Eigen::MatrixXd::Identity(2, 2), Eigen::MatrixXd::Identity(1, 1), 1.0);

  // The value network and the sampled states.
  const int width = quick ? 32 : 64;
  ValueFunction value = ValueFunction::Direct(
      MakeInitializedMlp({{2, width, width, 1}, {Activation::Softplus(), Activation::Softplus()}}, InitOptions::Ddn(),
                         1),
      2);
  const Eigen::MatrixXd states = UniformStates(quick ? 2000 : 10000, 2);
  TrainOptions options;
  options.batch_size = 128;
  options.val_fraction = 0.1;
  options.seed = 3;
  options.progress = false;

  // Two stages of Adam: 1e-3, then 1e-4.
  const int epochs = quick ? 400 : 1500;
  for (const double lr : {1e-3, 1e-4}) {
    options.learning_rate = lr;
    options.epochs = lr > 5e-4 ? epochs : epochs / 2;
    const TrainResult r = SolveResidual(equation, states, options, &value);
    fmt::print("stage lr {:.0e}: {} epochs, mean F^2 {:.3e} -> {:.3e} (held out), {:.1f} ms per epoch\n", lr,
               r.epochs.size(), r.epochs.front().val_loss, r.final_val_loss, 1e3 * r.seconds_per_epoch);
  }

  // Compare with the known solution on fresh states.
  const Eigen::MatrixXd p = equation.SolutionMatrix();
  const Eigen::MatrixXd x = UniformStates(1000, 4);
  Eigen::VectorXd v;
  Eigen::MatrixXd grad;
  value.Evaluate(x, &v, &grad);
  const Eigen::VectorXd truth = (x.cwiseProduct(p * x)).colwise().sum().transpose();
  const double v_error = (v - truth).norm() / truth.norm();
  const double p_error = (grad - 2.0 * p * x).norm() / (2.0 * p * x).norm();
  fmt::print("P = [{:.4f} {:.4f}; {:.4f} {:.4f}] (Riccati)\n", p(0, 0), p(0, 1), p(1, 0), p(1, 1));
  fmt::print("relative RMS error over 1000 fresh states: V {:.2f} %, dV/dx {:.2f} %\n", 100 * v_error,
             100 * p_error);
  const double tolerance = quick ? 0.03 : 0.01;
  if (!(v_error < tolerance)) {
    fmt::print(stderr, "error: V misses x^T P x by {:.2f} % (tolerance {:.0f} %)\n", 100 * v_error,
               100 * tolerance);
    return 1;
  }
  return 0;
}
