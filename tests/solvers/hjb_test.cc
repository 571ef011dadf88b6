// The task HJB: the action cost's conjugate against a brute-force maximum, the
// control-affine split against the plant's dynamics, F_p against central differences,
// and the policy inside the bounds; the homotopy solver's residual, determinism and
// value files, and its controller.
#include "diffdyn/solvers/hjb.h"

#include <cmath>
#include <filesystem>

#include <gtest/gtest.h>

#include "diffdyn/models/random.h"
#include "diffdyn/solvers/lqr.h"

namespace diffdyn {
namespace {

// max_u [w u - g(u)] over a grid of the open interval (-u_max, u_max), and its argmax.
std::pair<double, double> BruteConjugate(const ActionCost& g, double w, double u_max) {
  double best = -1e300, arg = 0.0;
  const int steps = 200000;
  for (int k = 1; k < steps; ++k) {
    const double u = -u_max + 2.0 * u_max * k / steps;
    const double value = w * u - g(VectorOf({u}));
    if (value > best) best = value, arg = u;
  }
  return {best, arg};
}

TEST(ActionCost, ConjugateIsTheMaximumOverActions) {
  const ControlTask pendulum = ControlTaskByName("pendulum");
  const ControlTask cartpole = ControlTaskByName("cartpole");
  for (const double w : {-30.0, -4.0, -0.3, 0.0, 0.7, 5.0, 40.0}) {
    const ActionCost& logcos = pendulum.action_cost;
    const auto [value, arg] = BruteConjugate(logcos, w, logcos.u_max);
    EXPECT_NEAR(logcos.Conjugate(VectorOf({w})), value, 1e-6 * (1 + std::abs(value))) << w;
    EXPECT_NEAR(logcos.ConjugateGradient(VectorOf({w}))[0], arg, 1e-4) << w;
    EXPECT_LT(std::abs(logcos.ConjugateGradient(VectorOf({w}))[0]), logcos.u_max);
    // The quadratic cost over a range wide enough to hold its maximiser w / (2 r).
    const ActionCost& quadratic = cartpole.action_cost;
    const auto [qvalue, qarg] = BruteConjugate(quadratic, w, 3000.0);
    EXPECT_NEAR(quadratic.Conjugate(VectorOf({w})), qvalue, 1e-3 * (1 + std::abs(qvalue))) << w;
    EXPECT_NEAR(quadratic.ConjugateGradient(VectorOf({w}))[0], qarg, 0.05) << w;
  }
}

TEST(TaskHjb, AffineSplitReproducesThePlant) {
  for (const char* name : {"pendulum", "cartpole"}) {
    const ControlTask task = ControlTaskByName(name);
    const TaskHjb hjb(task, 1.0);
    const auto model = task.plant.Model();
    Rng rng(2);
    const Eigen::VectorXd x = task.SampleStart(rng) + 0.2 * Eigen::VectorXd::Ones(task.state_size());
    Eigen::VectorXd a;
    Eigen::MatrixXd b;
    hjb.Affine(x, &a, &b);
    for (const double u : {-1.5, 0.0, 2.0}) {
      const VectorX<DiagJet> f = model->Dynamics(ParseParams(*model, task.plant.params), TaskActuatedJoints(task),
                                                 TaskDamping(task), x.cast<DiagJet>(),
                                                 VectorX<DiagJet>::Constant(1, DiagJet(u)));
      for (int i = 0; i < task.state_size(); ++i) EXPECT_NEAR(f[i].a, a[i] + b(i, 0) * u, 1e-12) << name;
    }
  }
}

TEST(TaskHjb, PartialsMatchCentralDifferences) {
  const ControlTask task = ControlTaskByName("pendulum");
  const TaskHjb hjb(task, 0.7);
  Eigen::MatrixXd x(2, 3), p(2, 3);
  x << 0.3, 2.0, 4.0, -1.0, 0.5, 3.0;
  p << 1.0, -2.0, 0.1, 0.4, 3.0, -6.0;
  const Eigen::VectorXd v = VectorOf({0.5, 2.0, -1.0});
  Eigen::VectorXd f, f_v;
  Eigen::MatrixXd f_p;
  hjb.Evaluate(x, v, p, &f, &f_v, &f_p, 1);
  const double h = 1e-6;
  for (int i = 0; i < 2; ++i) {
    Eigen::MatrixXd up = p, down = p;
    up.row(i).array() += h;
    down.row(i).array() -= h;
    Eigen::VectorXd fu, fd, dummy_v;
    Eigen::MatrixXd dummy_p;
    hjb.Evaluate(x, v, up, &fu, &dummy_v, &dummy_p, 1);
    hjb.Evaluate(x, v, down, &fd, &dummy_v, &dummy_p, 1);
    EXPECT_LT(((fu - fd) / (2 * h) - f_p.row(i).transpose()).cwiseAbs().maxCoeff(), 1e-6);
  }
  EXPECT_EQ(f_v, Eigen::VectorXd::Constant(3, 0.7));
  // The policy stays inside the bounds however steep V is.
  EXPECT_LT(std::abs(hjb.Policy(x.col(0), 1e6 * p.col(0))[0]), task.action_cost.u_max);
  EXPECT_THROW(TaskHjb(task, 0.0), Error);
}

// A small homotopy: 3 stages of 4 epochs on 2000 states, 16 wide.
HjbOptions SmallHjb(int threads) {
  HjbOptions o;
  o.hidden = {16, 16};
  o.stages = 2;
  o.polish_stages = 1;
  o.rollout_stages = 0;
  o.samples = 2000;
  o.rho_start = 2.0;
  o.rho_final = 0.5;
  o.train.epochs = 4;
  o.train.threads = threads;
  o.seed = 3;
  return o;
}

// The residual loss and its gradient on the pendulum's structured value: the network's
// chunks, the quadratic heads and the equation's per-state work shared over threads
// give the same bits as one thread, also when the batch size changes between calls on
// one workspace (its buffers resized in place).
TEST(ResidualLoss, SameBitsOnOneAndTwoThreads) {
  const ControlTask task = ControlTaskByName("pendulum");
  HjbOptions options;
  options.hidden = {24, 24};
  const ValueFunction value = MakeTaskValueFunction(task, options);
  const TaskHjb hjb(task, 0.3);
  Rng rng(5);
  ValueWorkspace one = value.MakeWorkspace(200, 16), two = value.MakeWorkspace(200, 16);
  for (const int batch : {200, 37, 200}) {
    Eigen::MatrixXd x(task.state_size(), batch);
    for (int j = 0; j < batch; ++j) {
      for (int i = 0; i < task.state_size(); ++i) x(i, j) = Uniform(rng, task.domain_low[i], task.domain_high[i]);
    }
    Eigen::VectorXd grad_one, grad_two;
    const double loss_one = ResidualLoss(hjb, value, x, &grad_one, &one, 1);
    const double loss_two = ResidualLoss(hjb, value, x, &grad_two, &two, 2);
    EXPECT_TRUE(std::isfinite(loss_one) && loss_one > 0.0) << batch;
    EXPECT_EQ(loss_one, loss_two) << batch;
    ASSERT_EQ(grad_one.size(), value.net().num_parameters());
    EXPECT_EQ(grad_one, grad_two) << batch;
    EXPECT_GT(grad_one.norm(), 0.0) << batch;
  }
}

// Each rollout anchor is the discounted cost-to-go of a run of the value's policy from
// its state: at the run's first state, summed forwards here,
//   G_0 = sum_k e^{-rho k T} T c(x_k, u_k) + e^{-rho K T} V(x_K),
// and G_k - e^{-rho T} G_{k+1} = T c(x_k, u_k) along the run.
TEST(RolloutAnchors, AreTheDiscountedCostsToGoOfThePolicysRuns) {
  const ControlTask task = ControlTaskByName("pendulum");
  ValueFunction value = MakeTaskValueFunction(task, SmallHjb(1));
  SolveHjb(task, SmallHjb(1), &value);
  const double rho = 0.3;
  const ValueAnchors anchors = RolloutAnchors(task, value, rho, 4.0, 2, 11);
  HjbController controller(task, value);
  const std::vector<ControlRun> runs = EvaluateController(task, controller, {.starts = 2, .seed = 11});
  ASSERT_EQ(anchors.states.cols(), 2 * task.periods());
  EXPECT_EQ(anchors.weight, 4.0);
  EXPECT_EQ(anchors.batch, 256);
  EXPECT_EQ(anchors.scales, Eigen::VectorXd::Ones(anchors.states.cols()));
  // The anchor whose state is x (the states of two runs differ).
  const auto anchor_at = [&](const Eigen::VectorXd& x) {
    Eigen::Index found = -1;
    for (Eigen::Index c = 0; c < anchors.states.cols(); ++c) found = anchors.states.col(c) == x ? c : found;
    return found;
  };
  for (const ControlRun& run : runs) {
    const Eigen::MatrixXd& x = run.trajectory.states;
    const Eigen::Index steps = x.cols() - 1;
    double g0 = 0.0;
    for (Eigen::Index k = 0; k < steps; ++k) {
      g0 += std::exp(-rho * k * task.period) * task.period * task.RunningCost(x.col(k), run.trajectory.actions.col(k));
    }
    Eigen::VectorXd v;
    Eigen::MatrixXd p;
    value.Evaluate(x.col(steps), &v, &p);
    g0 += std::exp(-rho * steps * task.period) * v[0];
    const Eigen::Index first = anchor_at(x.col(0));
    ASSERT_GE(first, 0);
    EXPECT_NEAR(anchors.values[first], g0, 1e-9 * g0);
    for (Eigen::Index k : {Eigen::Index{0}, steps / 2, steps - 2}) {
      const Eigen::Index a = anchor_at(x.col(k)), b = anchor_at(x.col(k + 1));
      ASSERT_GE(a, 0);
      ASSERT_GE(b, 0);
      EXPECT_NEAR(anchors.values[a] - std::exp(-rho * task.period) * anchors.values[b],
                  task.period * task.RunningCost(x.col(k), run.trajectory.actions.col(k)), 1e-9 * g0);
    }
  }
}

// A rollout stage moves V towards the policy's costs-to-go, also at the states of
// runs from other starts than its own (held out): their mean squared error falls.
TEST(SolveHjb, RolloutStagesFitThePolicysCostsToGo) {
  const ControlTask task = ControlTaskByName("pendulum");
  HjbOptions o = SmallHjb(1);
  ValueFunction before = MakeTaskValueFunction(task, o);
  SolveHjb(task, o, &before);
  o.rollout_stages = 1;
  o.rollout_starts = 16;
  o.rollout_epochs = 10;
  o.rollout_learning_rate = 1e-3;
  std::vector<HjbStageReport> reports;
  ValueFunction after = MakeTaskValueFunction(task, o);
  SolveHjb(task, o, &after, [&](const HjbStageReport& r) { reports.push_back(r); });
  ASSERT_EQ(reports.size(), 4u);
  EXPECT_EQ(reports[3].learning_rate, 1e-3);
  EXPECT_EQ(reports[3].result.epochs.size(), 10u);
  EXPECT_NEAR(reports[3].rho, o.rho_final, 1e-12);
  ValueAnchors held_out = RolloutAnchors(task, before, o.rho_final, 1.0, 16, 12345);
  held_out.batch = 0;
  ValueWorkspace ws = before.MakeWorkspace(static_cast<int>(held_out.states.cols()));
  const double error_before = AnchorLoss(held_out, before, nullptr, &ws);
  const double error_after = AnchorLoss(held_out, after, nullptr, &ws);
  EXPECT_LT(error_after, 0.7 * error_before) << error_before << " -> " << error_after;
}

// The goal anchors' values are h^2 d^T P d for a P that solves the discounted Riccati
// equation of the pendulum's linearisation (rebuilt here from the anchors themselves),
// and the quadratic value with that P is what they hold, to O(h^3).
TEST(GoalAnchors, HoldTheDiscountedRiccatiCostToGo) {
  const ControlTask task = ControlTaskByName("pendulum");
  const LqrSolution lqr = TaskLqr(task);
  for (double rho : {5.0, 0.0862}) {
    const double h = 1e-3;
    const ValueAnchors anchors = GoalAnchors(task, rho, 2.0, h);
    ASSERT_EQ(anchors.states.cols(), 8);
    EXPECT_EQ(anchors.weight, 2.0);
    // Directions e_0, e_1, (e_0 + e_1)/sqrt 2 at columns 0, 2, 4.
    Eigen::Matrix2d p;
    p(0, 0) = anchors.values[0] / (h * h);
    p(1, 1) = anchors.values[2] / (h * h);
    p(0, 1) = p(1, 0) = anchors.values[4] / (h * h) - 0.5 * (p(0, 0) + p(1, 1));
    const Eigen::Matrix2d a = lqr.A - 0.5 * rho * Eigen::Matrix2d::Identity();
    const Eigen::Matrix2d riccati =
        a.transpose() * p + p * a - p * lqr.B * lqr.R.inverse() * lqr.B.transpose() * p + lqr.Q;
    EXPECT_LT(riccati.norm(), 1e-9 * (a.norm() * p.norm() + lqr.Q.norm())) << "rho " << rho;
    EXPECT_GT(p.determinant(), 0.0);
    for (Eigen::Index c = 0; c < anchors.states.cols(); ++c) {
      const Eigen::Vector2d e = anchors.states.col(c) - task.goal;
      EXPECT_NEAR(e.norm(), h, 1e-15);
      EXPECT_NEAR(anchors.values[c], e.dot(p * e), 1e-12 * anchors.values[c]);
      EXPECT_EQ(anchors.scales[c], h * h);
    }
  }
  // A larger discount gives a smaller cost-to-go (the future counts less).
  EXPECT_LT(GoalAnchors(task, 5.0, 1.0).values[0], GoalAnchors(task, 0.0862, 1.0).values[0]);
}

// With goal anchors, the learned V near the goal is the final discount's LQR cost-to-go
// (its anchor values) to a few percent of the largest (measured 3 %); without them it
// is not pinned (measured 88 % off).
TEST(SolveHjb, GoalAnchorsPinTheValueNearTheGoal) {
  const ControlTask task = ControlTaskByName("pendulum");
  const auto anchor_error = [&](double weight) {
    HjbOptions o = SmallHjb(1);
    o.goal_anchor_weight = weight;
    o.train.epochs = 40;
    ValueFunction value = MakeTaskValueFunction(task, o);
    SolveHjb(task, o, &value);
    const ValueAnchors anchors = GoalAnchors(task, o.rho_final, 1.0, 1e-2);
    Eigen::VectorXd v;
    Eigen::MatrixXd p;
    value.Evaluate(anchors.states, &v, &p);
    return (v - anchors.values).cwiseAbs().maxCoeff() / anchors.values.maxCoeff();
  };
  const double anchored = anchor_error(10.0), free = anchor_error(0.0);
  EXPECT_LT(anchored, 0.1);
  EXPECT_GT(free, 0.5);
}

// Stages in order with the discounts of the schedule; the residual is finite and
// falls within the first stage; the same seed gives the same parameters at 1 and 2
// threads.
TEST(SolveHjb, AnnealsTheDiscountDeterministically) {
  const ControlTask task = ControlTaskByName("pendulum");
  std::vector<HjbStageReport> reports;
  ValueFunction value = MakeTaskValueFunction(task, SmallHjb(1));
  SolveHjb(task, SmallHjb(1), &value, [&](const HjbStageReport& r) { reports.push_back(r); });
  ASSERT_EQ(reports.size(), 3u);
  EXPECT_DOUBLE_EQ(reports[0].rho, 2.0);
  EXPECT_NEAR(reports[1].rho, 0.5, 1e-12);
  EXPECT_NEAR(reports[2].rho, 0.5, 1e-12);
  EXPECT_NEAR(reports[2].learning_rate, reports[1].learning_rate / 3.0, 1e-15);
  for (const HjbStageReport& r : reports) EXPECT_TRUE(std::isfinite(r.result.final_val_loss));
  EXPECT_LT(reports[0].result.epochs.back().train_loss, 0.5 * reports[0].result.epochs.front().train_loss);

  ValueFunction again = MakeTaskValueFunction(task, SmallHjb(2));
  SolveHjb(task, SmallHjb(2), &again);
  EXPECT_EQ(again.net().parameters(), value.net().parameters());
}

// The structured value is zero at the goal and positive elsewhere; the controller's
// actions stay inside the bounds; a saved file loads back to the same V.
TEST(SolveHjb, ValueFileRoundTripsAndTheControllerIsBounded) {
  const ControlTask task = ControlTaskByName("pendulum");
  ValueFunction value = MakeTaskValueFunction(task, SmallHjb(1));
  SolveHjb(task, SmallHjb(1), &value);
  const std::filesystem::path path = std::filesystem::path(::testing::TempDir()) / "hjb_value.json";
  SaveValueFunction(path, value, "pendulum", {{"seed", 3}});
  std::string name;
  const ValueFunction back = LoadValueFunction(path, &name);
  EXPECT_EQ(name, "pendulum");
  Rng rng(4);
  Eigen::MatrixXd x(2, 50);
  for (int j = 0; j < 50; ++j) x.col(j) << Uniform(rng, 0.0, 6.28), Uniform(rng, -8.0, 8.0);
  x.col(0) = task.goal;
  Eigen::VectorXd v, v_back;
  Eigen::MatrixXd p, p_back;
  value.Evaluate(x, &v, &p);
  back.Evaluate(x, &v_back, &p_back);
  EXPECT_EQ(v, v_back);
  EXPECT_EQ(p, p_back);
  EXPECT_LT(std::abs(v[0]), 1e-15);
  EXPECT_GT(v.tail(49).minCoeff(), 0.0);

  HjbController controller(task, back);
  for (int j = 0; j < 50; ++j) {
    EXPECT_LT(std::abs(controller.Command(x.col(j))[0]), task.action_cost.u_max);
  }
  EXPECT_EQ(controller.Command(task.goal)[0], 0.0);
  // A file of another kind, and a controller for another task, are refused.
  std::filesystem::remove(path);
  EXPECT_THROW(LoadValueFunction(path, &name), Error);
  EXPECT_THROW(HjbController(ControlTaskByName("cartpole"), back), Error);
}

// Two candidates from seeds 3 and 4: the one kept is the one with the lower validation
// cost, and it is the same function SolveHjb gives from that seed.
TEST(LearnTaskValue, KeepsTheCandidateWithTheLowestValidationCost) {
  const ControlTask task = ControlTaskByName("pendulum");
  HjbOptions o = SmallHjb(1);
  o.candidates = 2;
  o.validation_starts = 3;
  std::vector<HjbCandidateReport> reports;
  int stages = 0, kept_index = -1;
  const ValueFunction kept =
      LearnTaskValue(task, o, [&](const HjbStageReport&) { ++stages; },
                     [&](const HjbCandidateReport& r) { reports.push_back(r); }, &kept_index);
  ASSERT_EQ(reports.size(), 2u);
  EXPECT_EQ(stages, 6);
  EXPECT_EQ(reports[0].seed, 3u);
  EXPECT_EQ(reports[1].seed, 4u);
  EXPECT_NE(reports[0].mean_cost, reports[1].mean_cost);
  HjbOptions single = SmallHjb(1);
  single.seed = reports[0].mean_cost <= reports[1].mean_cost ? 3 : 4;
  EXPECT_EQ(kept_index, single.seed == 3 ? 0 : 1);
  ValueFunction expected = MakeTaskValueFunction(task, single);
  SolveHjb(task, single, &expected);
  EXPECT_EQ(kept.net().parameters(), expected.net().parameters());
}

TEST(SolveHjb, RefusesBadOptions) {
  const ControlTask task = ControlTaskByName("pendulum");
  HjbOptions o = SmallHjb(1);
  ValueFunction value = MakeTaskValueFunction(task, o);
  o.rho_final = 3.0;  // above rho_start
  EXPECT_THROW(SolveHjb(task, o, &value), Error);
  o = SmallHjb(1);
  o.samples = 1;
  EXPECT_THROW(SolveHjb(task, o, &value), Error);
  o = SmallHjb(1);
  o.hidden = {0};
  EXPECT_THROW(MakeTaskValueFunction(task, o), Error);
  o = SmallHjb(1);
  o.candidates = 0;
  EXPECT_THROW(LearnTaskValue(task, o), Error);
  o = SmallHjb(1);
  o.goal_anchor_weight = -1.0;
  EXPECT_THROW(SolveHjb(task, o, &value), Error);
  o = SmallHjb(1);
  o.rollout_stages = 1;
  o.rollout_weight = std::nan("");
  EXPECT_THROW(SolveHjb(task, o, &value), Error);
  o.rollout_weight = 1.0;
  o.rollout_starts = 0;
  EXPECT_THROW(SolveHjb(task, o, &value), Error);
  o.rollout_starts = 4;
  o.rollout_learning_rate = 0.0;
  EXPECT_THROW(SolveHjb(task, o, &value), Error);
}

}  // namespace
}  // namespace diffdyn
