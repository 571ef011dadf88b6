#include "diffdyn/solvers/control.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <mutex>
#include <string>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/models/parallel.h"

namespace diffdyn {
namespace {

using Clock = std::chrono::steady_clock;

double MillisecondsSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

}  // namespace

ControlRun RunEpisode(const Task& task, Controller& controller, const TaskStart& start) {
  const Clock::time_point begin = Clock::now();
  const int max_steps = task.max_steps(), n = task.state_size(), m = task.action_size();
  ControlRun run;
  run.x0 = start.x0;
  Eigen::MatrixXd states(n, max_steps + 1), actions(m, max_steps);
  const std::unique_ptr<TaskRun> plant = task.Begin();
  states.col(0) = plant->Reset(start.x0);
  controller.Reset(states.col(0), start.seed);
  Eigen::VectorXd u = Eigen::VectorXd::Zero(m), next(n);
  int steps = 0;
  for (; steps < max_steps && run.outcome.empty(); ++steps) {
    const Eigen::VectorXd x = states.col(steps);
    if (steps % controller.hold() == 0) {
      const Clock::time_point command = Clock::now();
      u = task.Clip(controller.Command(x));
      run.command_ms.push_back(MillisecondsSince(command));
      if (!u.allFinite()) {
        throw NumericalError(StrCat("control: the controller returned a non-finite action at step ", steps));
      }
    }
    const StepOutcome step = plant->Step(u, &next);
    actions.col(steps) = u;
    states.col(steps + 1) = next;
    run.cost += step.cost;
    run.max_abs_u = std::max(run.max_abs_u, u.cwiseAbs().maxCoeff());
    if (step.done) run.outcome = step.outcome;
  }
  if (run.outcome.empty()) run.outcome = plant->Finish();
  run.success = run.outcome == "success";
  Trajectory& tr = run.trajectory;
  tr.t = Eigen::VectorXd::LinSpaced(steps + 1, 0.0, steps * task.step_period());
  tr.states = states.leftCols(steps + 1);
  tr.actions = actions.leftCols(steps);
  run.seconds = MillisecondsSince(begin) / 1000.0;
  return run;
}

int PeriodsPerStep(double dt, double period, const std::string& what) {
  DIFFDYN_CHECK(dt > 0 && std::isfinite(dt), what, ": the model records no time step (train it with diffdyn train on "
                "timed data, or give an analytic model)");
  const double k = dt / period;
  const double whole = std::round(k);
  DIFFDYN_CHECK(whole >= 1 && std::abs(k - whole) <= 1e-6 * whole, what, ": the model's time step ", dt,
                " s is not a whole multiple of the control period ", period, " s");
  return static_cast<int>(whole);
}

std::vector<ControlRun> EvaluateController(const Task& task, Controller& controller,
                                           const EvaluationOptions& options) {
  DIFFDYN_CHECK(options.starts >= 1, "--starts must be >= 1, got ", options.starts);
  const std::vector<TaskStart> starts = task.Starts(options.starts, options.seed);
  std::vector<ControlRun> runs(static_cast<std::size_t>(options.starts));
  // One chunk per start; a clone of the controller per chunk when the controller
  // can be cloned, else the caller's controller on one thread.
  const bool parallel = ResolveThreads(options.threads) > 1 && options.starts > 1 && controller.Clone() != nullptr;
  std::mutex progress_mutex;
  int finished = 0, successes = 0;
  ParallelForChunks(options.starts, 1, parallel ? options.threads : 1, [&](int, int s, int) {
    std::unique_ptr<Controller> clone = parallel ? controller.Clone() : nullptr;
    const auto i = static_cast<std::size_t>(s);
    runs[i] = RunEpisode(task, clone ? *clone : controller, starts[i]);
    if (options.progress) {
      const std::lock_guard<std::mutex> lock(progress_mutex);
      successes += runs[i].success ? 1 : 0;
      options.progress(++finished, successes);
    }
  });
  return runs;
}

// ----------------------------------------------------------------------------
// MPPI with the task's cost.

void TaskMppiCost::Accumulate(const Eigen::Ref<const Eigen::MatrixXd>& states,
                              Eigen::Ref<Eigen::VectorXd> costs) const {
  for (Eigen::Index b = 0; b < states.cols(); ++b) {
    costs[b] += dt_ * task_.StateCost(states.col(b));
    if (task_.OutOfLimits(states.col(b))) costs[b] += limit_penalty_;
  }
}

void TaskMppiCost::AccumulateStep(int t, const Eigen::Ref<const Eigen::MatrixXd>&,
                                  const Eigen::Ref<const Eigen::MatrixXd>& actions,
                                  const Eigen::Ref<const Eigen::MatrixXd>& states,
                                  Eigen::Ref<Eigen::VectorXd> costs) const {
  Accumulate(states, costs);
  const bool last = t == horizon_ - 1 && terminal_ > 0;
  for (Eigen::Index b = 0; b < actions.cols(); ++b) {
    costs[b] += dt_ * task_.action_cost(actions.col(b));
    if (last) costs[b] += terminal_ * task_.StateCost(states.col(b));
  }
}

namespace {

// MppiOptions from the controller's settings: the horizon in model steps, noise
// scaled to the action bounds, bounds clamped.
MppiOptions MppiOptionsFor(const ControlTask& task, double dt, const MppiControlOptions& options) {
  DIFFDYN_CHECK(options.samples >= 1 && options.samples <= 1000000, "--samples must be in [1, 1e6], got ",
                options.samples);
  DIFFDYN_CHECK(options.horizon_seconds > 0 && options.horizon_seconds <= 60, "--horizon must be in (0, 60] s, got ",
                options.horizon_seconds);
  DIFFDYN_CHECK(options.lambda > 0 && std::isfinite(options.lambda), "--lambda must be positive, got ", options.lambda);
  DIFFDYN_CHECK(options.noise_fraction > 0 && options.noise_fraction <= 10, "--noise must be in (0, 10], got ",
                options.noise_fraction);
  DIFFDYN_CHECK(options.terminal_seconds >= 0 && options.terminal_seconds <= 1e3, "--terminal must be in [0, 1000] s, got ",
                options.terminal_seconds);
  MppiOptions m;
  m.samples = options.samples;
  m.horizon = std::max(1, static_cast<int>(std::lround(options.horizon_seconds / dt)));
  m.lambda = options.lambda;
  const Eigen::VectorXd sd = options.noise_fraction * task.plant.bound;
  m.noise_covariance = sd.array().square().matrix().asDiagonal();
  m.u_min = -task.plant.bound;
  m.u_max = task.plant.bound;
  m.threads = options.threads;
  return m;
}

}  // namespace

MppiController::MppiController(const ControlTask& task, const TransitionModel& model,
                               const MppiControlOptions& options)
    : model_(model),
      hold_(PeriodsPerStep(model.time_step(), task.period, "--model")),
      mppi_options_(MppiOptionsFor(task, model.time_step(), options)),
      cost_(task, model.time_step(), options.limit_penalty, mppi_options_.horizon, options.terminal_seconds) {
  DIFFDYN_CHECK(model.state_size() == task.state_size() && model.action_size() == task.action_size(),
                "--model: a model of ", model.state_size(), " states and ", model.action_size(),
                " actions does not fit the task (", task.state_size(), " states, ", task.action_size(),
                " actions)");
}

void MppiController::Reset(const Eigen::VectorXd&, std::uint64_t seed) {
  mppi_ = std::make_unique<Mppi>(model_, cost_, mppi_options_, seed);
}

Eigen::VectorXd MppiController::Command(const Eigen::VectorXd& x) {
  DIFFDYN_CHECK(mppi_ != nullptr, "MppiController: Command before Reset");
  return mppi_->Command(x);
}

}  // namespace diffdyn
