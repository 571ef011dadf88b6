// Diagnosis stage 1: noise estimates and the cutoff rule.
#include "diffdyn/solvers/diagnosis/prepare.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>
#include <numbers>
#include <random>

#include <gtest/gtest.h>

#include "diffdyn/physics/model_registry.h"
#include "diffdyn/solvers/dataset_io.h"

namespace diffdyn {
namespace {

// One joint's samples: times, q, qd and tau (1 x N).
struct Signals {
  Eigen::VectorXd t;
  Eigen::MatrixXd q, qd, tau;

  Dataset AsDataset() const { return JointSpaceDataset("record.csv", t, q, qd, tau); }
};

// One joint: `signal(t)` plus white noise sigma, samples at spacing dt (+- jitter).
Signals Record(double seconds, double dt, double jitter, double sigma, std::uint64_t seed,
               double (*signal)(double)) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> uniform(-jitter, jitter);
  Signals d;
  const int count = static_cast<int>(seconds / dt);
  d.t.resize(count);
  d.q.resize(1, count);
  d.qd.resize(1, count);
  d.tau.resize(1, count);
  for (int k = 0; k < count; ++k) {
    d.t[k] = k * dt + uniform(rng) * dt;
    d.q(0, k) = std::sin(d.t[k]);
    d.qd(0, k) = std::cos(d.t[k]);
    d.tau(0, k) = signal(d.t[k]) + sigma * normal(rng);
  }
  return d;
}

double Motion(double t) { return 3.0 * std::sin(2 * std::numbers::pi * 0.7 * t) + 0.5 * t; }
// Holds of 3 s at different levels (a static record with jumps between poses).
double Holds(double t) { return 2.0 * std::floor(t / 3.0) - 5.0; }

TEST(EstimateWhiteNoise, RecoversTheSigmaOfMovingAndHeldSignals) {
  struct Case {
    double dt, jitter;
    double (*signal)(double);
  };
  for (const Case& c : {Case{1e-3, 0.0, Motion}, Case{1e-3, 0.3, Motion}, Case{0.05, 0.0, Holds},
                        Case{0.05, 0.2, Holds}}) {
    const Signals d = Record(60.0, c.dt, c.jitter, 0.1, 3, c.signal);
    const Eigen::VectorXd sigma = EstimateWhiteNoise(d.t, d.tau, {0});
    EXPECT_NEAR(sigma[0], 0.1, 0.01) << "dt " << c.dt << " jitter " << c.jitter;
  }
}

TEST(EstimateWhiteNoise, IsZeroForALinearSignal) {
  const Signals d = Record(10.0, 1e-2, 0.0, 0.0, 1, [](double t) { return 2.0 * t - 1.0; });
  EXPECT_LT(EstimateWhiteNoise(d.t, d.tau, {0})[0], 1e-9);
}

// The real Panda log repeats its exciting trajectory every 2 pi / (0.15 pi) =
// 13.33 s (gen_params.txt), so tau(t + P) - tau(t) holds twice the torque
// sensor's scatter plus whatever does not repeat. The neighbour-line estimate
// of each joint's noise must be of that size (robust spread of the differences
// over sqrt(2)): measured 0.59-1.17 of it.
TEST(EstimateWhiteNoise, RealPandaNoiseIsTheScatterBetweenRepeats) {
  const Dataset d = ReadDataset(std::string(DIFFDYN_SHARED_DATA_DIR) + "/panda_gaz2019_traj1");
  const Trajectory& run = d.trajectories.at(0);
  const Eigen::VectorXd sigma = EstimateWhiteNoise(run.t, run.actions, {0});
  const double period = 2.0 / 0.15;
  for (int j = 0; j < 7; ++j) {
    std::vector<double> diff;
    for (Eigen::Index k = 0, m = 0; k < run.t.size() && run.t[k] + period <= run.t[run.t.size() - 1]; ++k) {
      while (run.t[m + 1] < run.t[k] + period) ++m;  // run.t[m] < t + P <= run.t[m + 1]
      const double w = (run.t[k] + period - run.t[m]) / (run.t[m + 1] - run.t[m]);
      diff.push_back((1 - w) * run.actions(j, m) + w * run.actions(j, m + 1) - run.actions(j, k));
    }
    const auto mid = diff.begin() + static_cast<std::ptrdiff_t>(diff.size() / 2);
    std::nth_element(diff.begin(), mid, diff.end());
    const double median = *mid;
    for (double& v : diff) v = std::abs(v - median);
    std::nth_element(diff.begin(), mid, diff.end());
    const double scatter = 1.4826 * *mid / std::sqrt(2.0);
    EXPECT_GT(sigma[j], 0.5 * scatter) << "joint " << j + 1 << " scatter " << scatter;
    EXPECT_LT(sigma[j], 1.5 * scatter) << "joint " << j + 1 << " scatter " << scatter;
  }
}

// A qd that is the backward difference of q is found and moved half a sample
// earlier: its error against the true velocity drops from O(T) to O(T^2).
TEST(RecentreVelocity, MovesABackwardDifferenceToTheSampleTimes) {
  Signals d = Record(10.0, 1e-2, 0.0, 0.0, 1, Motion);
  EXPECT_FALSE(IsBackwardDifference(d.AsDataset()));
  const int count = static_cast<int>(d.t.size());
  for (int k = 1; k < count; ++k) d.qd(0, k) = (d.q(0, k) - d.q(0, k - 1)) / (d.t[k] - d.t[k - 1]);
  d.qd(0, 0) = d.qd(0, 1);
  ASSERT_TRUE(IsBackwardDifference(d.AsDataset()));
  const Dataset r = RecentreVelocity(d.AsDataset());
  double before = 0, after = 0;
  for (int k = 1; k + 1 < count; ++k) {
    before = std::max(before, std::abs(d.qd(0, k) - std::cos(d.t[k])));
    after = std::max(after, std::abs(r.trajectories[0].states(1, k) - std::cos(d.t[k])));
  }
  EXPECT_GT(before, 4e-3);  // about T/2 |q''|
  EXPECT_LT(after, 5e-5);
}

double Sine2Hz(double t) { return std::sin(2 * std::numbers::pi * 2.0 * t); }
double Sine3Hz(double t) { return std::sin(2 * std::numbers::pi * 3.0 * t); }
double Still(double /*t*/) { return 1.5; }

TEST(TorqueBandwidthHz, IsTheFrequencyOfASineAndCappedForNoise) {
  EXPECT_NEAR(TorqueBandwidthHz(Record(30.0, 0.01, 0.05, 0.0, 1, Sine2Hz).AsDataset(), 0.99, 5.0), 2.0, 0.1);
  // White noise spreads its power to the Nyquist frequency: not reached below 5 Hz.
  EXPECT_DOUBLE_EQ(TorqueBandwidthHz(Record(30.0, 0.05, 0.0, 1.0, 1, Still).AsDataset(), 0.99, 5.0), 5.0);
}

// min(10 Hz, f_s / 4, max(f_s / 12, 2 f_99)): 10 Hz from 120 Hz up; at lower rates
// the kernel spans at least 1.6 samples (s = sqrt(ln 2) / (2 pi f_c)) unless the
// torque's bandwidth needs a higher cutoff.
TEST(DefaultCutoffHz, SpansSamplesAtLowRatesAndKeepsTheTorquesBandwidth) {
  EXPECT_DOUBLE_EQ(DefaultCutoffHz(Record(5.0, 1e-3, 0.0, 0.0, 1, Motion).AsDataset()), kMaxCutoffHz);
  EXPECT_NEAR(DefaultCutoffHz(Record(5.0, 1.0 / 120, 0.0, 0.0, 1, Motion).AsDataset()), kMaxCutoffHz, 1e-9);
  const double slow = DefaultCutoffHz(Record(30.0, 1.0 / 60, 0.0, 0.0, 1, Motion).AsDataset());
  EXPECT_NEAR(slow, 5.0, 1e-9);  // 0.7 Hz motion: f_s / 12
  EXPECT_GT(std::sqrt(std::log(2.0)) / (2 * std::numbers::pi * slow), 1.5 / 60);
  // A 3 Hz torque at 25 Hz: f_s / 12 = 2.1 Hz would remove it; the floor 2 f_99 keeps it.
  EXPECT_NEAR(DefaultCutoffHz(Record(30.0, 0.04, 0.0, 0.0, 1, Sine3Hz).AsDataset()), 6.0, 0.25);
  // A held pose at 20 Hz, torque noise only: f_s / 4.
  EXPECT_NEAR(DefaultCutoffHz(Record(30.0, 0.05, 0.0, 0.1, 1, Still).AsDataset()), 5.0, 1e-9);
}

TEST(PrepareData, SplitsInTimeAndRefusesAShortRecord) {
  const auto model = MakeAnalyticModel("pendulum");
  const Dataset d = Record(20.0, 1e-2, 0.0, 0.01, 2, Motion).AsDataset();
  const PreparedData prep = PrepareData(ExtendedModel(model, model->DefaultParams(), {}), d, PrepareOptions{});
  ASSERT_FALSE(prep.train.empty());
  EXPECT_LT(prep.train.back(), prep.heldout.front());
  EXPECT_NEAR(static_cast<double>(prep.heldout.size()) / prep.rows, 0.3, 0.02);
  EXPECT_GT(prep.n_eff, 10.0);
  EXPECT_TRUE(prep.residual.allFinite());
  EXPECT_NEAR(prep.noise_std[0], 0.01, 0.002);
  EXPECT_THROW(PrepareData(ExtendedModel(model, model->DefaultParams(), {}), Record(0.15, 1e-2, 0.0, 0.01, 2, Motion).AsDataset(),
                           PrepareOptions{}),
               Error);
}

}  // namespace
}  // namespace diffdyn
