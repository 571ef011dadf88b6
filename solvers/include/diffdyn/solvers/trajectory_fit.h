// Fitting the parameters of an ODE to measured trajectories, through the integrator.
//
// Given K measured trajectories x_k(t_i) of a system dx/dt = f(x, t; theta) with a
// handful of physical parameters theta (p), find
//
//   theta*, x0* = argmin  sum_k sum_i || S (phi(t_i; x0_k, theta) - x_k(t_i)) ||^2
//
// where phi is the flow computed by any integrator of autodiff_ode (dopri5 by
// default) started at x0_k, and S selects the observed state entries. The initial
// states x0_k are estimated with theta (the measured first sample is noisy, and
// starting from it would bias theta); with fit_initial_state = false they are the
// first samples and the residuals start at i = 1. Ceres's Levenberg-Marquardt solves it; the Jacobian d phi / d theta is
// exact for the discrete map: the integrator runs on ceres::Jet states carrying
// d/d(theta, x0_k) (forward sensitivities), no finite differences.
//
// Long horizons make this cost multimodal (a wrong frequency drifts out of phase),
// so the fit continues over growing horizons: it first fits the first
// 1/2^(S-1) of every trajectory, then doubles the horizon, warm-starting each stage
// from the last, S = horizon_stages times.
//
// Uncertainty: with r the stacked residuals, N their count and J = dr/dtheta at the
// optimum, Cov(theta) = sigma^2 (J^T J)^-1 with sigma^2 = ||r||^2 / (N - p) (the
// Gauss-Newton approximation, valid when the noise is white and the model right);
// the block of theta is the marginal covariance, the x0_k integrated out.
//
// The model is a callable object, generic in the scalar:
//
//   struct DampedPendulum {
//     template <typename T>
//     void operator()(const diffdyn::VectorX<T>& x, diffdyn::VectorX<T>& dxdt, double t,
//                     const T* theta) const {          // theta = (g, b)
//       dxdt[0] = x[1];
//       dxdt[1] = -theta[0] / 0.5 * sin(x[0]) - theta[1] * x[1];
//     }
//   };
//   auto fit = diffdyn::FitTrajectoryParameters<2>(DampedPendulum{}, data, {8.0, 0.0}, {});
//   // fit.params, fit.standard_errors
#pragma once

#include <algorithm>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <ceres/dynamic_autodiff_cost_function.h>
#include <Eigen/SVD>
#include <ceres/crs_matrix.h>
#include <ceres/problem.h>
#include <ceres/solver.h>

#include "diffdyn/autodiff_ode/check.h"
#include "diffdyn/autodiff_ode/integrate.h"
#include "diffdyn/models/trajectory.h"

namespace diffdyn {

/// Options of FitTrajectoryParameters.
struct TrajectoryFitOptions {
  /// The integrator (method, tolerances or step) that maps theta to predictions.
  OdeOptions ode;
  /// Indices of the observed state entries (S above); empty = all of them.
  std::vector<int> observed;
  /// Estimate each trajectory's initial state x0_k along with theta.
  bool fit_initial_state = true;
  /// Levenberg-Marquardt iterations at most, per horizon stage.
  int max_iterations = 100;
  /// Horizon continuation: stage s of S fits the first 2^(s - S) of every trajectory.
  int horizon_stages = 4;
};

/// The fitted parameters and their uncertainty.
struct TrajectoryFitResult {
  Eigen::VectorXd params;            ///< theta*, p entries
  Eigen::VectorXd standard_errors;   ///< sqrt(diag Cov(theta*)), p entries
  Eigen::MatrixXd covariance;        ///< Cov(theta*), p x p
  std::vector<Eigen::VectorXd> initial_states;  ///< x0_k (fitted, or the first samples)
  double initial_rms = 0;            ///< RMS residual at the initial guess
  double final_rms = 0;              ///< RMS residual at theta*
  int num_residuals = 0;             ///< N
  int iterations = 0;                ///< Levenberg-Marquardt iterations taken
  bool converged = false;            ///< Ceres reported convergence
  std::string summary;               ///< Ceres's one-line summary
};

namespace internal {

// Residuals of one trajectory, predicted minus measured observed entries, for the
// parameter blocks (theta, x0): at t_0..t_{T-1} when x0 is fitted, else at t_1.. .
template <typename Model>
class TrajectoryResidual {
 public:
  TrajectoryResidual(const Model& model, const Trajectory& data,
                     const std::vector<int>& observed, const OdeOptions& ode, bool fit_x0)
      : model_(model), data_(data), times_(data.t.data(), data.t.data() + data.t.size()),
        observed_(observed), ode_(ode), fit_x0_(fit_x0) {}

