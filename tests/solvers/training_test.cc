// Non-finite data rejected by file and line, windows, the state metric (pushing's
// pose loss, wrapped joint-space angles), the Trainer's batch gradients (single- and
// multi-step, through the NeuralODE) against finite differences, determinism at any
// thread count, learning, early stop, divergence reporting and the evaluation
// metrics, per-transition intervals included.
#include "diffdyn/solvers/training.h"

#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <numeric>
#include <string>
#include <tuple>
#include <vector>

#include <gtest/gtest.h>

#include "diffdyn/models/continuous_model.h"
#include "diffdyn/models/learned_model.h"
#include "diffdyn/models/random.h"
#include "diffdyn/models/state_loss.h"
#include "diffdyn/physics/pushing/csv.h"
#include "diffdyn/physics/pushing/system.h"
#include "diffdyn/solvers/dataset_io.h"

namespace diffdyn {
namespace {

// Trajectories of a smooth synthetic pushing law (not any model here):
// x_{t+1} = x_t + 0.05 u_2 (cos(theta + u_1), sin(theta + u_1), 0.5 u_0).
Dataset SyntheticTrajectories(int count, int pushes, std::uint64_t seed) {
  Rng rng(seed);
  Dataset out;
  out.system = PushingSystem();
  out.path = "synthetic";
  for (int i = 0; i < count; ++i) {
    Eigen::Vector3d x(0.4, 0.0, 0.2 * M_PI);
    std::vector<Eigen::Vector3d> poses{x}, actions;
    for (int k = 0; k < pushes; ++k) {
      const Eigen::Vector3d u(2 * UniformUnit(rng) - 1, M_PI * (UniformUnit(rng) - 0.5), UniformUnit(rng));
      x += 0.05 * u[2] * Eigen::Vector3d(std::cos(x[2] + u[1]), std::sin(x[2] + u[1]), 0.5 * u[0]);
      actions.push_back(u);
      poses.push_back(x);
    }
    out.trajectories.push_back(MakePushingTrajectory(poses, actions));
  }
  return out;
}

// Non-finite numbers are rejected by the reader itself, naming the file and the
// line as counted in the file (blank lines included), for states and actions alike.
TEST(ReadDataset, NonFiniteNumbersNameFileAndLine) {
  const std::string header = "trajectory,step,x,y,theta,push_location,push_angle,push_length\n";
  const std::string path = ::testing::TempDir() + "/pushing_training_nonfinite_" +
                           std::to_string(::getpid()) + ".csv";
  for (const auto& [row2, row4, line] : std::vector<std::tuple<std::string, std::string, int>>{
           {"0,0,nan,0,0,0,0,0.5", "0,1,0.1,0,0,,,", 2},
           {"0,0,0.4,0,0,0,0,0.5", "0,1,0.1,0,0,0,inf,0.5", 4},
           {"0,0,0.4,0,0,0,0,0.5", "0,1,0.1,-INF,0,,,", 4}}) {
    {
      std::ofstream out(path);
      out << header << row2 << "\n\n" << row4 << "\n";  // line 3 is blank
    }
    try {
      ReadDataset(path);
      ADD_FAILURE() << "accepted " << row2 << " / " << row4;
    } catch (const Error& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find(path + ":" + std::to_string(line) + ": "), std::string::npos) << what;
      EXPECT_NE(what.find("not finite"), std::string::npos) << what;
    }
  }
  {
    std::ofstream out(path);
    out << header << "0,0,0.4,0,0,0,0,0.5\n\n0,1,0.1,0,0,,,\n";
  }
  const Dataset good = ReadDataset(path);
  ASSERT_EQ(good.trajectories.size(), 1u);
  EXPECT_EQ(good.format, "pushing-csv");
  EXPECT_EQ(good.system.name, "pushing");
  EXPECT_EQ(good.trajectories[0].transitions(), 1);
  EXPECT_DOUBLE_EQ(good.trajectories[0].states(0, 1), 0.1);
  std::remove(path.c_str());
}

TEST(Windows, CountsAndContents) {
  Dataset data = SyntheticTrajectories(3, 10, 1);
  data.trajectories[1].t[5] = 4.5;  // dt 0.5 then 1.5 around step 5
  const auto& trajs = data.trajectories;
  const Windows one = MakeWindows(data, 1);
  const Windows four = MakeWindows(data, 4);
  EXPECT_EQ(one.size(), 30);
  EXPECT_EQ(four.size(), 21);  // 7 per 10-push trajectory, as in the paper
  // Window 8 of horizon 4 is trajectory 1, start step 1.
  EXPECT_EQ(four.start.col(8), trajs[1].states.col(1));
  EXPECT_EQ(four.actions[3].col(8), trajs[1].actions.col(4));
  EXPECT_EQ(four.targets[3].col(8), trajs[1].states.col(5));
  EXPECT_EQ(four.dt[3](8), 0.5);
  EXPECT_EQ(four.dt[2](8), 1.0);
  std::vector<int> index{8, 0};
  const Windows picked = SelectWindows(four, index);
  EXPECT_EQ(picked.size(), 2);
  EXPECT_EQ(picked.targets[2].col(0), four.targets[2].col(8));
  EXPECT_EQ(picked.dt[3](0), 0.5);
  EXPECT_THROW(MakeWindows(SyntheticTrajectories(2, 3, 1), 4), Error);
}

// Pushing's metric is the paper's pose loss: theta weighted by r_g, not wrapped.
TEST(StateLoss, PushingIsThePoseLossWithFiniteDifferenceGradient) {
  Rng rng(2);
  Eigen::MatrixXd pred(3, 5), target(3, 5);
  for (Eigen::Index i = 0; i < pred.size(); ++i) {
    pred.data()[i] = StandardNormal(rng);
    target.data()[i] = StandardNormal(rng);
  }
  Eigen::MatrixXd grad;
  const SystemDescription pushing = PushingSystem();
  const double loss = StateLoss(pushing, pred, target, 1.0 / 5, &grad);
  const Eigen::MatrixXd d = pred - target;
  const double expected = d.row(0).squaredNorm() / 5 + d.row(1).squaredNorm() / 5 +
                          std::sqrt(0.02 / 12) * d.row(2).squaredNorm() / 5;
  EXPECT_NEAR(loss, expected, 1e-14);
  EXPECT_NEAR(kBlockRadiusOfGyration, 0.040825, 1e-6);
  const double eps = 1e-6;
  for (Eigen::Index i = 0; i < pred.size(); ++i) {
    Eigen::MatrixXd p = pred, m = pred;
    p.data()[i] += eps;
    m.data()[i] -= eps;
    const double fd =
        (StateLoss(pushing, p, target, 0.2, nullptr) - StateLoss(pushing, m, target, 0.2, nullptr)) / (2 * eps);
    EXPECT_NEAR(grad.data()[i], fd, 1e-8);
  }
  // Not wrapped: a 2 pi error in theta counts.
  Eigen::MatrixXd turned = target;
  turned(2, 0) += 2 * M_PI;
  EXPECT_GT(StateLoss(pushing, turned, target, 1.0, nullptr), 1.0);
}

// Joint space: angles wrapped to (-pi, pi], a prismatic joint not; weights 1.
TEST(StateLoss, JointSpaceWrapsRevoluteAnglesOnly) {
  const SystemDescription cartpole = JointSpaceSystem(2, {.prismatic = {1}});
  Eigen::MatrixXd target = Eigen::MatrixXd::Zero(4, 1), pred(4, 1);
  pred << 0.1, 2 * M_PI + 0.2, 0.3, -0.4;
  Eigen::MatrixXd grad;
  const double loss = StateLoss(cartpole, pred, target, 1.0, &grad);
  EXPECT_NEAR(loss, 0.01 + 0.04 + 0.09 + 0.16, 1e-12);
  EXPECT_NEAR(grad(1, 0), 0.4, 1e-12);
  pred(0, 0) = 2 * M_PI;  // the cart is not an angle
  EXPECT_NEAR(StateLoss(cartpole, pred, target, 1.0, nullptr), 4 * M_PI * M_PI + 0.29, 1e-9);
  EXPECT_NEAR(WrapAngle(M_PI), M_PI, 1e-15);
  EXPECT_NEAR(WrapAngle(-M_PI), M_PI, 1e-15);
  EXPECT_NEAR(WrapAngle(3 * M_PI + 0.5), -M_PI + 0.5, 1e-12);
}

struct GradientCase {
  LearnedKind type;
  Method method;
  int horizon;
};

class TrainerGradient : public ::testing::TestWithParam<GradientCase> {};

// dL/dtheta of the batch loss (single step, or 4 steps with gamma 0.9) through the
// NeuralODE's solver and the rollout, against central differences of the loss.
TEST_P(TrainerGradient, BatchGradientMatchesFiniteDifferences) {
  const GradientCase c = GetParam();
  LearnedModelConfig config;
  config.type = c.type;
  config.method = c.method;
  config.hidden = 10;
  config.steps = 3;
  // A smooth field: with ReLU a kink can sit within the difference step of some
  // sample (seen on the x86-64 baseline ISA: central differences with eps 1e-5
  // off by 1e-4, with eps 1e-7 equal to the adjoint to 1e-9), and dopri5 needs one
  // (see learned_model_test.cc). ReLU's own VJP is checked in tests/models.
  config.activation = Activation::Tanh();
  if (TableauOf(c.method).adaptive) config.tolerance = 1e-12;
  config.system = PushingSystem();
  LearnedModel model = LearnedModel::Initialized(config, 4);
  const Windows data = MakeWindows(SyntheticTrajectories(4, 8, 3), c.horizon);
  std::vector<int> index(data.size());
  std::iota(index.begin(), index.end(), 0);
  // Chunks of 7 samples: the batch is split, as with both cores.
  Trainer trainer(&model, {.gamma = 0.9, .threads = 2, .chunk_size = 7, .progress = false});
  Eigen::VectorXd grad;
  const double loss = trainer.BatchLossAndGradient(data, index, &grad);
  EXPECT_NEAR(loss, RolloutLoss(model, data, 0.9, 1, 1000), 1e-12 * std::max(1.0, loss));
  Rng rng(9);
  const double eps = 1e-5;
  for (int k = 0; k < 3; ++k) {
    Eigen::VectorXd v(model.num_parameters());
    for (Eigen::Index i = 0; i < v.size(); ++i) v[i] = StandardNormal(rng);
    LearnedModel plus = model, minus = model;
    plus.mutable_parameters() += eps * v;
    minus.mutable_parameters() -= eps * v;
    const double fd = (RolloutLoss(plus, data, 0.9, 1, 1000) - RolloutLoss(minus, data, 0.9, 1, 1000)) / (2 * eps);
    const double adjoint = grad.dot(v);
    EXPECT_NEAR(adjoint, fd, 2e-5 * std::max(std::abs(fd), 1e-3)) << "direction " << k;
  }
}

INSTANTIATE_TEST_SUITE_P(
    Models, TrainerGradient,
    ::testing::Values(GradientCase{LearnedKind::kAbsNode, Method::kRk4, 1},
                      GradientCase{LearnedKind::kAbsNode, Method::kRk4, 4},
                      GradientCase{LearnedKind::kResNode, Method::kDopri5, 1},
                      GradientCase{LearnedKind::kResNode, Method::kDopri5, 4},
                      GradientCase{LearnedKind::kResNn, Method::kRk4, 4}));

LearnedModelConfig TinyNode() {
  LearnedModelConfig config;
  config.type = LearnedKind::kResNode;
  config.hidden = 16;
  config.steps = 3;
  return config;
}

TEST(Trainer, SameBytesAtAnyThreadCountAndSeedMatters) {
  const Windows data = MakeWindows(SyntheticTrajectories(30, 10, 5), 1);
  auto run = [&](int threads, std::uint64_t seed) {
    LearnedModel model = LearnedModel::Initialized(TinyNode(), 1);
    Trainer trainer(&model, {.epochs = 2, .batch_size = 64, .seed = seed, .threads = threads,
                             .chunk_size = 20, .progress = false});
    const TrainResult r = trainer.Train(data);
    EXPECT_EQ(r.n_train + r.n_val, 300);
    EXPECT_EQ(r.n_val, 60);
    return std::make_pair(Eigen::VectorXd(model.parameters()), r.final_val_loss);
  };
  const auto one = run(1, 7);
  const auto two = run(2, 7);
  EXPECT_EQ((one.first - two.first).cwiseAbs().maxCoeff(), 0.0);
  EXPECT_EQ(one.second, two.second);
  const auto other = run(2, 8);
  EXPECT_GT((one.first - other.first).cwiseAbs().maxCoeff(), 0.0);
}

TEST(Trainer, LearnsASyntheticPushingLaw) {
  const Windows data = MakeWindows(SyntheticTrajectories(60, 10, 6), 1);
  LearnedModel model = LearnedModel::Initialized(
      {.type = LearnedKind::kResNn, .hidden = 32}, 2);
  const double before = RolloutLoss(model, data, 1.0);
  Trainer trainer(&model, {.epochs = 60, .learning_rate = 3e-3, .batch_size = 100, .progress = false});
  std::vector<double> val;
  const TrainResult r = trainer.Train(data, [&](const EpochReport& e) { val.push_back(e.val_loss); });
  ASSERT_EQ(val.size(), 60u);
  EXPECT_EQ(r.final_val_loss, val.back());
  EXPECT_LT(r.final_val_loss, 0.05 * before);
  EXPECT_LT(r.final_train_loss, 0.05 * before);
  EXPECT_GT(r.seconds_per_epoch, 0.0);
}

TEST(Trainer, ReportsDivergenceAsNumericalError) {
  auto trajs = SyntheticTrajectories(10, 10, 7);
  trajs.trajectories[3].states(1, 4) = std::numeric_limits<double>::quiet_NaN();
  const Windows data = MakeWindows(trajs, 1);
  LearnedModel model = LearnedModel::Initialized({.type = LearnedKind::kAbsNn, .hidden = 8}, 3);
  Trainer trainer(&model, {.epochs = 2, .batch_size = 1000, .val_fraction = 0.0, .progress = false});
  try {
    trainer.Train(data);
    FAIL() << "NaN data trained without an error";
  } catch (const NumericalError& e) {
    EXPECT_NE(std::string(e.what()).find("epoch 1"), std::string::npos) << e.what();
  }
  EXPECT_THROW(Trainer(&model, {.learning_rate = -1.0}), Error);
  EXPECT_THROW(Trainer(&model, {.val_fraction = 1.0}), Error);
}

// Early stop: with a learning rate that makes the validation loss grow, training
// ends `patience` epochs after the best one.
TEST(Trainer, StopsEarlyWhenValidationStopsImproving) {
  const Windows data = MakeWindows(SyntheticTrajectories(20, 10, 9), 1);
  LearnedModel model = LearnedModel::Initialized({.type = LearnedKind::kAbsNn, .hidden = 8}, 5);
  Trainer trainer(&model, {.epochs = 50, .learning_rate = 0.5, .batch_size = 20, .patience = 2,
                           .progress = false});
  const TrainResult r = trainer.Train(data);
  ASSERT_TRUE(r.stopped_early) << r.epochs.size() << " epochs";
  ASSERT_GE(r.epochs.size(), 3u);
  const std::size_t last = r.epochs.size() - 1;
  double best = r.epochs[0].val_loss;
  for (std::size_t e = 0; e + 2 < r.epochs.size(); ++e) best = std::min(best, r.epochs[e].val_loss);
  EXPECT_GE(r.epochs[last].val_loss, best);
  EXPECT_GE(r.epochs[last - 1].val_loss, best);
  EXPECT_THROW(Trainer(&model, {.patience = -1}), Error);
}

TEST(EvaluateModel, MetricsFollowTheirDefinitions) {
  const Dataset data = SyntheticTrajectories(5, 10, 8);
  const auto& trajs = data.trajectories;
  LearnedModelConfig config{.type = LearnedKind::kAbsNn, .hidden = 8};
  config.system = PushingSystem();
  const LearnedModel model = LearnedModel::Initialized(config, 4);
  const Evaluation e = EvaluateModel(model, data, 2);
  EXPECT_EQ(e.n_samples, 50);
  EXPECT_EQ(e.n_windows, 35);
  // Single step and baseline by hand, one sample at a time through the templated path.
  double single = 0.0, baseline = 0.0;
  for (const auto& t : trajs) {
    for (int s = 0; s < t.transitions(); ++s) {
      const Eigen::Vector3d p = model.Predict(t.states.col(s), t.actions.col(s));
      single += StateLoss(data.system, p, t.states.col(s + 1), 1.0 / 50, nullptr);
      baseline += StateLoss(data.system, t.states.col(s), t.states.col(s + 1), 1.0 / 50, nullptr);
    }
  }
  EXPECT_NEAR(e.single_step_loss, single, 1e-12 * single);
  EXPECT_NEAR(e.baseline_single_step_loss, baseline, 1e-12 * baseline);
  std::vector<double> steps;
  RolloutLoss(model, MakeWindows(data, 4), 1.0, 1, 3, &steps);
  ASSERT_EQ(steps.size(), 4u);
  EXPECT_NEAR(e.avg_multi_step_loss, (steps[0] + steps[1] + steps[2] + steps[3]) / 4, 1e-12);
  // Rollouts drift: the first step of the windows is the single-step loss of their starts.
  EXPECT_GT(steps[3], 0.0);
  // A model of other sizes is refused, naming the data.
  const LearnedModel other = LearnedModel::Initialized(
      {.type = LearnedKind::kAbsNn, .hidden = 8, .system = SystemDescription::Unnamed(2, 1)}, 4);
  EXPECT_THROW(EvaluateModel(other, data), Error);
}

// dx/dt = -x + u: x(dt) = u + (x0 - u) exp(-dt), exact for the test's tolerance.
struct Relax {
  template <typename T>
  void operator()(const VectorX<T>& x, const VectorX<T>& u, const VectorX<T>&, double,
                  VectorX<T>& dxdt) const {
    dxdt = u - x;
  }
};

// A continuous-time model integrates each transition over its own interval: on
// irregularly sampled exact data its loss is at rounding level, while a model of
// the median interval alone is not.
TEST(EvaluateModel, PhysicsModelsIntegrateEachTransitionsOwnInterval) {
  Dataset data;
  data.system = SystemDescription::Unnamed(1, 1);
  data.path = "relax";
  Rng rng(3);
  for (int i = 0; i < 4; ++i) {
    Trajectory t;
    const int samples = 12;
    t.t.resize(samples);
    t.states.resize(1, samples);
    t.actions.resize(1, samples - 1);
    t.t[0] = 0.0;
    t.states(0, 0) = StandardNormal(rng);
    for (int k = 0; k + 1 < samples; ++k) {
      const double dt = 0.01 + 0.05 * UniformUnit(rng);
      t.actions(0, k) = StandardNormal(rng);
      t.t[k + 1] = t.t[k] + dt;
      t.states(0, k + 1) = t.actions(0, k) + (t.states(0, k) - t.actions(0, k)) * std::exp(-dt);
    }
    data.trajectories.push_back(t);
  }
  const SampleIntervals dt = data.Intervals();
  EXPECT_GT(dt.jitter(), 0.5);
  const ContinuousTransitionModel<Relax> model(Relax{}, data.system, Eigen::VectorXd(),
                                               {.method = Method::kRk4Classic, .dt = dt.median, .substeps = 8});
  const Evaluation e = EvaluateModel(model, data);
  EXPECT_LT(e.single_step_loss, 1e-14 * e.baseline_single_step_loss);
  // The same model at one fixed interval (PredictBatch) misses.
  const Windows single = MakeWindows(data, 1);
  auto ws = model.MakeWorkspace(single.size());
  Eigen::MatrixXd fixed(1, single.size());
  model.PredictBatch(single.start, single.actions[0], fixed, *ws);
  EXPECT_GT(StateLoss(data.system, fixed, single.targets[0], 1.0 / single.size(), nullptr),
            1e-6 * e.baseline_single_step_loss);
}

}  // namespace
}  // namespace diffdyn
