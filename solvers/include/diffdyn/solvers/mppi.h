// MPPI: model predictive path integral control over any TransitionModel.
//
// MPPI keeps a nominal action sequence U = (u_0, ..., u_{T-1}) (m each) and, at
// every command, samples K perturbed sequences, rolls each through the model
// x_{t+1} = F(x_t, u_t) from the current state, and averages the perturbations
// weighted by the exponentiated negative cost:
//
//   1. warm start: U <- (u_1, ..., u_{T-1}, 0)
//   2. eps_{k,t} ~ N(0, Sigma);  v_{k,t} = clamp(u_t + eps_{k,t}, u_min, u_max);
//      eps_{k,t} <- v_{k,t} - u_t            (the perturbation after clamping)
//   3. S_k = sum_{t=1..T} c(x_{k,t-1} -> x_{k,t}) + sum_t u_t^T lambda Sigma^-1 eps_{k,t}
//      (running cost over the predicted transitions, no terminal cost, plus the
//       perturbation cost; most costs only look at the new state, c(x_{k,t}),
//       MppiCost::AccumulateStep can also look at the step index t, the state
//       before the step and the action taken)
//   4. w_k = exp(-(S_k - min_j S_j) / lambda) / sum_j exp(-(S_j - min S) / lambda)
//   5. u_t <- u_t + sum_k w_k eps_{k,t};  execute u_0.
//   6. (optional, off by default: MppiOptions::fallback_margin) the averaged
//      sequence U is itself rolled out with the best sample k* = argmin S_k; if
//      its running cost exceeds the best sample's by more than the margin, U is
//      replaced by the best sample's sequence u + eps_{k*}. A weighted average of
//      safe sequences need not be safe (two pushes that each clear an obstacle
//      can average to one that hits it); this step never executes an average the
//      model predicts to be worse than a sequence it has already evaluated.
//
// This is the algorithm of pytorch_mppi as the NeuralODE-Panda seed used it
// (Sigma = 0.5 I is a covariance, lambda = 0.01, K = 1000, T = 20 for the
// obstacle task).
//
// Rollouts use the model's batched double path. Sample k draws its noise from
// its own SplitMix64 stream seeded by (seed, command index, k), so the draws
// do not depend on how samples are grouped. Samples are cut into fixed chunks
// (chunk_size only sets the width of the batched products) that run on all
// cores with one model workspace each: the result is identical at any thread
// count. Every buffer is sized
// once at construction: a command allocates nothing.
//
//   diffdyn::Mppi mppi(model, cost, diffdyn::MppiOptions{}, /*seed=*/1);
//   Eigen::VectorXd u = mppi.Command(x);   // x: n, u: m
#pragma once

#include <cstdint>
#include <limits>
#include <memory>
#include <vector>

#include <Eigen/Core>

#include "diffdyn/models/random.h"
#include "diffdyn/models/transition_model.h"

