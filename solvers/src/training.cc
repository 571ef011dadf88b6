#include "diffdyn/solvers/training.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <numeric>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/models/adam.h"
#include "diffdyn/models/losses.h"
#include "diffdyn/models/parallel.h"
#include "diffdyn/models/progress.h"
#include "diffdyn/models/random.h"
#include "diffdyn/models/state_loss.h"

namespace diffdyn {

Windows MakeWindows(const Dataset& data, int horizon) {
  DIFFDYN_CHECK(horizon >= 1, "MakeWindows: horizon must be >= 1, got ", horizon);
  int count = 0;
  for (const Trajectory& t : data.trajectories) count += std::max(0, t.transitions() - horizon + 1);
  DIFFDYN_CHECK(count > 0, data.path, ": no ", horizon, "-step windows in ", data.trajectories.size(),
                " trajectories (too short or empty data)");
  const int n = data.system.state_size(), m = data.system.action_size();
  Windows w;
  w.system = data.system;
  w.horizon = horizon;
  w.start.resize(n, count);
  w.actions.assign(horizon, Eigen::MatrixXd(m, count));
  w.targets.assign(horizon, Eigen::MatrixXd(n, count));
  w.dt.assign(horizon, Eigen::RowVectorXd(count));
  int i = 0;
  for (const Trajectory& t : data.trajectories) {
    const int windows = t.transitions() - horizon + 1;
    for (int s = 0; s < windows; ++s, ++i) {
      w.start.col(i) = t.states.col(s);
      for (int k = 0; k < horizon; ++k) {
        w.actions[k].col(i) = t.actions.col(s + k);
        w.targets[k].col(i) = t.states.col(s + k + 1);
        w.dt[k](i) = t.t[s + k + 1] - t.t[s + k];
      }
    }
  }
  return w;
}

Windows SelectWindows(const Windows& data, std::span<const int> index) {
  Windows w;
  w.system = data.system;
  w.horizon = data.horizon;
  GatherColumnBlocks(data.start, index, 1, &w.start);
  w.actions.resize(data.horizon);
  w.targets.resize(data.horizon);
  w.dt.resize(data.horizon);
  for (int k = 0; k < data.horizon; ++k) {
    GatherColumnBlocks(data.actions[k], index, 1, &w.actions[k]);
    GatherColumnBlocks(data.targets[k], index, 1, &w.targets[k]);
    w.dt[k].resize(static_cast<Eigen::Index>(index.size()));
    for (std::size_t j = 0; j < index.size(); ++j) w.dt[k](static_cast<Eigen::Index>(j)) = data.dt[k](index[j]);
  }
  return w;
}

void SplitWindows(int n, double val_fraction, std::uint64_t seed, std::vector<int>* train,
                  std::vector<int>* val) {
  std::vector<int> order(n);
  std::iota(order.begin(), order.end(), 0);
  Rng split_rng(seed);
  Shuffle(order.begin(), order.end(), split_rng);
  const int n_val = static_cast<int>(std::lround(val_fraction * n));
  if (val) val->assign(order.begin(), order.begin() + n_val);
  if (train) train->assign(order.begin() + n_val, order.end());
}

void CheckModelFits(const TransitionModel& model, const SystemDescription& system,
                    const std::string& what) {
  DIFFDYN_CHECK(model.state_size() == system.state_size() && model.action_size() == system.action_size(),
                what, ": the model (", model.kind(), ") takes ", model.state_size(), " states and ",
                model.action_size(), " actions; the data (", system.name, ") have ", system.state_size(),
                " and ", system.action_size());
}

double RolloutLoss(const TransitionModel& model, const Windows& data, double gamma,
                   int threads, int chunk_size, std::vector<double>* per_step) {
  CheckModelFits(model, data.system, "RolloutLoss");
  const int n = data.size();
  const int k_max = data.horizon;
  const int chunks = NumChunks(n, chunk_size);
  // Per chunk: K partial sums of D (scaled by 1 / N).
  std::vector<std::vector<double>> partial(chunks, std::vector<double>(k_max, 0.0));
  ParallelForChunks(n, chunk_size, threads, [&](int c, int begin, int end) {
    const int nb = end - begin;
    auto ws = model.MakeWorkspace(nb);
    Eigen::MatrixXd x = data.start.middleCols(begin, nb);
    Eigen::MatrixXd next(x.rows(), nb);
    for (int k = 0; k < k_max; ++k) {
      model.PredictBatchOver(x, data.actions[k].middleCols(begin, nb), data.dt[k].segment(begin, nb),
                             next, *ws);
      partial[c][k] =
          StateLoss(data.system, next, data.targets[k].middleCols(begin, nb), 1.0 / n, nullptr);
      x.swap(next);
    }
  });
  std::vector<double> steps(k_max, 0.0);
  for (int c = 0; c < chunks; ++c) {
    for (int k = 0; k < k_max; ++k) steps[k] += partial[c][k];
  }
  double loss = 0.0;
  for (int k = 0; k < k_max; ++k) loss += std::pow(gamma, k) * steps[k];
  if (per_step) *per_step = steps;
  return loss;
}

double BaselineLoss(const Windows& data) {
  return StateLoss(data.system, data.start, data.targets[0], 1.0 / data.size(), nullptr);
}

Evaluation EvaluateModel(const TransitionModel& model, const Dataset& data, int threads) {
  constexpr int kHorizon = 4;
  CheckModelFits(model, data.system, data.path);
  Evaluation e;
  const Windows single = MakeWindows(data, 1);
  e.n_samples = single.size();
  e.single_step_loss = RolloutLoss(model, single, 1.0, threads);
  e.baseline_single_step_loss = BaselineLoss(single);
  int windows = 0;
  for (const Trajectory& t : data.trajectories) windows += std::max(0, t.transitions() - kHorizon + 1);
  e.n_windows = windows;
  e.avg_multi_step_loss = std::numeric_limits<double>::quiet_NaN();
  if (windows > 0) {
    e.avg_multi_step_loss = RolloutLoss(model, MakeWindows(data, kHorizon), 1.0, threads) / kHorizon;
  }
  return e;
}

// Buffers of one chunk of a batch: gathered data, the rollout states, one tape per
// rollout step, cotangents and the chunk's gradient.
struct Trainer::Chunk {
  int size = -1;
  std::vector<std::unique_ptr<TransitionWorkspace>> tapes;
  std::vector<Eigen::MatrixXd> x, u, target;
  Eigen::MatrixXd g_loss, g_state, carry;
  Eigen::VectorXd grad;
  double loss = 0.0;

