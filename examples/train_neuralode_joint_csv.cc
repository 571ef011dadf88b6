// A NeuralODE learned from a joint-space CSV, scored against "the state stays".
//
// The C++ path of `diffdyn collect --system pendulum`, `diffdyn train --model abs-node`
// and `diffdyn eval`:
//
//   1. simulate the pendulum task under seeded sinusoidal torques and write the
//      joint-space CSV (t, q1, qd1, tau1 and the ground-truth components);
//   2. read it back as a Dataset: x = [q; qd], u = tau, dt per transition;
//   3. an absolute NeuralODE x_{t+1} = P z(1), dz/dt = MLP(z), z(0) = [x; u], with
//      inputs and outputs scaled to unit moments of the training split, trained by
//      Adam on the single-step loss (angles compared on the circle);
//   4. the single-step loss on a fresh file against the baseline x_{t+1} = x_t.
//
// Usage: example_train_neuralode_joint_csv [--quick] [--out DIR]
//   (exit 1 unless the held-out loss is below 2 % of the baseline; 10 % in --quick)
#include <cstring>
#include <filesystem>
#include <string>

#include <fmt/core.h>

#include "diffdyn/solvers/dataset_io.h"
#include "diffdyn/solvers/joint_collect.h"
#include "diffdyn/solvers/model_training.h"

int main(int argc, char** argv) {
  using namespace diffdyn;
  bool quick = false;
  std::filesystem::path out = std::filesystem::temp_directory_path() / "diffdyn_example_neuralode";
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--quick") == 0) quick = true;
    if (std::strcmp(argv[i], "--out") == 0 && i + 1 < argc) out = argv[++i];
  }
  std::filesystem::create_directories(out);

  // 1. Data: training and held-out files of the pendulum task (5 s at dt 0.04 each).
  const JointTask task = JointTaskByName("pendulum");
  const std::string train_csv = (out / "pendulum_train.csv").string();
  const std::string test_csv = (out / "pendulum_test.csv").string();
  WriteDataset(train_csv, CollectJointSpace(task, {.trajectories = quick ? 30 : 100, .seed = 1, .threads = 2}));
  WriteDataset(test_csv, CollectJointSpace(task, {.trajectories = 20, .seed = 2, .threads = 2}));

  // 2. Read the CSV as any user's log would be read.
  const Dataset data = ReadDataset(train_csv);
  fmt::print("{}: {} trajectories, n = {}, m = {}, dt = {} s\n", train_csv, data.trajectories.size(),
             data.system.state_size(), data.system.action_size(), data.Intervals().median);

  // 3. The model: scalings fitted on the trainer's training split, time step = the data's.
  const FittedModel fit = FitLearnedModel(data, {.type = LearnedKind::kAbsNode, .hidden = 64, .steps = 3},
                                          {.epochs = quick ? 30 : 100, .seed = 1, .progress = false});
  const LearnedModel& model = fit.model;
  const TrainResult& result = fit.result;
  fmt::print("{} epochs, {:.1f} ms each: training loss {:.3e}, validation loss {:.3e}\n", result.epochs.size(),
             1e3 * result.seconds_per_epoch, result.final_train_loss, result.final_val_loss);
  SaveLearnedModel(out / "pendulum_abs_node.json", model, {{"dt", model.time_step()}});

  // 4. Held-out score.
  const Evaluation e = EvaluateModel(model, ReadDataset(test_csv));
  const double ratio = e.single_step_loss / e.baseline_single_step_loss;
  fmt::print("held out ({} transitions): single-step loss {:.3e}, baseline {:.3e}: {:.3f} % of it\n",
             e.n_samples, e.single_step_loss, e.baseline_single_step_loss, 100 * ratio);
  const double target = quick ? 0.10 : 0.02;
  if (!(ratio < target)) {
    fmt::print(stderr, "error: held-out loss is {:.2f} % of the baseline (target < {:.0f} %)\n", 100 * ratio,
               100 * target);
    return 1;
  }
  return 0;
}
