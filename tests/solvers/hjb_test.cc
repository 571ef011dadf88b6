// The task HJB: the action cost's conjugate against a brute-force maximum, the
// control-affine split against the plant's dynamics, F_p against central differences,
// and the policy inside the bounds.
#include "diffdyn/solvers/hjb.h"

#include <cmath>

#include <gtest/gtest.h>

#include "diffdyn/autodiff_ode/random.h"

namespace diffdyn {
namespace {

// max_u [w u - g(u)] over a grid of the open interval (-u_max, u_max), and its argmax.
std::pair<double, double> BruteConjugate(const ActionCost& g, double w, double u_max) {
  double best = -1e300, arg = 0.0;
  const int steps = 200000;
  for (int k = 1; k < steps; ++k) {
    const double u = -u_max + 2.0 * u_max * k / steps;
    const double value = w * u - g(VectorOf({u}));
    if (value > best) best = value, arg = u;
  }
  return {best, arg};
}

TEST(ActionCost, ConjugateIsTheMaximumOverActions) {
  const ControlTask pendulum = ControlTaskByName("pendulum");
  const ControlTask cartpole = ControlTaskByName("cartpole");
  for (const double w : {-30.0, -4.0, -0.3, 0.0, 0.7, 5.0, 40.0}) {
    const ActionCost& logcos = pendulum.action_cost;
    const auto [value, arg] = BruteConjugate(logcos, w, logcos.u_max);
    EXPECT_NEAR(logcos.Conjugate(VectorOf({w})), value, 1e-6 * (1 + std::abs(value))) << w;
    EXPECT_NEAR(logcos.ConjugateGradient(VectorOf({w}))[0], arg, 1e-4) << w;
    EXPECT_LT(std::abs(logcos.ConjugateGradient(VectorOf({w}))[0]), logcos.u_max);
    // The quadratic cost over a range wide enough to hold its maximiser w / (2 r).
    const ActionCost& quadratic = cartpole.action_cost;
    const auto [qvalue, qarg] = BruteConjugate(quadratic, w, 3000.0);
    EXPECT_NEAR(quadratic.Conjugate(VectorOf({w})), qvalue, 1e-3 * (1 + std::abs(qvalue))) << w;
    EXPECT_NEAR(quadratic.ConjugateGradient(VectorOf({w}))[0], qarg, 0.05) << w;
  }
}

TEST(TaskHjb, AffineSplitReproducesThePlant) {
  for (const char* name : {"pendulum", "cartpole"}) {
    const ControlTask task = ControlTaskByName(name);
    const TaskHjb hjb(task, 1.0);
    const auto model = task.plant.Model();
    Rng rng(2);
    const Eigen::VectorXd x = task.SampleStart(rng) + 0.2 * Eigen::VectorXd::Ones(task.state_size());
    Eigen::VectorXd a;
    Eigen::MatrixXd b;
    hjb.Affine(x, &a, &b);
    for (const double u : {-1.5, 0.0, 2.0}) {
      const VectorX<DiagJet> f = model->Dynamics(ParseParams(*model, task.plant.params), TaskActuatedJoints(task),
                                                 TaskDamping(task), x.cast<DiagJet>(),
                                                 VectorX<DiagJet>::Constant(1, DiagJet(u)));
      for (int i = 0; i < task.state_size(); ++i) EXPECT_NEAR(f[i].a, a[i] + b(i, 0) * u, 1e-12) << name;
    }
  }
}

TEST(TaskHjb, PartialsMatchCentralDifferences) {
  const ControlTask task = ControlTaskByName("pendulum");
  const TaskHjb hjb(task, 0.7);
  Eigen::MatrixXd x(2, 3), p(2, 3);
  x << 0.3, 2.0, 4.0, -1.0, 0.5, 3.0;
  p << 1.0, -2.0, 0.1, 0.4, 3.0, -6.0;
  const Eigen::VectorXd v = VectorOf({0.5, 2.0, -1.0});
  Eigen::VectorXd f, f_v;
  Eigen::MatrixXd f_p;
  hjb.Evaluate(x, v, p, &f, &f_v, &f_p);
  const double h = 1e-6;
  for (int i = 0; i < 2; ++i) {
    Eigen::MatrixXd up = p, down = p;
    up.row(i).array() += h;
    down.row(i).array() -= h;
    Eigen::VectorXd fu, fd, dummy_v;
    Eigen::MatrixXd dummy_p;
    hjb.Evaluate(x, v, up, &fu, &dummy_v, &dummy_p);
    hjb.Evaluate(x, v, down, &fd, &dummy_v, &dummy_p);
    EXPECT_LT(((fu - fd) / (2 * h) - f_p.row(i).transpose()).cwiseAbs().maxCoeff(), 1e-6);
  }
  EXPECT_EQ(f_v, Eigen::VectorXd::Constant(3, 0.7));
  // The policy stays inside the bounds however steep V is.
  EXPECT_LT(std::abs(hjb.Policy(x.col(0), 1e6 * p.col(0))[0]), task.action_cost.u_max);
  EXPECT_THROW(TaskHjb(task, 0.0), Error);
}

}  // namespace
}  // namespace diffdyn
