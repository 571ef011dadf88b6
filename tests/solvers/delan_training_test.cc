// DeLaN training on joint-space data: the authors' split of the characters, a
// seeded split elsewhere, training that learns, thread invariance, and scores that
// agree with the training loss.
#include "diffdyn/solvers/delan_training.h"

#include <cmath>
#include <set>

#include <gtest/gtest.h>

#include "diffdyn/solvers/dataset_io.h"

namespace diffdyn {
namespace {

const std::string kCharacters = std::string(DIFFDYN_SHARED_DATA_DIR) + "/delan_characters";

TEST(DelanTraining, CharactersSplitHoldsOutEQV) {
  const Dataset data = ReadDataset(kCharacters);
  ASSERT_EQ(data.trajectories.size(), 20u);
  EXPECT_EQ(data.trajectories.front().label, "b");
  const DelanSplit split = SplitForDelan(data, 0.5, 7);  // val_fraction does not apply
  EXPECT_EQ(split.train.size(), 2459);
  EXPECT_EQ(split.test.size(), 454);
  EXPECT_EQ(split.test.qdd.cols(), 454);
  EXPECT_EQ(split.test.channels.at("g").cols(), 454);
  // The test samples are exactly those of e, q, v, in file order.
  std::vector<Eigen::VectorXd> test_tau;
  for (const Trajectory& t : data.trajectories) {
    if (t.label != "e" && t.label != "q" && t.label != "v") continue;
    for (Eigen::Index i = 0; i < t.states.cols(); ++i) test_tau.push_back(t.channels.at("tau").col(i));
  }
  ASSERT_EQ(test_tau.size(), 454u);
  for (int i = 0; i < 454; ++i) EXPECT_EQ(split.test.tau.col(i), test_tau[i]);
}

TEST(DelanTraining, OtherDataGetsASeededSplit) {
  Dataset data = ReadDataset(kCharacters);
  data.format = "joint-csv";
  const DelanSplit a = SplitForDelan(data, 0.25, 3), b = SplitForDelan(data, 0.25, 3),
                   c = SplitForDelan(data, 0.25, 4);
  EXPECT_EQ(a.test.size(), 728);  // round(0.25 * 2913)
  EXPECT_EQ(a.train.size() + a.test.size(), 2913);
  EXPECT_TRUE(a.test.q == b.test.q);
  EXPECT_FALSE(a.test.q == c.test.q);
}

// Without a qdd channel the samples are smoothed and qdd estimated: on a
// trajectory q = sin(t) the estimate is close to -sin(t) inside.
TEST(DelanTraining, SamplesEstimateAccelerationsWhereNoneWereMeasured) {
  const Eigen::VectorXd t = Eigen::VectorXd::LinSpaced(2001, 0.0, 4.0);
  const Eigen::MatrixXd q = t.array().sin().matrix().transpose();
  const Eigen::MatrixXd qd = t.array().cos().matrix().transpose();
  const Dataset data = JointSpaceDataset("sine", t, q, qd, Eigen::MatrixXd::Ones(1, t.size()));
  const DelanSamples s = SamplesOf(data);
  ASSERT_EQ(s.size(), 2001);
  for (int k = 500; k <= 1500; k += 250) EXPECT_NEAR(s.qdd(0, k), -std::sin(t[k]), 2e-3) << k;
  EXPECT_TRUE(s.measured_torque);
}

TEST(DelanTraining, LearnsAndIsTheSameAtAnyThreadCount) {
  const DelanSplit split = SplitForDelan(ReadDataset(kCharacters), 0.2, 0);
  TrainOptions options = DelanTrainDefaults();
  options.epochs = 60;
  options.progress = false;
  options.chunk_size = 128;
  Delan one = Delan::Initialized({.dof = 2, .hidden = 32}, 1), two = one;
  const std::map<std::string, double> before = ScoreDelan(one, split.test);
  options.threads = 1;
  const TrainResult r1 = TrainDelan(&one, split.train, split.test, options);
  options.threads = 2;
  const TrainResult r2 = TrainDelan(&two, split.train, split.test, options);
  EXPECT_TRUE(one.parameters() == two.parameters());
  EXPECT_EQ(r1.final_val_loss, r2.final_val_loss);
  const std::map<std::string, double> after = ScoreDelan(one, split.test);
  EXPECT_LT(after.at("torque_mse"), 0.2 * before.at("torque_mse"));
  // The score is the training loss's definition on the held-out samples.
  EXPECT_NEAR(after.at("torque_mse"), r1.final_val_loss, 1e-12 * r1.final_val_loss);
  EXPECT_GE(after.at("min_mass_eigenvalue"), one.options().epsilon);
  for (const char* key : {"inertial_mse", "coriolis_mse", "gravity_mse", "power_mse", "torque_nmse"}) {
    EXPECT_TRUE(after.count(key)) << key;
  }
}

TEST(DelanTraining, RefusesDataOfAnotherSize) {
  const DelanSplit split = SplitForDelan(ReadDataset(kCharacters), 0.2, 0);
  Delan model = Delan::Initialized({.dof = 3}, 0);
  EXPECT_THROW(TrainDelan(&model, split.train, split.test, DelanTrainDefaults()), Error);
  EXPECT_THROW(ScoreDelan(model, split.test), Error);
}

// w_j = 1 / Var(tau_j); an unactuated joint (tau = 0) gets the largest other weight;
// data without varying torque are refused.
TEST(DelanTraining, BalancedJointWeights) {
  DelanSamples d;
  d.path = "weights.csv";
  d.q = d.qd = d.qdd = Eigen::MatrixXd::Zero(3, 4);
  d.tau = Eigen::MatrixXd::Zero(3, 4);
  d.tau.row(0) << 1, -1, 1, -1;      // variance 1
  d.tau.row(1) << 10, -10, 10, -10;  // variance 100
  const Eigen::VectorXd w = BalancedJointWeights(d);
  ASSERT_EQ(w.size(), 3);
  EXPECT_DOUBLE_EQ(w[0], 1.0);
  EXPECT_DOUBLE_EQ(w[1], 0.01);
  EXPECT_DOUBLE_EQ(w[2], 1.0);
  d.tau.setZero();
  EXPECT_THROW(BalancedJointWeights(d), Error);
}

}  // namespace
}  // namespace diffdyn
