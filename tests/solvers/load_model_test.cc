// LoadTransitionModel: one loader for learned files, extended-physics files,
// analytic names and the oracle; what each loads predicts like the model it names;
// one-line errors naming --model.
#include "diffdyn/solvers/load_model.h"

#include <filesystem>
#include <memory>
#include <string>

#include <gtest/gtest.h>

#include "diffdyn/models/learned_model.h"
#include "diffdyn/physics/effects.h"
#include "diffdyn/physics/model_registry.h"
#include "diffdyn/physics/simple_models.h"
#include "diffdyn/solvers/extended_model_file.h"

namespace diffdyn {
namespace {

// One transition of `model` from x under u.
Eigen::VectorXd Step(const TransitionModel& model, const Eigen::VectorXd& x, const Eigen::VectorXd& u) {
  auto ws = model.MakeWorkspace(1);
  Eigen::MatrixXd next(model.state_size(), 1);
  model.PredictBatch(x, u, next, *ws);
  return next.col(0);
}

void ExpectErrorMentions(const std::string& spec, const LoadModelOptions& options,
                         const std::string& words) {
  try {
    LoadTransitionModel(spec, options);
    FAIL() << spec << " was accepted";
  } catch (const Error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("--model"), std::string::npos) << what;
    EXPECT_NE(what.find(words), std::string::npos) << what;
    EXPECT_EQ(what.find('\n'), std::string::npos) << what;
  }
}

TEST(LoadTransitionModel, OpensLearnedFilesAndTheOracle) {
  const std::string path = ::testing::TempDir() + "/load_res_nn.json";
  LearnedModelConfig config;
  config.type = LearnedKind::kResNn;
  config.hidden = 5;
  const LearnedModel learned = LearnedModel::Initialized(config, 1);
  SaveLearnedModel(path, learned);
  const auto loaded = LoadTransitionModel(path);
  EXPECT_EQ(loaded->kind(), "res-nn");
  const Eigen::Vector3d x(0.5, 0.1, 0.2), u(0.3, -0.2, 0.7);
  EXPECT_EQ(Step(*loaded, x, u), Step(learned, x, u));
  const auto oracle = LoadTransitionModel("oracle");
  EXPECT_EQ(oracle->kind(), "oracle");
  EXPECT_EQ(oracle->state_size(), 3);
  // The ODE engine has no derivatives; the learned model does.
  Eigen::MatrixXd jac;
  EXPECT_FALSE(oracle->differentiable());
  EXPECT_THROW(oracle->Jacobian(x, u, &jac), Error);
  EXPECT_TRUE(loaded->differentiable());
  EXPECT_LT((loaded->Jacobian(x, u, &jac) - Step(learned, x, u)).cwiseAbs().maxCoeff(), 1e-12);
}

TEST(LoadTransitionModel, AnalyticNamesIntegrateTheirDefaultModel) {
  const double dt = 0.02;
  const auto loaded = LoadTransitionModel("pendulum", {.dt = dt});
  EXPECT_EQ(loaded->kind(), "pendulum");
  ASSERT_EQ(loaded->state_size(), 2);
  ASSERT_EQ(loaded->action_size(), 1);
  const AnalyticModelAdapter<PendulumModel> runtime;
  const ContinuousTransitionModel<AnalyticDynamics<PendulumModel>> direct(
      {}, AnalyticSystem(runtime), runtime.DefaultParams(), {.method = Method::kRk4Classic, .dt = dt, .substeps = 4});
  const Eigen::Vector2d x(0.6, -0.3);
  const Eigen::VectorXd u = Eigen::VectorXd::Constant(1, 0.4);
  EXPECT_LT((Step(*loaded, x, u) - Step(direct, x, u)).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_EQ(LoadTransitionModel("panda", {.dt = 0.004})->state_size(), 14);
}

TEST(LoadTransitionModel, OpensTheExtendedPhysicsFileDiagnoseWrites) {
  std::shared_ptr<const AnalyticModel> pendulum = MakeAnalyticModel("pendulum");
  const ExtendedModel extended(pendulum, pendulum->DefaultParams(),
                               {Effect{EffectKind::kViscous, 1, {0.8}, {0.01}}});
  const std::string path = ::testing::TempDir() + "/load_extended.json";
  SaveExtendedModel(path, extended);
  const auto loaded = LoadTransitionModel(path, {.dt = 0.05});
  EXPECT_EQ(loaded->kind(), "extended-physics");
  const auto nominal = LoadTransitionModel("pendulum", {.dt = 0.05});
  // Moving, the viscous friction slows the joint: qd falls more than without it.
  const Eigen::Vector2d x(0.0, 2.0);
  const Eigen::VectorXd u = Eigen::VectorXd::Zero(1);
  const Eigen::VectorXd with = Step(*loaded, x, u), without = Step(*nominal, x, u);
  EXPECT_LT(with[1], without[1] - 0.01);
  // The adapter integrates the extended model's own forward dynamics.
  ExtendedDynamics dynamics(std::make_shared<const ExtendedModel>(extended));
  Eigen::VectorXd dxdt;
  dynamics(Eigen::VectorXd(x), u, Eigen::VectorXd(), 0.0, dxdt);
  EXPECT_NEAR(dxdt[1], -0.8 * 2.0 / (1.0 * 0.5 * 0.5), 1e-12);  // -b qd / (m l^2) at q = 0
  // Its Jacobian by Jets: d(qd_next)/d(qd) against central differences.
  Eigen::MatrixXd jac;
  ASSERT_TRUE(loaded->differentiable());
  loaded->Jacobian(x, u, &jac);
  const double eps = 1e-6;
  const double fd = (Step(*loaded, x + Eigen::Vector2d(0, eps), u)[1] -
                     Step(*loaded, x - Eigen::Vector2d(0, eps), u)[1]) / (2 * eps);
  EXPECT_NEAR(jac(1, 1), fd, 1e-7);
}

TEST(LoadTransitionModel, ErrorsNameTheModel) {
  ExpectErrorMentions("pendulum", {}, "--dt");
  ExpectErrorMentions("no-such-model.json", {}, "no such file");
  const std::string mlp = ::testing::TempDir() + "/load_mlp.json";
  SaveMlp(mlp, Mlp<double>(MlpArchitecture{{2, 3, 1}, {Activation::Tanh()}}));
  ExpectErrorMentions(mlp, {.dt = 0.1}, "not a dynamics model");
  std::shared_ptr<const AnalyticModel> pendulum = MakeAnalyticModel("pendulum");
  const ExtendedModel delayed(pendulum, pendulum->DefaultParams(),
                              {Effect{EffectKind::kDelay, 0, {0.01}, {}}});
  const std::string path = ::testing::TempDir() + "/load_delayed.json";
  SaveExtendedModel(path, delayed);
  ExpectErrorMentions(path, {.dt = 0.1}, "delay");
}

}  // namespace
}  // namespace diffdyn
