// Losses and metrics on batches (samples in columns), with their gradients.
//
// The training loss of the DDN experiments sums squared errors over a sample's
// entries and averages over the B samples of the batch:
//
//   L = (1/B) sum_b || yhat_b - y_b ||^2,        dL/dyhat_b = (2/B)(yhat_b - y_b).
//
// For stacked Jacobians J = [J_1 ... J_B] (n_L x n_0 B, see mlp.h) the same
// formula with ||.|| the Frobenius norm; pass B explicitly.
//
// The test metric is the plain mean over all entries:
//
//   MSE = (1/N) sum_i (a_i - b_i)^2.
//
// Also here: mini-batches from a seeded shuffle, and column gathers that fill
// preallocated batch matrices without allocating.
#pragma once

#include <numeric>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/models/random.h"

namespace diffdyn {

/// L = (1/batch) sum of squared entries of (pred - target); pred and target of
/// equal size; if grad is not null, *grad = (2/batch)(pred - target) (resized).
inline double SquaredErrorLoss(const Eigen::MatrixXd& pred, const Eigen::MatrixXd& target,
                               int batch, Eigen::MatrixXd* grad) {
  DIFFDYN_CHECK(pred.rows() == target.rows() && pred.cols() == target.cols(),
                "SquaredErrorLoss: prediction is ", pred.rows(), " x ", pred.cols(),
                ", target is ", target.rows(), " x ", target.cols());
  DIFFDYN_CHECK(batch > 0, "SquaredErrorLoss: batch must be positive, got ", batch);
  if (grad) {
    grad->noalias() = (2.0 / batch) * (pred - target);
  }
  return (pred - target).squaredNorm() / batch;
}

/// Mean over all entries of (a - b)^2; a and b of equal size, not empty.
inline double MeanSquaredError(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  DIFFDYN_CHECK(a.rows() == b.rows() && a.cols() == b.cols() && a.size() > 0,
                "MeanSquaredError: sizes ", a.rows(), " x ", a.cols(), " and ", b.rows(), " x ",
                b.cols());
  return (a - b).squaredNorm() / static_cast<double>(a.size());
}

/// Splits n samples into mini-batches of `batch_size` after a seeded shuffle per
/// epoch; the last incomplete batch is dropped if `drop_last` (as the DDN code does).
class MiniBatcher {
 public:
  /// Batches over samples 0 .. n-1 shuffled by an Rng seeded with `seed`.
  MiniBatcher(int n, int batch_size, bool drop_last, std::uint64_t seed)
      : batch_size_(batch_size), drop_last_(drop_last), order_(n), rng_(seed) {
    DIFFDYN_CHECK(n > 0 && batch_size > 0, "MiniBatcher: need n > 0 and batch size > 0, got ", n,
                  " and ", batch_size);
    DIFFDYN_CHECK(!drop_last || batch_size <= n, "MiniBatcher: batch size ", batch_size,
                  " exceeds the ", n, " samples and incomplete batches are dropped");
    std::iota(order_.begin(), order_.end(), 0);
  }

  /// Reshuffles the sample order (call at the start of each epoch).
  void Shuffle() { ::diffdyn::Shuffle(order_.begin(), order_.end(), rng_); }

  /// Number of batches per epoch.
  int num_batches() const {
    const int n = static_cast<int>(order_.size());
    return drop_last_ ? n / batch_size_ : (n + batch_size_ - 1) / batch_size_;
  }

  /// Sample indices of batch i (0 <= i < num_batches()).
  std::span<const int> Batch(int i) const {
    const int begin = i * batch_size_;
    const int end = std::min<int>(begin + batch_size_, static_cast<int>(order_.size()));
    return {order_.data() + begin, static_cast<std::size_t>(end - begin)};
  }

 private:
  int batch_size_;
  bool drop_last_;
  std::vector<int> order_;
  Rng rng_;
};

/// dst.middleCols(i * block, block) = src.middleCols(index[i] * block, block) for
/// each i; dst is resized to src.rows() x block * index.size() only if needed.
inline void GatherColumnBlocks(const Eigen::MatrixXd& src, std::span<const int> index, int block,
                               Eigen::MatrixXd* dst) {
  const Eigen::Index cols = Eigen::Index(block) * static_cast<Eigen::Index>(index.size());
  if (dst->rows() != src.rows() || dst->cols() != cols) dst->resize(src.rows(), cols);
  for (std::size_t i = 0; i < index.size(); ++i) {
    DIFFDYN_DCHECK(index[i] >= 0 && Eigen::Index(index[i] + 1) * block <= src.cols());
    dst->middleCols(Eigen::Index(i) * block, block) = src.middleCols(Eigen::Index(index[i]) * block, block);
  }
}

}  // namespace diffdyn
