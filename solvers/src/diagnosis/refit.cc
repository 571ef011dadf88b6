#include "diffdyn/solvers/diagnosis/refit.h"

#include "diffdyn/solvers/diagnosis/candidates.h"

#include <algorithm>
#include <cmath>

#include <ceres/ceres.h>

namespace diffdyn {
namespace {

// tau_hat at row r (header equation).
template <typename T>
VectorX<T> PredictRow(const PreparedData& prep, const ExtendedModel& ext, const VectorX<T>& theta,
                      int r) {
  const SmoothedData& sd = prep.sd;
  const int k = prep.Sample(r);
  bool shifted = false;
  for (const Effect& e : ext.effects()) shifted = shifted || e.kind == EffectKind::kDelay;
  VectorX<T> q, qd, qdd;
  if (shifted) {
    sd.StateAt<T>(T(sd.t[k]) + ext.Delay<T>(theta), sd.segment_of[k], q, qd, qdd);
  } else {
    q = sd.q.col(k).template cast<T>();
    qd = sd.qd.col(k).template cast<T>();
    qdd = sd.qdd.col(k).template cast<T>();
  }
  VectorX<T> tau = ext.JointTorque<T>(q, qd, qdd, theta);
  for (int i = 0; i < static_cast<int>(ext.effects().size()); ++i) {
    const Effect& e = ext.effects()[i];
    if (!IsFrictionKind(e.kind)) continue;
    const int j = e.joint - 1;
    const T* th = theta.data() + ext.ParamOffset(i);
    const T zero(0.0);
    tau[j] -= JointEffectTorque<T>(e.kind, th, q[j], qd[j], zero);
    tau[j] += sd.KernelAverage<T>(r, j, [&](double v) {
      return JointEffectTorque<T>(e.kind, th, zero, T(v), zero);
    });
  }
  return tau / ext.Gain<T>(theta);
}

// Weighted torque residuals at `rows` with the parameters `free` (indices into
// theta) as one block, the others fixed at `base`.
class RefitCost : public ceres::CostFunction {
 public:
  RefitCost(const PreparedData& prep, const ExtendedModel& ext, const std::vector<int>& rows,
            const Eigen::VectorXd& inv_sigma, std::vector<int> free, Eigen::VectorXd base)
      : prep_(prep), ext_(ext), rows_(rows), inv_sigma_(inv_sigma), free_(std::move(free)),
        base_(std::move(base)) {
    set_num_residuals(prep.n * static_cast<int>(rows.size()));
    mutable_parameter_block_sizes()->push_back(static_cast<int>(free_.size()));
  }

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const int p = static_cast<int>(free_.size()), n = prep_.n;
    VectorX<DiagJet> theta = base_.cast<DiagJet>();
    for (int i = 0; i < p; ++i) theta[free_[i]] = DiagJet(parameters[0][i], i);
    for (std::size_t i = 0; i < rows_.size(); ++i) {
      const VectorX<DiagJet> pred = PredictRow<DiagJet>(prep_, ext_, theta, rows_[i]);
      for (int j = 0; j < n; ++j) {
        const int row = static_cast<int>(i) * n + j;
        residuals[row] = (pred[j].a - prep_.tau(j, rows_[i])) * inv_sigma_[j];
        if (!std::isfinite(residuals[row])) return false;
        if (jacobians != nullptr && jacobians[0] != nullptr) {
          for (int c = 0; c < p; ++c) jacobians[0][row * p + c] = pred[j].v[c] * inv_sigma_[j];
        }
      }
    }
    return true;
  }

