// The control evaluator and MPPI on control tasks: the evaluator's cost is the
// task's integral, the plant conserves the undamped pendulum's energy, actions are
// held and clipped, runs are deterministic at any thread count, refusals name the
// option, and MPPI over the analytic pendulum swings it up. A counting task checks
// the evaluator's own rules on any Task: a step that reports done ends the run with
// its outcome, else Finish names it, costs add up, the trajectory holds the steps run.
#include "diffdyn/solvers/control.h"

#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include <gtest/gtest.h>

namespace diffdyn {
namespace {

// x_{k+1} = x_k + u_k on one state; the run ends "success" on reaching `target`
// (a step reports done), else Finish says "short"; cost per step = |u|.
class CountingTask final : public Task {
 public:
  explicit CountingTask(double target) : target_(target) {}
  int state_size() const override { return 1; }
  int action_size() const override { return 1; }
  double step_period() const override { return 0.5; }
  int max_steps() const override { return 6; }
  Eigen::VectorXd Clip(const Eigen::Ref<const Eigen::VectorXd>& u) const override {
    return u.cwiseMin(1.0).cwiseMax(-1.0);
  }
  std::vector<TaskStart> Starts(int count, std::uint64_t seed) const override {
    std::vector<TaskStart> starts;
    for (int s = 0; s < count; ++s) starts.push_back({Eigen::VectorXd::Constant(1, s), seed + s});
    return starts;
  }
  std::unique_ptr<TaskRun> Begin() const override { return std::make_unique<Run>(target_); }

 private:
  class Run final : public TaskRun {
   public:
    explicit Run(double target) : target_(target) {}
    Eigen::VectorXd Reset(const Eigen::VectorXd& x0) override { return x_ = x0; }
    StepOutcome Step(const Eigen::VectorXd& u, Eigen::VectorXd* x) override {
      x_ += u;
      *x = x_;
      const bool reached = x_[0] >= target_;
      return {std::abs(u[0]), reached, reached ? "success" : ""};
    }
    std::string Finish() override { return "short"; }

   private:
    double target_;
    Eigen::VectorXd x_;
  };
  double target_;
};

// Returns a constant action, counts its calls.
class ConstantController final : public Controller {
 public:
  ConstantController(double u, int hold) : u_(u), hold_(hold) {}
  int hold() const override { return hold_; }
  void Reset(const Eigen::VectorXd&, std::uint64_t) override { calls = 0; }
  Eigen::VectorXd Command(const Eigen::VectorXd&) override {
    ++calls;
    return Eigen::VectorXd::Constant(1, u_);
  }
  int calls = 0;