  void Resize(const DifferentiableTransitionModel& model, int n, int m, int horizon, int nb) {
    if (static_cast<int>(tapes.size()) != horizon) {
      tapes.clear();
      for (int k = 0; k < horizon; ++k) tapes.push_back(model.MakeWorkspace(nb));
      size = -1;
    }
    grad.resize(model.num_parameters());
    if (size == nb) return;
    size = nb;
    x.assign(horizon + 1, Eigen::MatrixXd(n, nb));
    u.assign(horizon, Eigen::MatrixXd(m, nb));
    target.assign(horizon, Eigen::MatrixXd(n, nb));
    g_loss.resize(n, nb);
    g_state.resize(n, nb);
    carry.resize(n, nb);
  }
};

namespace {

// Throws diffdyn::Error for options no trainer can run with.
void CheckTrainOptions(const TrainOptions& options) {
  DIFFDYN_CHECK(options.patience >= 0, "--patience must be >= 0, got ", options.patience);
  DIFFDYN_CHECK(options.epochs >= 1, "--epochs must be >= 1, got ", options.epochs);
  DIFFDYN_CHECK(options.learning_rate > 0 && std::isfinite(options.learning_rate),
                "--lr must be positive, got ", options.learning_rate);
  DIFFDYN_CHECK(options.batch_size >= 1, "--batch must be >= 1, got ", options.batch_size);
  DIFFDYN_CHECK(options.val_fraction >= 0 && options.val_fraction < 1,
                "--val-fraction must be in [0, 1), got ", options.val_fraction);
  DIFFDYN_CHECK(options.gamma > 0 && std::isfinite(options.gamma), "--gamma must be positive, got ",
                options.gamma);
  DIFFDYN_CHECK(options.chunk_size >= 1, "chunk size must be >= 1, got ", options.chunk_size);
  DIFFDYN_CHECK(options.weight_decay >= 0 && std::isfinite(options.weight_decay),
                "--weight-decay must be >= 0, got ", options.weight_decay);
}

}  // namespace

Trainer::Trainer(DifferentiableTransitionModel* model, const TrainOptions& options)
    : model_(model), options_(options) {
  DIFFDYN_CHECK(model != nullptr, "Trainer needs a model");
  CheckTrainOptions(options);
}

Trainer::~Trainer() = default;

double Trainer::BatchLossAndGradient(const Windows& data, std::span<const int> index,
                                     Eigen::VectorXd* grad) {
  const int n = static_cast<int>(index.size());
  DIFFDYN_CHECK(n > 0, "Trainer: empty batch");
  const int horizon = data.horizon;
  const int chunks = NumChunks(n, options_.chunk_size);
  while (static_cast<int>(chunks_.size()) < chunks) chunks_.push_back(std::make_unique<Chunk>());
  const double scale = 1.0 / n;
  const DifferentiableTransitionModel& model = *model_;
  const int n_state = data.system.state_size(), n_action = data.system.action_size();
  ParallelForChunks(n, options_.chunk_size, options_.threads, [&](int c, int begin, int end) {
    Chunk& ch = *chunks_[c];
    const int nb = end - begin;
    ch.Resize(model, n_state, n_action, horizon, nb);
    const std::span<const int> idx = index.subspan(begin, nb);
    // Gather the chunk's windows.
    for (int j = 0; j < nb; ++j) {
      ch.x[0].col(j) = data.start.col(idx[j]);
      for (int k = 0; k < horizon; ++k) {
        ch.u[k].col(j) = data.actions[k].col(idx[j]);
        ch.target[k].col(j) = data.targets[k].col(idx[j]);
      }
    }
    // Forward rollout with one tape per step.
    for (int k = 0; k < horizon; ++k) model.Forward(ch.x[k], ch.u[k], ch.x[k + 1], *ch.tapes[k]);
    // Backward: step k's cotangent is its discounted loss gradient plus what flows
    // back from step k + 1.
    ch.loss = 0.0;
    ch.grad.setZero();
    ch.carry.setZero();
    for (int k = horizon - 1; k >= 0; --k) {
      const double w = std::pow(options_.gamma, k);
      ch.loss += w * StateLoss(data.system, ch.x[k + 1], ch.target[k], scale, &ch.g_loss);
      if (grad == nullptr) continue;
      ch.carry += w * ch.g_loss;
      model.Backward(ch.carry, *ch.tapes[k], &ch.grad, k > 0 ? &ch.g_state : nullptr);
      if (k > 0) ch.carry.swap(ch.g_state);
    }
  });
  // Chunk order: the same sums at any thread count.
  double loss = 0.0;
  if (grad) grad->setZero(model.num_parameters());
  for (int c = 0; c < chunks; ++c) {
    loss += chunks_[c]->loss;
    if (grad) *grad += chunks_[c]->grad;
  }
  return loss;
}

TrainResult FitMinibatches(const MinibatchProblem& problem, const TrainOptions& options,
                           Eigen::VectorXd* theta,
                           const std::function<void(const EpochReport&)>& on_epoch) {
  DIFFDYN_CHECK(problem.n_train >= 1, "training needs at least one sample");
  CheckTrainOptions(options);
  TrainResult result;
  result.n_train = problem.n_train;
  result.n_val = problem.n_val;
  Adam adam(theta->size(), {.learning_rate = options.learning_rate,
                            .weight_decay = options.weight_decay,
                            .amsgrad = options.amsgrad});
  MiniBatcher batcher(problem.n_train, options.batch_size, /*drop_last=*/false, options.seed + 1);
  Eigen::VectorXd grad(theta->size());
  ProgressBar bar("train", options.epochs, options.progress);
  std::vector<double> times;
  double best_val = std::numeric_limits<double>::infinity();
  int since_best = 0;
  for (int epoch = 1; epoch <= options.epochs; ++epoch) {
    batcher.Shuffle();
    const auto start = std::chrono::steady_clock::now();
    double sum = 0.0;
    for (int b = 0; b < batcher.num_batches(); ++b) {
      double loss = 0.0;
      try {
        loss = problem.batch_loss(batcher.Batch(b), &grad);
      } catch (const NumericalError& e) {
        throw NumericalError(StrCat("training diverged at epoch ", epoch, ", batch ", b + 1, ": ",
                                    e.what()));
      }
      if (!std::isfinite(loss) || !grad.allFinite()) {
        throw NumericalError(StrCat("training diverged at epoch ", epoch, ", batch ", b + 1,
                                    ": loss = ", loss, (grad.allFinite() ? "" : ", non-finite gradient"),
                                    " (try a smaller --lr)"));
      }
      adam.Step(grad, theta);
      sum += loss;
    }
    EpochReport report;
    report.epoch = epoch;
    report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    report.train_loss = sum / batcher.num_batches();
    report.val_loss = problem.n_val > 0 ? problem.validation_loss()
                                        : std::numeric_limits<double>::quiet_NaN();
    if (problem.n_val > 0 && !std::isfinite(report.val_loss)) {
      throw NumericalError(StrCat("validation loss is ", report.val_loss, " after epoch ", epoch));
    }
    times.push_back(report.seconds);
    result.epochs.push_back(report);
    bar.Update(epoch, StrCat("epoch ", epoch, " train ", report.train_loss, " val ", report.val_loss));
    if (on_epoch) on_epoch(report);
    // Early stop: no improvement of the validation loss for `patience` epochs.
    if (report.val_loss < best_val) {
      best_val = report.val_loss;
      since_best = 0;
    } else if (options.patience > 0 && problem.n_val > 0 && ++since_best >= options.patience) {
      result.stopped_early = epoch < options.epochs;
      break;
    }
  }
  bar.Finish();
  std::vector<double> sorted = times;
  std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
  result.seconds_per_epoch = sorted[sorted.size() / 2];
  result.final_train_loss = result.epochs.back().train_loss;
  result.final_val_loss = result.epochs.back().val_loss;
  return result;
}

TrainResult Trainer::Train(const Windows& data,
                           const std::function<void(const EpochReport&)>& on_epoch) {
  CheckModelFits(*model_, data.system, "train");
  const int n = data.size();
  const int n_val = static_cast<int>(std::lround(options_.val_fraction * n));
  DIFFDYN_CHECK(n - n_val >= 1, "Trainer: no training samples left after the split (", n,
                " windows, --val-fraction ", options_.val_fraction, ")");
  // Seeded split: a shuffled permutation, validation first.
  std::vector<int> train_index, val_index;
  SplitWindows(n, options_.val_fraction, options_.seed, &train_index, &val_index);
  const Windows val = SelectWindows(data, val_index);
  std::vector<int> batch_index(std::min(options_.batch_size, n - n_val));
  MinibatchProblem problem;
  problem.n_train = n - n_val;
  problem.n_val = n_val;
  problem.batch_loss = [&](std::span<const int> positions, Eigen::VectorXd* grad) {
    for (size_t i = 0; i < positions.size(); ++i) batch_index[i] = train_index[positions[i]];
    return BatchLossAndGradient(data, std::span<const int>(batch_index.data(), positions.size()), grad);
  };
  problem.validation_loss = [&] {
    return RolloutLoss(*model_, val, options_.gamma, options_.threads, options_.chunk_size);
  };
  // The tapes outlive a Train call: count this call's steps only.
  for (const auto& chunk : chunks_) {
    for (const auto& tape : chunk->tapes) tape->accepted_steps = tape->rejected_steps = 0;
  }
  TrainResult result = FitMinibatches(problem, options_, &model_->mutable_parameters(), on_epoch);
  for (const auto& chunk : chunks_) {
    for (const auto& tape : chunk->tapes) {
      result.solver_steps += tape->accepted_steps;
      result.rejected_steps += tape->rejected_steps;
    }
  }
  return result;
}

}  // namespace diffdyn
