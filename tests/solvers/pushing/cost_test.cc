// The pushing cost's safety margin and swept test, and MPPI's transition-cost form.
#include "diffdyn/solvers/pushing/cost.h"

#include <cmath>
#include <numbers>
#include <vector>

#include <gtest/gtest.h>

#include "diffdyn/models/random.h"
#include "diffdyn/solvers/mppi.h"
#include "diffdyn/solvers/pushing/trials.h"
#include "../toy_models.h"

namespace diffdyn {
namespace {

const Eigen::Vector3d kGoal(0.8, -0.1, 0.0);
constexpr double kPi = std::numbers::pi;

// Sums the cost of one pose (Accumulate) or one transition (AccumulateStep).
double PoseCost(const PushingCost& cost, const Eigen::Vector3d& x) {
  Eigen::VectorXd c = Eigen::VectorXd::Zero(1);
  cost.Accumulate(x, c);
  return c[0];
}
double StepCost(const PushingCost& cost, const Eigen::Vector3d& x0, const Eigen::Vector3d& x1) {
  Eigen::VectorXd c = Eigen::VectorXd::Zero(1);
  cost.AccumulateStep(0, x0, Eigen::Vector3d::Zero(), x1, c);
  return c[0];
}
double GoalTerm(const Eigen::Vector3d& x) {
  const Eigen::Vector3d d = x - kGoal;
  return d.x() * d.x() + d.y() * d.y() + 0.1 * d.z() * d.z();
}

TEST(PushingCostSafety, SweptTestCatchesAJumpAcrossTheObstacle) {
  // Both ends clear (obstacle x in [0.55, 0.65]); the straight path crosses it.
  const Eigen::Vector3d before(0.48, 0.2, 0.0), after(0.72, 0.2, 0.3);
  PushingCost cost(kGoal, true);
  EXPECT_FALSE(cost.InCollision(before));
  EXPECT_FALSE(cost.InCollision(after));
  EXPECT_DOUBLE_EQ(StepCost(cost, before, after), GoalTerm(after));
  cost.set_collision_substeps(4);
  EXPECT_DOUBLE_EQ(StepCost(cost, before, after), GoalTerm(after) + 100.0);
  // Reversed, too; and a step that stays clear costs nothing extra.
  EXPECT_DOUBLE_EQ(StepCost(cost, after, before), GoalTerm(before) + 100.0);
  const Eigen::Vector3d below(0.72, -0.2, 0.0);
  EXPECT_DOUBLE_EQ(StepCost(cost, Eigen::Vector3d(0.48, -0.2, 0.0), below), GoalTerm(below));
  // The angle is interpolated the short way round. At x = 0.49 the block is clear
  // when axis-aligned (x <= 0.54) and at 3 rad (x <= 0.5465), and overlaps at
  // 2.25 rad (x <= 0.5603). From 3 to -3 rad the short way passes pi (clear), the
  // long way would pass 2.25 rad.
  cost.set_collision_substeps(7);
  const Eigen::Vector3d at3(0.49, 0.2, 3.0), at_minus3(0.49, 0.2, -3.0), at15(0.49, 0.2, 1.5);
  EXPECT_FALSE(cost.InCollision(at3));
  EXPECT_FALSE(cost.InCollision(at_minus3));
  EXPECT_FALSE(cost.InCollision(at15));
  EXPECT_TRUE(cost.InCollision(Eigen::Vector3d(0.49, 0.2, 2.25)));
  EXPECT_DOUBLE_EQ(StepCost(cost, at3, at_minus3), GoalTerm(at_minus3));
  EXPECT_DOUBLE_EQ(StepCost(cost, at3, at15), GoalTerm(at15) + 100.0);
}

TEST(PushingCostSafety, MarginCatchesAPoseFiveMillimetresAway) {
  const Eigen::Vector3d pose(0.495, 0.2, 0.0);  // block x in [0.445, 0.545]: 5 mm gap
  PushingCost cost(kGoal, true);
  EXPECT_FALSE(cost.InCollision(pose));
  cost.set_collision_margin(0.004);
  EXPECT_FALSE(cost.InCollision(pose));
  cost.set_collision_margin(0.01);
  EXPECT_TRUE(cost.InCollision(pose));
  EXPECT_DOUBLE_EQ(PoseCost(cost, pose), GoalTerm(pose) + 100.0);
  // Resting 0.1 mm from it (the ODE world stops the block at the obstacle): clear
  // for the seed's test, caught by a 1 mm margin.
  const Eigen::Vector3d touching(0.4999, 0.2, 0.0);
  cost.set_collision_margin(0.0);
  EXPECT_FALSE(cost.InCollision(touching));
  cost.set_collision_margin(0.001);
  EXPECT_TRUE(cost.InCollision(touching));
  EXPECT_THROW(cost.set_collision_margin(-0.01), Error);
  EXPECT_THROW(cost.set_collision_substeps(-1), Error);
  PushTaskOptions options;
  options.collision_margin = -1;
  EXPECT_THROW(ValidatePushTaskOptions(options), Error);
}

TEST(RectangleDistance, GapsBetweenEdgesAndCorners) {
  const Rectangle obstacle = PushingCost::Obstacle();  // x in [0.55, 0.65], y in [-0.05, 0.45]
  // Edge to edge: block x in [0.445, 0.545], 5 mm to the obstacle's left face.
  EXPECT_NEAR(RectangleDistance({{0.495, 0.2}, {0.05, 0.05}, 0.0}, obstacle), 0.005, 1e-12);
  // Below the lower-left corner (0.55, -0.05), diagonally: 3 cm and 4 cm apart -> 5 cm.
  EXPECT_NEAR(RectangleDistance({{0.47, -0.14}, {0.05, 0.05}, 0.0}, obstacle), 0.05, 1e-12);
  // A block turned by 45 degrees whose corner points at the left face from 1 cm.
  const double half_diagonal = 0.05 * std::sqrt(2.0);
  EXPECT_NEAR(RectangleDistance({{0.54 - half_diagonal, 0.2}, {0.05, 0.05}, std::numbers::pi / 4},
                                obstacle),
              0.01, 1e-12);
  // Overlapping: 0, and symmetric in its arguments.
  EXPECT_EQ(RectangleDistance({{0.55, 0.2}, {0.05, 0.05}, 0.3}, obstacle), 0.0);
  const Rectangle block{{0.4, -0.1}, {0.05, 0.05}, -0.4};
  EXPECT_DOUBLE_EQ(RectangleDistance(block, obstacle), RectangleDistance(obstacle, block));
}

TEST(PushingCostSafety, ClearanceGrowsSmoothlyTowardTheObstacle) {
  PushingCost cost(kGoal, true);
  cost.set_collision_substeps(4);
  // Off by default: the step cost is the goal term alone away from the obstacle.
  const Eigen::Vector3d far(0.3, -0.2, 0.0), near(0.48, 0.2, 0.0), nearer(0.495, 0.2, 0.0);
  EXPECT_DOUBLE_EQ(StepCost(cost, far, near), GoalTerm(near));
  cost.set_clearance(0.05, 2.0);
  // 2 cm gap: 2 (1 - 0.02 / 0.05)^2 = 0.72; 5 mm: 2 (0.9)^2 = 1.62; far away: 0.
  EXPECT_NEAR(StepCost(cost, near, near), GoalTerm(near) + 0.72, 1e-12);
  EXPECT_NEAR(StepCost(cost, nearer, nearer), GoalTerm(nearer) + 1.62, 1e-12);
  EXPECT_DOUBLE_EQ(StepCost(cost, far, far), GoalTerm(far));
  // A step is charged at its closest swept pose: sliding 5 mm past the left face
  // costs 1.62 although both of its ends are 15 cm from the obstacle.
  const Eigen::Vector3d below(0.495, -0.25, 0.0), above(0.495, 0.65, 0.0);
  EXPECT_NEAR(StepCost(cost, below, above), GoalTerm(above) + 1.62, 1e-12);
  EXPECT_DOUBLE_EQ(PoseCost(cost, above), GoalTerm(above));
  // The state form charges the end pose.
  EXPECT_NEAR(PoseCost(cost, near), GoalTerm(near) + 0.72, 1e-12);
  EXPECT_THROW(cost.set_clearance(-0.01, 1.0), Error);
  EXPECT_THROW(cost.set_clearance(0.05, -1.0), Error);
  PushTaskOptions options;
  options.clearance_weight = -1;
  EXPECT_THROW(ValidatePushTaskOptions(options), Error);
}

TEST(PushingCostSafety, MarginZeroWithoutSweepIsTheSeedsCostExactly) {
  // The seed's cost written out: quadratic goal term + 100 x exact overlap of the block.
  Rng rng(5);
  const int n = 3000;
  Eigen::MatrixXd prev(3, n), states(3, n);
  for (int b = 0; b < n; ++b) {
    for (Eigen::MatrixXd* m : {&prev, &states}) {
      (*m)(0, b) = Uniform(rng, 0.35, 0.85);
      (*m)(1, b) = Uniform(rng, -0.2, 0.6);
      (*m)(2, b) = Uniform(rng, -std::numbers::pi, std::numbers::pi);
    }
  }
  PushingCost cost(kGoal, true);
  Eigen::VectorXd pose_costs = Eigen::VectorXd::Zero(n), step_costs = Eigen::VectorXd::Zero(n);
  cost.Accumulate(states, pose_costs);
  cost.AccumulateStep(0, prev, Eigen::MatrixXd::Zero(3, n), states, step_costs);
  int collisions = 0;
  for (int b = 0; b < n; ++b) {
    const Eigen::Vector3d x = states.col(b);
    const bool hit =
        RectanglesOverlap({x.head<2>(), {0.05, 0.05}, x.z()}, PushingCost::Obstacle());
    collisions += hit;
    const double seed = GoalTerm(x) + (hit ? 100.0 : 0.0);
    ASSERT_EQ(pose_costs[b], seed) << "pose " << x.transpose();
    ASSERT_EQ(step_costs[b], seed) << "pose " << x.transpose();
  }
  EXPECT_GT(collisions, 50);
  EXPECT_LT(collisions, n - 50);
}

// The seed's pushing cost with only the pose form (MppiCost's default step form).
class PoseOnlyCost : public MppiCost {
 public:
  void Accumulate(const Eigen::Ref<const Eigen::MatrixXd>& states,
                  Eigen::Ref<Eigen::VectorXd> costs) const override {
    inner_.Accumulate(states, costs);
  }