 private:
  double u_;
  int hold_;
};

// Total energy of the task pendulum (m 0.75, l 2/3, q = 0 hanging).
double Energy(const Eigen::VectorXd& x) {
  const double m = 0.75, l = 2.0 / 3.0, g = 9.81;
  return 0.5 * m * l * l * x[1] * x[1] - m * g * l * std::cos(x[0]);
}

TEST(EvaluateController, CostIsTheTaskIntegralAndThePlantConservesEnergy) {
  const ControlTask task = ControlTaskByName("pendulum");
  ConstantController zero(0.0, 5);
  const std::vector<ControlRun> runs = EvaluateController(task, zero, {.starts = 3, .seed = 2});
  ASSERT_EQ(runs.size(), 3u);
  for (const ControlRun& r : runs) {
    const Trajectory& tr = r.trajectory;
    ASSERT_EQ(tr.states.cols(), 626);
    EXPECT_EQ(zero.calls, 125);
    double cost = 0.0;
    for (int k = 0; k < 625; ++k) cost += task.RunningCost(tr.states.col(k), tr.actions.col(k)) / 125.0;
    EXPECT_NEAR(r.cost, cost, 1e-12 * cost);
    // Free swing: rk4 at 2 ms keeps the energy to ~1e-9 relative over 5 s.
    const double e0 = Energy(r.x0);
    for (int k = 0; k <= 625; k += 25) EXPECT_NEAR(Energy(tr.states.col(k)), e0, 1e-7 * std::abs(e0));
    EXPECT_FALSE(r.success);
    EXPECT_EQ(r.max_abs_u, 0.0);
  }
}

TEST(EvaluateController, ActionsAreClippedAndStartsSeeded) {
  const ControlTask task = ControlTaskByName("pendulum");
  ConstantController big(7.0, 1);
  const auto a = EvaluateController(task, big, {.starts = 2, .seed = 4});
  const auto b = EvaluateController(task, big, {.starts = 2, .seed = 4});
  const auto c = EvaluateController(task, big, {.starts = 2, .seed = 5});
  EXPECT_EQ(big.calls, 625);
  EXPECT_EQ(a[0].max_abs_u, 2.5);
  EXPECT_EQ(a[1].x0, b[1].x0);
  EXPECT_EQ(a[1].cost, b[1].cost);
  EXPECT_NE(a[1].x0, c[1].x0);
  EXPECT_THROW(EvaluateController(task, big, {.starts = 0}), Error);
}

// dt * (q(x_{t+1}) + g(u_t)), a penalty outside the limits, q(x_T) weighed at the last step.
TEST(TaskMppiCost, IsTheTaskCostPerStepWithATerminalTerm) {
  const ControlTask task = ControlTaskByName("cartpole");
  const TaskMppiCost cost(task, 0.04, 1000.0, /*horizon=*/25, /*terminal_seconds=*/2.0);
  Eigen::MatrixXd x(4, 2), u(1, 2);
  x.col(0) << 0.1, 0.5, 1.0, -1.0;
  x.col(1) << 0.7, 0.0, 0.0, 0.0;  // off the track
  u << 3.0, -1.0;
  Eigen::VectorXd first = Eigen::VectorXd::Zero(2), last = Eigen::VectorXd::Zero(2);
  cost.AccumulateStep(0, x, u, x, first);
  cost.AccumulateStep(24, x, u, x, last);
  EXPECT_NEAR(first[0], 0.04 * task.RunningCost(x.col(0), u.col(0)), 1e-12);
  EXPECT_NEAR(first[1], 0.04 * task.RunningCost(x.col(1), u.col(1)) + 1000.0, 1e-9);
  EXPECT_NEAR(last[0] - first[0], 2.0 * task.StateCost(x.col(0)), 1e-12);
}

TEST(MppiController, RefusesModelsThatDoNotFitTheTask) {
  const ControlTask pendulum = ControlTaskByName("pendulum");
  const ControlTask cartpole = ControlTaskByName("cartpole");
  const auto off_grid = TaskModel(pendulum, 0.01, 1);  // not a multiple of 8 ms
  try {
    MppiController mppi(pendulum, *off_grid, {});
    FAIL() << "a 10-ms model was accepted for an 8-ms control period";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("whole multiple"), std::string::npos) << e.what();
  }
  const auto other = TaskModel(cartpole, 0.04, 1);
  EXPECT_THROW(MppiController(pendulum, *other, {}), Error);
  const auto model = TaskModel(pendulum, 0.04, 1);
  EXPECT_THROW(MppiController(pendulum, *model, {.samples = 0}), Error);
  EXPECT_THROW(MppiController(pendulum, *model, {.horizon_seconds = -1}), Error);
  EXPECT_EQ(MppiController(pendulum, *model, {}).hold(), 5);
}

TEST(MppiController, SwingsThePendulumUpTheSameWayOnAnyThreadCount) {
  const ControlTask task = ControlTaskByName("pendulum");
  const auto model = TaskModel(task, 0.04, 1);
  MppiController one(task, *model, {.samples = 500, .threads = 1});
  MppiController two(task, *model, {.samples = 500, .threads = 2});
  const auto a = EvaluateController(task, one, {.starts = 2, .seed = 1});
  const auto b = EvaluateController(task, two, {.starts = 2, .seed = 1});
  int successes = 0;
  for (int s = 0; s < 2; ++s) {
    EXPECT_EQ(a[s].cost, b[s].cost) << "start " << s;
    EXPECT_LE(a[s].max_abs_u, 2.5);
    successes += a[s].success ? 1 : 0;
  }
  EXPECT_EQ(successes, 2) << "costs " << a[0].cost << ", " << a[1].cost;
}

TEST(EvaluateController, AnyTaskEndsOnDoneOrAtTheStepLimit) {
  const CountingTask task(4.0);
  ConstantController push(2.0, 2);  // clipped to 1, commanded every second step
  const std::vector<ControlRun> runs = EvaluateController(task, push, {.starts = 3, .seed = 7});
  ASSERT_EQ(runs.size(), 3u);
  // From 0: reaches 4 after 4 steps; from 1: after 3; from 2: after 2 (done ends the run).
  for (int s = 0; s < 3; ++s) {
    const ControlRun& r = runs[static_cast<std::size_t>(s)];
    const int steps = 4 - s;
    EXPECT_EQ(r.outcome, "success");
    EXPECT_TRUE(r.success);
    EXPECT_EQ(r.trajectory.transitions(), steps);
    EXPECT_DOUBLE_EQ(r.cost, steps * 1.0);
    EXPECT_DOUBLE_EQ(r.max_abs_u, 1.0);
    EXPECT_DOUBLE_EQ(r.trajectory.t[steps], 0.5 * steps);
    EXPECT_DOUBLE_EQ(r.trajectory.states(0, steps), 4.0);
    EXPECT_EQ(r.command_ms.size(), static_cast<std::size_t>((steps + 1) / 2));
  }
  // Out of reach within 6 steps: Finish names the outcome, every step is run.
  const CountingTask far(100.0);
  const ControlRun r = EvaluateController(far, push, {.starts = 1, .seed = 7})[0];
  EXPECT_EQ(r.outcome, "short");
  EXPECT_FALSE(r.success);
  EXPECT_EQ(r.trajectory.transitions(), 6);
  EXPECT_EQ(r.trajectory.states.cols(), 7);
}

}  // namespace
}  // namespace diffdyn