  template <typename T>
  bool operator()(T const* const* blocks, T* residuals) const {
    const T* theta = blocks[0];
    const int n = static_cast<int>(data_.states.rows());
    VectorX<T> x(n);
    for (int j = 0; j < n; ++j) x[j] = fit_x0_ ? blocks[1][j] : T(data_.states(j, 0));
    auto system = [this, theta](const VectorX<T>& state, VectorX<T>& dxdt, double t) {
      model_(state, dxdt, t, theta);
    };
    const int m = static_cast<int>(observed_.size());
    const int first = fit_x0_ ? 0 : 1;
    // A trial point whose flow fails (blows up, step-size underflow) is reported to
    // Ceres as an infeasible step, which shrinks the trust region; it is not an error.
    try {
      IntegrateTimes(system, x, times_, ode_, [&](int i, double, const VectorX<T>& state) {
        if (i < first) return;
        for (int j = 0; j < m; ++j) {
          residuals[(i - first) * m + j] = state[observed_[j]] - data_.states(observed_[j], i);
        }
      });
    } catch (const NumericalError&) {
      return false;
    }
    return true;
  }

 private:
  const Model& model_;
  const Trajectory& data_;
  std::vector<double> times_;  // data_.t for the integrator
  const std::vector<int>& observed_;
  OdeOptions ode_;
  bool fit_x0_;
};

}  // namespace internal

/// Fits theta (kNumParams entries, starting at `initial`) so that the flow of
/// `model` from each trajectory's first sample matches its later samples (see the
/// header comment). Each trajectory (models/trajectory.h) gives times t_0 < ... <
/// t_{T-1} (T >= 2) and states n x T (column i = x(t_i); entries that are not
/// observed may hold anything finite); its actions and channels are not used. Throws diffdyn::Error for empty data, bad sizes or non-finite
/// measurements; diffdyn::NumericalError if the integration fails at the optimum
/// or the covariance is singular (parameters not identifiable from the data).
template <int kNumParams, typename Model>
TrajectoryFitResult FitTrajectoryParameters(const Model& model,
                                            const std::vector<Trajectory>& data,
                                            const Eigen::Matrix<double, kNumParams, 1>& initial,
                                            const TrajectoryFitOptions& options) {
  static_assert(kNumParams > 0, "FitTrajectoryParameters needs at least one parameter");
  DIFFDYN_CHECK(!data.empty(), "FitTrajectoryParameters: no trajectories");
  const int n = static_cast<int>(data[0].states.rows());
  std::vector<int> observed = options.observed;
  if (observed.empty()) {
    for (int j = 0; j < n; ++j) observed.push_back(j);
  }
  for (int j : observed) {
    DIFFDYN_CHECK(j >= 0 && j < n, "observed state index ", j, " outside [0, ", n, ")");
  }
  for (std::size_t k = 0; k < data.size(); ++k) {
    const auto& d = data[k];
    DIFFDYN_CHECK(d.states.rows() == n && d.states.cols() == d.t.size() && d.t.size() >= 2,
                  "trajectory ", k, ": states are ", d.states.rows(), "x", d.states.cols(),
                  " for ", d.t.size(), " times; expected ", n, "xT with T >= 2");
    DIFFDYN_CHECK(d.states.allFinite(), "trajectory ", k, " has non-finite measurements");
  }

  DIFFDYN_CHECK(options.horizon_stages >= 1, "horizon_stages must be >= 1, got ",
                options.horizon_stages);
  using Residual = internal::TrajectoryResidual<Model>;
  constexpr int kStride = 8;  // Jets carry p + n directions in passes of 8
  Eigen::Matrix<double, kNumParams, 1> theta = initial;
  TrajectoryFitResult result;
  for (const auto& d : data) result.initial_states.push_back(d.states.col(0));

  // Builds the problem on the first `fraction` of every trajectory (at least 2 samples).
  std::vector<Trajectory> prefixes(data.size());
  auto build = [&](double fraction, ceres::Problem& problem) {
    int num_residuals = 0;
    for (std::size_t k = 0; k < data.size(); ++k) {
      const int total = static_cast<int>(data[k].t.size());
      const int keep = std::clamp(static_cast<int>(std::ceil(fraction * total)), 2, total);
      prefixes[k].t = data[k].t.head(keep);
      prefixes[k].states = data[k].states.leftCols(keep);
      const int samples = keep - (options.fit_initial_state ? 0 : 1);
      const int count = samples * static_cast<int>(observed.size());
      num_residuals += count;
      auto* cost = new ceres::DynamicAutoDiffCostFunction<Residual, kStride>(
          new Residual(model, prefixes[k], observed, options.ode, options.fit_initial_state));
      cost->AddParameterBlock(kNumParams);
      std::vector<double*> blocks = {theta.data()};
      if (options.fit_initial_state) {
        cost->AddParameterBlock(n);
        blocks.push_back(result.initial_states[k].data());
      }
      cost->SetNumResiduals(count);
      problem.AddResidualBlock(cost, nullptr, blocks);
    }
    return num_residuals;
  };

  ceres::Solver::Options solver_options;
  solver_options.max_num_iterations = options.max_iterations;
  solver_options.linear_solver_type = ceres::DENSE_QR;
  solver_options.function_tolerance = 1e-12;
  solver_options.parameter_tolerance = 1e-12;
  solver_options.logging_type = ceres::SILENT;

  // Horizon continuation; the last stage is the whole data and stays for the covariance.
  std::unique_ptr<ceres::Problem> problem;
  ceres::Solver::Summary summary;
  int num_residuals = 0;
  for (int stage = 1; stage <= options.horizon_stages; ++stage) {
    problem = std::make_unique<ceres::Problem>();
    num_residuals = build(std::ldexp(1.0, stage - options.horizon_stages), *problem);
    if (stage == 1) {
      double cost = 0;
      if (!problem->Evaluate(ceres::Problem::EvaluateOptions(), &cost, nullptr, nullptr,
                             nullptr)) {
        throw NumericalError("FitTrajectoryParameters: the integration fails at the initial guess");
      }
      result.initial_rms = std::sqrt(2 * cost / num_residuals);
    }
    ceres::Solve(solver_options, problem.get(), &summary);
    result.iterations += static_cast<int>(summary.iterations.size()) - 1;
    if (!summary.IsSolutionUsable()) {
      throw NumericalError("FitTrajectoryParameters: Ceres failed: " + summary.message);
    }
  }
  result.num_residuals = num_residuals;
  // An element loop: Eigen's AVX-512 copy of a fixed 2-vector trips g++ 12's -Warray-bounds.
  result.params.resize(kNumParams);
  for (int i = 0; i < kNumParams; ++i) result.params[i] = theta[i];
  result.final_rms = std::sqrt(2 * summary.final_cost / num_residuals);
  result.converged = summary.termination_type == ceres::CONVERGENCE;
  result.summary = summary.BriefReport();

  // Cov = sigma^2 (J^T J)^-1 over theta and the x0_k, from the SVD J = U S V^T:
  // (J^T J)^-1 = V S^-2 V^T. Its theta block is the marginal covariance.
  ceres::CRSMatrix crs;
  double final_cost = 0;
  problem->Evaluate(ceres::Problem::EvaluateOptions(), &final_cost, nullptr, nullptr, &crs);
  Eigen::MatrixXd jacobian = Eigen::MatrixXd::Zero(crs.num_rows, crs.num_cols);
  for (int r = 0; r < crs.num_rows; ++r) {
    for (int i = crs.rows[r]; i < crs.rows[r + 1]; ++i) jacobian(r, crs.cols[i]) = crs.values[i];
  }
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(jacobian, Eigen::ComputeThinV);
  const Eigen::VectorXd& singular = svd.singularValues();
  if (singular.size() == 0 || !(singular.minCoeff() > 1e-10 * singular.maxCoeff())) {
    throw NumericalError(StrCat("FitTrajectoryParameters: the parameters are not identifiable "
                                "from the data (J has condition number ",
                                singular.maxCoeff() / singular.minCoeff(), ")"));
  }
  // theta is the first parameter block of every residual block: columns 0..p-1.
  const Eigen::MatrixXd v_theta = svd.matrixV().topRows(kNumParams);
  const Eigen::MatrixXd jtj_inverse =
      v_theta * singular.array().square().inverse().matrix().asDiagonal() * v_theta.transpose();
  const int num_unknowns = static_cast<int>(jacobian.cols());
  const double dof = std::max(1, num_residuals - num_unknowns);
  const double sigma2 = 2 * final_cost / dof;
  result.covariance = sigma2 * jtj_inverse;
  result.standard_errors = result.covariance.diagonal().cwiseSqrt();
  return result;
}

}  // namespace diffdyn
