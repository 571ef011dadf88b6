// The four learned models on the pushing layout (3 states, 3 actions): batched =
// training = templated paths, gradients of single- and multi-step losses = central
// finite differences = Jets, model files.
#include "diffdyn/models/learned_model.h"

#include <filesystem>
#include <fstream>
#include <string>
#include <tuple>
#include <vector>

#include <ceres/jet.h>
#include <gtest/gtest.h>

#include "diffdyn/models/random.h"

namespace diffdyn {
namespace {

constexpr int kDirections = 3;
using Jet = ceres::Jet<double, kDirections>;

struct Case {
  LearnedKind type;
  Method method;
};

std::string CaseName(const ::testing::TestParamInfo<Case>& info) {
  std::string name = LearnedKindName(info.param.type) + "_" + MethodName(info.param.method);
  for (char& c : name) {
    if (c == '-') c = '_';
  }
  return name;
}

LearnedModelConfig SmallConfig(const Case& c) {
  LearnedModelConfig config;
  config.type = c.type;
  config.method = c.method;
  config.hidden = 12;
  config.steps = 4;
  // dopri5 runs on a tanh field. A ReLU field has kinks that dopri5's error estimate
  // does not see, so even at 1e-12 its map is only piecewise smooth in theta with many
  // stages near a kink: central differences through it and odeint's Jets (other steps)
  // then differ from the adjoint by ~1e-4 relative. A smooth field and a tight
  // tolerance make all three agree to ~1e-7 through the adaptive step choice.
  if (TableauOf(c.method).adaptive) {
    config.activation = Activation::Tanh();
    config.tolerance = 1e-12;
  }
  return config;
}

// States and actions in the data's ranges.
void RandomBatch(int b, Rng& rng, Eigen::MatrixXd* states, Eigen::MatrixXd* actions) {
  states->resize(3, b);
  actions->resize(3, b);
  for (int j = 0; j < b; ++j) {
    (*states)(0, j) = 0.4 + 0.4 * UniformUnit(rng);
    (*states)(1, j) = -0.2 + 0.5 * UniformUnit(rng);
    (*states)(2, j) = -1.0 + 2.0 * UniformUnit(rng);
    (*actions)(0, j) = -1.0 + 2.0 * UniformUnit(rng);
    (*actions)(1, j) = -1.5 + 3.0 * UniformUnit(rng);
    (*actions)(2, j) = UniformUnit(rng);
  }
}

Eigen::MatrixXd RandomMatrix(int rows, int cols, Rng& rng) {
  Eigen::MatrixXd m(rows, cols);
  for (Eigen::Index i = 0; i < m.size(); ++i) m.data()[i] = StandardNormal(rng);
  return m;
}

class PushingModelTest : public ::testing::TestWithParam<Case> {};

TEST_P(PushingModelTest, BatchedForwardAndTemplatedPathsAgree) {
  const LearnedModelConfig config = SmallConfig(GetParam());
  const LearnedModel model = LearnedModel::Initialized(config, 3);
  Rng rng(11);
  Eigen::MatrixXd states, actions;
  RandomBatch(9, rng, &states, &actions);
  auto ws = model.MakeWorkspace(9);
  Eigen::MatrixXd predicted(3, 9), taped(3, 9);
  model.PredictBatch(states, actions, predicted, *ws);
  model.Forward(states, actions, taped, *ws);
  // odeint's dopri5 picks other steps (max norm) than the batched RMS controller.
  const double tol = TableauOf(config.method).adaptive ? 1e-10 : 1e-12;
  // PredictBatch runs the values-only products (Mlp::Evaluate), Forward the taped
  // ones: equal up to rounding.
  EXPECT_LT((predicted - taped).cwiseAbs().maxCoeff(), tol);
  for (int j = 0; j < 9; ++j) {
    const Eigen::Vector3d single =
        model.Predict(states.col(j), actions.col(j));
    for (int i = 0; i < 3; ++i) EXPECT_NEAR(predicted(i, j), single[i], tol) << i << "," << j;
  }
  // The prediction moved the state (the model is not trivially the identity or zero).
  EXPECT_GT((predicted - states).norm(), 1e-3);
}

// L(theta, X) = <C, F(X, U)>: its gradients from Backward, central differences and Jets.
TEST_P(PushingModelTest, SingleStepGradientsMatchFiniteDifferencesAndJets) {
  const LearnedModelConfig config = SmallConfig(GetParam());
  LearnedModel model = LearnedModel::Initialized(config, 5);
  Rng rng(12);
  const int b = 6;
  Eigen::MatrixXd states, actions;
  RandomBatch(b, rng, &states, &actions);
  const Eigen::MatrixXd c = RandomMatrix(3, b, rng);
  auto ws = model.MakeWorkspace(b);
  Eigen::MatrixXd next(3, b);
  model.Forward(states, actions, next, *ws);
  Eigen::VectorXd grad = Eigen::VectorXd::Zero(model.num_parameters());
  Eigen::MatrixXd dl_dx;
  model.Backward(c, *ws, &grad, &dl_dx);
  ASSERT_GT(grad.norm(), 0.0);

  auto loss = [&](const LearnedModel& m) {
    Eigen::MatrixXd out(3, b);
    auto w = m.MakeWorkspace(b);
    m.PredictBatch(states, actions, out, *w);
    return c.cwiseProduct(out).sum();
  };
  // Parameter directions v_k: FD and Jets of <C, F> along each.
  std::vector<Eigen::VectorXd> dirs;
  for (int k = 0; k < kDirections; ++k) dirs.push_back(RandomMatrix(model.num_parameters(), 1, rng));
  Mlp<Jet> jet_net = model.net().cast<Jet>();
  for (Eigen::Index i = 0; i < model.num_parameters(); ++i) {
    for (int k = 0; k < kDirections; ++k) jet_net.mutable_parameters()[i].v[k] = dirs[k][i];
  }
  Jet jet_loss(0.0);
  for (int j = 0; j < b; ++j) {
    const Eigen::Vector3d x = states.col(j), u = actions.col(j);
    const Eigen::Matrix<Jet, 3, 1> f = PredictLearned(jet_net, config, model.features(), model.output_map(), x, u);
    for (int i = 0; i < 3; ++i) jet_loss += c(i, j) * f[i];
  }
  const double eps = 1e-5;
  for (int k = 0; k < kDirections; ++k) {
    const double adjoint = grad.dot(dirs[k]);
    LearnedModel plus = model, minus = model;
    plus.mutable_parameters() += eps * dirs[k];
    minus.mutable_parameters() -= eps * dirs[k];
    const double fd = (loss(plus) - loss(minus)) / (2 * eps);
    const double scale = std::max(1.0, std::abs(adjoint));
    EXPECT_NEAR(adjoint, fd, 1e-5 * scale) << "direction " << k;
    EXPECT_NEAR(adjoint, jet_loss.v[k], 1e-6 * scale) << "direction " << k;
  }
  // State gradient against Jets seeded in the state.
  for (int j = 0; j < b; ++j) {
    Eigen::Matrix<ceres::Jet<double, 3>, 3, 1> x, u;
    for (int i = 0; i < 3; ++i) {
      x[i] = ceres::Jet<double, 3>(states(i, j), i);
      u[i] = ceres::Jet<double, 3>(actions(i, j));
    }
    const auto f = model.Predict(x, u);
    for (int i = 0; i < 3; ++i) {
      double expected = 0.0;
      for (int r = 0; r < 3; ++r) expected += c(r, j) * f[r].v[i];
      EXPECT_NEAR(dl_dx(i, j), expected, 1e-6 * std::max(1.0, std::abs(expected)));
    }
  }
}

// Four-step rollout x^_{k+1} = F(x^_k, u_k) with loss sum_k gamma^k <C_k, x^_{k+1}>:
// chained Backward (through dL/dx) = central differences = Jets through the rollout.
TEST_P(PushingModelTest, MultiStepRolloutGradientMatchesFiniteDifferencesAndJets) {
  const LearnedModelConfig config = SmallConfig(GetParam());
  LearnedModel model = LearnedModel::Initialized(config, 8);
  Rng rng(13);
  const int b = 4, horizon = 4;
  const double gamma = 0.9;
  Eigen::MatrixXd x0, unused;
  RandomBatch(b, rng, &x0, &unused);
  std::vector<Eigen::MatrixXd> actions(horizon), weights(horizon);
  for (int k = 0; k < horizon; ++k) {
    RandomBatch(b, rng, &unused, &actions[k]);
    weights[k] = std::pow(gamma, k) * RandomMatrix(3, b, rng);
  }
  std::vector<std::unique_ptr<TransitionWorkspace>> tapes;
  std::vector<Eigen::MatrixXd> xs(horizon + 1, Eigen::MatrixXd(3, b));
  xs[0] = x0;
  for (int k = 0; k < horizon; ++k) {
    tapes.push_back(model.MakeWorkspace(b));
    model.Forward(xs[k], actions[k], xs[k + 1], *tapes[k]);
  }
  Eigen::VectorXd grad = Eigen::VectorXd::Zero(model.num_parameters());
  Eigen::MatrixXd carry = Eigen::MatrixXd::Zero(3, b), dl_dx;
  for (int k = horizon - 1; k >= 0; --k) {
    const Eigen::MatrixXd g = weights[k] + carry;
    model.Backward(g, *tapes[k], &grad, &dl_dx);
    carry = dl_dx;
  }
  auto rollout_loss = [&](const LearnedModel& m) {
    Eigen::MatrixXd x = x0, nx(3, b);
    auto w = m.MakeWorkspace(b);
    double l = 0.0;
    for (int k = 0; k < horizon; ++k) {
      m.PredictBatch(x, actions[k], nx, *w);
      l += weights[k].cwiseProduct(nx).sum();
      x = nx;
    }
    return l;
  };
  std::vector<Eigen::VectorXd> dirs;
  for (int k = 0; k < kDirections; ++k) dirs.push_back(RandomMatrix(model.num_parameters(), 1, rng));
  Mlp<Jet> jet_net = model.net().cast<Jet>();
  for (Eigen::Index i = 0; i < model.num_parameters(); ++i) {
    for (int k = 0; k < kDirections; ++k) jet_net.mutable_parameters()[i].v[k] = dirs[k][i];
  }
  Jet jet_loss(0.0);
  for (int j = 0; j < b; ++j) {
    Eigen::Matrix<Jet, 3, 1> x;
    for (int i = 0; i < 3; ++i) x[i] = Jet(x0(i, j));
    for (int k = 0; k < horizon; ++k) {
      Eigen::Matrix<Jet, 3, 1> u;
      for (int i = 0; i < 3; ++i) u[i] = Jet(actions[k](i, j));
      x = PredictLearned(jet_net, config, model.features(), model.output_map(), x, u);
      for (int i = 0; i < 3; ++i) jet_loss += weights[k](i, j) * x[i];
    }
  }
  const double eps = 1e-5;
  for (int k = 0; k < kDirections; ++k) {
    const double adjoint = grad.dot(dirs[k]);
    LearnedModel plus = model, minus = model;
    plus.mutable_parameters() += eps * dirs[k];
    minus.mutable_parameters() -= eps * dirs[k];
    const double fd = (rollout_loss(plus) - rollout_loss(minus)) / (2 * eps);
    const double scale = std::max(1.0, std::abs(adjoint));
    EXPECT_NEAR(adjoint, fd, 1e-5 * scale) << "direction " << k;
    EXPECT_NEAR(adjoint, jet_loss.v[k], 1e-6 * scale) << "direction " << k;
  }
}

TEST_P(PushingModelTest, ModelFileRoundTripsBitExactly) {
  const LearnedModelConfig config = SmallConfig(GetParam());
  const LearnedModel model = LearnedModel::Initialized(config, 21);
  const std::filesystem::path path =
      std::filesystem::temp_directory_path() /
      ("diffdyn_pushing_" + LearnedKindName(config.type) + MethodName(config.method) + ".json");
  SaveLearnedModel(path, model, {{"seed", 21}}, {{"val_loss", 1e-4}});
  ModelFile contents;
  const LearnedModel back = LoadLearnedModel(path, &contents);
  EXPECT_EQ(back.kind(), model.kind());
  EXPECT_EQ(back.config().method, config.method);
  EXPECT_EQ(back.config().steps, config.steps);
  EXPECT_EQ(back.config().hidden, config.hidden);
  EXPECT_EQ((back.parameters() - model.parameters()).cwiseAbs().maxCoeff(), 0.0);
  EXPECT_EQ(contents.provenance["seed"], 21);
  std::filesystem::remove(path);
}

INSTANTIATE_TEST_SUITE_P(
    AllModels, PushingModelTest,
    ::testing::Values(Case{LearnedKind::kAbsNn, Method::kRk4},
                      Case{LearnedKind::kResNn, Method::kRk4},
                      Case{LearnedKind::kAbsNode, Method::kRk4},
                      Case{LearnedKind::kResNode, Method::kRk4},
                      Case{LearnedKind::kAbsNode, Method::kDopri5},
                      Case{LearnedKind::kResNode, Method::kDopri5},
                      Case{LearnedKind::kAbsNode, Method::kEuler},
                      Case{LearnedKind::kAbsNode, Method::kRk4Classic}),
    CaseName);

TEST(LearnedModel, RejectsInconsistentModelFiles) {
  const LearnedModel model = LearnedModel::Initialized({.type = LearnedKind::kResNode, .hidden = 8}, 1);
  const std::filesystem::path path = std::filesystem::temp_directory_path() / "diffdyn_bad_node.json";
  SaveLearnedModel(path, model);
  nlohmann::json j;
  std::ifstream(path) >> j;
  auto expect_rejected = [&](nlohmann::json bad, const std::string& fragment) {
    {
      std::ofstream out(path);
      out << bad.dump();
    }
    try {
      LoadLearnedModel(path);
      FAIL() << "accepted a file with " << fragment;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(path.string()), std::string::npos) << e.what();
    }
  };
  nlohmann::json bad = j;
  bad["architecture"]["hidden"] = 9;  // sizes say 8
  expect_rejected(bad, "does not match");
  bad = j;
  bad["architecture"]["solver"] = "rk5";
  expect_rejected(bad, "rk5");
  bad = j;
  bad["architecture"]["steps"] = 1;
  expect_rejected(bad, "'steps'");
  bad = j;
  bad["kind"] = "mlp";
  expect_rejected(bad, "kind 'mlp'");
  std::filesystem::remove(path);
}

TEST(LearnedModel, ParsesNamesAndRejectsUnknownOnes) {
  EXPECT_EQ(ParseLearnedKind("res-node"), LearnedKind::kResNode);
  EXPECT_TRUE(IsNeuralOde(LearnedKind::kAbsNode));
  EXPECT_FALSE(IsResidual(LearnedKind::kAbsNn));
  EXPECT_THROW(ParseLearnedKind("node"), Error);
  // The paper's parameter counts: 11,103 (NN, h = 100) and 11,406 (NODE).
  EXPECT_EQ(LearnedModel::Initialized({.type = LearnedKind::kAbsNn}, 0).num_parameters(), 11103);
  EXPECT_EQ(LearnedModel::Initialized({.type = LearnedKind::kAbsNode}, 0).num_parameters(), 11406);
}

}  // namespace
}  // namespace diffdyn
