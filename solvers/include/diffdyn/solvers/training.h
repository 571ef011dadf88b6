// Training and evaluating transition models on trajectories of any system.
//
// Data. A trajectory x_0, u_0, x_1, ..., u_{T-1}, x_T gives, for a horizon K, the
// T - K + 1 windows (x_t; u_t .. u_{t+K-1}; x_{t+1} .. x_{t+K}), each step with
// its own interval dt. K = 1 gives the single-step transitions (x_t, u_t, x_{t+1});
// the NeuralODE-Panda paper's multi-step loss uses K = 4 (7 windows per 10-push
// trajectory).
//
// Losses, with D the system's state metric (state_loss.h: pushing's pose loss, the
// joint-space sum of squared SI errors with angles wrapped), a mean over samples:
//
//   single step   L1 = D(F(x_t, u_t), x_{t+1})
//   multi step    LK = sum_{k=0}^{K-1} gamma^k D(x^_{k+1}, x_{t+k+1}),
//                 x^_0 = x_t,  x^_{k+1} = F(x^_k, u_{t+k})        (summed, not averaged)
//
// the evaluation metric "average multi-step loss" = LK(gamma = 1) / K, and the
// baseline single-step loss D(x_t, x_{t+1}) of the predictor "the state stays".
// Evaluation runs each transition over its own dt (PredictBatchOver): a physics
// model integrates the real interval, a learned model its fixed one.
//
// Gradients. A rollout is run forward with a tape per step; backward, step k gets
// dL/dx^_{k+1} = gamma^k dD_k/dx^_{k+1} + (dL/dx^_{k+1} from step k+1) and returns
// dL/dx^_k and adds dL/dtheta: reverse mode through the rollout and through the
// model (for a NeuralODE the discrete adjoint of its solver, learned_model.h).
//
// Trainer: any DifferentiableTransitionModel. A seeded split of the windows
// (validation first in a shuffled order), Adam, mini-batches (seeded shuffle each
// epoch, the last partial batch kept), the epoch's training loss the unweighted
// mean of its batch losses, the validation loss over the whole held-out set after
// each epoch, and an optional early stop when the validation loss has not improved
// for `patience` epochs. A batch is cut into fixed chunks of `chunk_size` samples
// that run on the threads; chunk losses and gradients are summed in chunk order, so
// results are identical at any thread count. (For dopri5 each chunk picks its own
// step sizes: the RMS error norm runs over the chunk rather than the whole batch.)
// A non-finite loss or gradient throws diffdyn::NumericalError naming the epoch
// and batch.
//
//   const Dataset data = ReadDataset(path);                 // solvers/dataset_io.h
//   LearnedModel model = LearnedModel::Initialized({.system = data.system}, seed);
//   Trainer trainer(&model, {.epochs = 100, .seed = seed});
//   TrainResult result = trainer.Train(MakeWindows(data, 1));
//   Evaluation e = EvaluateModel(model, data);
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "diffdyn/models/system_description.h"
#include "diffdyn/models/trajectory.h"
#include "diffdyn/models/transition_model.h"

namespace diffdyn {

/// N windows of horizon K of one system: start states (n x N), K action matrices
/// (m x N), K target matrices (n x N) and K interval rows (1 x N); column i of every
/// matrix belongs to window i.
struct Windows {
  SystemDescription system;
  int horizon = 1;
  Eigen::MatrixXd start;
  std::vector<Eigen::MatrixXd> actions;
  std::vector<Eigen::MatrixXd> targets;
  std::vector<Eigen::RowVectorXd> dt;

