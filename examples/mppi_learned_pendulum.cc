// MPPI over a learned model: swinging up the torque-limited pendulum.
//
// The task (DESIGN.md): a pendulum hanging from seeded starts, |u| <= 2.5 N m, 5 s
// with a control period of 8 ms, success when it ends upright and still. The planner
// knows the plant only through an absolute NeuralODE learned from 0.04-s samples
// (the data of `diffdyn collect --system pendulum`). MPPI draws K noisy action
// sequences over a 1-s horizon, rolls all of them through the learned model in one
// batch per step, and weighs them by exp(-cost / lambda) with the task's cost
// (TaskMppiCost); each action is held for the model's 5 control periods.
// EvaluateController runs it on the true plant from each start, the same way
// `diffdyn control --system pendulum --controller mppi --model M` does.
//
// Usage: example_mppi_learned_pendulum [--quick]
//   (exit 1 unless at least 80 % of the starts swing up and max |u| <= 2.5 N m)
#include <cstring>

#include <fmt/core.h>

#include "diffdyn/solvers/control.h"
#include "diffdyn/solvers/joint_collect.h"
#include "diffdyn/solvers/model_training.h"

int main(int argc, char** argv) {
  using namespace diffdyn;
  const bool quick = argc > 1 && std::strcmp(argv[1], "--quick") == 0;
  const ControlTask task = ControlTaskByName("pendulum");

  // The learned model (train_neuralode_joint_csv.cc explains these steps).
  const Dataset data = CollectJointSpace(task.plant, {.trajectories = quick ? 40 : 100, .seed = 1, .threads = 2});
  const LearnedModel model = FitLearnedModel(data, {.type = LearnedKind::kAbsNode, .hidden = 64, .steps = 3},
                                             {.epochs = quick ? 40 : 100, .seed = 1, .progress = false})
                                 .model;

  // MPPI with the task's cost over the learned model, run on the true plant.
  MppiControlOptions mppi;
  mppi.samples = quick ? 500 : 1000;
  MppiController controller(task, model, mppi);
  const int starts = quick ? 2 : 10;
  const std::vector<ControlRun> runs = EvaluateController(task, controller, {.starts = starts, .seed = 1});

  int successes = 0;
  double max_u = 0.0;
  for (const ControlRun& run : runs) {
    double ms = 0.0;
    for (double c : run.command_ms) ms += c;
    fmt::print("start (q {:6.3f}, qd {:6.3f}): {}  cost {:7.2f}  max |u| {:.2f}  {:.1f} ms per command\n",
               run.x0[0], run.x0[1], run.success ? "swung up" : "failed  ", run.cost, run.max_abs_u,
               ms / static_cast<double>(run.command_ms.size()));
    successes += run.success ? 1 : 0;
    max_u = std::max(max_u, run.max_abs_u);
  }
  fmt::print("{} of {} starts swung up, max |u| {:.3f} N m\n", successes, starts, max_u);
  if (5 * successes < 4 * starts || max_u > 2.5 + 1e-12) {
    fmt::print(stderr, "error: {} of {} swung up (need 80 %), max |u| {:.3f}\n", successes, starts, max_u);
    return 1;
  }
  return 0;
}
