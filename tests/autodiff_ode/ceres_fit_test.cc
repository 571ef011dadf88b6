// Fitting a pendulum's gravity and damping through dopri5 with Ceres: residuals are
// integrated on Jets inside an AutoDiffCostFunction.
#include <ceres/ceres.h>

#include <cmath>
#include <cstdio>
#include <vector>

#include <gtest/gtest.h>

#include "diffdyn/autodiff_ode/sensitivity.h"
#include "diffdyn/models/random.h"

namespace diffdyn {
namespace {

// q'' = -g sin q - c q'; theta = (g, c).
struct DampedPendulum {
  template <typename T>
  void operator()(const VectorX<T>& x, const VectorX<T>&, const VectorX<T>& theta, double,
                  VectorX<T>& dxdt) const {
    using std::sin;
    dxdt[0] = x[1];
    dxdt[1] = -theta[0] * sin(x[0]) - theta[1] * x[1];
  }
};

// Whitened residuals (model - measured) / sigma of one trajectory: angle and rate.
struct TrajectoryResidual {
  Eigen::VectorXd x0;
  std::vector<double> times;
  std::vector<Eigen::Vector2d> measured;
  double sigma;
  OdeOptions options;

  template <typename T>
  bool operator()(const T* theta, T* residual) const {
    const VectorX<T> params = Eigen::Map<const Eigen::Matrix<T, 2, 1>>(theta);
    const VectorX<T> start = x0.cast<T>();
    const std::vector<VectorX<T>> xs =
        Simulate<T>(DampedPendulum{}, start, VectorX<T>(), params, times, options);
    for (size_t i = 1; i < times.size(); ++i) {
      for (int j = 0; j < 2; ++j) residual[2 * (i - 1) + j] = (xs[i][j] - measured[i][j]) / sigma;
    }
    return true;
  }
};

TEST(CeresFit, PendulumGravityAndDampingThroughDopri5) {
  Eigen::VectorXd truth(2);
  truth << 9.81, 0.35;
  const double sigma = 0.02;
  OdeOptions options;
  options.method = Method::kDopri5;
  options.abs_tol = options.rel_tol = 1e-10;
  Rng rng(20261122);
  std::vector<double> times;
  for (int i = 0; i <= 60; ++i) times.push_back(0.05 * i);

  ceres::Problem problem;
  double theta[2] = {7.0, 0.1};
  int residuals = 0;
  const double starts[4][2] = {{0.5, 0.0}, {1.5, -1.0}, {-2.0, 2.0}, {0.1, 3.0}};
  for (const auto& start : starts) {
    Eigen::VectorXd x0(2);
    x0 << start[0], start[1];
    auto* functor = new TrajectoryResidual{x0, times, {}, sigma, options};
    const auto clean =
        Simulate<double>(DampedPendulum{}, x0, Eigen::VectorXd(), truth, times, options);
    for (const auto& x : clean) {
      functor->measured.emplace_back(x[0] + sigma * StandardNormal(rng),
                                     x[1] + sigma * StandardNormal(rng));
    }
    const int m = 2 * static_cast<int>(times.size() - 1);
    residuals += m;
    problem.AddResidualBlock(
        new ceres::AutoDiffCostFunction<TrajectoryResidual, ceres::DYNAMIC, 2>(functor, m),
        nullptr, theta);
  }
  ceres::Solver::Options solver_options;
  solver_options.max_num_iterations = 50;
  ceres::Solver::Summary summary;
  ceres::Solve(solver_options, &problem, &summary);
  ASSERT_TRUE(summary.IsSolutionUsable()) << summary.FullReport();

  // Whitened residuals: covariance = (J^T J)^-1, scaled by the reduced chi^2.
  ceres::Covariance::Options cov_options;
  ceres::Covariance covariance(cov_options);
  std::vector<std::pair<const double*, const double*>> blocks{{theta, theta}};
  ASSERT_TRUE(covariance.Compute(blocks, &problem));
  double cov[4];
  covariance.GetCovarianceBlock(theta, theta, cov);
  const double reduced_chi2 = 2.0 * summary.final_cost / (residuals - 2);
  EXPECT_GT(reduced_chi2, 0.7);
  EXPECT_LT(reduced_chi2, 1.3);
  for (int k = 0; k < 2; ++k) {
    const double stderr_k = std::sqrt(cov[3 * k] * reduced_chi2);
    EXPECT_LT(std::abs(theta[k] - truth[k]), 3.0 * stderr_k)
        << "parameter " << k << " = " << theta[k] << " +- " << stderr_k;
    EXPECT_LT(std::abs(theta[k] - truth[k]), 0.02 * truth[k]) << "parameter " << k;
    EXPECT_GT(stderr_k, 0.0);
    std::printf("parameter %d: %.5f +- %.5f (truth %.5f)\n", k, theta[k], stderr_k, truth[k]);
  }
}

}  // namespace
}  // namespace diffdyn
