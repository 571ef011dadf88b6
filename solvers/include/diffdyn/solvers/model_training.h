// Training a model on a dataset file and saving it: what `diffdyn train` does.
//
// TrainFiles reads a dataset (pushing CSV, joint-space CSV, real-data folder),
// trains one of the four learned transition models (abs-nn, res-nn, abs-node,
// res-node) with Adam on the single- or 4-step loss of the data's state metric and
// a seeded train/validation split, or a DeLaN ("delan", "delan-friction") on the
// torques of joint-space data with the DeLaN authors' defaults for what is not
// given, writes the model file, and returns the summary `train --json` prints; the
// command line and the Python module (`diffdyn.train`) both call it:
//
//   TrainRequest request{.data = "pendulum.csv", .model = "abs-node", .out = "model.json"};
//   request.epochs = 200;
//   nlohmann::json summary = TrainFiles(request);   // model_path, n_train, ..., final_val_loss
//
// Summary keys: `model_path`, `n_train`, `n_val`, `epochs` (run), `stopped_early`,
// `seconds_per_epoch` (median training pass), `final_train_loss`, `final_val_loss`,
// `system`, `model`, `parameters`, `precision`, `solver_steps` and `rejected_steps`
// (the ODE solver's accepted and rejected steps over all training passes; 0 without
// an ODE), `loss`; learned models add `dt`, `dt_jitter` and `normalized`. Learned models scale
// their inputs and outputs to unit size from the training split unless `normalize` says otherwise
// ("auto": on except for pushing CSVs, the paper's models); a DeLaN weighs each joint's torque
// error by 1 / its variance with normalize "on".
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include <nlohmann/json.hpp>

#include "diffdyn/models/learned_model.h"
#include "diffdyn/solvers/dataset_io.h"
#include "diffdyn/solvers/training.h"

namespace diffdyn {

/// What TrainFiles trains, named as `diffdyn train`'s options (errors name them).
struct TrainRequest {
  std::string data;                ///< --data: the dataset
  std::string model = "abs-nn";    ///< --model: abs-nn, res-nn, abs-node, res-node, delan, delan-friction
  std::string out = "model.json";  ///< --out: the model file written
  std::string solver = "rk4";      ///< --solver: a NeuralODE's solver
  int steps = 10;                  ///< --steps: a NeuralODE's grid points on [0, 1] (>= 2)
  std::string loss = "single";     ///< --loss: single or multi (4-step, discount gamma)
  double gamma = 0.9;              ///< --gamma, in [0, 1]
  double val_fraction = 0.2;       ///< --val-fraction, in (0, 0.9]
  int threads = 0;                 ///< --threads: 0 for all cores; results do not depend on it
  int patience = 0;                ///< --patience: epochs without improvement that stop (0: never)
  std::string normalize = "auto";  ///< --normalize: auto, on, off
  std::string precision = "f64";   ///< --precision: f64 or f32 (parameters and Adam stay double)
  std::uint64_t seed = 0;          ///< --seed: split, initialisation and batch order
  bool progress = false;           ///< a progress bar on stderr
  /// Not given: 100 epochs, lr 1e-3, batch 500, width 100 (a DeLaN: the authors'
  /// 10000, 5e-4, 512 and 64).
  std::optional<int> epochs{}, batch{}, hidden{};
  std::optional<double> lr{};
  /// delan: H = L L^T + eps I with L_ii = softplus(d_i - 1) + floor.
  double mass_epsilon = 0.01, diagonal_floor = 0.05;
  /// How joint-space data maps to states and actions (--actuated, --prismatic,
  /// --angle-features); a DeLaN's trunk sees (sin q, cos q) of the joints not
  /// prismatic only when `angle_features_given`, else q itself (the authors' version).
  JointLayout layout{};
  bool angle_features_given = false;
};

/// A learned model and how its training went.
struct FittedModel {
  LearnedModel model;
  TrainResult result;
};

/// The learned model of `config` (its system replaced by the data's) fitted to `data`:
/// the windows of `horizon` steps (1: single-step loss, 4: the paper's multi-step
/// loss), the trainer's seeded split (options.val_fraction, options.seed), input and
/// output scalings fitted on the training split's first steps when `normalize`
/// (FitScaling), the parameters initialised from Rng(options.seed), the time step the
/// data's median interval, then Trainer. Throws diffdyn::Error for bad options or
/// data (e.g. a split that leaves no training window) and diffdyn::NumericalError when
/// training diverges.
///
///   FittedModel fit = FitLearnedModel(ReadDataset("pendulum.csv"),
///                                     {.type = LearnedKind::kAbsNode, .hidden = 64, .steps = 3},
///                                     {.epochs = 100, .seed = 1});
FittedModel FitLearnedModel(const Dataset& data, LearnedModelConfig config, const TrainOptions& options,
                            int horizon = 1, bool normalize = true);

/// Trains and saves the model of `request` and returns the `train --json` summary
/// (file comment). Throws diffdyn::Error (one line naming the option) for bad
/// input, diffdyn::NumericalError when training diverges (nothing is written then).
nlohmann::json TrainFiles(const TrainRequest& request);

}  // namespace diffdyn
