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
//
// This file parses the options and prints; TrainFiles (solvers/model_training.h)
// trains and saves.
#include <memory>
#include <string>

#include <fmt/core.h>

#include "command.h"
#include "diffdyn/solvers/model_training.h"
#include "joint_layout_options.h"

namespace diffdyn::cli {
namespace {

struct TrainCommandOptions {
  CommonOptions common;
  TrainRequest request;
  // Plain copies of the options whose default depends on the model (TrainRequest).
  int hidden = 100, epochs = 100, batch = 500;
  double lr = 1e-3;
  JointLayoutOptions layout;
};

// The request with the options the user gave.
TrainRequest Request(const TrainCommandOptions& o, const CLI::App& command) {
  TrainRequest r = o.request;
  r.seed = o.common.seed;
  r.progress = !o.common.quiet;
  if (command.count("--hidden") > 0) r.hidden = o.hidden;
  if (command.count("--epochs") > 0) r.epochs = o.epochs;
  if (command.count("--batch") > 0) r.batch = o.batch;
  if (command.count("--lr") > 0) r.lr = o.lr;
  r.layout = ResolveJointLayout(o.layout);
  r.angle_features_given = command.count("--angle-features") > 0;
  return r;
}

// The summary as text.
void PrintSummary(const TrainRequest& r, const nlohmann::json& s) {
  const bool delan = !s.contains("state_size");
  if (delan) {
    fmt::print("{} ({} parameters, {} joints) trained on {} samples, validated on {} ({})\n", r.model,
               s["parameters"].get<long>(), s["dof"].get<int>(), s["n_train"].get<int>(), s["n_val"].get<int>(),
               s["split"].get<std::string>());
  } else {
    fmt::print("{} ({} parameters, {} states, {} actions) trained on {} {}-step samples of {}, validated on {}\n",
               r.model, s["parameters"].get<long>(), s["state_size"].get<int>(), s["action_size"].get<int>(),
               s["n_train"].get<int>(), s["horizon"].get<int>(), s["system"].get<std::string>(),
               s["n_val"].get<int>());
    if (s["dt_jitter"].get<double>() > 1e-6) {
      fmt::print("irregular sampling: dt from {:.4g} to {:.4g} s (median {:.4g} s, which the model learns)\n",
                 s["dt_min"].get<double>(), s["dt_max"].get<double>(), s["dt"].get<double>());
    }
    if (s["stopped_early"].get<bool>()) {
      fmt::print("stopped early after {} epochs (--patience {})\n", s["epochs"].get<int>(), r.patience);
    }
  }
  fmt::print("final train loss {:.4e}, validation loss {:.4e}{}, {:.3f} s per epoch\n",
             s["final_train_loss"].get<double>(), s["final_val_loss"].get<double>(),
             delan ? " (torque MSE)" : "", s["seconds_per_epoch"].get<double>());
  fmt::print("saved {}\n", r.out);
}

void RunTrain(const TrainCommandOptions& o, const CLI::App& command) {
  const TrainRequest request = Request(o, command);
  const nlohmann::json summary = TrainFiles(request);
  if (o.common.json) {
    PrintJson(summary);
  } else {
    PrintSummary(request, summary);
  }
}

}  // namespace

void RegisterTrainCommand(CLI::App& app) {
  auto* command = app.add_subcommand(
      "train", "Train a learned dynamics model (NN or NeuralODE) on a pushing or joint-space dataset");
  auto o = std::make_shared<TrainCommandOptions>();
  AddCommonOptions(command, o->common);
  command->add_option("--data", o->request.data,
                      "Dataset: a pushing CSV, a joint-space CSV (t, q, qd, tau) or a real-data folder")
      ->check(InputPath(true))
      ->required();
  command->add_option("--model", o->request.model,
                      "Model: abs-nn, res-nn, abs-node, res-node (transition models), delan or "
                      "delan-friction (inverse dynamics from torques, the latter with viscous and "
                      "Coulomb friction per joint; defaults: the DeLaN authors' 10000 epochs, "
                      "lr 5e-4, batch 512, hidden 64; the trunk sees q unless --angle-features "
                      "sincos is given)");
  command->add_option("--solver", o->request.solver,
                      "NeuralODE solver: rk4 (3/8 rule), rk4-classic, euler, midpoint, dopri5 "
                      "(tolerance 1e-8)");
  command->add_option("--steps", o->request.steps, "NeuralODE grid points on [0, 1] (steps - 1 fixed steps)")
      ->check(Bounded(2, 10000));
  command->add_option("--hidden", o->hidden, "Width of both hidden layers")
      ->check(Bounded(1, 4096));
  command->add_option("--mass-epsilon", o->request.mass_epsilon,
                      "delan: eps of H = L L^T + eps I, a lower bound on H's eigenvalues (must be "
                      "below the smallest true one: the cart-pole's pole has 0.0036 kg m^2)")
      ->check(Bounded(1e-12, 1e6))
      ->capture_default_str();
  command->add_option("--diagonal-floor", o->request.diagonal_floor,
                      "delan: L_ii = softplus(d_i - 1) + floor (floor^2 + eps bounds H's diagonal from below)")
      ->check(Bounded(0.0, 1e3))
      ->capture_default_str();
  command->add_option("--loss", o->request.loss, "single (one step) or multi (4-step rollout, --gamma)");
  command->add_option("--epochs", o->epochs, "Training epochs")
      ->check(Bounded(1, 1e6));
  command->add_option("--lr", o->lr, "Adam learning rate")
      ->check(Bounded(1e-12, 10));
  command->add_option("--batch", o->batch, "Mini-batch size")
      ->check(Bounded(1, 1e7));
  command->add_option("--val-fraction", o->request.val_fraction, "Held-out fraction (seeded split)")
      ->check(Bounded(1e-6, 0.9));
  command->add_option("--gamma", o->request.gamma, "Discount of the multi-step loss")
      ->check(Bounded(0, 1));
  command->add_option("--threads", o->request.threads, "Threads (0: all cores; results do not depend on it)")
      ->check(Bounded(0, 256));
  command
      ->add_option("--precision", o->request.precision,
                   "f64 or f32: the precision of the network and solver passes (every model; "
                   "parameters, Adam and loss sums stay double)")
      ->capture_default_str();
  command->add_option("--patience", o->request.patience,
                      "Stop when the validation loss has not improved for this many epochs (0: never)")
      ->check(Bounded(0, 1e6));
  command->add_option("--normalize", o->request.normalize,
                      "Scale the network's inputs and outputs to unit size from the training data: "
                      "auto = on except for pushing CSVs (the paper's models), on, off; delan: on weighs "
                      "each joint's torque error by 1 / its variance, auto = off (the authors' loss)")
      ->check(CLI::IsMember({"auto", "on", "off"}))
      ->capture_default_str();
  AddJointLayoutOptions(command, o->layout);
  command->add_option("--out", o->request.out, "Model file to write")
      ->check(OutputPath());
  command->callback([o, command] { RunTrain(*o, *command); });
}

}  // namespace diffdyn::cli