 private:
  PushingCost inner_{kGoal, true};
};

// Records the transitions MPPI hands to the step form (one chunk, one thread).
class RecordingCost : public MppiCost {
 public:
  void Accumulate(const Eigen::Ref<const Eigen::MatrixXd>&,
                  Eigen::Ref<Eigen::VectorXd>) const override {
    ADD_FAILURE() << "Mppi should call the step form";
  }
  void AccumulateStep(int t, const Eigen::Ref<const Eigen::MatrixXd>& prev,
                      const Eigen::Ref<const Eigen::MatrixXd>& actions,
                      const Eigen::Ref<const Eigen::MatrixXd>& states,
                      Eigen::Ref<Eigen::VectorXd>) const override {
    steps.push_back(t);
    prevs.push_back(prev);
    acts.push_back(actions);
    nexts.push_back(states);
  }
  mutable std::vector<int> steps;
  mutable std::vector<Eigen::MatrixXd> prevs, acts, nexts;
};

MppiOptions SmallOptions() {
  MppiOptions o;
  o.samples = 64;
  o.horizon = 6;
  o.chunk_size = 64;
  o.threads = 1;
  o.u_min = Eigen::Vector3d(-1.0, -1.0, -1.0);
  o.u_max = Eigen::Vector3d(1.0, 1.0, 1.0);
  return o;
}

TEST(MppiStepCost, CostsWithoutAStepFormGiveUnchangedResults) {
  // PushingCost with margin 0 and no sweep, and the same cost without a step form,
  // give bit-identical commands and sample costs.
  toy::DriftModel model(3);
  PoseOnlyCost pose_only;
  PushingCost seed_cost(kGoal, true);
  Mppi a(model, pose_only, SmallOptions(), 3), b(model, seed_cost, SmallOptions(), 3);
  Eigen::Vector3d x(0.45, 0.1, -0.5);
  for (int i = 0; i < 6; ++i) {
    const Eigen::VectorXd ua = a.Command(x), ub = b.Command(x);
    ASSERT_EQ(ua, ub);
    ASSERT_EQ(a.sample_costs(), b.sample_costs());
    x += 0.1 * ua;
  }
}

TEST(MppiStepCost, StepFormSeesTheStateBeforeEachStep) {
  toy::DriftModel model(3);
  RecordingCost cost;
  Mppi mppi(model, cost, SmallOptions(), 4);
  const Eigen::Vector3d x(0.3, -0.2, 0.1);
  mppi.Command(x);
  ASSERT_EQ(cost.prevs.size(), 6u);
  EXPECT_EQ(cost.steps, (std::vector<int>{0, 1, 2, 3, 4, 5}));
  EXPECT_EQ(cost.prevs[0], x.replicate(1, 64));
  for (int t = 1; t < 6; ++t) EXPECT_EQ(cost.prevs[t], cost.nexts[t - 1]) << "step " << t;
  // Each step moved by exactly 0.1 u (the drift model) with the clamped |u_i| <= 1.
  for (int t = 0; t < 6; ++t) {
    ASSERT_EQ(cost.acts[t].rows(), 3);
    ASSERT_EQ(cost.acts[t].cols(), 64);
    EXPECT_LE(cost.acts[t].cwiseAbs().maxCoeff(), 1.0);
    EXPECT_LT((cost.nexts[t] - cost.prevs[t] - 0.1 * cost.acts[t]).cwiseAbs().maxCoeff(), 1e-15);
    EXPECT_GT((cost.nexts[t] - cost.prevs[t]).cwiseAbs().maxCoeff(), 0.0);
  }
}

TEST(PushingCostReach, ChargesEachPlannedPushTheArmCannotExecute) {
  PushingCost cost(kGoal, true);
  const PushReach reach{0.27, 0.8};
  cost.set_reach(reach, 50.0, 1);
  // A block at 0.8 m pushed straight out by 0.05 m moves the tool 0.7 -> 0.735 ->
  // 0.785 m (inside); at 0.95 m the tool starts at 0.85 m (outside).
  const Eigen::Vector3d inside_pose(0.8, 0.0, 0.0), far_pose(0.95, 0.0, 0.0);
  EXPECT_FALSE(cost.Unreachable(inside_pose, Eigen::Vector3d(0.0, 0.0, 0.5)));
  EXPECT_TRUE(cost.Unreachable(far_pose, Eigen::Vector3d(0.0, 0.0, 0.0)));
  // Sideways push: (0.45, -0.3) -> (0.45, -0.265) -> (0.35, -0.265), 0.44 m or more away.
  EXPECT_FALSE(cost.Unreachable(Eigen::Vector3d(0.45, -0.2, kPi / 2),
                                Eigen::Vector3d(0.0, kPi / 2, 1.0)));
  // Towards the base: (0.35, 0.05) -> (0.215, 0.05) ends 0.22 m from it (inside the inner radius).
  EXPECT_TRUE(cost.Unreachable(Eigen::Vector3d(0.25, 0.05, kPi), Eigen::Vector3d(0.0, 0.0, 1.0)));
  // The step form adds the weight for the push from x_t at steps t < H_r only, and
  // not at all when off.
  const Eigen::Vector3d x1(0.9, 0.0, 0.0), stay(0.0, 0.0, 0.0);
  auto step_cost = [&](int t) {
    Eigen::VectorXd c = Eigen::VectorXd::Zero(1);
    cost.AccumulateStep(t, far_pose, stay, x1, c);
    return c[0];
  };
  EXPECT_DOUBLE_EQ(step_cost(0), GoalTerm(x1) + 50.0);
  EXPECT_DOUBLE_EQ(step_cost(1), GoalTerm(x1));
  cost.set_reach(reach, 50.0, 3);
  EXPECT_DOUBLE_EQ(step_cost(2), GoalTerm(x1) + 50.0);
  EXPECT_DOUBLE_EQ(step_cost(3), GoalTerm(x1));
  cost.set_reach(reach, 0.0, 3);
  EXPECT_DOUBLE_EQ(step_cost(0), GoalTerm(x1));
  EXPECT_THROW(cost.set_reach({0.5, 0.4}, 1.0, 1), Error);
  EXPECT_THROW(cost.set_reach(reach, -1.0, 1), Error);
  EXPECT_THROW(cost.set_reach(reach, 1.0, 0), Error);
}

}  // namespace
}  // namespace diffdyn
