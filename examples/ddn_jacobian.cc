// A deep differential network (DDN) gives a value and its exact input Jacobian
// in one forward pass, so it can be trained on derivative data too.
//
// Fits f(x, y) = cos x sin y and its Jacobian with a 2-32-32-1 softplus Mlp,
// then compares the closed-form Jacobian with Jets and with the truth.
//
//   example_ddn_jacobian [--quick]
#include <cmath>
#include <cstdio>
#include <cstring>

#include <ceres/jet.h>

#include "diffdyn/models/adam.h"
#include "diffdyn/models/init.h"
#include "diffdyn/models/losses.h"
#include "diffdyn/models/mlp.h"

using namespace diffdyn;

int main(int argc, char** argv) {
  const bool quick = argc > 1 && std::strcmp(argv[1], "--quick") == 0;
  const int steps = quick ? 1500 : 6000;

  // Data: 512 points, f and its Jacobian J = [-sin x sin y, cos x cos y].
  const int n = 512;
  Rng rng(42);
  Eigen::MatrixXd x(2, n), f(1, n), jac(1, 2 * n);
  for (int i = 0; i < n; ++i) {
    x(0, i) = Uniform(rng, -M_PI, M_PI);
    x(1, i) = Uniform(rng, -M_PI, M_PI);
    f(0, i) = std::cos(x(0, i)) * std::sin(x(1, i));
    jac(0, 2 * i) = -std::sin(x(0, i)) * std::sin(x(1, i));
    jac(0, 2 * i + 1) = std::cos(x(0, i)) * std::cos(x(1, i));
  }

  // Network, optimiser and the per-thread workspace (sized once).
  const MlpArchitecture arch{{2, 32, 32, 1}, {Activation::Softplus(), Activation::Softplus()}};
  Mlp<double> net = MakeInitializedMlp(arch, InitOptions::Ddn(), 1);
  Adam adam(net.num_parameters(), {.learning_rate = 1e-2, .amsgrad = true});
  MlpWorkspace ws(arch, n);
  Eigen::MatrixXd pred, pred_jac, gy, gj;
  Eigen::VectorXd grad;

  // Full-batch training on L = mean ||f - y||^2 + ||J - dy||^2.
  double first = 0.0, last = 0.0;
  for (int step = 0; step < steps; ++step) {
    net.Forward(x, &pred, &pred_jac, &ws);
    last = SquaredErrorLoss(pred, f, n, &gy) + SquaredErrorLoss(pred_jac, jac, n, &gj);
    if (step == 0) first = last;
    net.Backward(gy, gj, &grad, nullptr, &ws);
    adam.Step(grad, &net.mutable_parameters());
  }
  std::printf("loss %.3e -> %.3e after %d steps\n", first, last, steps);

  // Closed-form Jacobian vs Jets vs truth at one point.
  const Eigen::Vector2d p(0.3, -1.1);
  Eigen::VectorXd y;
  Eigen::MatrixXd j;
  net.ValueAndJacobian(p, &y, &j);
  using Jet2 = ceres::Jet<double, 2>;
  const auto yj = net(Eigen::Matrix<Jet2, 2, 1>(Jet2(p[0], 0), Jet2(p[1], 1)));
  const double jet_gap = std::max(std::abs(j(0, 0) - yj[0].v[0]), std::abs(j(0, 1) - yj[0].v[1]));
  std::printf("f  = %+.4f  (true %+.4f)\n", y[0], std::cos(p[0]) * std::sin(p[1]));
  std::printf("J  = [%+.4f %+.4f]  (true [%+.4f %+.4f])\n", j(0, 0), j(0, 1),
              -std::sin(p[0]) * std::sin(p[1]), std::cos(p[0]) * std::cos(p[1]));
  std::printf("|closed form - Jets| = %.1e\n", jet_gap);

  const bool ok = jet_gap < 1e-12 && last < 0.5 * first;
  std::printf("%s\n", ok ? "ok" : "FAILED");
  return ok ? 0 : 1;
}
