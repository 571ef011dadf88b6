// Multiple shooting: the step Jacobians against finite differences and against the
// exponential of the linearisation, and solutions on a short pendulum run that are
// continuous, replay exactly on the evaluator and do not lose to the clipped LQR.
#include "diffdyn/solvers/multiple_shooting.h"

#include <cmath>
#include <numbers>

#include <gtest/gtest.h>

#include "diffdyn/solvers/lqr.h"

namespace diffdyn {
namespace {

// One warm start (both directions) keeps the tests short.
MultipleShootingOptions QuickOptions() {
  MultipleShootingOptions o;
  o.warm_starts = {{1.0, 0.5}};
  return o;
}

// The pendulum task shortened to `seconds`, every start at x0.
ControlTask PinnedPendulum(double seconds, const Eigen::VectorXd& x0) {
  ControlTask task = ControlTaskByName("pendulum");
  task.duration = seconds;
  task.start_low = task.start_high = x0;
  return task;
}

TEST(TaskStep, JacobiansMatchCentralDifferences) {
  for (const char* name : {"pendulum", "cartpole"}) {
    const ControlTask task = ControlTaskByName(name);
    const TaskStep step(task);
    Rng rng(3);
    const Eigen::VectorXd x =
        task.SampleStart(rng) + 0.3 * Eigen::VectorXd::Ones(task.state_size());
    const Eigen::VectorXd u = 0.4 * task.plant.bound;
    Eigen::MatrixXd fx, fu;
    const Eigen::VectorXd next = step.Jacobians(x, u, &fx, &fu);
    EXPECT_LT((next - step.Value(x, u)).cwiseAbs().maxCoeff(), 1e-14) << name;
    const double h = 1e-6;
    for (int i = 0; i < x.size(); ++i) {
      const Eigen::VectorXd e = h * Eigen::VectorXd::Unit(x.size(), i);
      const Eigen::VectorXd fd = (step.Value(x + e, u) - step.Value(x - e, u)) / (2 * h);
      EXPECT_LT((fd - fx.col(i)).cwiseAbs().maxCoeff(), 1e-8) << name << " x" << i;
    }
    const Eigen::VectorXd e = h * Eigen::VectorXd::Unit(u.size(), 0);
    const Eigen::VectorXd fd = (step.Value(x, u + e) - step.Value(x, u - e)) / (2 * h);
    EXPECT_LT((fd - fu.col(0)).cwiseAbs().maxCoeff(), 1e-8) << name << " u";
  }
}

// At the goal (an equilibrium) the step's Jacobian is exp([[A, B], [0, 0]] period) up to
// RK4's truncation error, A and B the continuous linearisation (LQR's Jets).
TEST(TaskStep, JacobiansAtTheGoalAreTheExponentialOfTheLinearisation) {
  for (const char* name : {"pendulum", "cartpole"}) {
    const ControlTask task = ControlTaskByName(name);
    const LqrSolution lqr = TaskLqr(task);
    const int n = task.state_size(), m = task.action_size();
    Eigen::MatrixXd g = Eigen::MatrixXd::Zero(n + m, n + m);
    g.topLeftCorner(n, n) = lqr.A * task.period;
    g.topRightCorner(n, m) = lqr.B * task.period;
    Eigen::MatrixXd exp = Eigen::MatrixXd::Identity(n + m, n + m), term = exp;
    for (int k = 1; k < 30; ++k) {
      term = term * g / k;
      exp += term;
    }
    Eigen::MatrixXd fx, fu;
    TaskStep(task).Jacobians(task.goal, Eigen::VectorXd::Zero(m), &fx, &fu);
    EXPECT_LT((fx - exp.topLeftCorner(n, n)).cwiseAbs().maxCoeff(), 1e-9) << name;
    EXPECT_LT((fu - exp.topRightCorner(n, m)).cwiseAbs().maxCoeff(), 1e-9) << name;
  }
}

TEST(MultipleShooting, SwingsUpContinuouslyAndReplaysOnTheEvaluator) {
  const Eigen::VectorXd x0 = VectorOf({std::numbers::pi - 1.2, 0.0});
  const ControlTask task = PinnedPendulum(2.0, x0);
  const MultipleShootingSolution s = SolveMultipleShooting(task, x0, QuickOptions());
  EXPECT_TRUE(task.Succeeded(s.states.col(s.states.cols() - 1)));
  EXPECT_LT(s.defect, 1e-9);
  EXPECT_LE(s.actions.cwiseAbs().maxCoeff(), task.plant.bound[0]);

  // The evaluator replays the actions open loop: same states, same cost.
  MultipleShootingController controller(task, QuickOptions());
  const std::vector<ControlRun> runs =
      EvaluateController(task, controller, {.starts = 1, .seed = 0});
  EXPECT_TRUE(runs[0].success);
  EXPECT_NEAR(runs[0].cost, s.cost, 1e-9 * s.cost);
  EXPECT_LT((runs[0].trajectory.states - s.states).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_EQ(controller.totals().solves, 1);
}

// A per-start optimum cannot lose to a feasible controller from the same start.
TEST(MultipleShooting, DoesNotLoseToTheClippedLqr) {
  const Eigen::VectorXd x0 = VectorOf({std::numbers::pi + 0.35, 0.0});
  const ControlTask task = PinnedPendulum(1.5, x0);
  LqrController lqr(task, TaskLqr(task));
  const ControlRun lqr_run = EvaluateController(task, lqr, {.starts = 1, .seed = 0})[0];
  ASSERT_TRUE(lqr_run.success);
  const MultipleShootingSolution s = SolveMultipleShooting(task, x0, QuickOptions());
  EXPECT_LE(s.cost, lqr_run.cost + 1e-9);
}

TEST(MultipleShooting, RefusesBadOptionsAndStarts) {
  const ControlTask task = ControlTaskByName("pendulum");
  MultipleShootingOptions o;
  o.warm_starts = {};
  EXPECT_THROW(SolveMultipleShooting(task, task.goal, o), Error);
  o = MultipleShootingOptions{};
  o.warm_starts = {{-1.0, 0.5}};
  EXPECT_THROW(MultipleShootingController(task, o), Error);
  o = MultipleShootingOptions{};
  o.max_iterations = 0;
  EXPECT_THROW(SolveMultipleShooting(task, task.goal, o), Error);
  EXPECT_THROW(SolveMultipleShooting(task, VectorOf({1.0}), MultipleShootingOptions{}), Error);
  EXPECT_THROW(
      SolveMultipleShooting(task, VectorOf({1.0, std::nan("")}), MultipleShootingOptions{}), Error);
}

// Starts on two threads give the runs of one thread, in start order.
TEST(EvaluateController, RunsDoNotDependOnTheThreadCount) {
  const ControlTask task = ControlTaskByName("pendulum");
  LqrController lqr(task, TaskLqr(task));
  const auto one = EvaluateController(task, lqr, {.starts = 6, .seed = 4, .threads = 1});
  const auto two = EvaluateController(task, lqr, {.starts = 6, .seed = 4, .threads = 2});
  ASSERT_EQ(one.size(), two.size());
  for (std::size_t s = 0; s < one.size(); ++s) {
    EXPECT_EQ(one[s].x0, two[s].x0);
    EXPECT_EQ(one[s].cost, two[s].cost);
    EXPECT_EQ(one[s].trajectory.states, two[s].trajectory.states);
  }
}

}  // namespace
}  // namespace diffdyn
