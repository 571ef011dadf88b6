// diffdyn train: fits one of the four learned transition models (abs-nn, res-nn,
// abs-node, res-node) to any dataset (a pushing CSV, a joint-space CSV, a real-data
// folder) with Adam, the single- or multi-step loss of the data's state metric and
// a seeded train/validation split, then saves it as a model file that records the
// system description and the data's median sample interval. `--model delan` fits a
// deep Lagrangian network (models/delan.h) to the torques of joint-space data
// instead, with the DeLaN authors' defaults for every option not given;
// `--model delan-friction` adds a viscous and a Coulomb coefficient per joint, and
// `--angle-features sincos` feeds the joints not --prismatic as (sin q, cos q).
//
//   diffdyn train --data pendulum.csv --model abs-node --epochs 200 --out pendulum.json
//   diffdyn train --data ../shared/data/delan_characters --model delan --out delan.json
//   diffdyn train --data cartpole.csv --model delan-friction --prismatic 1 --angle-features sincos
//                 --out cartpole_delan.json
#include <algorithm>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include <fmt/core.h>

#include "command.h"
#include "diffdyn/autodiff_ode/butcher.h"
#include "diffdyn/models/delan.h"
#include "diffdyn/models/learned_model.h"
#include "diffdyn/solvers/dataset_io.h"
#include "diffdyn/solvers/delan_training.h"
#include "diffdyn/solvers/training.h"
#include "joint_layout_options.h"

