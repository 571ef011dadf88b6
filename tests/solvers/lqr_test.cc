// LQR: Riccati solutions with known closed forms, the task linearisation by Jets
// against finite differences of the plant, and the clipped regulator near the goal.
#include "diffdyn/solvers/lqr.h"

#include <cmath>

#include <Eigen/Eigenvalues>
#include <gtest/gtest.h>

namespace diffdyn {
namespace {

Eigen::MatrixXd M(std::initializer_list<std::initializer_list<double>> rows) {
  Eigen::MatrixXd m(rows.size(), rows.begin()->size());
  int i = 0;
  for (const auto& r : rows) {
    int j = 0;
    for (double v : r) m(i, j++) = v;
    ++i;
  }
  return m;
}

// Scalar: 2 a p - p^2 b^2 / r + q = 0, p = r (a + sqrt(a^2 + b^2 q / r)) / b^2.
TEST(Lqr, ScalarRiccatiHasItsClosedForm) {
  for (double a : {-1.0, 0.0, 2.5}) {
    const double b = 0.7, q = 3.0, r = 0.4;
    const LqrSolution s = SolveLqr(M({{a}}), M({{b}}), M({{q}}), M({{r}}));
    const double p = r * (a + std::sqrt(a * a + b * b * q / r)) / (b * b);
    EXPECT_NEAR(s.P(0, 0), p, 1e-12 * p) << a;
    EXPECT_NEAR(s.K(0, 0), b * p / r, 1e-12 * p) << a;
    EXPECT_LT(s.riccati_residual, 1e-14);
  }
}

// Double integrator, Q = I, R = 1: P = [[sqrt 3, 1], [1, sqrt 3]], K = [1, sqrt 3].
TEST(Lqr, DoubleIntegratorHasItsClosedForm) {
  const LqrSolution s = SolveLqr(M({{0, 1}, {0, 0}}), M({{0}, {1}}), Eigen::MatrixXd::Identity(2, 2), M({{1}}));
  const double r3 = std::sqrt(3.0);
  EXPECT_LT((s.P - M({{r3, 1}, {1, r3}})).norm(), 1e-12);
  EXPECT_LT((s.K - M({{1, r3}})).norm(), 1e-12);
  EXPECT_LT(s.riccati_residual, 1e-14);
}

TEST(Lqr, RefusesUnstabilisableSystems) {
  // x1' = x1 (unstable, not actuated), x2' = u.
  EXPECT_THROW(SolveLqr(M({{1, 0}, {0, 0}}), M({{0}, {1}}), Eigen::MatrixXd::Identity(2, 2), M({{1}})),
               NumericalError);
  EXPECT_THROW(SolveLqr(M({{1}}), M({{1}}), M({{1}}), M({{-1}})), Error);
}

// A, B by Jets against central differences of the plant's continuous dynamics
// (one tiny rk4 step of the task model approximates x + h f(x, u)).
TEST(Lqr, TaskLinearisationMatchesFiniteDifferences) {
  for (const std::string name : {"pendulum", "cartpole"}) {
    const ControlTask task = ControlTaskByName(name);
    const LqrSolution s = TaskLqr(task);
    const double h = 1e-6, eps = 1e-5;
    const auto plant = TaskModel(task, h, 1);
    auto ws = plant->MakeWorkspace(1);
    const int n = task.state_size(), m = task.action_size();
    const auto f = [&](const Eigen::VectorXd& x, const Eigen::VectorXd& u) {
      Eigen::MatrixXd next(n, 1);
      plant->PredictBatch(x, u, next, *ws);
      return Eigen::VectorXd((next.col(0) - x) / h);
    };
    const Eigen::VectorXd u0 = Eigen::VectorXd::Zero(m);
    for (int i = 0; i < n + m; ++i) {
      Eigen::VectorXd xp = task.goal, xm = task.goal, up = u0, um = u0;
      (i < n ? xp[i] : up[i - n]) += eps;
      (i < n ? xm[i] : um[i - n]) -= eps;
      const Eigen::VectorXd fd = (f(xp, up) - f(xm, um)) / (2 * eps);
      const Eigen::VectorXd jet = i < n ? Eigen::VectorXd(s.A.col(i)) : Eigen::VectorXd(s.B.col(i - n));
      EXPECT_LT((fd - jet).norm(), 1e-4 * (1.0 + jet.norm())) << name << " input " << i;
    }
    // The closed loop is stable and the residual is far below 1e-9.
    const Eigen::VectorXcd poles = (s.A - s.B * s.K).eigenvalues();
    for (Eigen::Index k = 0; k < poles.size(); ++k) EXPECT_LT(poles[k].real(), 0.0) << name;
    EXPECT_LT(s.riccati_residual, 1e-12) << name;
  }
}

// The pendulum's upright: 3 g / (2 l) for the uniform rod of the HJB paper (m = l = 1).
TEST(Lqr, PendulumLinearisationIsTheUprightRod) {
  const LqrSolution s = TaskLqr(ControlTaskByName("pendulum"));
  EXPECT_NEAR(s.A(0, 1), 1.0, 1e-12);
  EXPECT_NEAR(s.A(1, 0), 1.5 * 9.81, 1e-9);
  EXPECT_NEAR(s.B(1, 0), 3.0, 1e-9);
}

TEST(Lqr, ClippedRegulatorCatchesStartsNearTheGoal) {
  const ControlTask task = ControlTaskByName("pendulum");
  LqrController lqr(task, TaskLqr(task));
  ControlTask near = task;
  near.start_low = task.goal.array() - 0.3;
  near.start_high = task.goal.array() + 0.3;
  const std::vector<ControlRun> runs = EvaluateController(near, lqr, {.starts = 10, .seed = 3});
  for (const ControlRun& r : runs) EXPECT_TRUE(r.success) << r.x0.transpose();
}

}  // namespace
}  // namespace diffdyn
