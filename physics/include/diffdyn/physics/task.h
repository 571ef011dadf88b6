// A control task: a plant run from seeded starts, step by step, judged the same way
// for every controller.
//
// A Task states what is controlled (n states, m actions and their bounds), how long
// a run may last (max_steps steps of period() seconds each), where runs start, and
// how a run is judged. Each run gets its own plant from Begin(); the evaluator
// (solvers/control.h) then repeats
//
//   u_k = task.Clip(controller.Command(x_k))         (held for controller.hold() steps)
//   x_{k+1}, cost_k, done = run.Step(u_k)
//
// until a step reports `done` (its outcome ends the run) or max_steps steps have
// passed (then run.Finish() names the outcome from the final state). A run succeeds
// when its outcome is "success"; its cost is the sum of the step costs.
//
// Implementations: the joint-space swing-up tasks (ControlTask, control_task.h: rk4
// plant per 8-ms period, cost integral, success at t = 5 s) and the pushing task
// (solvers/pushing/trials.h: one push per step in the ODE world, ending at the goal,
// on obstacle contact, off the table or at an unreachable push).
//
//   const ControlTask task = ControlTaskByName("pendulum");
//   for (const TaskStart& s : task.Starts(20, seed)) { ... s.x0, s.seed ... }
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace diffdyn {

/// Where run s of a series starts, and the seed its controller gets.
struct TaskStart {
  Eigen::VectorXd x0;
  std::uint64_t seed = 0;
};

/// What one step of a run gave.
struct StepOutcome {
  /// The step's cost.
  double cost = 0.0;
  /// Whether the run ends here; `outcome` then says how ("success" or a failure name).
  bool done = false;
  std::string outcome{};
};

/// One run's plant (Task::Begin).
class TaskRun {
 public:
  virtual ~TaskRun() = default;
  /// Puts the plant at x0 (n); returns the state the controller sees first (n).
  virtual Eigen::VectorXd Reset(const Eigen::VectorXd& x0) = 0;
  /// Applies the clipped action u (m) for one step from the current state and
  /// writes the state after it to *x (n). Throws diffdyn::NumericalError when the
  /// plant's state becomes non-finite.
  virtual StepOutcome Step(const Eigen::VectorXd& u, Eigen::VectorXd* x) = 0;
  /// The outcome of a run that no step ended: "success" or a failure name.
  virtual std::string Finish() = 0;
};

/// A control task (file comment).
class Task {
 public:
  virtual ~Task() = default;
  /// n and m.
  virtual int state_size() const = 0;
  virtual int action_size() const = 0;
  /// Seconds per step (1 for tasks whose steps are not timed, e.g. pushes).
  virtual double step_period() const = 0;
  /// The most steps of a run.
  virtual int max_steps() const = 0;
  /// u (m) within the task's action bounds.
  virtual Eigen::VectorXd Clip(const Eigen::Ref<const Eigen::VectorXd>& u) const = 0;
  /// Runs 0 .. count - 1 of a series seeded by `seed`: run s's start depends only on
  /// (seed, s) and the task, never on count.
  virtual std::vector<TaskStart> Starts(int count, std::uint64_t seed) const = 0;
  /// A fresh plant for one run (one per thread).
  virtual std::unique_ptr<TaskRun> Begin() const = 0;
};

}  // namespace diffdyn