namespace diffdyn {

/// A running cost evaluated on a batch of predicted states.
class MppiCost {
 public:
  virtual ~MppiCost() = default;
  /// costs(b) += c(states(:, b)) for every column b; states: n x B, costs: B.
  virtual void Accumulate(const Eigen::Ref<const Eigen::MatrixXd>& states,
                          Eigen::Ref<Eigen::VectorXd> costs) const = 0;
  /// The transition form: costs(b) += c_t(x_t, u_t -> x_{t+1}) for step t of the
  /// horizon (0 = the push executed now), with x_t = prev_states(:, b) (n x B),
  /// u_t = actions(:, b) (m x B, after clamping) and x_{t+1} = states(:, b) (n x B).
  /// Mppi calls this one; the default ignores t, x_t and u_t and calls
  /// Accumulate(states, costs), so a cost without a step form gives the running
  /// cost sum_t c(x_{t+1}) of the file comment.
  virtual void AccumulateStep(int t, const Eigen::Ref<const Eigen::MatrixXd>& prev_states,
                              const Eigen::Ref<const Eigen::MatrixXd>& actions,
                              const Eigen::Ref<const Eigen::MatrixXd>& states,
                              Eigen::Ref<Eigen::VectorXd> costs) const {
    (void)t;
    (void)prev_states;
    (void)actions;
    Accumulate(states, costs);
  }
};

/// Settings of Mppi. Empty bounds are taken as unbounded.
struct MppiOptions {
  int samples = 1000;            ///< K
  int horizon = 20;              ///< T
  double lambda = 0.01;          ///< temperature
  double noise_variance = 0.5;   ///< Sigma = noise_variance I (m x m) unless `noise_covariance` is set
  Eigen::MatrixXd noise_covariance;  ///< Sigma (m x m), symmetric positive definite; empty = above
  Eigen::VectorXd u_min;         ///< lower action bounds (m) or empty
  Eigen::VectorXd u_max;         ///< upper action bounds (m) or empty
  int threads = 0;               ///< <= 0: all cores
  int chunk_size = 250;          ///< samples per rollout chunk (speed only: each sample has its own random stream)
  /// Step 6 of the file comment: replace the averaged U by the best sample's
  /// sequence when U's running cost exceeds the best's by more than this (cost
  /// units, >= 0). Infinity (the default) turns the check off: pytorch_mppi's algorithm.
  double fallback_margin = std::numeric_limits<double>::infinity();
};

/// The MPPI controller (see the file comment). Not thread-safe itself; it uses
/// several threads inside Command.
class Mppi {
 public:
  /// Keeps references to `model` and `cost`, which must outlive the controller.
  /// Throws diffdyn::Error for inconsistent options (sizes, a non-positive-definite Sigma).
  Mppi(const TransitionModel& model, const MppiCost& cost, MppiOptions options,
       std::uint64_t seed);
  ~Mppi();

  /// One MPPI iteration from state x (n); returns the action to execute, u_0 (m).
  Eigen::VectorXd Command(const Eigen::Ref<const Eigen::VectorXd>& x);

  /// Draws a fresh nominal sequence U ~ N(0, Sigma), clamped (as at construction).
  void Reset();

  /// The nominal sequence U (m x T) after the last command.
  const Eigen::MatrixXd& nominal() const { return nominal_; }

  /// Total costs S_k of the last command's samples (K).
  const Eigen::VectorXd& sample_costs() const { return costs_; }

  /// Commands so far in which step 6 replaced the averaged sequence.
  int fallbacks() const { return fallbacks_; }

  /// The predicted state path of the updated nominal sequence from the last
  /// command's state (n x (T + 1)), for pictures.
  Eigen::MatrixXd PredictNominal(const Eigen::Ref<const Eigen::VectorXd>& x) const;

 private:
  void RolloutChunk(int chunk, int begin, int end, const Eigen::VectorXd& x);
  void Clamp(Eigen::Ref<Eigen::MatrixXd> actions) const;

  const TransitionModel& model_;
  const MppiCost& cost_;
  MppiOptions options_;
  std::uint64_t seed_;
  std::uint64_t commands_ = 0;
  int n_, m_;
  Eigen::MatrixXd chol_;           // L with Sigma = L L^T (m x m)
  Eigen::MatrixXd lambda_sigma_inv_;  // lambda Sigma^-1 (m x m)
  Eigen::MatrixXd nominal_;        // U, m x T
  Eigen::MatrixXd weighted_nominal_;  // lambda Sigma^-1 U, m x T
  Eigen::VectorXd state_;          // x of the current command, n
  std::vector<Eigen::MatrixXd> noise_;  // eps_t, m x K each (T of them)
  Eigen::VectorXd costs_;          // S, K
  Eigen::VectorXd weights_;        // w, K
  Rng reset_rng_;
  int fallbacks_ = 0;
  // Step 6: the averaged and the best sequence rolled out side by side (n x 2, m x 2).
  Eigen::MatrixXd check_states_, check_next_, check_actions_;
  Eigen::MatrixXd best_sequence_;  // u + eps_{k*}, m x T
  Eigen::VectorXd check_costs_;
  std::unique_ptr<TransitionWorkspace> check_workspace_;
  struct ChunkScratch;
  std::vector<std::unique_ptr<ChunkScratch>> scratch_;  // one per chunk
};

}  // namespace diffdyn
