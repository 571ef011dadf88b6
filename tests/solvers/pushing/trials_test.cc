// Pushing trials: Wilson intervals, MPPI in the ODE world, determinism, bad options.
#include "diffdyn/solvers/pushing/trials.h"

#include <cmath>
#include <numbers>

#include <gtest/gtest.h>

#include "diffdyn/physics/pushing/oracle.h"
#include "../toy_models.h"

namespace diffdyn {
namespace {

// A rough kinematic block: the push moves the centre along the block's x axis by the
// push's component d = 0.1 u2 cos(u1) on it, and an off-centre push (u0) turns it.
class KinematicBlock : public toy::ToyModel {
 public:
  KinematicBlock() : ToyModel(3, 3, "kinematic") {}
  void PredictBatch(const Eigen::Ref<const Eigen::MatrixXd>& states,
                    const Eigen::Ref<const Eigen::MatrixXd>& actions,
                    Eigen::Ref<Eigen::MatrixXd> next, TransitionWorkspace&) const override {
    CheckBatchSizes(states, actions, next);
    for (Eigen::Index b = 0; b < states.cols(); ++b) {
      const double theta = states(2, b), d = 0.1 * actions(2, b) * std::cos(actions(1, b));
      next(0, b) = states(0, b) + d * std::cos(theta);
      next(1, b) = states(1, b) + d * std::sin(theta);
      next(2, b) = theta - 5.0 * actions(0, b) * d;
    }
  }
};

// A model of the wrong shape.
class WrongSizes : public KinematicBlock {
 public:
  int state_size() const override { return 2; }
};

TEST(PushTrials, KinematicModelPushesToTheFreeGoalInTheOdeWorld) {
  KinematicBlock model;
  PushTaskOptions o;
  o.obstacle = false;
  o.samples = 200;
  o.horizon = 6;
  o.max_steps = 15;
  const PushTrialsSummary s = RunPushTrials(model, 2, o, /*seed=*/3);
  ASSERT_EQ(s.runs.size(), 2u);
  for (const PushTrial& t : s.runs) {
    EXPECT_EQ(t.outcome, "success") << "pushes " << t.pushes;
    EXPECT_EQ(t.poses.size(), t.actions.size() + 1);
    EXPECT_EQ(static_cast<int>(t.command_ms.size()), t.pushes);
    // The model's prediction of every executed push, F(poses[k], actions[k]).
    ASSERT_EQ(t.predicted.size(), t.actions.size());
    auto ws = model.MakeWorkspace(1);
    for (std::size_t k = 0; k < t.predicted.size(); ++k) {
      Eigen::MatrixXd next(3, 1);
      model.PredictBatch(t.poses[k], t.actions[k], next, *ws);
      EXPECT_EQ(t.predicted[k], Eigen::Vector3d(next.col(0))) << "push " << k;
    }
    EXPECT_LT((t.poses.back().head<2>() - t.goal.head<2>()).norm(), o.goal_tolerance);
    // The perturbed start lies within the jitter of the free task's start.
    const Eigen::Vector3d d = t.start - PushTaskStart(false);
    EXPECT_LE(d.head<2>().norm(), o.start_xy_jitter + 1e-12);
    EXPECT_LE(std::abs(d.z()), o.start_theta_jitter + 1e-12);
    for (const auto& a : t.actions) {
      EXPECT_TRUE(a[0] >= -1 && a[0] <= 1 && std::abs(a[1]) <= std::numbers::pi / 2 &&
                  a[2] >= 0 && a[2] <= 1)
          << a.transpose();
    }
  }
  EXPECT_EQ(s.successes, 2);
  EXPECT_DOUBLE_EQ(s.success_rate, 1.0);
  EXPECT_NEAR(s.ci95_high, 1.0, 1e-12);
  EXPECT_GT(s.ms_per_command, 0.0);
  EXPECT_NEAR(s.mean_pushes, (s.runs[0].pushes + s.runs[1].pushes) / 2.0, 1e-12);
}

TEST(PushTrials, OracleReachesANearbyGoal) {
  // The ODE world itself as the MPPI model, from 0.16 m before the goal.
  PushingOracle oracle(PushingConfig{});
  PushTaskOptions o;
  o.obstacle = false;
  o.samples = 24;
  o.horizon = 2;
  o.max_steps = 4;
  o.start = Eigen::Vector3d(0.64, 0.0, 0.0);
  const PushTrial t = RunPushTrial(oracle, 0, o, /*seed=*/5);
  EXPECT_TRUE(t.success) << t.outcome << " after " << t.pushes << " pushes, at "
                         << t.poses.back().transpose();
}

TEST(PushTrials, SameSeedSameTrialsAtAnyThreadCount) {
  KinematicBlock model;
  PushTaskOptions o;  // obstacle task
  o.samples = 250;
  o.horizon = 8;
  o.max_steps = 6;
  o.threads = 1;
  const PushTrialsSummary a = RunPushTrials(model, 2, o, 9);
  o.threads = 2;
  const PushTrialsSummary b = RunPushTrials(model, 2, o, 9);
  // Trial 1 alone equals trial 1 of the series.
  const PushTrial c = RunPushTrial(model, 1, o, 9);
  ASSERT_EQ(a.runs.size(), b.runs.size());
  for (std::size_t i = 0; i < a.runs.size(); ++i) {
    EXPECT_EQ(a.runs[i].outcome, b.runs[i].outcome);
    ASSERT_EQ(a.runs[i].poses.size(), b.runs[i].poses.size());
    for (std::size_t k = 0; k < a.runs[i].poses.size(); ++k) {
      EXPECT_EQ(a.runs[i].poses[k], b.runs[i].poses[k]);
    }
    ASSERT_EQ(a.runs[i].actions.size(), b.runs[i].actions.size());
    for (std::size_t k = 0; k < a.runs[i].actions.size(); ++k) {
      EXPECT_EQ(a.runs[i].actions[k], b.runs[i].actions[k]);
    }
  }
  ASSERT_EQ(c.actions.size(), a.runs[1].actions.size());
  for (std::size_t k = 0; k < c.actions.size(); ++k) EXPECT_EQ(c.actions[k], a.runs[1].actions[k]);
  // Another seed starts elsewhere.
  const PushTrial other = RunPushTrial(model, 0, o, 10);
  EXPECT_NE(other.start, a.runs[0].start);
}

TEST(PushTrials, RejectsBadOptions) {
  KinematicBlock model;
  PushTaskOptions o;
  EXPECT_THROW(RunPushTrials(model, 0, o, 1), Error);
  PushTaskOptions bad = o;
  bad.samples = 0;
  EXPECT_THROW(RunPushTrials(model, 1, bad, 1), Error);
  bad = o;
  bad.horizon = -1;
  EXPECT_THROW(RunPushTrials(model, 1, bad, 1), Error);
  bad = o;
  bad.max_steps = 0;
  EXPECT_THROW(RunPushTrials(model, 1, bad, 1), Error);
  bad = o;
  bad.goal_tolerance = 0;
  EXPECT_THROW(RunPushTrials(model, 1, bad, 1), Error);
  bad = o;
  bad.start_xy_jitter = std::nan("");
  EXPECT_THROW(RunPushTrials(model, 1, bad, 1), Error);
  bad = o;
  bad.fallback_margin = -1;
  EXPECT_THROW(RunPushTrials(model, 1, bad, 1), Error);
  WrongSizes wrong;
  EXPECT_THROW(RunPushTrials(wrong, 1, o, 1), Error);
}

}  // namespace
}  // namespace diffdyn
