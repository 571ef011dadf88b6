// Training and evaluating block-pushing transition models on pose trajectories.
//
// Data. A trajectory x_0, u_0, x_1, ..., u_{T-1}, x_T gives, for a horizon K, the
// T - K + 1 windows (x_t; u_t .. u_{t+K-1}; x_{t+1} .. x_{t+K}). K = 1 gives the
// single-step transitions (x_t, u_t, x_{t+1}); the paper's multi-step loss uses K = 4
// (7 windows per 10-push trajectory).
//
// Losses, with SE2 the pose loss of pose_loss.h (a mean over the samples):
//
//   single step   L1 = SE2(F(x_t, u_t), x_{t+1})
//   multi step    LK = sum_{k=0}^{K-1} gamma^k SE2(x^_{k+1}, x_{t+k+1}),
//                 x^_0 = x_t,  x^_{k+1} = F(x^_k, u_{t+k})        (summed, not averaged)
//
// and the paper's evaluation metric "average multi-step loss" = LK(gamma = 1) / K.
//
// Gradients. A rollout is run forward with a tape per step; backward, step k gets
// dL/dx^_{k+1} = gamma^k dSE2_k/dx^_{k+1} + (dL/dx^_{k+1} from step k+1) and returns
// dL/dx^_k and adds dL/dtheta: reverse mode through the rollout and through the ODE
// solver (discrete adjoint, learned_model.h).
//
// Trainer (the paper's loop): a seeded 80/20 split of the windows, Adam, mini-batches
// (seeded shuffle each epoch, the last partial batch kept), the epoch's training loss
// the unweighted mean of its batch losses, the validation loss over the whole held-out
// set after each epoch. A batch is cut into fixed chunks of `chunk_size` samples that
// run on the threads; chunk losses and gradients are summed in chunk order, so results
// are identical at any thread count. (For dopri5 each chunk picks its own step sizes:
// the RMS error norm runs over the chunk rather than the whole batch.) A non-finite
// loss or gradient throws diffdyn::NumericalError naming the epoch and batch.
//
//   auto data = MakePushingWindows(ReadPushingCsv(path), 1);
//   LearnedModel model = LearnedModel::Initialized(config, seed);
//   Trainer trainer(&model, {.epochs = 100, .seed = seed});
//   TrainResult result = trainer.Train(data);
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "diffdyn/models/learned_model.h"
#include "diffdyn/models/transition_model.h"
#include "diffdyn/physics/pushing_csv.h"

namespace diffdyn {

/// N windows of horizon K: start states (3 x N), K action matrices and K target
/// matrices (3 x N each; column i of every matrix belongs to window i).
struct PushingWindows {
  int horizon = 1;
  Eigen::MatrixXd start;
  std::vector<Eigen::MatrixXd> actions;
  std::vector<Eigen::MatrixXd> targets;

  /// N, the number of windows.
  int size() const { return static_cast<int>(start.cols()); }
};

/// The trajectories of a pushing CSV: ReadPushingCsv, which throws diffdyn::Error
/// "<path>:<line>: ..." for a missing column, text in a numeric field, a NaN or
/// infinite number or a ragged trajectory.
std::vector<PushingTrajectory> ReadPushingData(const std::filesystem::path& path);

/// All windows of `horizon` >= 1 steps of every trajectory, in file order (a
/// trajectory with T < horizon actions gives none). Throws diffdyn::Error for
/// horizon < 1 or when no window results.
PushingWindows MakePushingWindows(const std::vector<PushingTrajectory>& trajectories, int horizon);

/// The windows `index` of `data`, in that order.
PushingWindows SelectWindows(const PushingWindows& data, std::span<const int> index);

/// sum_k gamma^k SE2(x^_{k+1}, x_{t+k+1}) averaged over all windows of `data`, by
/// rollouts of model.PredictBatch in fixed chunks of `chunk_size` windows on `threads`
/// threads (<= 0: all cores). If per_step is not null it receives the K per-step
/// SE2 losses (undiscounted).
double RolloutLoss(const TransitionModel& model, const PushingWindows& data, double gamma,
                   int threads = 0, int chunk_size = 250, std::vector<double>* per_step = nullptr);

/// The paper's metrics (Fig. 5) of a model on a set of trajectories.
struct PushingEvaluation {
  /// Single-step transitions and 4-step windows evaluated.
  int n_samples = 0;
  int n_windows = 0;
  /// SE2 of one step over all transitions.
  double single_step_loss = 0.0;
  /// sum_{k<4} SE2_k / 4 over all 4-step windows (gamma = 1).
  double avg_multi_step_loss = 0.0;
};

/// Single-step loss and average 4-step loss of `model` on `trajectories`.
PushingEvaluation EvaluatePushingModel(const TransitionModel& model,
                                       const std::vector<PushingTrajectory>& trajectories,
                                       int threads = 0);

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
  /// Threads (<= 0: all cores) and the fixed chunk size that makes results independent of them.
  int threads = 0;
  int chunk_size = 250;
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
};

/// Trains a LearnedModel in place with Adam on windows of any horizon (see the header
/// comment). Keeps its buffers between batches: a batch allocates nothing once every
/// chunk size has been seen.
class Trainer {
 public:
  /// Trainer of *model (must outlive the trainer); throws diffdyn::Error for bad options.
  Trainer(LearnedModel* model, const TrainOptions& options);
  ~Trainer();
  Trainer(const Trainer&) = delete;
  Trainer& operator=(const Trainer&) = delete;

  /// Trains for options.epochs epochs; `on_epoch` (may be empty) sees each epoch.
  TrainResult Train(const PushingWindows& data,
                    const std::function<void(const EpochReport&)>& on_epoch = {});

  /// Loss of the windows `index` of `data` (sum_k gamma^k SE2_k over the batch) and,
  /// if grad is not null, its gradient dL/dtheta (resized to the parameter count).
  double BatchLossAndGradient(const PushingWindows& data, std::span<const int> index,
                              Eigen::VectorXd* grad);

 private:
  struct Chunk;
  LearnedModel* model_;
  TrainOptions options_;
  std::vector<std::unique_ptr<Chunk>> chunks_;
};

}  // namespace diffdyn