namespace diffdyn::cli {
namespace {

struct TrainCommandOptions {
  CommonOptions common;
  std::string data;
  std::string model = "abs-nn";
  std::string solver = "rk4";
  int steps = 10;
  int hidden = 100;
  std::string loss = "single";
  int epochs = 100;
  double lr = 1e-3;
  int batch = 500;
  double val_fraction = 0.2;
  double gamma = 0.9;
  int threads = 0;
  int patience = 0;
  std::string normalize = "auto";
  double mass_epsilon = 0.01, diagonal_floor = 0.05;  // delan: H = L L^T + eps I, L_ii >= floor
  JointLayoutOptions layout;
  std::string out = "model.json";
};

// The losses and timing a model file records of its training.
nlohmann::json TrainMetrics(const TrainResult& r) {
  return {{"final_train_loss", r.final_train_loss},
          {"final_val_loss", r.final_val_loss},
          {"seconds_per_epoch", r.seconds_per_epoch}};
}

// The --json keys every train run prints; callers add their model's own.
nlohmann::json TrainSummary(const TrainCommandOptions& o, const TrainResult& r, const std::string& system,
                            Eigen::Index parameters) {
  nlohmann::json j = TrainMetrics(r);
  j.update({{"model_path", o.out},
            {"n_train", r.n_train},
            {"n_val", r.n_val},
            {"epochs", static_cast<int>(r.epochs.size())},
            {"stopped_early", r.stopped_early},
            {"system", system},
            {"model", o.model},
            {"parameters", parameters}});
  return j;
}

// The DeLaN authors' value of an option the user did not give.
template <typename T>
T OrDefault(const CLI::App& command, const char* name, T given, T fallback) {
  return command.count(name) > 0 ? given : fallback;
}

// A DeLaN's trunk sees q itself (the authors' PyTorch version) unless
// --angle-features sincos is given: then every joint not --prismatic enters as
// (sin q, cos q). 0-based joints.
std::vector<int> DelanPeriodicJoints(const TrainCommandOptions& o, const CLI::App& command, int dof) {
  if (command.count("--angle-features") == 0 || o.layout.angle_features != "sincos") return {};
  const JointLayout layout = ResolveJointLayout(o.layout);
  std::vector<int> periodic;
  for (int j = 1; j <= dof; ++j) {
    if (std::find(layout.prismatic.begin(), layout.prismatic.end(), j) == layout.prismatic.end()) {
      periodic.push_back(j - 1);
    }
  }
  for (int j : layout.prismatic) {
    DIFFDYN_CHECK(j >= 1 && j <= dof, "--prismatic: joint ", j, " is not one of the ", dof, " joints of --data");
  }
  return periodic;
}

void RunTrainDelan(const TrainCommandOptions& o, const CLI::App& command) {
  const JointData data = ReadMeasured(o.data);
  const TrainOptions defaults = DelanTrainDefaults();
  TrainOptions options = defaults;
  options.epochs = OrDefault(command, "--epochs", o.epochs, defaults.epochs);
  options.learning_rate = OrDefault(command, "--lr", o.lr, defaults.learning_rate);
  options.batch_size = OrDefault(command, "--batch", o.batch, defaults.batch_size);
  options.val_fraction = o.val_fraction;
  options.seed = o.common.seed;
  options.threads = o.threads;
  options.patience = o.patience;
  options.progress = !o.common.quiet;
  const DelanSplit split = SplitForDelan(data, o.val_fraction, o.common.seed);
  DelanOptions arch;
  arch.dof = data.dof();
  arch.hidden = OrDefault(command, "--hidden", o.hidden, arch.hidden);
  arch.friction = o.model == "delan-friction";
  arch.epsilon = o.mass_epsilon;
  arch.diagonal_floor = o.diagonal_floor;
  arch.periodic = DelanPeriodicJoints(o, command, arch.dof);
  Delan model = Delan::Initialized(arch, o.common.seed);
  // --normalize on: every joint's torque weighs the same; auto and off: the authors' plain MSE.
  const Eigen::VectorXd weights = o.normalize == "on" ? BalancedJointWeights(split.train) : Eigen::VectorXd();
  const TrainResult result = TrainDelan(&model, split.train, split.test, options, {}, weights);
  if (!std::isfinite(result.final_train_loss) || !model.parameters().allFinite()) {
    throw NumericalError(StrCat("training diverged: the train loss is ", result.final_train_loss,
                                " (try a smaller --lr); nothing written"));
  }
  const nlohmann::json provenance = {
      {"command", "diffdyn train"}, {"data", o.data},        {"seed", o.common.seed},
      {"epochs", options.epochs},   {"lr", options.learning_rate}, {"batch", options.batch_size},
      {"weight_decay", options.weight_decay}, {"amsgrad", options.amsgrad}, {"split", split.how},
      {"n_train", result.n_train},  {"n_val", result.n_val}, {"epochs_run", result.epochs.size()},
      {"joint_weights", std::vector<double>(weights.data(), weights.data() + weights.size())}};
  SaveDelan(o.out, model, provenance, TrainMetrics(result));
  if (o.common.json) {
    nlohmann::json summary = TrainSummary(o, result, data.format, model.num_parameters());
    summary["loss"] = weights.size() > 0 ? "torque (joints weighted by 1 / variance)" : "torque";
    PrintJson(summary);
  } else {
    fmt::print("{} ({} parameters, {} joints) trained on {} samples, validated on {} ({})\n",
               arch.kind(), model.num_parameters(), model.dof(), result.n_train, result.n_val, split.how);
    fmt::print("final train loss {:.4e}, validation loss {:.4e} (torque MSE), {:.3f} s per epoch\n",
               result.final_train_loss, result.final_val_loss, result.seconds_per_epoch);
    fmt::print("saved {}\n", o.out);
  }
}

void RunTrain(const TrainCommandOptions& o, const CLI::App& command) {
  CheckDistinct(o.data, "--out", o.out);
  if (o.model == "delan" || o.model == "delan-friction") return RunTrainDelan(o, command);
  const Dataset dataset = ReadDataset(o.data, ResolveJointLayout(o.layout));
  const SampleIntervals dt = dataset.Intervals();
  LearnedModelConfig config;
  config.type = ParseLearnedKind(o.model);
  config.system = dataset.system;
  config.method = ParseMethod(o.solver);
  config.steps = o.steps;
  config.hidden = o.hidden;
  config.Validate();
  DIFFDYN_CHECK(o.loss == "single" || o.loss == "multi", "--loss: unknown loss '", o.loss,
                "' (expected single or multi)");
  const int horizon = o.loss == "multi" ? 4 : 1;
  const Windows data = MakeWindows(dataset, horizon);
  std::vector<int> train_index, val_index;
  SplitWindows(data.size(), o.val_fraction, o.common.seed, &train_index, &val_index);
  DIFFDYN_CHECK(!train_index.empty() && !val_index.empty(), "--val-fraction ", o.val_fraction, " of the ",
                data.size(), " samples of ", o.data, " leaves ", train_index.size(), " for training and ",
                val_index.size(), " for validation (both need at least one)");
  // Unit-scale network inputs and outputs, fitted on the training split's first steps.
  const bool normalize = o.normalize == "on" || (o.normalize == "auto" && dataset.format != "pushing-csv");
  if (normalize) {
    const Windows train = SelectWindows(data, train_index);
    config.scaling = FitScaling(config, train.start, train.actions[0], train.targets[0]);
  }

  LearnedModel model = LearnedModel::Initialized(config, o.common.seed);
  TrainOptions options;
  options.epochs = o.epochs;
  options.learning_rate = o.lr;
  options.batch_size = o.batch;
  options.val_fraction = o.val_fraction;
  options.gamma = o.gamma;
  options.seed = o.common.seed;
  options.threads = o.threads;
  options.patience = o.patience;
  options.progress = !o.common.quiet;
  Trainer trainer(&model, options);
  const TrainResult result = trainer.Train(data);
  if (!std::isfinite(result.final_train_loss) || !model.parameters().allFinite()) {
    throw NumericalError(StrCat("training diverged: the train loss is ", result.final_train_loss,
                                " (try a smaller --lr or --normalize on); nothing written"));
  }

  const nlohmann::json provenance = {
      {"command", "diffdyn train"}, {"data", o.data},         {"seed", o.common.seed},
      {"loss", o.loss},             {"gamma", o.gamma},        {"epochs", o.epochs},
      {"lr", o.lr},                 {"batch", o.batch},        {"val_fraction", o.val_fraction},
      {"n_train", result.n_train},  {"n_val", result.n_val},    {"dt", dt.median},
      {"dt_min", dt.min},           {"dt_max", dt.max},        {"epochs_run", result.epochs.size()},
      {"normalized", normalize}};
  SaveLearnedModel(o.out, model, provenance, TrainMetrics(result));

  if (o.common.json) {
    nlohmann::json summary = TrainSummary(o, result, dataset.system.name, model.num_parameters());
    summary.update({{"dt", dt.median}, {"dt_jitter", dt.jitter()}, {"normalized", normalize}, {"loss", o.loss}});
    PrintJson(summary);
  } else {
    fmt::print("{} ({} parameters, {} states, {} actions) trained on {} {}-step samples of {}, "
               "validated on {}\n",
               o.model, model.num_parameters(), model.state_size(), model.action_size(),
               result.n_train, horizon, dataset.system.name, result.n_val);
    if (dt.jitter() > 1e-6) {
      fmt::print("irregular sampling: dt from {:.4g} to {:.4g} s (median {:.4g} s, which the "
                 "model learns)\n", dt.min, dt.max, dt.median);
    }
    if (result.stopped_early) {
      fmt::print("stopped early after {} epochs (--patience {})\n", result.epochs.size(), o.patience);
    }
    fmt::print("final train loss {:.4e}, validation loss {:.4e}, {:.3f} s per epoch\n",
               result.final_train_loss, result.final_val_loss, result.seconds_per_epoch);
    fmt::print("saved {}\n", o.out);
  }
}

}  // namespace

void RegisterTrainCommand(CLI::App& app) {
  auto* command = app.add_subcommand(
      "train", "Train a learned dynamics model (NN or NeuralODE) on a pushing or joint-space dataset");
  auto o = std::make_shared<TrainCommandOptions>();
  AddCommonOptions(command, o->common);
  command->add_option("--data", o->data,
                      "Dataset: a pushing CSV, a joint-space CSV (t, q, qd, tau) or a real-data folder")
      ->check(InputPath(true))
      ->required();
  command->add_option("--model", o->model,
                      "Model: abs-nn, res-nn, abs-node, res-node (transition models), delan or "
                      "delan-friction (inverse dynamics from torques, the latter with viscous and "
                      "Coulomb friction per joint; defaults: the DeLaN authors' 10000 epochs, "
                      "lr 5e-4, batch 512, hidden 64; the trunk sees q unless --angle-features "
                      "sincos is given)");
  command->add_option("--solver", o->solver,
                      "NeuralODE solver: rk4 (3/8 rule), rk4-classic, euler, midpoint, dopri5 "
                      "(tolerance 1e-8)");
  command->add_option("--steps", o->steps, "NeuralODE grid points on [0, 1] (steps - 1 fixed steps)")
      ->check(Bounded(2, 10000));
  command->add_option("--hidden", o->hidden, "Width of both hidden layers")
      ->check(Bounded(1, 4096));
  command->add_option("--mass-epsilon", o->mass_epsilon,
                      "delan: eps of H = L L^T + eps I, a lower bound on H's eigenvalues (must be "
                      "below the smallest true one: the cart-pole's pole has 0.0036 kg m^2)")
      ->check(Bounded(1e-12, 1e6))
      ->capture_default_str();
  command->add_option("--diagonal-floor", o->diagonal_floor,
                      "delan: L_ii = softplus(d_i - 1) + floor (floor^2 + eps bounds H's diagonal from below)")
      ->check(Bounded(0.0, 1e3))
      ->capture_default_str();
  command->add_option("--loss", o->loss, "single (one step) or multi (4-step rollout, --gamma)");
  command->add_option("--epochs", o->epochs, "Training epochs")
      ->check(Bounded(1, 1e6));
  command->add_option("--lr", o->lr, "Adam learning rate")
      ->check(Bounded(1e-12, 10));
  command->add_option("--batch", o->batch, "Mini-batch size")
      ->check(Bounded(1, 1e7));
  command->add_option("--val-fraction", o->val_fraction, "Held-out fraction (seeded split)")
      ->check(Bounded(1e-6, 0.9));
  command->add_option("--gamma", o->gamma, "Discount of the multi-step loss")
      ->check(Bounded(0, 1));
  command->add_option("--threads", o->threads, "Threads (0: all cores; results do not depend on it)")
      ->check(Bounded(0, 256));
  command->add_option("--patience", o->patience,
                      "Stop when the validation loss has not improved for this many epochs (0: never)")
      ->check(Bounded(0, 1e6));
  command->add_option("--normalize", o->normalize,
                      "Scale the network's inputs and outputs to unit size from the training data: "
                      "auto = on except for pushing CSVs (the paper's models), on, off; delan: on weighs "
                      "each joint's torque error by 1 / its variance, auto = off (the authors' loss)")
      ->check(CLI::IsMember({"auto", "on", "off"}))
      ->capture_default_str();
  AddJointLayoutOptions(command, o->layout);
  command->add_option("--out", o->out, "Model file to write")
      ->check(OutputPath());
  command->callback([o, command] { RunTrain(*o, *command); });
}

}  // namespace diffdyn::cli
