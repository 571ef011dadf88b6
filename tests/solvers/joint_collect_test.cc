// Joint-space collection checked against an independent generator: the pendulum
// task's closed form m l^2 qdd + m g l sin q = tau integrated by a hand-written
// classic RK4 here; the ground-truth components add up to the torque; energies
// match their closed forms; the data do not depend on the thread count.
#include "diffdyn/solvers/joint_collect.h"

#include <cmath>

#include <gtest/gtest.h>

namespace diffdyn {
namespace {

constexpr double kM = 0.75, kL = 2.0 / 3.0, kG = 9.81;

// The pendulum task's closed form: (qd, (tau - m g l sin q) / (m l^2)).
Eigen::Vector2d PendulumRate(const Eigen::Vector2d& x, double tau) {
  return {x[1], (tau - kM * kG * kL * std::sin(x[0])) / (kM * kL * kL)};
}

TEST(CollectJointSpace, PendulumMatchesAnIndependentClosedFormIntegration) {
  const Dataset d = CollectJointSpace(JointTaskByName("pendulum"),
                                     {.trajectories = 3, .seconds = 1.0, .dt = 0.04, .seed = 7});
  ASSERT_EQ(d.trajectories.size(), 3u);
  EXPECT_EQ(d.system.action_names, std::vector<std::string>{"tau1"});
  for (const Trajectory& t : d.trajectories) {
    ASSERT_EQ(t.transitions(), 25);
    EXPECT_LE(t.actions.cwiseAbs().maxCoeff(), 2.5 * 0.6 + 1e-12);
    for (int k = 0; k < t.transitions(); ++k) {
      // Classic RK4, 10 steps of dt / 10 under the held torque.
      Eigen::Vector2d x = t.states.col(k);
      const double tau = t.actions(0, k), h = 0.004;
      for (int s = 0; s < 10; ++s) {
        const Eigen::Vector2d k1 = PendulumRate(x, tau), k2 = PendulumRate(x + 0.5 * h * k1, tau);
        const Eigen::Vector2d k3 = PendulumRate(x + 0.5 * h * k2, tau), k4 = PendulumRate(x + h * k3, tau);
        x += h / 6 * (k1 + 2 * k2 + 2 * k3 + k4);
      }
      EXPECT_NEAR((x - t.states.col(k + 1)).norm(), 0.0, 1e-10) << "transition " << k;
    }
    for (int k = 0; k <= t.transitions(); ++k) {
      const double q = t.states(0, k), qd = t.states(1, k);
      EXPECT_NEAR(t.channels.at("qdd")(0, k), PendulumRate(t.states.col(k), t.channels.at("tau")(0, k))[1], 1e-9);
      EXPECT_NEAR(t.channels.at("g")(0, k), kM * kG * kL * std::sin(q), 1e-9);
      EXPECT_NEAR(t.channels.at("c")(0, k), 0.0, 1e-9);
      EXPECT_NEAR(t.channels.at("kinetic")(0, k), 0.5 * kM * kL * kL * qd * qd, 1e-9);
      EXPECT_NEAR(t.channels.at("potential")(0, k), kM * kG * kL * (1 - std::cos(q)), 1e-7);
    }
  }
}

// tau = m + c + g + f on every joint of every sample (the cart-pole task has
// viscous friction on both joints; the pole is not actuated: its torque is 0).
TEST(CollectJointSpace, ComponentsAddUpToTheTorque) {
  const Dataset d = CollectJointSpace(JointTaskByName("cartpole"),
                                     {.trajectories = 2, .seconds = 0.5, .dt = 0.04, .seed = 3});
  EXPECT_EQ(d.system.action_names, std::vector<std::string>{"tau1"});
  for (const Trajectory& t : d.trajectories) {
    const Eigen::MatrixXd sum = t.channels.at("m") + t.channels.at("c") + t.channels.at("g") + t.channels.at("f");
    EXPECT_LT((sum - t.channels.at("tau")).cwiseAbs().maxCoeff(), 1e-9);
    EXPECT_EQ(t.channels.at("tau").row(1).cwiseAbs().maxCoeff(), 0.0);
    // Viscous friction: f = b qd.
    EXPECT_LT((t.channels.at("f").row(0) - 0.1 * t.states.row(2)).cwiseAbs().maxCoeff(), 1e-12);
  }
}

TEST(CollectJointSpace, SameDataAtAnyThreadCountAndSeedMatters) {
  const JointTask task = JointTaskByName("double-pendulum");
  const Dataset one = CollectJointSpace(task, {.trajectories = 4, .seconds = 0.4, .seed = 2, .threads = 1});
  const Dataset two = CollectJointSpace(task, {.trajectories = 4, .seconds = 0.4, .seed = 2, .threads = 2});
  const Dataset other = CollectJointSpace(task, {.trajectories = 4, .seconds = 0.4, .seed = 3, .threads = 2});
  for (int i = 0; i < 4; ++i) {
    EXPECT_EQ(one.trajectories[i].states, two.trajectories[i].states);
    EXPECT_EQ(one.trajectories[i].channels, two.trajectories[i].channels);
    EXPECT_NE(one.trajectories[i].states, other.trajectories[i].states);
  }
  EXPECT_THROW(CollectJointSpace(task, {.dt = -1.0}), Error);
  EXPECT_THROW(CollectJointSpace(task, {.seconds = 0.01, .dt = 0.04}), Error);
}

TEST(JointTask, SystemsEffectsAndActuation) {
  const JointTask cartpole = JointTaskByName("cartpole");
  const SystemDescription s = cartpole.System();
  EXPECT_EQ(s.state_size(), 4);
  EXPECT_EQ(s.action_names, std::vector<std::string>{"tau1"});
  EXPECT_EQ(s.angles, std::vector<int>{1});  // the cart is not an angle
  EXPECT_EQ(s.action_high[0], 20.0);
  const JointTask all = cartpole.ActuatingAll();
  EXPECT_EQ(all.System().action_names, (std::vector<std::string>{"tau1", "tau2"}));
  EXPECT_EQ(all.feedback.rows(), 2);
  EXPECT_EQ(all.feedback(0, 0), 3.0);
  EXPECT_EQ(all.feedback.row(1).cwiseAbs().maxCoeff(), 0.0);
  const Effect e = ParseEffectSpec("stribeck:2=0.1,0.3,0.05", "--effect");
  EXPECT_EQ(e.kind, EffectKind::kStribeck);
  EXPECT_EQ(e.joint, 2);
  EXPECT_EQ(e.params, (std::vector<double>{0.1, 0.3, 0.05}));
  for (const char* bad : {"viscous", "viscous:1", "friction:1=2", "viscous:x=1", "viscous:1=nan",
                          "viscous:1=1,2", "stribeck:1=1"}) {
    EXPECT_THROW(ParseEffectSpec(bad, "--effect"), Error) << bad;
  }
  EXPECT_THROW(JointTaskByName("robot"), Error);
  for (const std::string& name : JointTaskNames()) EXPECT_NO_THROW(JointTaskByName(name).Plant()) << name;
}

}  // namespace
}  // namespace diffdyn