 private:
  const PreparedData& prep_;
  const ExtendedModel& ext_;
  const std::vector<int>& rows_;
  Eigen::VectorXd inv_sigma_;
  std::vector<int> free_;
  Eigen::VectorXd base_;
};

// Blocks of whole effects with at most kDiagJetSize parameters each.
std::vector<std::vector<int>> ParameterBlocks(const ExtendedModel& ext) {
  std::vector<std::vector<int>> blocks(1);
  for (int i = 0; i < static_cast<int>(ext.effects().size()); ++i) {
    const int o = ext.ParamOffset(i), count = static_cast<int>(ext.effects()[i].params.size());
    if (static_cast<int>(blocks.back().size()) + count > kDiagJetSize) blocks.emplace_back();
    for (int k = 0; k < count; ++k) blocks.back().push_back(o + k);
  }
  return blocks;
}

// The admissible range of every entry of theta.
void ThetaBounds(const ExtendedModel& ext, Eigen::VectorXd* lower, Eigen::VectorXd* upper) {
  const int p = static_cast<int>(ext.EffectParams().size());
  lower->resize(p);
  upper->resize(p);
  for (int e = 0; e < static_cast<int>(ext.effects().size()); ++e) {
    const EffectKindInfo& info = Info(ext.effects()[e].kind);
    for (std::size_t i = 0; i < info.params.size(); ++i) {
      (*lower)[ext.ParamOffset(e) + static_cast<int>(i)] = info.lower[i];
      (*upper)[ext.ParamOffset(e) + static_cast<int>(i)] = info.upper[i];
    }
  }
}

// Standard errors of the block `free` at theta: sqrt(diag(s^2 (J^T J)^+ inflation)).
Eigen::VectorXd BlockStderrs(const PreparedData& prep, const ExtendedModel& ext,
                             const std::vector<int>& rows, const Eigen::VectorXd& inv_sigma,
                             const std::vector<int>& free, const Eigen::VectorXd& theta,
                             double inflation) {
  const int k = static_cast<int>(free.size());
  Eigen::VectorXd x(k);
  for (int i = 0; i < k; ++i) x[i] = theta[free[i]];
  RefitCost at(prep, ext, rows, inv_sigma, free, theta);
  const int m = at.num_residuals();
  Eigen::VectorXd residuals(m);
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> jac(m, k);
  const double* params[] = {x.data()};
  double* jacs[] = {jac.data()};
  at.Evaluate(params, residuals.data(), jacs);
  const double s2 = residuals.squaredNorm() / std::max(1, m - k);
  const Eigen::MatrixXd cov =
      Eigen::MatrixXd(jac.transpose() * jac).completeOrthogonalDecomposition().pseudoInverse() * s2 *
      inflation;
  return cov.diagonal().cwiseMax(0.0).cwiseSqrt();
}

}  // namespace

Eigen::MatrixXd PredictAll(const PreparedData& prep, const ExtendedModel& ext) {
  Eigen::MatrixXd out(prep.n, prep.rows);
  const Eigen::VectorXd theta = ext.EffectParams();
  for (int r = 0; r < prep.rows; ++r) out.col(r) = PredictRow<double>(prep, ext, theta, r);
  return out;
}

Eigen::VectorXd RowSse(const PreparedData& prep, const Eigen::MatrixXd& prediction,
                       const std::vector<int>& rows) {
  Eigen::VectorXd sse = Eigen::VectorXd::Zero(prep.n);
  for (int r : rows) sse += (prep.tau.col(r) - prediction.col(r)).array().square().matrix();
  return sse;
}

ExtendedModel RefitEffects(const PreparedData& prep, const ExtendedModel& ext,
                           const std::vector<int>& rows, const Eigen::VectorXd& inv_sigma,
                           double inflation) {
  Eigen::VectorXd theta = ext.EffectParams();
  const int p = static_cast<int>(theta.size());
  if (p == 0) return ext;
  Eigen::VectorXd lower, upper;
  ThetaBounds(ext, &lower, &upper);
  theta = theta.cwiseMax(lower).cwiseMin(upper);
  const std::vector<std::vector<int>> blocks = ParameterBlocks(ext);
  Eigen::VectorXd stderrs = Eigen::VectorXd::Zero(p);
  const int sweeps = blocks.size() > 1 ? 2 : 1;
  for (int sweep = 0; sweep < sweeps; ++sweep) {
    for (const std::vector<int>& free : blocks) {
      Eigen::VectorXd x(free.size());
      for (std::size_t i = 0; i < free.size(); ++i) x[i] = theta[free[i]];
      ceres::Problem problem;
      problem.AddResidualBlock(new RefitCost(prep, ext, rows, inv_sigma, free, theta), nullptr,
                               x.data());
      for (std::size_t i = 0; i < free.size(); ++i) {
        const int c = static_cast<int>(i);
        if (std::isfinite(lower[free[i]])) problem.SetParameterLowerBound(x.data(), c, lower[free[i]]);
        if (std::isfinite(upper[free[i]])) problem.SetParameterUpperBound(x.data(), c, upper[free[i]]);
      }
      ceres::Solver::Options options;
      options.max_num_iterations = 50;
      options.linear_solver_type = ceres::DENSE_QR;
      options.logging_type = ceres::SILENT;
      ceres::Solver::Summary summary;
      ceres::Solve(options, &problem, &summary);
      if (!x.allFinite()) throw NumericalError("diagnose: refit produced non-finite parameters");
      for (std::size_t i = 0; i < free.size(); ++i) theta[free[i]] = x[i];
      const Eigen::VectorXd se = BlockStderrs(prep, ext, rows, inv_sigma, free, theta, inflation);
      for (std::size_t i = 0; i < free.size(); ++i) stderrs[free[i]] = se[static_cast<int>(i)];
    }
  }
  return ext.WithEffectParams(theta, stderrs);
}

}  // namespace diffdyn
