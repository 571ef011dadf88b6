// One evaluator for every controller on every control task, and MPPI over any
// transition model with the task's cost.
//
// EvaluateController runs a Controller on any Task (physics/task.h) from its seeded
// starts (task.Starts(starts, seed)): each run gets its own plant (task.Begin()), the
// controller is Reset at the start with the run's seed, and the run steps until a
// step ends it or task.max_steps() steps have passed. Every run is measured the same
// way: the sum of the step costs, the outcome ("success" or how it failed), max |u|,
// wall time, and the milliseconds of every Command call. On a ControlTask
// (physics/control_task.h) this is
//
//   cost    = sum_{k < K} period * c(x_k, clip(u_k)),   K = duration / period,
//   success = task.Succeeded(x_K) and no state limit broken on the way,
//
// with TaskModel (rk4-classic, 4 substeps per control period) as the plant; on the
// pushing task (solvers/pushing/trials.h) one push per step in the ODE world.
//
// Starts run on `threads` threads when the controller can be cloned (Clone); the runs
// do not depend on the thread count.
//
// A controller may hold its action for hold() periods (it then plans on a grid of
// hold() * period seconds): Command is called every hold() periods, the action is
// clipped to the task's bounds and held (zero-order hold).
//
// MppiController plans with Mppi (mppi.h) over any TransitionModel whose time step
// is a whole multiple k of the control period (k = hold()), with the running cost
// dt * c(x_{t+1}, u_t) plus `limit_penalty` per step outside the task's state limits,
// the horizon given in seconds, and a terminal cost `terminal_seconds` * q(x_T) (the
// state cost held for that long: a crude cost-to-go, so that a short horizon still
// prefers states nearer the goal to cheaper actions now).
//
//   ControlTask task = ControlTaskByName("pendulum");
//   auto model = TaskModel(task, 0.04, 1);                 // plan on 40 ms steps
//   MppiController mppi(task, *model, MppiControlOptions{});
//   std::vector<ControlRun> runs = EvaluateController(task, mppi, {.starts = 20, .seed = 1});
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "diffdyn/models/trajectory.h"
#include "diffdyn/models/transition_model.h"
#include "diffdyn/physics/control_task.h"
#include "diffdyn/physics/task.h"
#include "diffdyn/solvers/mppi.h"

namespace diffdyn {

/// A feedback controller for EvaluateController.
class Controller {
 public:
  virtual ~Controller() = default;
  /// Control periods each action is held (>= 1).
  virtual int hold() const { return 1; }
  /// Prepares a run from x0 (n); `seed` seeds whatever the controller draws.
  virtual void Reset(const Eigen::VectorXd& x0, std::uint64_t seed) = 0;
  /// The action (m) at state x (n); the evaluator clips it to the task's bounds.
  virtual Eigen::VectorXd Command(const Eigen::VectorXd& x) = 0;
  /// A fresh copy for another thread, or null when the controller cannot be copied
  /// (the evaluator then runs its starts one after another).
  virtual std::unique_ptr<Controller> Clone() const { return nullptr; }
};

/// What one run from one start gave.
struct ControlRun {
  Eigen::VectorXd x0;
  bool success = false;
  /// "success" or how the run failed (the task's names, e.g. "failed", "left_limits",
  /// "obstacle_contact", "max_steps").
  std::string outcome;
  double cost = 0.0;
  double max_abs_u = 0.0;
  double seconds = 0.0;
  /// Milliseconds of each Command call.
  std::vector<double> command_ms;
  /// t (k step periods), states (n x (K + 1)), clipped actions (m x K) of the K steps run.
  Trajectory trajectory;
};

/// Settings of EvaluateController.
struct EvaluationOptions {
  int starts = 20;
  std::uint64_t seed = 0;
  /// Threads running starts at once when the controller can be cloned (<= 0: all cores).
  int threads = 1;
  /// Called with the number of finished runs and the successes among them.
  std::function<void(int done, int successes)> progress{};
};

/// One run of `controller` on `task` from `start` (file comment). Throws
/// diffdyn::NumericalError when the plant's state or the controller's action
/// becomes non-finite.
ControlRun RunEpisode(const Task& task, Controller& controller, const TaskStart& start);

/// Runs `controller` from each of the task's first `options.starts` seeded starts
/// (file comment), in start order.
std::vector<ControlRun> EvaluateController(const Task& task, Controller& controller,
                                           const EvaluationOptions& options);

/// Settings of MppiController (MppiOptions' horizon and noise set from these).
struct MppiControlOptions {
  int samples = 1000;
  /// Horizon in seconds (rounded to whole model steps).
  double horizon_seconds = 1.0;
  double lambda = 0.1;
  /// Noise standard deviation as a fraction of each action's bound.
  double noise_fraction = 0.5;
  /// Cost per model step spent outside the task's state limits.
  double limit_penalty = 1000.0;
  /// Weight (s) of the terminal state cost.
  double terminal_seconds = 10.0;
  int threads = 0;
};

/// The task's running cost for Mppi over model steps of `dt` seconds (file comment).
class TaskMppiCost final : public MppiCost {
 public:
  /// Steps of `dt` seconds; q(x_T) weighs `terminal_seconds` at step `horizon` - 1.
  TaskMppiCost(const ControlTask& task, double dt, double limit_penalty, int horizon, double terminal_seconds)
      : task_(task), dt_(dt), limit_penalty_(limit_penalty), horizon_(horizon), terminal_(terminal_seconds) {}
  void Accumulate(const Eigen::Ref<const Eigen::MatrixXd>& states,
                  Eigen::Ref<Eigen::VectorXd> costs) const override;
  void AccumulateStep(int t, const Eigen::Ref<const Eigen::MatrixXd>& prev_states,
                      const Eigen::Ref<const Eigen::MatrixXd>& actions,
                      const Eigen::Ref<const Eigen::MatrixXd>& states,
                      Eigen::Ref<Eigen::VectorXd> costs) const override;

 private:
  const ControlTask& task_;
  double dt_, limit_penalty_;
  int horizon_;
  double terminal_;
};

/// MPPI over `model` with the task's cost (file comment). Keeps references to the
/// task and the model. Throws diffdyn::Error when the model's sizes are not the
/// task's or its time step is not a whole multiple of the control period.
class MppiController final : public Controller {
 public:
  MppiController(const ControlTask& task, const TransitionModel& model, const MppiControlOptions& options);
  int hold() const override { return hold_; }
  void Reset(const Eigen::VectorXd& x0, std::uint64_t seed) override;
  Eigen::VectorXd Command(const Eigen::VectorXd& x) override;

 private:
  const TransitionModel& model_;
  int hold_ = 1;
  MppiOptions mppi_options_;
  TaskMppiCost cost_;
  std::unique_ptr<Mppi> mppi_;
};

/// The number of control periods in one step of a model with time step `dt`: dt /
/// period when that is a whole number (within 1e-6 relative); throws diffdyn::Error
/// naming `what` otherwise or when dt is unknown (0).
int PeriodsPerStep(double dt, double period, const std::string& what);

}  // namespace diffdyn
