// The four learned kinds on systems other than pushing: a pendulum-like system
// (n = 2, m = 1, its angle seen as sin/cos) and a 5-state, 2-action system without
// angles. Batched = training = templated paths; parameter and state gradients =
// Jets = central differences (through the sin/cos features); periodicity in the
// encoded angle; the system recorded in model files.
#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <string>
#include <vector>

#include <ceres/jet.h>
#include <gtest/gtest.h>

#include "diffdyn/autodiff_ode/random.h"
#include "diffdyn/models/learned_model.h"

namespace diffdyn {
namespace {

using Jet = ceres::Jet<double, 2>;

SystemDescription PendulumLike() {
  SystemDescription s;
  s.name = "pendulum-like";
  s.state_names = {"q1", "qd1"};
  s.action_names = {"tau1"};
  s.angles = {0};
  s.angle_features = AngleFeatures::kSinCos;
  return s;
}

struct Case {
  LearnedKind type;
  bool pendulum;  // else 5 states, 2 actions, no angles
};

std::string CaseName(const ::testing::TestParamInfo<Case>& info) {
  std::string name = LearnedKindName(info.param.type);
  for (char& c : name) c = c == '-' ? '_' : c;
  return name.append(info.param.pendulum ? "_pendulum" : "_wide");
}

// A smooth (tanh) field, so that central differences see no kink.
LearnedModelConfig ConfigOf(const Case& c) {
  LearnedModelConfig config;
  config.type = c.type;
  config.method = Method::kRk4;
  config.steps = 4;
  config.hidden = 9;
  config.activation = Activation::Tanh();
  config.system = c.pendulum ? PendulumLike() : SystemDescription::Unnamed(5, 2);
  return config;
}

Eigen::MatrixXd Normal(int rows, int cols, Rng& rng) {
  Eigen::MatrixXd m(rows, cols);
  for (Eigen::Index i = 0; i < m.size(); ++i) m.data()[i] = StandardNormal(rng);
  return m;
}

class AnySystem : public ::testing::TestWithParam<Case> {};

TEST_P(AnySystem, BatchedTrainingAndTemplatedPathsAgree) {
  const LearnedModel model = LearnedModel::Initialized(ConfigOf(GetParam()), 5);
  const int n = model.state_size(), m = model.action_size(), b = 7;
  EXPECT_EQ(model.net().num_inputs(), model.system().feature_size());
  Rng rng(3);
  const Eigen::MatrixXd x = 2.0 * Normal(n, b, rng), u = Normal(m, b, rng);
  Eigen::MatrixXd batched(n, b), taped(n, b);
  auto ws = model.MakeWorkspace(b);
  model.PredictBatch(x, u, batched, *ws);
  model.Forward(x, u, taped, *ws);
  for (int j = 0; j < b; ++j) {
    const Eigen::VectorXd one = model.Predict(x.col(j), u.col(j));
    EXPECT_LT((batched.col(j) - one).cwiseAbs().maxCoeff(), 1e-12) << "sample " << j;
    EXPECT_LT((taped.col(j) - one).cwiseAbs().maxCoeff(), 1e-12) << "sample " << j;
  }
}

// L = <C, F(x, u)>: Backward's dL/dtheta against central differences along random
// directions, and dL/dx against Jets seeded in the state.
TEST_P(AnySystem, GradientsMatchJetsAndFiniteDifferences) {
  LearnedModel model = LearnedModel::Initialized(ConfigOf(GetParam()), 6);
  const int n = model.state_size(), m = model.action_size(), b = 5;
  Rng rng(4);
  const Eigen::MatrixXd x = 2.0 * Normal(n, b, rng), u = Normal(m, b, rng), c = Normal(n, b, rng);
  auto ws = model.MakeWorkspace(b);
  Eigen::MatrixXd next(n, b), dl_dx;
  model.Forward(x, u, next, *ws);
  Eigen::VectorXd grad = Eigen::VectorXd::Zero(model.num_parameters());
  model.Backward(c, *ws, &grad, &dl_dx);
  const auto loss = [&](const LearnedModel& mm) {
    Eigen::MatrixXd out(n, b);
    auto w = mm.MakeWorkspace(b);
    mm.PredictBatch(x, u, out, *w);
    return c.cwiseProduct(out).sum();
  };
  const double eps = 1e-6;
  for (int k = 0; k < 3; ++k) {
    const Eigen::VectorXd v = Normal(static_cast<int>(model.num_parameters()), 1, rng);
    LearnedModel plus = model, minus = model;
    plus.mutable_parameters() += eps * v;
    minus.mutable_parameters() -= eps * v;
    const double fd = (loss(plus) - loss(minus)) / (2 * eps);
    EXPECT_NEAR(grad.dot(v), fd, 1e-6 * std::max(1.0, std::abs(fd))) << "direction " << k;
  }
  for (int j = 0; j < b; ++j) {
    for (int i0 = 0; i0 < n; i0 += 2) {  // two state directions per Jet
      VectorX<Jet> xj(n), uj(m);
      for (int i = 0; i < n; ++i) xj[i] = Jet(x(i, j));
      for (int i = 0; i < m; ++i) uj[i] = Jet(u(i, j));
      for (int d = 0; d < 2 && i0 + d < n; ++d) xj[i0 + d].v[d] = 1.0;
      const VectorX<Jet> f = model.Predict(xj, uj);
      for (int d = 0; d < 2 && i0 + d < n; ++d) {
        double expected = 0.0;
        for (int r = 0; r < n; ++r) expected += c(r, j) * f[r].v[d];
        EXPECT_NEAR(dl_dx(i0 + d, j), expected, 1e-9 * std::max(1.0, std::abs(expected)))
            << "sample " << j << " state " << i0 + d;
      }
    }
  }
}

// With the angle seen as (sin, cos), shifting it by 2 pi changes no prediction but
// the angle itself, and that by a whole turn (0 for abs-nn, 2 pi for the others).
TEST_P(AnySystem, PeriodicInTheEncodedAngle) {
  if (!GetParam().pendulum) GTEST_SKIP() << "no encoded angle";
  const LearnedModel model = LearnedModel::Initialized(ConfigOf(GetParam()), 7);
  const Eigen::Vector2d x(0.7, -1.3);
  const Eigen::Matrix<double, 1, 1> u(0.4);
  const Eigen::VectorXd a = model.Predict(x, u);
  const Eigen::VectorXd b = model.Predict(Eigen::Vector2d(x[0] + 2 * std::numbers::pi, x[1]), u);
  const double turns = (b[0] - a[0]) / (2 * std::numbers::pi);
  EXPECT_NEAR(turns, std::round(turns), 1e-9);
  EXPECT_NEAR(b[1], a[1], 1e-9);
}

INSTANTIATE_TEST_SUITE_P(
    Kinds, AnySystem,
    ::testing::Values(Case{LearnedKind::kAbsNn, true}, Case{LearnedKind::kResNn, true},
                      Case{LearnedKind::kAbsNode, true}, Case{LearnedKind::kResNode, true},
                      Case{LearnedKind::kAbsNn, false}, Case{LearnedKind::kResNode, false}),
    CaseName);

TEST(LearnedModelFile, RecordsTheSystemAndReadsFilesWithoutOne) {
  const std::filesystem::path dir = ::testing::TempDir();
  const LearnedModel model =
      LearnedModel::Initialized(ConfigOf({LearnedKind::kResNode, /*pendulum=*/true}), 8);
  SaveLearnedModel(dir / "pendulum_res_node.json", model);
  const LearnedModel back = LoadLearnedModel(dir / "pendulum_res_node.json");
  EXPECT_TRUE(back.system().SameLayout(model.system()));
  EXPECT_EQ(back.system().name, "pendulum-like");
  EXPECT_TRUE(back.parameters() == model.parameters());
  const Eigen::Vector2d x(0.2, 0.1);
  const Eigen::Matrix<double, 1, 1> u(-0.5);
  EXPECT_EQ(back.Predict(x, u), model.Predict(x, u));

  // A file without "system" (as written before systems were recorded): 3 x 3, raw.
  LearnedModelConfig old;
  old.type = LearnedKind::kAbsNn;
  old.hidden = 4;
  const LearnedModel three = LearnedModel::Initialized(old, 9);
  SaveLearnedModel(dir / "old.json", three);
  std::ifstream in(dir / "old.json");
  nlohmann::json j = nlohmann::json::parse(in);
  j.erase("system");
  std::ofstream(dir / "old.json") << j.dump();
  const LearnedModel loaded = LoadLearnedModel(dir / "old.json");
  EXPECT_EQ(loaded.state_size(), 3);
  EXPECT_EQ(loaded.action_size(), 3);
  EXPECT_TRUE(loaded.system().angles.empty());

  // A system that does not fit the network is refused, naming the file.
  j["system"] = SystemToJson(PendulumLike());
  std::ofstream(dir / "mismatch.json") << j.dump();
  try {
    LoadLearnedModel(dir / "mismatch.json");
    FAIL() << "a 2-state system was accepted for a 3-state network";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("mismatch.json"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("2 states and 1 actions"), std::string::npos) << e.what();
  }
}

TEST(SystemDescription, ValidatesAndRoundTripsThroughJson) {
  SystemDescription s = PendulumLike();
  s.action_low = Eigen::VectorXd::Constant(1, -2.5);
  s.action_high = Eigen::VectorXd::Constant(1, 2.5);
  EXPECT_EQ(s.feature_size(), 4);
  const SystemDescription back = SystemFromJson(SystemToJson(s));
  EXPECT_TRUE(back.SameLayout(s));
  SystemDescription bad = s;
  bad.angles = {2};
  EXPECT_THROW(bad.Validate(), Error);
  bad = s;
  bad.action_low[0] = 3.0;
  EXPECT_THROW(bad.Validate(), Error);
  nlohmann::json j = SystemToJson(s);
  j["angle_features"] = "polar";
  EXPECT_THROW(SystemFromJson(j), Error);
}

}  // namespace
}  // namespace diffdyn
