// Diagnosis selection: chi-square tail, and the family-wise error of ForwardSelect.
#include "diffdyn/solvers/diagnosis/selection.h"

#include <cmath>
#include <random>

#include <Eigen/QR>
#include <gtest/gtest.h>

namespace diffdyn {
namespace {

TEST(ChiSquareSurvival, MatchesTabulatedQuantiles) {
  // 95 % and 99.9 % quantiles of chi^2_k (standard tables).
  const double q95[] = {3.841459, 5.991465, 7.814728, 9.487729, 11.070498};
  const double q999[] = {10.827566, 13.815511, 16.266236, 18.466827, 20.515006};
  for (int k = 1; k <= 5; ++k) {
    EXPECT_NEAR(ChiSquareSurvival(q95[k - 1], k), 0.05, 1e-6) << k;
    EXPECT_NEAR(ChiSquareSurvival(q999[k - 1], k), 0.001, 1e-7) << k;
  }
  EXPECT_DOUBLE_EQ(ChiSquareSurvival(0.0, 3), 1.0);
  EXPECT_THROW(ChiSquareSurvival(1.0, 0), Error);
}

// Ordinary least squares of y on chosen columns of x, with Gaussian noise.
class Regression : public SelectionProblem {
 public:
  Regression(Eigen::MatrixXd x, Eigen::VectorXd y) : x_(std::move(x)), y_(std::move(y)) {}
  int NumCandidates() const override { return static_cast<int>(x_.cols()); }
  std::string Label(int c) const override { return StrCat("x", c); }
  int NumParams(int) const override { return 1; }
  double Deviance(const std::vector<int>& set) const override {
    return y_.size() * std::log(Sse(set, 0, static_cast<int>(y_.size())) / y_.size());
  }
  double LogSamples() const override { return std::log(static_cast<double>(y_.size())); }
  double CrossValidationError(const std::vector<int>& set) const override {
    // Two halves, each predicted from the other.
    const int h = static_cast<int>(y_.size() / 2);
    return Holdout(set, 0, h, h, static_cast<int>(y_.size())) + Holdout(set, h, static_cast<int>(y_.size()), 0, h);
  }
  std::string Veto(const std::vector<int>&, int c) const override { return c == vetoed ? "vetoed" : ""; }
  int vetoed = -1;

 private:
  Eigen::MatrixXd Design(const std::vector<int>& set, int a, int b) const {
    Eigen::MatrixXd d(b - a, set.size());
    for (std::size_t i = 0; i < set.size(); ++i) d.col(static_cast<int>(i)) = x_.col(set[i]).segment(a, b - a);
    return d;
  }
  Eigen::VectorXd Beta(const std::vector<int>& set, int a, int b) const {
    return Design(set, a, b).colPivHouseholderQr().solve(y_.segment(a, b - a));
  }
  double Sse(const std::vector<int>& set, int a, int b) const {
    if (set.empty()) return y_.segment(a, b - a).squaredNorm();
    return (y_.segment(a, b - a) - Design(set, a, b) * Beta(set, a, b)).squaredNorm();
  }
  double Holdout(const std::vector<int>& set, int fa, int fb, int ta, int tb) const {
    if (set.empty()) return y_.segment(ta, tb - ta).squaredNorm();
    return (y_.segment(ta, tb - ta) - Design(set, ta, tb) * Beta(set, fa, fb)).squaredNorm();
  }
  Eigen::MatrixXd x_;
  Eigen::VectorXd y_;
};

Regression MakeRegression(std::uint64_t seed, double b0, double b3) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  Eigen::MatrixXd x(400, 10);
  Eigen::VectorXd y(400);
  for (int r = 0; r < 400; ++r) {
    for (int c = 0; c < 10; ++c) x(r, c) = normal(rng);
    y[r] = b0 * x(r, 0) + b3 * x(r, 3) + normal(rng);
  }
  return Regression(x, y);
}

TEST(ForwardSelect, FindsTheTrueColumnsAndStops) {
  const Regression problem = MakeRegression(1, 0.5, -0.3);
  SelectionOptions options;
  options.family = 10;
  std::vector<SelectionStep> log;
  std::vector<int> chosen = ForwardSelect(problem, options, &log);
  std::sort(chosen.begin(), chosen.end());
  EXPECT_EQ(chosen, (std::vector<int>{0, 3}));
  ASSERT_EQ(log.size(), 3u);
  EXPECT_FALSE(log.back().accepted);
}

// Under "nothing is there" the chance of naming anything stays near alpha.
TEST(ForwardSelect, KeepsTheFamilyWiseErrorNearAlpha) {
  SelectionOptions options;
  options.family = 10;
  options.alpha = 0.05;
  int false_discoveries = 0;
  const int trials = 200;
  for (int seed = 0; seed < trials; ++seed) {
    std::vector<SelectionStep> log;
    false_discoveries += ForwardSelect(MakeRegression(100 + seed, 0.0, 0.0), options, &log).empty() ? 0 : 1;
  }
  // Expected about 0.05 * 200 = 10 (binomial sd 3); more than 20 means no control.
  EXPECT_LE(false_discoveries, 20);
}

TEST(ForwardSelect, AVetoedCandidateIsDroppedAndTheSearchGoesOn) {
  Regression problem = MakeRegression(2, 0.5, -0.3);
  problem.vetoed = 0;
  SelectionOptions options;
  options.family = 10;
  std::vector<SelectionStep> log;
  const std::vector<int> chosen = ForwardSelect(problem, options, &log);
  EXPECT_EQ(chosen, (std::vector<int>{3}));
  EXPECT_EQ(log.front().reason, "vetoed");
}

}  // namespace
}  // namespace diffdyn
