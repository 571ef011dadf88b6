// Control tasks: the fast plant model against the general effect library, the
// costs against their closed forms, the success test on the circle, seeded starts.
#include "diffdyn/physics/control_task.h"

#include <cmath>
#include <numbers>

#include <gtest/gtest.h>

#include "diffdyn/physics/effects.h"

namespace diffdyn {
namespace {

// The task's plant through ExtendedModel (effects.h, every effect kind) and the
// generic adapter, the actuated torques spread to full torque by hand.
struct FullTorquePlant {
  ExtendedDynamics inner;
  JointTask task;
  void operator()(const Eigen::VectorXd& x, const Eigen::VectorXd& u, const Eigen::VectorXd& theta, double t,
                  Eigen::VectorXd& dxdt) const {
    inner(x, task.FullTorque(u, inner.model->dof()), theta, t, dxdt);
  }
};

TEST(ControlTask, PlantModelMatchesTheEffectLibrary) {
  for (const std::string name : {"pendulum", "cartpole"}) {
    const ControlTask task = ControlTaskByName(name);
    const auto fast = TaskModel(task, 0.04, 5);
    const ContinuousTransitionModel<FullTorquePlant> general(FullTorquePlant{ExtendedDynamics(task.plant.Plant()), task.plant},
                                                             task.plant.System(), Eigen::VectorXd(),
                                                             {.method = Method::kRk4Classic, .dt = 0.04, .substeps = 5});
    EXPECT_EQ(fast->time_step(), 0.04);
    Rng rng(3);
    const int b = 16, n = task.state_size(), m = task.action_size();
    Eigen::MatrixXd x(n, b), u(m, b), a(n, b), c(n, b);
    for (int j = 0; j < b; ++j) {
      x.col(j) = task.plant.start_low + (task.plant.start_high - task.plant.start_low).cwiseProduct(
                                            Eigen::VectorXd::NullaryExpr(n, [&] { return UniformUnit(rng); }));
      for (int i = 0; i < m; ++i) u(i, j) = task.plant.bound[i] * (2 * UniformUnit(rng) - 1);
    }
    auto ws1 = fast->MakeWorkspace(b);
    auto ws2 = general.MakeWorkspace(b);
    fast->PredictBatch(x, u, a, *ws1);
    general.PredictBatch(x, u, c, *ws2);
    EXPECT_LT((a - c).cwiseAbs().maxCoeff(), 1e-10 * (1 + c.cwiseAbs().maxCoeff())) << name;
    EXPECT_GT((a - x).cwiseAbs().maxCoeff(), 1e-3) << name << ": the plant did not move";
  }
}

TEST(ControlTask, CostsAreTheTaskTable) {
  const ControlTask pendulum = ControlTaskByName("pendulum");
  // q = pi sin(theta / 2)^2 weighting: hanging (q = 0) costs pi^2, upright 0, any turn the same.
  EXPECT_NEAR(pendulum.StateCost(Eigen::Vector2d(0.0, 0.0)), std::numbers::pi * std::numbers::pi,
              1e-12);
  EXPECT_NEAR(pendulum.StateCost(Eigen::Vector2d(std::numbers::pi, 2.0)), 0.4, 1e-12);
  EXPECT_NEAR(pendulum.StateCost(Eigen::Vector2d(3 * std::numbers::pi, 0.0)), 0.0, 1e-12);
  // Log-cosine: g(0) = 0, even, and its closed form at u = 1.
  const double u_max = 2.501, beta = 4 * u_max * u_max * 0.5 / std::numbers::pi;
  const double g1 = -(2 * beta * u_max / std::numbers::pi) *
                    std::log(std::cos(std::numbers::pi * 1.0 / (2 * u_max)));
  EXPECT_EQ(pendulum.action_cost(Eigen::VectorXd::Zero(1)), 0.0);
  EXPECT_NEAR(pendulum.action_cost(Eigen::VectorXd::Constant(1, 1.0)), g1, 1e-12);
  EXPECT_NEAR(pendulum.action_cost(Eigen::VectorXd::Constant(1, -1.0)), g1, 1e-12);

  const ControlTask cartpole = ControlTaskByName("cartpole");
  Eigen::Vector4d x(0.2, std::numbers::pi, 1.0, -2.0);
  EXPECT_NEAR(cartpole.RunningCost(x, Eigen::VectorXd::Constant(1, 3.0)),
              0.04 + std::numbers::pi * std::numbers::pi + 0.1 * (1.0 + 4.0) + 0.01 * 9.0, 1e-12);
}

TEST(ControlTask, SuccessIsTestedOnTheCircleAndLimitsFail) {
  const ControlTask pendulum = ControlTaskByName("pendulum");
  EXPECT_TRUE(pendulum.Succeeded(Eigen::Vector2d(std::numbers::pi + 0.05, 0.4)));
  EXPECT_TRUE(pendulum.Succeeded(
      Eigen::Vector2d(-std::numbers::pi - 0.05, -0.4)));  // the same point, one turn back
  EXPECT_FALSE(pendulum.Succeeded(Eigen::Vector2d(std::numbers::pi + 0.15, 0.0)));
  EXPECT_FALSE(pendulum.Succeeded(Eigen::Vector2d(std::numbers::pi, 0.6)));
  const ControlTask cartpole = ControlTaskByName("cartpole");
  EXPECT_TRUE(cartpole.Succeeded(Eigen::Vector4d(0.3, 2 * std::numbers::pi + 0.05, 5.0, 0.1)));
  EXPECT_FALSE(cartpole.Succeeded(Eigen::Vector4d(0.6, 0.0, 0.0, 0.0)));  // off the track
  EXPECT_TRUE(cartpole.OutOfLimits(Eigen::Vector4d(-0.51, 0.0, 0.0, 0.0)));
  EXPECT_THROW(ControlTaskByName("pushing"), Error);
}

TEST(ControlTask, StartsAreSeededAndInsideTheBox) {
  const ControlTask task = ControlTaskByName("cartpole");
  Rng a(5), b(5);
  for (int k = 0; k < 50; ++k) {
    const Eigen::VectorXd x = task.SampleStart(a);
    EXPECT_EQ(x, task.SampleStart(b));
    EXPECT_TRUE(((x - task.start_low).array() >= 0).all() && ((task.start_high - x).array() >= 0).all());
    EXPECT_EQ(x[2], 0.0);
    EXPECT_LE(std::abs(x[1] - std::numbers::pi), 0.1);
  }
}

}  // namespace
}  // namespace diffdyn
