#include "diffdyn/solvers/mppi.h"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <limits>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/models/parallel.h"

namespace diffdyn {

// Per-chunk buffers: states, actions and the model's workspace, sized once.
struct Mppi::ChunkScratch {
  Eigen::MatrixXd states, next, actions;
  Eigen::VectorXd standard_normal;  // m x T normals per sample, sample after sample
  std::unique_ptr<TransitionWorkspace> workspace;
};

namespace {

// The seed of stream b of stream family a (the command, or ~0 for resets).
std::uint64_t MixSeed(std::uint64_t seed, std::uint64_t a, std::uint64_t b) {
  return SplitMix64Hash(SplitMix64Hash(SplitMix64Hash(seed) ^ a) ^ b);
}

}  // namespace

Mppi::Mppi(const TransitionModel& model, const MppiCost& cost, MppiOptions options,
           std::uint64_t seed)
    : model_(model),
      cost_(cost),
      options_(std::move(options)),
      seed_(seed),
      n_(model.state_size()),
      m_(model.action_size()),
      reset_rng_(MixSeed(seed, ~0ULL, 0)) {
  const auto& o = options_;
  DIFFDYN_CHECK(o.samples >= 1 && o.horizon >= 1 && o.chunk_size >= 1,
                "MPPI: samples, horizon and chunk_size must be >= 1, got ", o.samples, ", ",
                o.horizon, ", ", o.chunk_size);
  DIFFDYN_CHECK(o.lambda > 0 && std::isfinite(o.lambda), "MPPI: lambda must be positive, got ",
                o.lambda);
  DIFFDYN_CHECK(o.u_min.size() == 0 || o.u_min.size() == m_, "MPPI: u_min has ", o.u_min.size(),
                " entries, the model's action has ", m_);
  DIFFDYN_CHECK(o.u_max.size() == 0 || o.u_max.size() == m_, "MPPI: u_max has ", o.u_max.size(),
                " entries, the model's action has ", m_);
  if (o.u_min.size() == m_ && o.u_max.size() == m_) {
    DIFFDYN_CHECK((o.u_min.array() <= o.u_max.array()).all(), "MPPI: u_min exceeds u_max");
  }
  Eigen::MatrixXd sigma = o.noise_covariance;
  if (sigma.size() == 0) {
    DIFFDYN_CHECK(o.noise_variance > 0, "MPPI: noise variance must be positive, got ",
                  o.noise_variance);
    sigma = o.noise_variance * Eigen::MatrixXd::Identity(m_, m_);
  }
  DIFFDYN_CHECK(sigma.rows() == m_ && sigma.cols() == m_, "MPPI: noise covariance is ",
                sigma.rows(), "x", sigma.cols(), ", expected ", m_, "x", m_);
  Eigen::LLT<Eigen::MatrixXd> llt(sigma);
  DIFFDYN_CHECK(llt.info() == Eigen::Success && sigma.isApprox(sigma.transpose()),
                "MPPI: noise covariance is not symmetric positive definite");
  chol_ = llt.matrixL();
  lambda_sigma_inv_ = o.lambda * llt.solve(Eigen::MatrixXd::Identity(m_, m_));

  noise_.assign(o.horizon, Eigen::MatrixXd(m_, o.samples));
  weighted_nominal_.resize(m_, o.horizon);
  state_.resize(n_);
  costs_.resize(o.samples);
  weights_.resize(o.samples);
  const int chunks = NumChunks(o.samples, o.chunk_size);
  for (int c = 0; c < chunks; ++c) {
    auto s = std::make_unique<ChunkScratch>();
    const int width = std::min(o.chunk_size, o.samples - c * o.chunk_size);
    s->states.resize(n_, width);
    s->next.resize(n_, width);
    s->actions.resize(m_, width);
    s->standard_normal.resize(Eigen::Index(m_) * width * o.horizon);
    s->workspace = model_.MakeWorkspace(width);
    scratch_.push_back(std::move(s));
  }
  DIFFDYN_CHECK(o.fallback_margin >= 0, "MPPI: fallback_margin must be >= 0, got ",
                o.fallback_margin);
  if (std::isfinite(o.fallback_margin)) {
    check_states_.resize(n_, 2);
    check_next_.resize(n_, 2);
    check_actions_.resize(m_, 2);
    check_costs_.resize(2);
    best_sequence_.resize(m_, o.horizon);
    check_workspace_ = model_.MakeWorkspace(2);
  }
  Reset();
}

Mppi::~Mppi() = default;

void Mppi::Clamp(Eigen::Ref<Eigen::MatrixXd> actions) const {
  if (options_.u_min.size() == m_) {
    actions = actions.cwiseMax(options_.u_min.replicate(1, actions.cols()));
  }
  if (options_.u_max.size() == m_) {
    actions = actions.cwiseMin(options_.u_max.replicate(1, actions.cols()));
  }
}

void Mppi::Reset() {
  nominal_.resize(m_, options_.horizon);
  for (int t = 0; t < options_.horizon; ++t) {
    Eigen::VectorXd e(m_);
    for (int d = 0; d < m_; ++d) e[d] = StandardNormal(reset_rng_);
    nominal_.col(t) = chol_ * e;
  }
  Clamp(nominal_);
}

void Mppi::RolloutChunk(int chunk, int begin, int end, const Eigen::VectorXd& x) {
  ChunkScratch& s = *scratch_[chunk];
  const int width = end - begin;
  const int m = m_;
  // The m x T standard normals of each sample from the sample's own stream, so the
  // draws depend on (seed, command, sample) only, never on the chunking.
  const Eigen::Index per_sample = Eigen::Index(m) * options_.horizon;
  double* z = s.standard_normal.data();
  for (int k = 0; k < width; ++k) {
    SplitMix64 stream(MixSeed(seed_, commands_, static_cast<std::uint64_t>(begin + k)));
    FillStandardNormal(stream, z + k * per_sample, per_sample);
  }
  const double* lo = options_.u_min.size() == m ? options_.u_min.data() : nullptr;
  const double* hi = options_.u_max.size() == m ? options_.u_max.data() : nullptr;
  const double* chol = chol_.data();  // column-major, lower triangular
  s.states.colwise() = x;
  auto costs = costs_.segment(begin, width);
  costs.setZero();
  for (int t = 0; t < options_.horizon; ++t) {
    // Perturb (eps = L e), clamp, keep the perturbation that survived the clamp, and
    // add the perturbation cost u_t^T lambda Sigma^-1 eps.
    double* eps = noise_[t].data() + Eigen::Index(begin) * m;
    const double* u = nominal_.col(t).data();
    const double* wu = weighted_nominal_.col(t).data();
    // (restrict: the writes to a and eps_k leave the inputs' loads in registers)
    for (int k = 0; k < width; ++k) {
      const double* __restrict e = z + k * per_sample + Eigen::Index(t) * m;
      double* __restrict a = s.actions.col(k).data();
      double* __restrict eps_k = eps + Eigen::Index(k) * m;
      double perturbation_cost = 0;
      for (int i = 0; i < m; ++i) {
        double v = 0;
        for (int j = 0; j <= i; ++j) v += chol[i + j * m] * e[j];
        v += u[i];
        if (lo) v = std::max(v, lo[i]);
        if (hi) v = std::min(v, hi[i]);
        a[i] = v;
        eps_k[i] = v - u[i];
        perturbation_cost += wu[i] * (v - u[i]);
      }
      costs[k] += perturbation_cost;
    }
    // The step and its running cost.
    model_.PredictBatch(s.states, s.actions, s.next, *s.workspace);
    cost_.AccumulateStep(t, s.states, s.actions, s.next, costs);
    s.states.swap(s.next);
  }
}

Eigen::VectorXd Mppi::Command(const Eigen::Ref<const Eigen::VectorXd>& x_in) {
  DIFFDYN_CHECK(x_in.size() == n_, "MPPI: state has ", x_in.size(), " entries, the model's has ",
                n_);
  DIFFDYN_CHECK(x_in.allFinite(), "MPPI: non-finite state");
  state_ = x_in;
  const int T = options_.horizon;

  // 1. Warm start by shifting.
  for (int t = 0; t + 1 < T; ++t) nominal_.col(t) = nominal_.col(t + 1);
  nominal_.col(T - 1).setZero();
  Clamp(nominal_.col(T - 1));
  weighted_nominal_.noalias() = lambda_sigma_inv_ * nominal_;  // Sigma^-1 symmetric

  // 2-3. Sample and roll out, chunk by chunk on all cores.
  ParallelForChunks(options_.samples, options_.chunk_size, options_.threads,
                    [&](int chunk, int begin, int end) { RolloutChunk(chunk, begin, end, state_); });
  ++commands_;
  if (!costs_.allFinite()) {
    int bad = 0;
    for (int k = 0; k < costs_.size(); ++k) bad += !std::isfinite(costs_[k]);
    throw NumericalError(StrCat("MPPI: ", bad, " of ", costs_.size(),
                                " rollouts gave a non-finite cost (the model diverged)"));
  }

  // 4. Weights.
  Eigen::Index best_sample = 0;
  const double best = costs_.minCoeff(&best_sample);
  weights_ = (-(costs_.array() - best) / options_.lambda).exp();
  weights_ /= weights_.sum();

  // 5. Update the nominal sequence.
  // u_t + sum_k w_k eps_k is a convex combination of clamped actions; clamping again
  // only removes rounding (a push length of -3e-20, say).
  // The best sample's sequence u + eps_{k*} (already within the bounds), for step 6.
  if (check_workspace_) {
    for (int t = 0; t < T; ++t) best_sequence_.col(t) = nominal_.col(t) + noise_[t].col(best_sample);
  }
  for (int t = 0; t < T; ++t) nominal_.col(t).noalias() += noise_[t] * weights_;
  Clamp(nominal_);

  // 6. Keep the averaged sequence only if the model does not predict it to be worse
  // than the best sample by more than the margin (column 0: U, column 1: best).
  if (check_workspace_) {
    check_states_.colwise() = state_;
    check_costs_.setZero();
    for (int t = 0; t < T; ++t) {
      check_actions_.col(0) = nominal_.col(t);
      check_actions_.col(1) = best_sequence_.col(t);
      model_.PredictBatch(check_states_, check_actions_, check_next_, *check_workspace_);
      cost_.AccumulateStep(t, check_states_, check_actions_, check_next_, check_costs_);
      check_states_.swap(check_next_);
    }
    if (!(check_costs_[0] <= check_costs_[1] + options_.fallback_margin)) {
      nominal_ = best_sequence_;
      ++fallbacks_;
    }
  }
  return nominal_.col(0);
}

Eigen::MatrixXd Mppi::PredictNominal(const Eigen::Ref<const Eigen::VectorXd>& x) const {
  DIFFDYN_CHECK(x.size() == n_, "MPPI: state has ", x.size(), " entries, the model's has ", n_);
  Eigen::MatrixXd path(n_, options_.horizon + 1);
  path.col(0) = x;
  auto ws = model_.MakeWorkspace(1);
  Eigen::MatrixXd next(n_, 1);
  for (int t = 0; t < options_.horizon; ++t) {
    model_.PredictBatch(path.col(t), nominal_.col(t), next, *ws);
    path.col(t + 1) = next;
  }
  return path;
}

}  // namespace diffdyn