  /// N, the number of windows.
  int size() const { return static_cast<int>(start.cols()); }
};

/// All windows of `horizon` >= 1 steps of every trajectory of `data`, in file order
/// (a trajectory with T < horizon actions gives none). Throws diffdyn::Error for
/// horizon < 1 or when no window results.
Windows MakeWindows(const Dataset& data, int horizon);

/// The windows `index` of `data`, in that order.
Windows SelectWindows(const Windows& data, std::span<const int> index);

/// The trainer's seeded split of N windows: a shuffled permutation drawn from
/// Rng(seed), its first round(val_fraction N) entries held out for validation, the
/// rest for training (both in shuffled order).
void SplitWindows(int n, double val_fraction, std::uint64_t seed, std::vector<int>* train,
                  std::vector<int>* val);

/// Throws diffdyn::Error (naming `what`) unless `model` takes the states and actions
/// of `system` (same n and m).
void CheckModelFits(const TransitionModel& model, const SystemDescription& system,
                    const std::string& what);

/// sum_k gamma^k D(x^_{k+1}, x_{t+k+1}) averaged over all windows of `data`, by
/// rollouts of model.PredictBatchOver in fixed chunks of `chunk_size` windows on
/// `threads` threads (<= 0: all cores). If per_step is not null it receives the K
/// per-step losses (undiscounted).
double RolloutLoss(const TransitionModel& model, const Windows& data, double gamma,
                   int threads = 0, int chunk_size = 250, std::vector<double>* per_step = nullptr);

/// D(x_t, x_{t+1}) averaged over the first step of every window: the loss of the
/// predictor "the state stays", by the same metric.
double BaselineLoss(const Windows& data);

/// The evaluation metrics of a model on a dataset.
struct Evaluation {
  /// Single-step transitions and 4-step windows evaluated.
  int n_samples = 0;
  int n_windows = 0;
  /// D of one step over all transitions.
  double single_step_loss = 0.0;
  /// sum_{k<4} D_k / 4 over all 4-step windows (gamma = 1); NaN when there is none.
  double avg_multi_step_loss = 0.0;
  /// D(x_t, x_{t+1}) over all transitions.
  double baseline_single_step_loss = 0.0;
};

/// Single-step, average 4-step and baseline losses of `model` on `data`.
Evaluation EvaluateModel(const TransitionModel& model, const Dataset& data, int threads = 0);

/// Options of Trainer (defaults: the paper's single-step training).
struct TrainOptions {
  int epochs = 100;
  double learning_rate = 1e-3;
  int batch_size = 500;
  /// Fraction of the windows held out for validation (0 <= f < 1).
  double val_fraction = 0.2;
  /// Discount of the multi-step loss (ignored when the data's horizon is 1).
  double gamma = 0.9;
  /// Seeds the split (Rng(seed)) and the batch order (Rng(seed + 1)).
  std::uint64_t seed = 0;
  /// Adam's L2 weight decay and AMSGrad (adam.h; off for the paper's models).
  double weight_decay = 0.0;
  bool amsgrad = false;
  /// Threads (<= 0: all cores) and the fixed chunk size that makes results independent of them.
  int threads = 0;
  int chunk_size = 250;
  /// Stop when the validation loss has not improved for this many epochs (0: never).
  int patience = 0;
  /// Draw a progress bar on stderr (only when it is a terminal).
  bool progress = true;
};

/// One epoch's numbers.
struct EpochReport {
  int epoch = 0;
  double train_loss = 0.0;
  double val_loss = 0.0;
  /// Wall time of the training pass (no evaluation).
  double seconds = 0.0;
};

/// What Train returns.
struct TrainResult {
  int n_train = 0;
  int n_val = 0;
  std::vector<EpochReport> epochs;
  /// Median training-pass time per epoch.
  double seconds_per_epoch = 0.0;
  double final_train_loss = 0.0;
  /// NaN when there is no validation set.
  double final_val_loss = 0.0;
  /// Whether the early stop ended training before options.epochs.
  bool stopped_early = false;
  /// ODE-solver steps of the training passes (Trainer::Train on a model that
  /// integrates; TransitionWorkspace): accepted, and rejected by adaptive error control.
  long solver_steps = 0;
  long rejected_steps = 0;
};

/// A supervised problem for FitMinibatches: n_train training samples addressed by
/// position 0 .. n_train - 1, and a held-out set of n_val samples.
struct MinibatchProblem {
  int n_train = 0;
  int n_val = 0;
  /// Mean loss of the training samples at `positions` and its gradient dL/dtheta
  /// (sized like theta) at the current theta.
  std::function<double(std::span<const int> positions, Eigen::VectorXd* grad)> batch_loss;
  /// Loss on the whole held-out set (called after each epoch when n_val > 0).
  std::function<double()> validation_loss;
};

/// The mini-batch loop every trainer runs: per epoch a seeded shuffle of the
/// training positions (Rng(options.seed + 1)), batches of options.batch_size (the
/// last partial batch kept), one Adam step on *theta per batch (learning rate,
/// weight decay, AMSGrad from options), the epoch's training loss the mean of its
/// batch losses, the validation loss after the epoch, a progress bar, and the early
/// stop of options.patience. A non-finite loss or gradient throws
/// diffdyn::NumericalError naming the epoch and batch.
TrainResult FitMinibatches(const MinibatchProblem& problem, const TrainOptions& options,
                           Eigen::VectorXd* theta,
                           const std::function<void(const EpochReport&)>& on_epoch = {});

/// Trains a DifferentiableTransitionModel in place with Adam on windows of any horizon
/// (see the header comment). Keeps its buffers between batches: a batch allocates
/// nothing once every chunk size has been seen.
class Trainer {
 public:
  /// Trainer of *model (must outlive the trainer); throws diffdyn::Error for bad options.
  Trainer(DifferentiableTransitionModel* model, const TrainOptions& options);
  ~Trainer();
  Trainer(const Trainer&) = delete;
  Trainer& operator=(const Trainer&) = delete;

  /// Trains for options.epochs epochs (fewer on an early stop); `on_epoch` (may be
  /// empty) sees each epoch. Throws diffdyn::Error when the model does not fit the data.
  TrainResult Train(const Windows& data,
                    const std::function<void(const EpochReport&)>& on_epoch = {});

  /// Loss of the windows `index` of `data` (sum_k gamma^k D_k over the batch) and,
  /// if grad is not null, its gradient dL/dtheta (resized to the parameter count).
  double BatchLossAndGradient(const Windows& data, std::span<const int> index,
                              Eigen::VectorXd* grad);

 private:
  struct Chunk;
  DifferentiableTransitionModel* model_;
  TrainOptions options_;
  std::vector<std::unique_ptr<Chunk>> chunks_;
};

}  // namespace diffdyn
